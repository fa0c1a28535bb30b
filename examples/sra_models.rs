//! The two SRA reading models against ground truth (SCIENCE.md §5.1): the
//! "flat vs luminance" table of SCIENCE.md §12.2.
//!
//! Trial `t` simulates the paper sample `t mod 8` (`brdfd::synth`) with multiplicative N(1, σ)
//! noise on every reading, seed `t`, once per SRA response of the simulated instrument (band
//! mean, the paper's assumption; luminance under illuminant C and the 2° V(λ), what a gloss
//! meter reads). The same scan is then fitted with each cost function under both SRA models
//! (`flat`, `luminance`; default method and seed), and per response, cost function and model
//! the table gives the means over the trials of:
//! - `ks`, `α`, `μ`: relative error of the fitted lobe against the truth, %;
//! - `ΔE00 diff`: mean ΔE00 over the 12 MA-T12 geometries against the measurement;
//! - `|ΔL*| meas`: specular |ΔL*| between model and measured luminance (illuminant C, 2°);
//! - `|ΔL*| true`: specular |ΔL*| between model and the true BRDF's luminance;
//! - `ΔE00 true`: specular ΔE00 between model and the true spectral BRDF;
//! - `ΔE00 paper`: the paper's specular metric, ΔE00 against the grey spectrum the reading is
//!   spread into.
//!
//! Run: `cargo run --release --example sra_models [-- --trials 40 --noise 0.01]` (defaults
//! shown). SCIENCE.md §12.2 quotes its output, BENCHMARKS.md its run time.

mod common;

use std::fmt::Write as _;
use std::time::Instant;

use brdfd::cost::CostFunction;
use brdfd::evaluation::evaluate;
use brdfd::fit::{FitRequest, fit_scan};
use brdfd::model::FresnelCosine;
use brdfd::optimise::Settings;
use brdfd::sra_reading::{SraReading, specular_delta_l};
use brdfd::synth::{SraResponse, SynthOptions, paper_samples, synth_scan};

use common::shared::arg;

/// Sums of the table's columns over the trials.
#[derive(Default, Clone, Copy)]
struct Row {
    ks: f64,
    alpha: f64,
    ior: f64,
    diffuse: f64,
    dl_measured: f64,
    dl_true: f64,
    de_true: f64,
    de_paper: f64,
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let trials: u64 = arg(&args, "--trials", 40);
    let noise: f64 = arg(&args, "--noise", 0.01);
    let started = Instant::now();
    let samples = paper_samples();
    let models = [SraReading::FLAT, SraReading::LUMINANCE];
    let mut out = String::new();
    let _ = writeln!(
        out,
        "{trials} scans (8 samples, noise σ = {noise}), means; errors of ks, α, μ in %"
    );
    let _ = writeln!(
        out,
        "| SRA response | cost | model | ks | α | μ | ΔE00 diff | \\|ΔL*\\| meas | \\|ΔL*\\| true | ΔE00 true | ΔE00 paper |"
    );
    let _ = writeln!(out, "|---|---|---|--:|--:|--:|--:|--:|--:|--:|--:|");
    for response in SraResponse::ALL {
        for cf in CostFunction::ALL {
            let mut rows = [Row::default(); 2];
            for t in 0..trials {
                let truth = &samples[(t % 8) as usize];
                let opts = SynthOptions {
                    noise,
                    seed: t,
                    sra_response: response,
                    ..SynthOptions::default()
                };
                let scan = synth_scan(truth, &opts).expect("synthetic scan");
                let true_brdf = truth.brdf(FresnelCosine::Incidence);
                for (row, sra) in rows.iter_mut().zip(models) {
                    let request = FitRequest {
                        settings: Settings {
                            cost: cf,
                            sra,
                            ..Settings::default()
                        },
                        ..FitRequest::default()
                    };
                    let r = fit_scan(&scan, &request).expect("fit");
                    let (p, q) = (&r.outcome.params, &truth.params);
                    let rel = |a: f64, b: f64| 100.0 * (a - b).abs() / b;
                    row.ks += rel(p.ks, q.ks);
                    row.alpha += rel(p.alpha, q.alpha);
                    row.ior += rel(p.ior, q.ior);
                    row.diffuse += r.evaluation.diffuse.mean;
                    row.dl_measured += r.specular_delta_l.unwrap().mean;
                    row.dl_true += specular_delta_l(&true_brdf, &r.estimated, sra).mean;
                    row.de_true += evaluate(&true_brdf, &r.estimated).specular.unwrap().mean;
                    row.de_paper += r.evaluation.specular.unwrap().mean;
                }
            }
            for (row, sra) in rows.iter().zip(models) {
                let n = trials as f64;
                let _ = writeln!(
                    out,
                    "| {response} | {cf} | {} | {:.2} | {:.2} | {:.2} | {:.3} | {:.3} | {:.3} | {:.2} | {:.2} |",
                    sra.model,
                    row.ks / n,
                    row.alpha / n,
                    row.ior / n,
                    row.diffuse / n,
                    row.dl_measured / n,
                    row.dl_true / n,
                    row.de_true / n,
                    row.de_paper / n
                );
            }
        }
    }
    print!("{out}");
    println!(
        "{} fits in {:.1} s",
        trials as usize * 2 * 3 * 2,
        started.elapsed().as_secs_f64()
    );
}
