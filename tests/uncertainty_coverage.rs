//! The bootstrap intervals are calibrated, not decorative (SCIENCE.md §10): a reduced, debug-build
//! check beside `examples/coverage.rs` (whose full output, 200 trials × 3 cost functions × 200
//! resamples under each SRA model, is in SCIENCE.md §12.3, and which CI runs in release for cf1, cf2
//! and m2 under the luminance SRA model). Here: cf1 under the paper's flat SRA model (simulated
//! SRA reading the band mean), 40 trials (the 8 example samples × 5 noise draws, 1 % noise per
//! reading), 50 resamples each.
//!
//! Checks, per lobe parameter: the 95 % intervals contain the truth in at least 80 % of the
//! trials (a 95 % interval misses that often with probability below 0.001 at n = 40), and they
//! are about as wide as the estimates actually scatter: the median relative width is within a
//! factor 2.5 of 5.81 × the median absolute relative error of the point estimates (for normal
//! errors, 3.92 σ = 5.81 × the median of |error|; medians, because a few fits land far off —
//! the heavy tail SCIENCE.md §10 discusses).

use std::sync::atomic::AtomicBool;

use brdfd::cost::CostFunction;
use brdfd::fit::{FitRequest, fit_scan};
use brdfd::optimise::Settings;
use brdfd::synth::{SynthOptions, paper_samples, synth_scan};
use brdfd::uncertainty::{BootstrapOptions, bootstrap};

#[test]
fn cf1_intervals_cover_the_truth_and_match_the_scatter() {
    let samples = paper_samples();
    let never = AtomicBool::new(false);
    let trials = 40u64;
    let mut hits = [0u32; 3];
    let mut widths: [Vec<f64>; 3] = Default::default();
    let mut errors: [Vec<f64>; 3] = Default::default();
    for t in 0..trials {
        let truth = &samples[(t % 8) as usize];
        let scan = synth_scan(
            truth,
            &SynthOptions {
                noise: 0.01,
                seed: 1000 + t,
                ..Default::default()
            },
        )
        .unwrap();
        let request = FitRequest {
            settings: Settings {
                cost: CostFunction::Cf1,
                ..Settings::default()
            },
            ..FitRequest::default()
        };
        let report = fit_scan(&scan, &request).unwrap();
        let u = bootstrap(
            &report.measured,
            &request.settings,
            request.colorimetry,
            &report.outcome.params,
            &BootstrapOptions {
                resamples: 50,
                seed: t,
                threads: 2,
                noise: None,
            },
            &never,
        )
        .unwrap();
        let p = &report.outcome.params;
        let want = &truth.params;
        for (k, (name, estimate, value, iv)) in [
            ("ks", p.ks, want.ks, u.ks),
            ("alpha", p.alpha, want.alpha, u.alpha),
            ("ior", p.ior, want.ior, u.ior),
        ]
        .into_iter()
        .enumerate()
        {
            hits[k] += u32::from(u.contains(name, value));
            widths[k].push((iv[1] - iv[0]) / value);
            errors[k].push(((estimate - value) / value).abs());
        }
    }
    let n = trials as f64;
    let median = |xs: &mut Vec<f64>| {
        xs.sort_by(f64::total_cmp);
        0.5 * (xs[xs.len() / 2 - 1] + xs[xs.len() / 2])
    };
    for (k, name) in ["ks", "alpha", "ior"].into_iter().enumerate() {
        let coverage = f64::from(hits[k]) / n;
        let width = median(&mut widths[k]);
        let scatter = 5.81 * median(&mut errors[k]);
        eprintln!(
            "cf1 {name}: coverage {:.1} %, median relative width {width:.4}, 5.81 × median |error| {scatter:.4}",
            100.0 * coverage
        );
        assert!(
            coverage >= 0.8,
            "{name}: 95 % intervals hold the truth in only {:.0} % of {trials} trials",
            100.0 * coverage
        );
        assert!(
            width > scatter / 2.5 && width < scatter * 2.5,
            "{name}: intervals {width:.4} wide (relative) against a scatter of {scatter:.4}"
        );
    }
}
