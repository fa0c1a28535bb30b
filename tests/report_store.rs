//! From the store to the report and the exchange formats: three scans with their fits (one
//! sample's m2 fit failed) are written through the store's verbs into a file store; the study
//! loaded back holds the same scans and fits, leaves the failed sample out of the comparison,
//! and `brdfd report`, `brdfd export-format` and `brdfd import-format` work on it end to end.

use std::path::Path;
use std::process::Command;

use brdfd::cost::CostFunction;
use brdfd::fit::{FitRequest, fit_scan};
use brdfd::geometry::{Device, GEOMETRIES, MA_T12_COUNT};
use brdfd::optimise::Settings;
use brdfd::report::load::{Selection, from_store};
use brdfd::report::{Analysis, FitState};
use brdfd::scan::Scan;
use brdfd::store::{FitResult, NewFit, ReadingValues, Store};
use brdfd::synth::{SynthOptions, paper_samples, synth_scan};

fn values(readings: &brdfd::scan::DeviceReadings, g: &brdfd::geometry::Geometry) -> ReadingValues {
    match g.device {
        Device::MaT12 => ReadingValues::Spectrum(readings.ma_t12[g.index]),
        Device::Sra => ReadingValues::Intensity(readings.sra[g.index - MA_T12_COUNT]),
    }
}

/// Three synthetic scans (1 % noise) stored with fits under cf1, cf2, m2; the third sample's
/// m2 fit fails.
async fn fill(path: &Path) -> Vec<Scan> {
    let store = Store::open(path).await.unwrap();
    let mut scans = Vec::new();
    for (i, truth) in paper_samples().iter().take(3).enumerate() {
        let scan = synth_scan(
            truth,
            &SynthOptions {
                noise: 0.01,
                seed: i as u64,
                ..SynthOptions::default()
            },
        )
        .unwrap();
        let r = store
            .begin_reference(&scan.reference.name, None)
            .await
            .unwrap();
        for g in &GEOMETRIES {
            store
                .add_reference_reading(r, g.device, g, &values(&scan.reference.readings, g), b"")
                .await
                .unwrap();
        }
        store.complete_reference(r).await.unwrap();
        let id = store.request_scan(&scan.sample, r).await.unwrap();
        store.start_measuring(id).await.unwrap();
        for g in &GEOMETRIES {
            store
                .add_reading(id, g.device, g, &values(&scan.readings, g), b"")
                .await
                .unwrap();
        }
        store.complete_scan(id).await.unwrap();
        let request = FitRequest::default();
        let measured = brdfd::processing::process(&scan, &request.processing).unwrap();
        let p = store
            .add_processed(id, request.processing.specular, &measured)
            .await
            .unwrap();
        for cost in CostFunction::ALL {
            let settings = Settings {
                cost,
                ..Settings::default()
            };
            let fit = store
                .queue_fit(
                    p,
                    &NewFit {
                        method: settings.method.to_string(),
                        cost_function: cost,
                        settings: serde_json::to_value(settings).unwrap(),
                        seed: settings.seed,
                    },
                )
                .await
                .unwrap();
            store.start_fit(fit).await.unwrap();
            if i == 2 && cost == CostFunction::M2 {
                store.fail_fit(fit, "optimiser diverged").await.unwrap();
                continue;
            }
            let report = fit_scan(
                &scan,
                &FitRequest {
                    settings,
                    ..FitRequest::default()
                },
            )
            .unwrap();
            let o = &report.outcome;
            store
                .finish_fit(
                    fit,
                    &FitResult {
                        cost: o.cost,
                        params: serde_json::to_value(o.params).unwrap(),
                        best_cost_per_generation: o.best_cost_per_generation.clone(),
                        evaluations: o.evaluations,
                        generations: o.generations,
                        wall_ms: o.wall_ms,
                    },
                    &report.evaluation.per_geometry,
                )
                .await
                .unwrap();
        }
        scans.push(scan);
    }
    store.close().await;
    scans
}

fn brdfd(args: &[&str]) -> std::process::Output {
    let out = Command::new(env!("CARGO_BIN_EXE_brdfd"))
        .args(args)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "brdfd {args:?} failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    out
}

#[tokio::test(flavor = "multi_thread", worker_threads = 1)]
async fn stored_scans_and_fits_make_a_report_and_exports() {
    let dir = tempfile::tempdir().unwrap();
    let db = dir.path().join("brdfd.db");
    let scans = fill(&db).await;

    // The study read back.
    let store = Store::open(&db).await.unwrap();
    let study = from_store(&store, &Selection::All).await.unwrap();
    store.close().await;
    assert_eq!(study.samples.len(), 3);
    for (s, scan) in study.samples.iter().zip(&scans) {
        assert_eq!(&s.scan, scan);
        assert_eq!(s.fits.len(), 3);
    }
    let failed = study.samples[2].fit(CostFunction::M2).unwrap();
    assert_eq!(
        failed.state,
        FitState::Failed {
            reason: "optimiser diverged".into()
        }
    );
    // The stored evaluation is what the loader recomputes from the stored parameters.
    let again = fit_scan(
        &scans[0],
        &FitRequest {
            settings: Settings {
                cost: CostFunction::Cf2,
                ..Settings::default()
            },
            ..FitRequest::default()
        },
    )
    .unwrap();
    let d = study.samples[0].done(CostFunction::Cf2).unwrap();
    assert_eq!(d.params, again.outcome.params);
    assert_eq!(d.evaluation, again.evaluation);
    let a = Analysis::of(&study);
    assert_eq!(a.included, vec![0, 1]);
    assert_eq!(a.excluded[0].sample, "T.Manzana green");

    // `brdfd report --all`.
    let out_dir = dir.path().join("report");
    let db_s = db.to_str().unwrap();
    let out = brdfd(&[
        "report",
        "--all",
        "--db",
        db_s,
        "--out",
        out_dir.to_str().unwrap(),
    ]);
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        stdout.contains("3 samples, 13 figures (PNG and SVG)"),
        "{stdout}"
    );
    for stem in [
        "fig04-measured-swatches",
        "fig05-lightness-diffuse",
        "fig06-lightness-specular",
        "fig07-swatches-cf1",
        "fig07-swatches-cf2",
        "fig07-swatches-m2",
        "fig08-spectra-t-freesia-pink",
        "fig09-lightness-15deg",
        "fig10-lightness-45deg",
        "fig11-delta-e-boxplots",
        "fig12-mean-delta-e",
    ] {
        for ext in ["png", "svg"] {
            let p = out_dir.join(format!("{stem}.{ext}"));
            assert!(
                p.metadata().map(|m| m.len() > 1000).unwrap_or(false),
                "{}",
                p.display()
            );
        }
    }
    let md = std::fs::read_to_string(out_dir.join("summary.md")).unwrap();
    assert!(
        md.contains("- T.Manzana green: m2 fit failed: optimiser diverged"),
        "{md}"
    );
    // Two samples take part: 28 (sample, geometry) pairs per sign test, ties included.
    assert!(
        md.contains("| cf1 vs cf2 | separable / separable |"),
        "{md}"
    );
    assert!(md.contains("| cf1 | separable | 2 |"), "{md}");

    // A scan id that is not there, and a store that is not there.
    let e = Command::new(env!("CARGO_BIN_EXE_brdfd"))
        .args([
            "report",
            "99",
            "--db",
            db_s,
            "--out",
            out_dir.to_str().unwrap(),
        ])
        .output()
        .unwrap();
    assert!(!e.status.success());
    let e = Command::new(env!("CARGO_BIN_EXE_brdfd"))
        .args([
            "report",
            "--all",
            "--db",
            "nope.db",
            "--out",
            out_dir.to_str().unwrap(),
        ])
        .output()
        .unwrap();
    assert_eq!(
        String::from_utf8_lossy(&e.stderr).trim(),
        "error: no store at nope.db; run `brdfd demo` or the daemon first, or pass --db PATH"
    );

    // Export in every format from the store, import back: the same scans.
    for (format, file) in [
        ("cgats", "x.cgats.txt"),
        ("cxf3", "x.cxf"),
        ("csv", "x.csv"),
        ("json", "x.json"),
    ] {
        let path = dir.path().join(file);
        brdfd(&[
            "export-format",
            "--format",
            format,
            "--all",
            "--db",
            db_s,
            "--out",
            path.to_str().unwrap(),
        ]);
        let back = dir.path().join(format!("back-{format}"));
        brdfd(&[
            "import-format",
            path.to_str().unwrap(),
            "--out",
            back.to_str().unwrap(),
        ]);
        for scan in &scans {
            let f = back.join(format!("{}.scan.json", brdfd::synth::slug(&scan.sample)));
            assert_eq!(&Scan::read_file(&f).unwrap(), scan, "{format}");
        }
    }
}
