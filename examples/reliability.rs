//! Reliability harness for the optimiser (SCIENCE.md §6: "a fit that ends far from the best
//! cost reachable is a defect").
//!
//! Over every synthetic scan — the 16 example scans in `tests/data/` (eight paper-style samples,
//! noise-free and with 1 % noise, processed as the CLI does) and the optimiser's own 6
//! ColorChecker cases (noise-free and 1 % noise) — × 3 cost functions × N seeds, fits with both methods and takes the best cost any run found
//! as the reference. Checks that the default (separable) method ends within 1 % of it every
//! time, and counts how often the paper GA does not. Exits non-zero on any separable miss.
//!
//! Run: `cargo run --release --example reliability [-- --seeds N]` (default 10 seeds).

use std::process::ExitCode;
use std::time::Instant;

use brdfd::cost::CostFunction;
use brdfd::model::FresnelCosine;
use brdfd::optimise::{Method, Settings, fit, synthetic};
use brdfd::processing::{MeasuredBrdf, ProcessingOptions, process};
use brdfd::scan::Scan;

/// Every scan the harness fits: (label, noise, measured BRDF).
fn scans() -> Vec<(String, f64, MeasuredBrdf)> {
    let mut out = Vec::new();
    let data = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data");
    let mut files: Vec<_> = std::fs::read_dir(&data)
        .expect("tests/data holds the example scans")
        .map(|e| e.expect("readable tests/data entry").path())
        .filter(|p| p.to_string_lossy().ends_with(".scan.json"))
        .collect();
    files.sort();
    for path in files {
        let scan = Scan::read_file(&path).expect("example scans are valid");
        let noise = if path.to_string_lossy().ends_with(".noisy.scan.json") {
            0.01
        } else {
            0.0
        };
        let m = process(&scan, &ProcessingOptions::default()).expect("example scans process");
        out.push((scan.sample.clone(), noise, m));
    }
    for case in synthetic::cases() {
        let clean = synthetic::measured(&case.truth, FresnelCosine::Incidence);
        out.push((case.patch.to_string(), 0.0, clean));
        out.push((
            case.patch.to_string(),
            0.01,
            synthetic::with_noise(&clean, 0.01, 1),
        ));
    }
    out
}

/// "Within 1 % of the best".
const TOLERANCE: f64 = 1.01;

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().collect();
    let seeds: u64 = match args.iter().position(|a| a == "--seeds") {
        Some(i) => match args.get(i + 1).and_then(|s| s.parse().ok()) {
            Some(n) if n > 0 => n,
            _ => {
                eprintln!("reliability: --seeds needs a positive integer");
                return ExitCode::FAILURE;
            }
        },
        None => 10,
    };

    let started = Instant::now();
    let (mut runs, mut separable_misses, mut paper_misses) = (0u32, 0u32, 0u32);
    let (mut separable_ms, mut paper_ms) = (0.0, 0.0);
    let (mut separable_evals, mut paper_evals) = (0u64, 0u64);
    let mut worst_separable: f64 = 1.0;
    println!(
        "{:<20} {:>5} {:>4} {:>13} {:>10} {:>10} {:>10} {:>7}",
        "sample", "noise", "cost", "best", "sep worst", "paper med", "paper max", "p miss"
    );
    let scans = scans();
    for (label, noise, m) in &scans {
        {
            for cf in CostFunction::ALL {
                let mut sep = Vec::new();
                let mut paper = Vec::new();
                for seed in 0..seeds {
                    for method in Method::ALL {
                        let s = Settings {
                            cost: cf,
                            method,
                            seed,
                            ..Settings::default()
                        };
                        let out = fit(m, &s).expect("synthetic scans are valid");
                        match method {
                            Method::Separable => {
                                separable_ms += out.wall_ms;
                                separable_evals += out.evaluations;
                                sep.push(out.cost);
                            }
                            Method::Paper => {
                                paper_ms += out.wall_ms;
                                paper_evals += out.evaluations;
                                paper.push(out.cost);
                            }
                        }
                    }
                }
                let best = sep
                    .iter()
                    .chain(paper.iter())
                    .copied()
                    .fold(f64::INFINITY, f64::min);
                let sep_worst = sep.iter().copied().fold(0.0, f64::max) / best;
                let mut paper_ratio: Vec<f64> = paper.iter().map(|c| c / best).collect();
                paper_ratio.sort_by(f64::total_cmp);
                let sep_miss = sep.iter().filter(|&&c| c > best * TOLERANCE).count() as u32;
                let paper_miss = paper.iter().filter(|&&c| c > best * TOLERANCE).count() as u32;
                runs += seeds as u32;
                separable_misses += sep_miss;
                paper_misses += paper_miss;
                worst_separable = worst_separable.max(sep_worst);
                println!(
                    "{:<20} {:>4}% {:>4} {:>13.6e} {:>10.6} {:>10.4} {:>10.4} {:>4}/{:<2}{}",
                    label,
                    noise * 100.0,
                    cf,
                    best,
                    sep_worst,
                    paper_ratio[paper_ratio.len() / 2],
                    paper_ratio[paper_ratio.len() - 1],
                    paper_miss,
                    seeds,
                    if sep_miss > 0 {
                        "  SEPARABLE MISSED"
                    } else {
                        ""
                    }
                );
            }
        }
    }
    println!();
    println!(
        "fits per method: {runs} ({} scans × 3 cost functions × {seeds} seeds)",
        scans.len()
    );
    println!(
        "separable: {separable_misses} of {runs} fits more than 1 % above the best; worst \
         ratio {worst_separable:.6}; mean {:.2} ms, {} evaluations per fit",
        separable_ms / runs as f64,
        separable_evals / runs as u64
    );
    println!(
        "paper GA:  {paper_misses} of {runs} fits more than 1 % above the best; mean {:.2} ms, \
         {} evaluations per fit",
        paper_ms / runs as f64,
        paper_evals / runs as u64
    );
    println!("total {:.1} s", started.elapsed().as_secs_f64());
    if separable_misses > 0 {
        ExitCode::FAILURE
    } else {
        ExitCode::SUCCESS
    }
}
