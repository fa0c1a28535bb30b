//! Coverage of the held-out prediction intervals on the real MA-T12 exports (SCIENCE.md §10,
//! §12.3): for every export in `tests/data/real-mat12/` and `more/` and every cost function, the
//! fit, its leave-one-geometry-out jackknife (`brdfd::uncertainty::jackknife`), and for each of the 12
//! geometries whether the 95 % prediction interval of its L*, a* and b* (built without that
//! geometry's reading or error) contains the measured value. Also how many left-out refits land
//! outside the fit's parameter intervals: the bootstrap's alone (`--bootstrap N` resamples; 0,
//! the default, skips it) and the hull with the jackknife's that brdfd reports.
//!
//! `--files N` takes the first N exports in file-name order (the six of `real-mat12/`, then
//! `more/`); `--require P` (e.g. 0.85) exits non-zero when the L* coverage of any cost function
//! is below P, as CI runs it on a subset. `--fresnel exact|incidence|light-half` chooses the
//! Fresnel term (default the fit's default).
//!
//! Run: `cargo run --release -p brdfd-tools --bin heldout [-- --files 47 --costs cf1,cf2,m2
//! --bootstrap 0 --require 0]` (defaults shown). SCIENCE.md §10 quotes its output.

use std::path::Path;
use std::sync::atomic::AtomicBool;
use std::time::Instant;

use brdfd::colour::Colorimetry;
use brdfd::cost::CostFunction;
use brdfd::geometry::GEOMETRIES;
use brdfd::model::{FresnelCosine, Params};
use brdfd::optimise::Settings;
use brdfd::processing::MeasuredBrdf;
use brdfd::uncertainty::jackknife::{Jackknife, hull, jackknife};
use brdfd::uncertainty::{BootstrapOptions, Interval, PointFit, Uncertainty, draw};
use brdfd_tools::shared::{arg, real_exports};

/// The real exports, in file-name order: `real-mat12/` first, then `more/`.
fn exports() -> Vec<(String, MeasuredBrdf)> {
    real_exports(&Path::new(env!("CARGO_MANIFEST_DIR")).join("../tests/data/real-mat12"))
}

fn inside(v: f64, [lo, hi]: Interval) -> bool {
    lo <= v && v <= hi
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let files: usize = arg(&args, "--files", usize::MAX);
    let resamples: u32 = arg(&args, "--bootstrap", 0);
    let require: f64 = arg(&args, "--require", 0.0);
    let costs: String = arg(&args, "--costs", "cf1,cf2,m2".to_string());
    let costs: Vec<CostFunction> = costs
        .split(',')
        .map(|c| c.parse().expect("cost function"))
        .collect();
    let fresnel: FresnelCosine = arg(&args, "--fresnel", Settings::default().fresnel);
    let mut scans = exports();
    scans.truncate(files);
    let never = AtomicBool::new(false);
    let colorimetry = Colorimetry::default();
    println!(
        "held-out 95 % prediction intervals on {} real MA-T12 exports × 12 geometries, Fresnel {}, \
         colorimetry {colorimetry}; binomial s.e. of a coverage near 95 % over {} geometries: ±{:.1} %",
        scans.len(),
        fresnel.name(),
        12 * scans.len(),
        100.0 * (0.95 * 0.05 / (12 * scans.len()) as f64).sqrt()
    );
    println!(
        "| cost | L* | a* | b* | all three | median L* half-width | refits outside: bootstrap alone / reported (ks, α, μ) | at a bound | s per scan |"
    );
    println!("|---|---|---|---|---|---|---|---|---|");
    let mut per_geometry = vec![[0usize; 2]; GEOMETRIES.len()];
    let mut failed = Vec::new();
    for &cost in &costs {
        let settings = Settings {
            cost,
            fresnel,
            ..Settings::default()
        };
        let started = Instant::now();
        let (mut hits, mut n) = ([0usize; 4], 0usize);
        let mut half = Vec::new();
        let (mut out_boot, mut out_rep, mut params_seen) = (0usize, 0usize, 0usize);
        let mut bounded = 0usize;
        for (sample, m) in &scans {
            let fit = brdfd::optimise::fit(m, &settings)
                .unwrap_or_else(|e| panic!("{sample} {cost}: {e}"));
            let point = PointFit {
                measured: m,
                settings: &settings,
                colorimetry,
                params: &fit.params,
            };
            let jk: Jackknife = jackknife(point, &never).expect("jackknife");
            for (i, h) in jk.held_out.iter().enumerate() {
                let [l, a, b] = jk.prediction_interval(i).expect("11 other geometries");
                let got = [
                    inside(h.measured.l, l),
                    inside(h.measured.a, a),
                    inside(h.measured.b, b),
                ];
                for (c, g) in got.iter().enumerate() {
                    hits[c] += usize::from(*g);
                }
                hits[3] += usize::from(got.iter().all(|g| *g));
                per_geometry[h.geometry][0] += usize::from(got[0]);
                per_geometry[h.geometry][1] += 1;
                half.push((l[1] - l[0]) / 2.0);
                n += 1;
            }
            let boot = (resamples >= 2).then(|| {
                let opts = BootstrapOptions {
                    resamples,
                    seed: fit.seed,
                    threads: 2,
                    ..Default::default()
                };
                let d = draw(point, &opts, &never).expect("bootstrap");
                Uncertainty::from_draws(&d, &settings, m.geometries.has_sra(), &opts)
            });
            let misfit = jk.misfit(&fit.params, &settings.bounds);
            let of = |p: &Params| [p.ks, p.alpha, p.ior];
            for h in &jk.held_out {
                for (k, v) in of(&h.params).into_iter().enumerate() {
                    let jk_iv = [misfit.ks, misfit.alpha, misfit.ior][k];
                    let reported = match &boot {
                        Some(u) => hull([u.ks, u.alpha, u.ior][k], jk_iv),
                        None => jk_iv,
                    };
                    if let Some(u) = &boot {
                        out_boot += usize::from(!inside(v, [u.ks, u.alpha, u.ior][k]));
                    }
                    out_rep += usize::from(!inside(v, reported));
                    params_seen += 1;
                }
            }
            bounded += usize::from(
                !brdfd::uncertainty::jackknife::at_bound(&fit.params, &settings.bounds).is_empty(),
            );
        }
        half.sort_by(f64::total_cmp);
        let pct = |k: usize| 100.0 * k as f64 / n as f64;
        let boot_col = if resamples >= 2 {
            format!("{:.1} %", 100.0 * out_boot as f64 / params_seen as f64)
        } else {
            "—".to_string()
        };
        println!(
            "| {cost} | {:.1} % | {:.1} % | {:.1} % | {:.1} % | {:.2} | {boot_col} / {:.1} % | {bounded} of {} | {:.2} |",
            pct(hits[0]),
            pct(hits[1]),
            pct(hits[2]),
            pct(hits[3]),
            half[half.len() / 2],
            100.0 * out_rep as f64 / params_seen as f64,
            scans.len(),
            started.elapsed().as_secs_f64() / scans.len() as f64,
        );
        if pct(hits[0]) < 100.0 * require {
            failed.push(format!("{cost}: L* {:.1} %", pct(hits[0])));
        }
    }
    println!();
    println!("L* coverage per held-out geometry, all cost functions pooled:");
    println!("| geometry | L* |");
    println!("|---|---|");
    for (g, [h, n]) in per_geometry.iter().enumerate() {
        if *n > 0 {
            println!(
                "| {} | {:.1} % |",
                GEOMETRIES[g].name,
                100.0 * *h as f64 / *n as f64
            );
        }
    }
    if !failed.is_empty() {
        eprintln!(
            "held-out L* coverage below {:.0} %: {}",
            100.0 * require,
            failed.join("; ")
        );
        std::process::exit(1);
    }
}
