//! The report's statistics on the demo data (the eight example scans of `tests/data/`, fitted
//! under all three cost functions with the default method) match a direct computation: the
//! 95 % t interval from the textbook formula, and the sign test from an exact binomial sum in
//! integers.

mod common;

use brdfd::optimise::Settings;
use brdfd::report::{Analysis, Study};
use brdfd::scan::Scan;
use statrs::distribution::{ContinuousCDF, StudentsT};

use common::fit_every_cost;

const SCANS: [&str; 8] = [
    include_str!("data/t-freesia-pink.noisy.scan.json"),
    include_str!("data/t-prairie-green.noisy.scan.json"),
    include_str!("data/t-manzana-green.noisy.scan.json"),
    include_str!("data/t-mandarin-orange.noisy.scan.json"),
    include_str!("data/t-saffron-yellow.noisy.scan.json"),
    include_str!("data/t-lavender-blue.noisy.scan.json"),
    include_str!("data/t-sky-blue.noisy.scan.json"),
    include_str!("data/t-pebble-grey.noisy.scan.json"),
];

fn demo_study() -> Study {
    let scans: Vec<Scan> = SCANS
        .iter()
        .map(|t| Scan::from_json(t.as_bytes()).unwrap())
        .collect();
    let reports: Vec<Vec<_>> = scans
        .iter()
        .map(|scan| fit_every_cost(scan, Settings::default()))
        .collect();
    Study::from_fit_reports(&scans, &reports)
}

/// C(n, 0) + … + C(n, k), exactly.
fn binomial_sum(n: u32, k: u32) -> u128 {
    let mut sum = 0u128;
    let mut c = 1u128;
    for i in 0..=k {
        if i > 0 {
            c = c * u128::from(n - i + 1) / u128::from(i);
        }
        sum += c;
    }
    sum
}

#[test]
fn sign_tests_and_confidence_intervals_match_a_direct_computation() {
    let study = demo_study();
    let a = Analysis::of(&study);
    assert_eq!(a.included.len(), 8, "every demo fit finishes");
    assert!(a.excluded.is_empty());

    for s in &a.per_cost {
        let xs: Vec<f64> = study
            .samples
            .iter()
            .map(|x| x.done(s.cost).unwrap().evaluation.all.mean)
            .collect();
        let n = xs.len() as f64;
        let mean = xs.iter().sum::<f64>() / n;
        let sd = (xs.iter().map(|x| (x - mean) * (x - mean)).sum::<f64>() / (n - 1.0)).sqrt();
        let t = StudentsT::new(0.0, 1.0, n - 1.0)
            .unwrap()
            .inverse_cdf(0.975);
        // t(0.975, 7) from the tables.
        assert!((t - 2.364624).abs() < 1e-6, "{t}");
        let half = t * sd / n.sqrt();
        let ci = s.all.unwrap();
        assert_eq!(ci.n, 8);
        assert!((ci.mean - mean).abs() < 1e-12, "{}", s.cost);
        assert!((ci.half_width - half).abs() < 1e-12, "{}", s.cost);
        assert!((ci.lo - (mean - half)).abs() < 1e-12 && (ci.hi - (mean + half)).abs() < 1e-12);
    }

    assert_eq!(a.sign_tests.len(), 3);
    for row in &a.sign_tests {
        let (mut plus, mut minus, mut ties) = (0u32, 0u32, 0u32);
        for s in &study.samples {
            let da = s.done(row.a).unwrap().evaluation.per_geometry;
            let db = s.done(row.b).unwrap().evaluation.per_geometry;
            for g in 0..14 {
                if da[g] > db[g] {
                    plus += 1;
                } else if da[g] < db[g] {
                    minus += 1;
                } else {
                    ties += 1;
                }
            }
        }
        let n = plus + minus;
        let k = plus.min(minus);
        let p = (2.0 * binomial_sum(n, k) as f64 / 2f64.powi(n as i32)).min(1.0);
        let t = row.test;
        assert_eq!(
            (t.n, t.plus, t.minus, t.ties),
            (n as usize, plus as usize, minus as usize, ties as usize),
            "{} vs {}",
            row.a,
            row.b
        );
        assert_eq!(t.n + t.ties, 8 * 14);
        assert!(
            (t.p - p).abs() <= 1e-12 * p.max(1e-300),
            "{} vs {}: {} vs {p}",
            row.a,
            row.b,
            t.p
        );
        eprintln!(
            "{} vs {}: n {n}, + {plus}, − {minus}, ties {ties}, p {p:.6}",
            row.a, row.b
        );
    }
}
