//! Preview benchmarks (criterion): how long the sphere preview takes to draw on request
//! (`brdfd render`, `GET /fits/{id}/preview.png`).
//!
//! - `render/sphere`: one 256 × 256 sphere of a fitted material (per pixel: the model's lobe at
//!   the local angles, XYZ, sRGB before clipping).
//! - `render/preview_png`: the whole picture of one sample: three spheres, the 14 measured
//!   swatches and the captions, encoded as PNG — what the HTTP route answers.
//!
//! Run: `cargo bench --bench render -- --warm-up-time 1 --measurement-time 5`.

use std::hint::black_box;

use brdfd::cost::CostFunction;
use brdfd::fit::{FitRequest, fit_scan};
use brdfd::optimise::Settings;
use brdfd::render::{View, preview, render_sphere};
use brdfd::report::Study;
use brdfd::scan::Scan;
use criterion::{Criterion, criterion_group, criterion_main};

fn study() -> Study {
    let path = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/tests/data/t-freesia-pink.scan.json"
    );
    let scan = Scan::read_file(std::path::Path::new(path)).unwrap();
    let reports: Vec<_> = CostFunction::ALL
        .iter()
        .map(|&cost| {
            let request = FitRequest {
                processing: Default::default(),
                settings: Settings {
                    cost,
                    ..Settings::default()
                },
                ..FitRequest::default()
            };
            fit_scan(&scan, &request).unwrap()
        })
        .collect();
    Study::from_fit_reports(std::slice::from_ref(&scan), &[reports])
}

fn benches(c: &mut Criterion) {
    let study = study();
    let sample = &study.samples[0];
    let fit = sample.done(CostFunction::Cf2).unwrap();
    let mut group = c.benchmark_group("render");
    group.bench_function("sphere", |b| {
        b.iter(|| {
            render_sphere(
                black_box(&fit.params),
                fit.model,
                fit.fresnel,
                &View::default(),
            )
        })
    });
    group.bench_function("preview_png", |b| {
        b.iter(|| {
            preview(black_box(sample), &CostFunction::ALL)
                .unwrap()
                .png()
                .unwrap()
        })
    });
    group.finish();
}

criterion_group!(render, benches);
criterion_main!(render);
