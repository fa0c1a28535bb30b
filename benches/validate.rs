//! `brdfd validate` benchmark (criterion): the whole validation of one measured BRDF — every
//! fit of the 14 readings (three cost functions × model options: 17 fits), the oracles, Lambert
//! and the prediction of every direction (SCIENCE.md §12.6).
//!
//! - `validate/astm_1561`: a generated spectral ASTM E1392 file on the project's sampled grid
//!   (θi 10–70° every 10°, θs 0–80° every 5°, φs 0–180° every 15°, plus the 14 instrument
//!   geometries: 1,561 directions, about the size of a Cornell measurement) of a material the
//!   model cannot represent (brdfd's model plus a second, sharper lobe), so the fits and the
//!   oracles work as hard as on real gloss. The target is ≤ 2 s on one core, release.
//!
//! Run: `cargo bench --bench validate -- --warm-up-time 1 --measurement-time 20`.

use std::hint::black_box;

use brdfd::geometry::Vec3;
use brdfd::gonio::Measurement;
use brdfd::gonio::astm::AstmFile;
use brdfd::gonio::validate::{Options, validate_with, variants};
use brdfd::model::{EXTRA, FresnelCosine, ModelKind, Params, evaluate_at};
use brdfd::spectral::BANDS;
use criterion::{Criterion, criterion_group, criterion_main};

fn material(wi: Vec3, wo: Vec3) -> Vec<f64> {
    let base = Params {
        kd: std::array::from_fn(|b| 0.02 + 0.1 * (-((b as f64 - 8.0) / 6.0).powi(2)).exp()),
        ks: 0.3,
        alpha: 0.15,
        ior: 1.5,
        extra: [0.0; EXTRA],
    };
    let sharp = Params {
        kd: [0.0; BANDS],
        ks: 0.4,
        alpha: 0.04,
        ..base
    };
    let lobe = evaluate_at(&sharp, ModelKind::Paper, FresnelCosine::Exact, wi, wo)[0];
    evaluate_at(&base, ModelKind::Paper, FresnelCosine::Exact, wi, wo)
        .iter()
        .map(|v| v + lobe)
        .collect()
}

fn bench(c: &mut Criterion) {
    let file = AstmFile::sampled("two-lobe coat", "generated", &material);
    let m = Measurement::parse(file.write().as_bytes()).expect("the generated file reads back");
    let opts = Options::default();
    let variants = variants();
    let mut g = c.benchmark_group("validate");
    g.sample_size(10);
    g.bench_function("astm_1561", |b| {
        b.iter(|| black_box(validate_with(&m, &opts, &variants).expect("validates")))
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
