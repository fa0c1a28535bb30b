//! Calibration of the bootstrap intervals (SCIENCE.md §10): how often the 95 % intervals of
//! ks, α, μ and kd per band contain the true values, on synthetic scans from a known truth with
//! the documented noise model, per cost function and SRA reading model.
//!
//! Trial `t` simulates the paper sample `t mod 8` (`brdfd::synth`) with multiplicative N(1, σ)
//! noise on every reading (sample and reference), noise and bootstrap seed `first seed + t`, and
//! a simulated SRA that reads what the SRA model assumes (`--sra luminance`: the luminance;
//! `--sra flat`: the band mean; or `--sra-response` to mismatch them); fits it with each cost
//! function (default method and settings, that SRA model) and bootstraps the fit as the daemon
//! does; then records, per cost function and parameter, whether the interval holds the truth,
//! and the median interval width relative to the truth. kd is summarised by the lowest coverage
//! over the 31 bands and the mean over them. The binomial sampling error of a coverage p over n
//! trials, √(p(1 − p)/n), is printed at p = 95 %.
//!
//! `--require P` (e.g. 0.9) makes the run exit non-zero when any cell (ks, α, μ, or any kd
//! band) of any cost function covers less than P: CI runs it that way, on noise draws
//! (`--first-seed 10000`) other than those the calibration table was measured on (seeds 0–199).
//! `--refit warm-start|full-search` overrides how every cost function refits (the default is
//! the daemon's, `brdfd::uncertainty::Refit::for_cost`); `--dump FILE` writes one JSON line per
//! trial with the truth, the point fit and every refit's parameters, to study other interval
//! constructions on the same draws.
//!
//! `--fresnel exact|incidence|light-half` is the Fresnel factor of both the synthetic truth and
//! the fits (the paper's `incidence` by default). `--sra-weight paper|balanced` weighs the SRA
//! readings in every cost function (SCIENCE.md §5.2); by default each cost function is fitted
//! with the measured preset's weight under `--sra luminance` (balanced for cf1 and m2) and the
//! paper's under `--sra flat`, what the daemon does under each preset.
//!
//! Run: `cargo run --release -p brdfd-tools --bin coverage [-- --trials 200 --resamples 200
//! --noise 0.01 --costs cf1,cf2,m2 --sra luminance --fresnel incidence --threads 2
//! --first-seed 0 --require 0.9]`
//! (defaults shown, but for `--require`, off by default). SCIENCE.md §12.3 quotes its output.

use std::io::Write;
use std::sync::atomic::AtomicBool;
use std::time::Instant;

use brdfd::cost::CostFunction;
use brdfd::fit::{FitRequest, fit_scan};
use brdfd::model::FresnelCosine;
use brdfd::optimise::{Preset, Settings};
use brdfd::processing::{ProcessingOptions, process};
use brdfd::scan::Scan;
use brdfd::spectral::BANDS;
use brdfd::sra_reading::{SraModel, SraReading, SraWeight};
use brdfd::synth::{SraResponse, SynthOptions, paper_samples, synth_scan};
use brdfd::uncertainty::{BootstrapOptions, Refit, Uncertainty, draw};
use brdfd_tools::shared::arg;

/// `scan` as an MA-T12-only scan: its 12 processed spectra (the readings' noise included) as
/// the instrument's own reflectance factors, no reference tile, no SRA readings.
fn ma_t12_only(scan: &Scan) -> Scan {
    let m = process(scan, &ProcessingOptions::default()).expect("processing");
    let mut out = scan.clone();
    out.reference = None;
    out.readings.sra = None;
    for (g, values) in out.readings.ma_t12.iter_mut().enumerate() {
        *values = m.values[g].map(|f| f * std::f64::consts::PI);
    }
    out
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let trials: u64 = arg(&args, "--trials", 200);
    let resamples: u32 = arg(&args, "--resamples", 200);
    let noise: f64 = arg(&args, "--noise", 0.01);
    let threads: usize = arg(&args, "--threads", 2);
    let require: f64 = arg(&args, "--require", 0.0);
    let sra: SraModel = arg(&args, "--sra", SraModel::Luminance);
    let matched = match sra {
        SraModel::Flat => SraResponse::BandMean,
        SraModel::Luminance => SraResponse::Luminance,
    };
    let response: SraResponse = arg(&args, "--sra-response", matched);
    let no_sra = args.iter().any(|a| a == "--no-sra");
    let fresnel: FresnelCosine = arg(&args, "--fresnel", FresnelCosine::Incidence);
    let sra_weight: Option<SraWeight> = args
        .iter()
        .position(|a| a == "--sra-weight")
        .and_then(|i| args.get(i + 1))
        .map(|v| v.parse().unwrap_or_else(|e| panic!("--sra-weight: {e}")));
    let weight_of = |cf: CostFunction| {
        sra_weight.unwrap_or(match sra {
            SraModel::Luminance => Preset::Measured.sra_weight(cf),
            SraModel::Flat => SraWeight::Paper,
        })
    };
    let first_seed: u64 = arg(&args, "--first-seed", 0);
    let refit = match arg(&args, "--refit", "by-cost".to_string()).as_str() {
        "by-cost" => Refit::ByCost,
        "warm-start" => Refit::WarmStart,
        "full-search" => Refit::FullSearch,
        other => panic!("--refit: {other:?} is not by-cost, warm-start or full-search"),
    };
    // `--dump FILE`: one JSON line per trial with the truth, the point fit and every draw.
    let mut dump = args
        .iter()
        .position(|a| a == "--dump")
        .and_then(|i| args.get(i + 1))
        .map(|f| std::io::BufWriter::new(std::fs::File::create(f).expect("create --dump file")));
    let costs: String = arg(&args, "--costs", "cf1,cf2,m2".to_string());
    let costs: Vec<CostFunction> = costs
        .split(',')
        .map(|c| c.parse().expect("cost function"))
        .collect();
    let samples = paper_samples();
    let never = AtomicBool::new(false);
    let started_all = Instant::now();
    let se = (0.95 * 0.05 / trials as f64).sqrt();
    println!(
        "coverage of the 95 % bootstrap intervals: {trials} trials (the 8 example samples in turn), \
         noise σ = {noise} per reading, seeds {first_seed}–{}, {resamples} resamples, {}, Fresnel {fresnel}; sampling error of a coverage near 95 %: ±{:.1} % (1 s.e.)",
        first_seed + trials - 1,
        if no_sra {
            "MA-T12-only scans (12 geometries, no SRA readings)".to_string()
        } else {
            let weights: Vec<String> = costs
                .iter()
                .map(|&cf| format!("{cf} {}", weight_of(cf)))
                .collect();
            format!(
                "SRA model {sra}, simulated SRA reads the {response}, SRA weight {}",
                weights.join(", ")
            )
        },
        100.0 * se
    );
    println!(
        "| cost | ks | α | μ | kd lowest band | kd mean | median width ks / α / μ (relative to truth) | bootstrap s per fit |"
    );
    println!("|---|---|---|---|---|---|---|---|");
    let mut failed = Vec::new();
    for &cf in &costs {
        let mut hits = [0u64; 3];
        let mut kd_hits = [0u64; BANDS];
        let mut widths: [Vec<f64>; 3] = Default::default();
        let mut seconds = 0.0;
        for t in 0..trials {
            let truth = &samples[(t % 8) as usize];
            let scan = synth_scan(
                truth,
                &SynthOptions {
                    noise,
                    seed: first_seed + t,
                    sra_response: response,
                    fresnel,
                    ..Default::default()
                },
            )
            .expect("synthetic scan");
            let scan = if no_sra { ma_t12_only(&scan) } else { scan };
            let request = FitRequest {
                settings: Settings {
                    cost: cf,
                    sra: SraReading::default()
                        .with_model(sra)
                        .with_weight(weight_of(cf)),
                    fresnel,
                    ..Settings::default()
                },
                ..FitRequest::default()
            };
            let report = fit_scan(&scan, &request).expect("fit");
            let started = Instant::now();
            let opts = BootstrapOptions {
                resamples,
                seed: first_seed + t,
                threads,
                noise: None,
                refit,
            };
            let draws = draw(report.point_fit(), &opts, &never).expect("bootstrap");
            let u = Uncertainty::from_draws(
                &draws,
                &request.settings,
                report.measured.geometries.has_sra(),
                &opts,
            );
            if let Some(out) = dump.as_mut() {
                let line = serde_json::json!({
                    "cost": cf.to_string(),
                    "seed": first_seed + t,
                    "sigma": draws.sigma,
                    "truth": truth.params,
                    "point": report.outcome.params,
                    "draws": draws.draws.iter().map(|d| d.params).collect::<Vec<_>>(),
                });
                writeln!(out, "{line}").expect("write --dump");
            }
            seconds += started.elapsed().as_secs_f64();
            let p = &truth.params;
            for (k, (name, v, iv)) in [
                ("ks", p.ks, u.ks),
                ("alpha", p.alpha, u.alpha),
                ("ior", p.ior, u.ior),
            ]
            .into_iter()
            .enumerate()
            {
                if u.contains(name, v) {
                    hits[k] += 1;
                }
                widths[k].push((iv[1] - iv[0]) / v);
            }
            for (b, iv) in u.kd.iter().enumerate() {
                if iv[0] <= p.kd[b] && p.kd[b] <= iv[1] {
                    kd_hits[b] += 1;
                }
            }
        }
        let share = |h: u64| h as f64 / trials as f64;
        let pct = |h: u64| format!("{:.1} %", 100.0 * share(h));
        let med = |w: &mut Vec<f64>| {
            w.sort_by(f64::total_cmp);
            w[w.len() / 2]
        };
        let (low_band, low) = kd_hits
            .iter()
            .enumerate()
            .min_by_key(|(_, h)| **h)
            .map(|(b, h)| (b, *h))
            .expect("31 bands");
        let kd_mean = kd_hits.iter().sum::<u64>() as f64 / (BANDS as f64 * trials as f64);
        let [w0, w1, w2] = &mut widths;
        println!(
            "| {cf} | {} | {} | {} | {} ({} nm) | {:.1} % | {:.2} / {:.2} / {:.3} | {:.3} |",
            pct(hits[0]),
            pct(hits[1]),
            pct(hits[2]),
            pct(low),
            400 + 10 * low_band,
            100.0 * kd_mean,
            med(w0),
            med(w1),
            med(w2),
            seconds / trials as f64
        );
        for (name, h) in [("ks", hits[0]), ("α", hits[1]), ("μ", hits[2]), ("kd", low)] {
            if share(h) < require {
                failed.push(format!("{cf} {name} {}", pct(h)));
            }
        }
    }
    println!(
        "{:.0} s wall for the whole run",
        started_all.elapsed().as_secs_f64()
    );
    if !failed.is_empty() {
        eprintln!(
            "coverage below {:.0} %: {}",
            100.0 * require,
            failed.join(", ")
        );
        std::process::exit(1);
    }
}
