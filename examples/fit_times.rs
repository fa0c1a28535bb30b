//! Fit times on the eight example scans (`tests/data/`, the paper samples of
//! `brdfd::synth::paper_samples`, noise-free and with 1 % noise), default method and settings,
//! one thread: the speed targets (cf2 ≤ 10 ms, m2 ≤ 5 ms median on one core; BENCHMARKS.md).
//!
//! Each scan is fitted `--reps` times per cost function; a scan's time is the median of its
//! repetitions (machine noise), and the table gives the median and maximum over the scans.
//!
//! Run: `cargo run --release --example fit_times [-- --reps 5 --costs cf1,cf2,m2]`. With
//! `--reps 1` it is also the driver for `valgrind --tool=callgrind`, whose instruction counts
//! do not depend on what else the machine is doing.

mod common;

use std::time::Instant;

use brdfd::cost::CostFunction;
use brdfd::optimise::{Settings, fit};

use common::shared::{arg, example_scans};

fn median(xs: &mut [f64]) -> f64 {
    xs.sort_by(f64::total_cmp);
    let n = xs.len();
    if n % 2 == 1 {
        xs[n / 2]
    } else {
        0.5 * (xs[n / 2 - 1] + xs[n / 2])
    }
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let reps: usize = arg(&args, "--reps", 5);
    let costs: String = arg(&args, "--costs", "cf1,cf2,m2".to_string());
    let costs: Vec<CostFunction> = costs
        .split(',')
        .map(|c| c.parse().expect("cost function"))
        .collect();
    let data = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data");
    let scans = example_scans(&data);
    println!(
        "fit times, default method and settings, one thread, median of {reps} repetitions per scan"
    );
    println!("| cost | scans | median ms | max ms | evaluations per fit |");
    println!("|---|---|---|---|---|");
    for &cf in &costs {
        let settings = Settings {
            cost: cf,
            ..Settings::default()
        };
        for (label, noisy) in [("noise-free", false), ("1 % noise", true)] {
            let mut per_scan = Vec::new();
            let mut evals = 0u64;
            for s in scans.iter().filter(|s| s.noisy == noisy) {
                let mut times = Vec::with_capacity(reps);
                for _ in 0..reps {
                    let started = Instant::now();
                    let out = fit(&s.measured, &settings).expect("fit");
                    times.push(started.elapsed().as_secs_f64() * 1e3);
                    evals += out.evaluations;
                }
                per_scan.push(median(&mut times));
            }
            let n = per_scan.len();
            let max = per_scan.iter().copied().fold(0.0, f64::max);
            println!(
                "| {cf} | {n} {label} | {:.2} | {:.2} | {} |",
                median(&mut per_scan),
                max,
                evals / (n * reps) as u64
            );
        }
    }
}
