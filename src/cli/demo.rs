//! `brdfd demo`: the main job on the embedded default — fit the eight example scans (synthetic,
//! 1 % noise, from `tests/data/`) with all three cost functions and compare them as the paper
//! does: mean ΔE00 per sample and cost function (diffuse and specular), the mean over samples
//! with its 95 % confidence interval, and sign tests between cost functions (SCIENCE.md §8).

use std::fmt::Write as _;

use anyhow::Context;

use crate::cost::CostFunction;
use crate::fit::{FitReport, FitRequest, fit_scan};
use crate::optimise::{Method, Settings};
use crate::scan::Scan;
use crate::stats::{mean_ci95, sign_test};

/// The embedded example scans: (file name, document).
pub const EXAMPLE_SCANS: [(&str, &str); 8] = [
    (
        "t-freesia-pink.noisy.scan.json",
        include_str!("../../tests/data/t-freesia-pink.noisy.scan.json"),
    ),
    (
        "t-prairie-green.noisy.scan.json",
        include_str!("../../tests/data/t-prairie-green.noisy.scan.json"),
    ),
    (
        "t-manzana-green.noisy.scan.json",
        include_str!("../../tests/data/t-manzana-green.noisy.scan.json"),
    ),
    (
        "t-mandarin-orange.noisy.scan.json",
        include_str!("../../tests/data/t-mandarin-orange.noisy.scan.json"),
    ),
    (
        "t-saffron-yellow.noisy.scan.json",
        include_str!("../../tests/data/t-saffron-yellow.noisy.scan.json"),
    ),
    (
        "t-lavender-blue.noisy.scan.json",
        include_str!("../../tests/data/t-lavender-blue.noisy.scan.json"),
    ),
    (
        "t-sky-blue.noisy.scan.json",
        include_str!("../../tests/data/t-sky-blue.noisy.scan.json"),
    ),
    (
        "t-pebble-grey.noisy.scan.json",
        include_str!("../../tests/data/t-pebble-grey.noisy.scan.json"),
    ),
];

/// The embedded example scans, parsed.
pub fn example_scans() -> anyhow::Result<Vec<Scan>> {
    EXAMPLE_SCANS
        .iter()
        .map(|(name, text)| {
            Scan::from_json(text.as_bytes()).with_context(|| format!("embedded scan {name}"))
        })
        .collect()
}

#[derive(Debug, clap::Args)]
pub struct DemoArgs {
    /// Optimiser for every fit (see `brdfd fit --help`).
    #[arg(long, value_name = "NAME", default_value_t = Method::default())]
    pub method: Method,

    /// Seed of every fit.
    #[arg(long, value_name = "N", default_value_t = Settings::default().seed)]
    pub seed: u64,
}

/// Every fit of the demo: `fits[sample][cost function]`, cost functions in [`CostFunction::ALL`] order.
pub fn fit_all(scans: &[Scan], method: Method, seed: u64) -> anyhow::Result<Vec<Vec<FitReport>>> {
    scans
        .iter()
        .map(|scan| {
            CostFunction::ALL
                .iter()
                .map(|&cost| {
                    let request = FitRequest {
                        settings: Settings {
                            method,
                            cost,
                            seed,
                            ..Settings::default()
                        },
                        ..FitRequest::default()
                    };
                    Ok(fit_scan(scan, &request)?)
                })
                .collect()
        })
        .collect()
}

pub fn run(args: &DemoArgs) -> anyhow::Result<()> {
    let scans = example_scans()?;
    let fits = fit_all(&scans, args.method, args.seed)?;
    print!("{}", summary(&fits, args.method, args.seed));
    Ok(())
}

/// The demo's printed report.
pub fn summary(fits: &[Vec<FitReport>], method: Method, seed: u64) -> String {
    let mut t = String::new();
    let _ = writeln!(
        t,
        "{} example scans (synthetic, 1 % noise) × {} cost functions, method {method}, seed {seed}",
        fits.len(),
        CostFunction::ALL.len()
    );
    let _ = writeln!(t, "mean ΔE00 between measured and fitted colour per sample");
    let _ = writeln!(
        t,
        "{:<20} {:<4} {:>9} {:>9} {:>9} {:>10} {:>9}",
        "sample", "cost", "diffuse", "specular", "all", "cost value", "wall ms"
    );
    for sample in fits {
        for r in sample {
            let e = &r.evaluation;
            let _ = writeln!(
                t,
                "{:<20} {:<4} {:>9.3} {:>9.3} {:>9.3} {:>10.3e} {:>9.1}",
                r.sample,
                r.request.settings.cost.name(),
                e.diffuse.mean,
                e.specular.mean,
                e.all.mean,
                r.outcome.cost,
                r.outcome.wall_ms
            );
        }
    }
    let _ = writeln!(
        t,
        "over samples: mean of the per-sample means, 95 % CI (Student t)"
    );
    for (k, cost) in CostFunction::ALL.iter().enumerate() {
        let ci = |pick: fn(&FitReport) -> f64| {
            let xs: Vec<f64> = fits.iter().map(|s| pick(&s[k])).collect();
            match mean_ci95(&xs) {
                Some(c) => format!("{:.3} ± {:.3}", c.mean, c.half_width),
                None => "n/a".to_string(),
            }
        };
        let _ = writeln!(
            t,
            "  {:<4} diffuse {}   specular {}   all {}",
            cost.name(),
            ci(|r| r.evaluation.diffuse.mean),
            ci(|r| r.evaluation.specular.mean),
            ci(|r| r.evaluation.all.mean)
        );
    }
    let _ = writeln!(
        t,
        "sign tests on paired ΔE00 per (sample, geometry), ties dropped"
    );
    let paired = |k: usize| -> Vec<f64> {
        fits.iter()
            .flat_map(|s| s[k].evaluation.per_geometry)
            .collect()
    };
    for (a, b) in [(0, 1), (0, 2), (1, 2)] {
        let st = sign_test(&paired(a), &paired(b));
        let _ = writeln!(
            t,
            "  {} vs {}: {} pairs, {} lower with {}, {} lower with {}, p = {}",
            CostFunction::ALL[a],
            CostFunction::ALL[b],
            st.n,
            st.minus,
            CostFunction::ALL[a],
            st.plus,
            CostFunction::ALL[b],
            format_p(st.p)
        );
    }
    t
}

/// A p-value readably: three decimals, or scientific notation below 0.001.
fn format_p(p: f64) -> String {
    if p < 1e-3 {
        format!("{p:.1e}")
    } else {
        format!("{p:.3}")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn embedded_scans_parse_and_are_the_eight_samples() {
        let scans = example_scans().unwrap();
        let names: Vec<&str> = scans.iter().map(|s| s.sample.as_str()).collect();
        let truths: Vec<String> = crate::synth::paper_samples()
            .into_iter()
            .map(|t| t.sample)
            .collect();
        assert_eq!(names, truths);
    }
}
