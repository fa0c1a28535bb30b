//! What the paper's model does on real materials: the six real MA-T12 measurements in
//! `tests/data/real-mat12/` (X-Rite's QC exports; painted marble mock-ups), each fitted under
//! the three cost functions with the default method over its 12 geometries, normalised by the
//! instrument's own calibration (SCIENCE.md §3).
//!
//! Prints, per cost function and geometry, the mean and largest ΔE00 over the samples and the
//! mean signed ΔL* (fitted − measured: positive where the model is too bright), then the same
//! by leave-one-geometry-out prediction: fit 11 of the 12 geometries, predict the 12th, so that
//! a model cannot win by reproducing readings it was fitted to.
//!
//! Run: `cargo run --release --example real_fits [-- DIR]` (DIR: other `.xlsx` exports; by
//! default the committed six). Colorimetry: D65, 10° observer, ASTM E308 weighting, as
//! X-Rite's software reports the files' L*a*b*.

use std::path::PathBuf;

use brdfd::colour::{Colorimetry, Observer, Weighting};
use brdfd::cost::CostFunction;
use brdfd::evaluation::{evaluate_with, lab_per_geometry_with};
use brdfd::geometry::{GEOMETRIES, GeometrySet, MA_T12_COUNT};
use brdfd::model::{self, SpecularGeometry};
use brdfd::optimise::{Settings, fit};
use brdfd::processing::{MeasuredBrdf, ProcessingOptions, process};

fn main() {
    let dir = std::env::args()
        .nth(1)
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/data/real-mat12"));
    let mut files: Vec<PathBuf> = std::fs::read_dir(&dir)
        .unwrap_or_else(|e| panic!("cannot read {}: {e}", dir.display()))
        .map(|e| e.expect("readable entry").path())
        .filter(|p| {
            p.extension()
                .is_some_and(|e| e.eq_ignore_ascii_case("xlsx"))
        })
        .collect();
    files.sort();
    let mut scans: Vec<(String, MeasuredBrdf)> = Vec::new();
    for path in &files {
        for x in brdfd::formats::xrite::read_file(path)
            .unwrap_or_else(|e| panic!("{}: {e}", path.display()))
        {
            let m = process(&x.scan, &ProcessingOptions::default()).expect("a real scan processes");
            scans.push((x.scan.sample.clone(), m));
        }
    }
    let colorimetry = Colorimetry {
        observer: Observer::Cie1964TenDegree,
        weighting: Weighting::AstmE308,
    };
    println!(
        "{} real MA-T12 measurements from {}; colorimetry {colorimetry}; default method",
        scans.len(),
        dir.display()
    );
    for cost in CostFunction::ALL {
        // Per geometry: ΔE00 and signed ΔL* of each sample, fitted to all 12 and held out.
        let mut de = vec![Vec::new(); MA_T12_COUNT];
        let mut dl = vec![Vec::new(); MA_T12_COUNT];
        let mut de_out = vec![Vec::new(); MA_T12_COUNT];
        let mut dl_out = vec![Vec::new(); MA_T12_COUNT];
        let mut means = Vec::new();
        for (_, m) in &scans {
            let settings = Settings {
                cost,
                ..Settings::default()
            };
            let out = fit(m, &settings).expect("a real scan fits");
            let est = model::evaluate(&out.params, settings.fresnel, &SpecularGeometry::all());
            let e = evaluate_with(&m.values, &est, colorimetry, m.geometries);
            means.push(e.all.mean);
            let lab_m = lab_per_geometry_with(&m.values, colorimetry);
            let lab_e = lab_per_geometry_with(&est, colorimetry);
            for g in 0..MA_T12_COUNT {
                de[g].push(e.per_geometry[g]);
                dl[g].push(lab_e[g].l - lab_m[g].l);
            }
            for g in 0..MA_T12_COUNT {
                let held = MeasuredBrdf {
                    geometries: GeometrySet::MA_T12.without(g),
                    ..*m
                };
                let out = fit(&held, &settings).expect("11 geometries fit");
                let est = model::evaluate(&out.params, settings.fresnel, &SpecularGeometry::all());
                let e = evaluate_with(&m.values, &est, colorimetry, m.geometries);
                let lab_e = lab_per_geometry_with(&est, colorimetry);
                de_out[g].push(e.per_geometry[g]);
                dl_out[g].push(lab_e[g].l - lab_m[g].l);
            }
        }
        let mean = |xs: &[f64]| xs.iter().sum::<f64>() / xs.len() as f64;
        let max = |xs: &[f64]| xs.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        println!();
        println!(
            "{cost}: mean ΔE00 over geometries and samples {:.3} fitted, {:.3} held out",
            mean(&means),
            mean(&de_out.concat())
        );
        println!(
            "  {:<8} {:>9} {:>9} {:>11}   {:>9} {:>9} {:>11}",
            "geometry", "ΔE00 mean", "ΔE00 max", "ΔL* fit−m", "held mean", "held max", "held ΔL*"
        );
        for g in 0..MA_T12_COUNT {
            println!(
                "  {:<8} {:>9.3} {:>9.3} {:>+11.3}   {:>9.3} {:>9.3} {:>+11.3}",
                GEOMETRIES[g].name,
                mean(&de[g]),
                max(&de[g]),
                mean(&dl[g]),
                mean(&de_out[g]),
                max(&de_out[g]),
                mean(&dl_out[g])
            );
        }
    }
}
