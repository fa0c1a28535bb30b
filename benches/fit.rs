//! Fit benchmarks (criterion): how long one scan takes to fit, and the floor under that.
//!
//! - `fit/<cost>`: the default (separable) method on one synthetic 14-geometry scan with 1 %
//!   noise, for each cost function. Targets: cf2 ≤ 10 ms and m2 ≤ 5 ms median on
//!   one core, release. A cf2 fit includes its continuation stages (cf1, then weighted L1;
//!   `optimise::separable`), which are what make it reliable (2 405 evaluations over the three
//!   stages). BENCHMARKS.md ("Fitting") quotes the figures; `examples/fit_times.rs` times the
//!   eight example scans.
//! - `fit_paper/cf2`: the paper GA with its default settings on the same scan (fewer samples:
//!   it is slow, which is part of the point).
//! - `bootstrap/all_costs_200`: the bootstrap intervals (SCIENCE.md §10) of the three fits of the
//!   same scan, 200 resamples each, on 2 threads — the target is ≤ 2 s wall.
//!   `bootstrap/<cost>_200`: one cost function's, on one thread.
//! - `crossval/<scan>_<fresnel>`: a scan's full set, one core — the three cost functions, each
//!   fitted to every reading and once per MA-T12 geometry held out (39 fits; SCIENCE.md §12.5,
//!   `brdfd crossval`): on the real export `tests/data/real-mat12/PAR_PW_RO_NG_1.xlsx` (12
//!   geometries) and on the synthetic scan (14). The target is ≤ 2 s.
//! - `cost_eval/<cost>`: one model evaluation (14 specular terms, 434 values) plus one cost,
//!   through the public API — the price of one GA individual.
//!
//! Run: `cargo bench --bench fit -- --warm-up-time 1 --measurement-time 5`.

use std::hint::black_box;

use brdfd::colour::Colorimetry;
use brdfd::cost::{CostFunction, cost};
use brdfd::crossval::crossval_measured;
use brdfd::fit::FitRequest;
use brdfd::model::{FresnelCosine, SpecularGeometry, evaluate};
use brdfd::optimise::{Method, Settings, fit, synthetic};
use brdfd::uncertainty::{BootstrapOptions, bootstrap};
use criterion::{Criterion, criterion_group, criterion_main};
use std::sync::atomic::AtomicBool;

fn scan() -> (brdfd::processing::MeasuredBrdf, brdfd::model::Params) {
    // "orange" with ks 0.3, α 0.25, μ 1.6.
    let truth = synthetic::cases()[2].truth;
    let m = synthetic::with_noise(
        &synthetic::measured(&truth, FresnelCosine::Incidence),
        0.01,
        1,
    );
    (m, truth)
}

fn benches(c: &mut Criterion) {
    let (m, truth) = scan();

    let mut group = c.benchmark_group("fit");
    for cf in CostFunction::ALL {
        let settings = Settings {
            cost: cf,
            ..Settings::default()
        };
        let out = fit(&m, &settings).expect("fit");
        eprintln!(
            "fit/{cf}: {} evaluations, {} generations, cost {:.6e}",
            out.evaluations, out.generations, out.cost
        );
        group.bench_function(cf.name(), |b| {
            b.iter(|| fit(black_box(&m), &settings).unwrap())
        });
    }
    group.finish();

    let mut group = c.benchmark_group("fit_paper");
    group.sample_size(10);
    let settings = Settings {
        cost: CostFunction::Cf2,
        method: Method::Paper,
        ..Settings::default()
    };
    let out = fit(&m, &settings).expect("fit");
    eprintln!(
        "fit_paper/cf2: {} evaluations, {} generations, cost {:.6e}",
        out.evaluations, out.generations, out.cost
    );
    group.bench_function("cf2", |b| b.iter(|| fit(black_box(&m), &settings).unwrap()));
    group.finish();

    let mut group = c.benchmark_group("bootstrap");
    group.sample_size(10);
    let never = AtomicBool::new(false);
    let points: Vec<(Settings, brdfd::model::Params)> = CostFunction::ALL
        .iter()
        .map(|&cf| {
            let settings = Settings {
                cost: cf,
                ..Settings::default()
            };
            let p = fit(&m, &settings).expect("fit").params;
            (settings, p)
        })
        .collect();
    let run = |(settings, p): &(Settings, brdfd::model::Params), threads| {
        let opts = BootstrapOptions {
            resamples: 200,
            threads,
            ..BootstrapOptions::default()
        };
        bootstrap(
            black_box(&m),
            settings,
            Colorimetry::default(),
            p,
            &opts,
            &never,
        )
        .unwrap()
    };
    for point in &points {
        group.bench_function(format!("{}_200", point.0.cost), |b| {
            b.iter(|| run(point, 1))
        });
    }
    group.bench_function("all_costs_200", |b| {
        b.iter(|| points.iter().map(|p| run(p, 2)).collect::<Vec<_>>())
    });
    group.finish();

    let mut group = c.benchmark_group("crossval");
    group.sample_size(10);
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data/real-mat12/PAR_PW_RO_NG_1.xlsx");
    let real = brdfd::formats::xrite::read_file(&path, &Default::default())
        .expect("the committed real export")[0]
        .scan
        .clone();
    let real = brdfd::processing::process(&real, &Default::default()).expect("processes");
    for (name, measured) in [("real", &real), ("synthetic", &m)] {
        for fresnel in [FresnelCosine::Incidence, FresnelCosine::Exact] {
            let full_set = || {
                CostFunction::ALL.map(|cost| {
                    let request = FitRequest {
                        settings: Settings {
                            cost,
                            fresnel,
                            ..Settings::default()
                        },
                        ..FitRequest::default()
                    };
                    crossval_measured("bench", "N9", black_box(measured), &request).unwrap()
                })
            };
            for cv in full_set() {
                eprintln!(
                    "crossval/{name}_{}: {} held-out mean ΔE00 {:.4} (fitted {:.4})",
                    fresnel.name(),
                    cv.cost,
                    cv.held_out_mean,
                    cv.fitted_mean
                );
            }
            group.bench_function(format!("{name}_{}", fresnel.name()), |b| b.iter(full_set));
        }
    }
    group.finish();

    let geos = SpecularGeometry::all();
    let mut group = c.benchmark_group("cost_eval");
    for cf in CostFunction::ALL {
        group.bench_function(cf.name(), |b| {
            b.iter(|| {
                let model = evaluate(black_box(&truth), FresnelCosine::Incidence, &geos);
                cost(cf, black_box(&m), &model)
            })
        });
    }
    group.finish();
}

criterion_group! {
    name = fit_benches;
    // No HTML plots: the figures that matter are printed, and plotting needs system fonts.
    config = Criterion::default().without_plots();
    targets = benches
}
criterion_main!(fit_benches);
