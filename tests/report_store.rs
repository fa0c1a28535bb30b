//! From the store to the report and the exchange formats: three scans with their fits (one
//! sample's m2 fit failed) are written through the store's verbs into a file store; the study
//! loaded back holds the same scans and fits, leaves the failed sample out of the comparison,
//! and `brdfd report`, `brdfd export-format` and `brdfd import-format` work on it end to end.

use std::path::Path;

use serde_json::Value;
use std::process::Command;

use brdfd::cost::CostFunction;
use brdfd::fit::{FitRequest, fit_scan};
use brdfd::geometry::{Device, GEOMETRIES, MA_T12_COUNT};
use brdfd::optimise::Settings;
use brdfd::report::load::{Selection, from_store};
use brdfd::report::{Analysis, FitState};
use brdfd::scan::Scan;
use brdfd::store::{
    FitResult, InstrumentProvenance, NewFit, NewReading, Provenance, ReadingValues, Source, Store,
};
use brdfd::synth::{SynthOptions, paper_samples, synth_scan};

fn values(readings: &brdfd::scan::DeviceReadings, g: &brdfd::geometry::Geometry) -> ReadingValues {
    match g.device {
        Device::MaT12 => ReadingValues::Spectrum(readings.ma_t12[g.index]),
        Device::Sra => ReadingValues::Intensity(readings.sra.unwrap()[g.index - MA_T12_COUNT]),
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
            .begin_reference(&scan.reference.as_ref().unwrap().name, None)
            .await
            .unwrap();
        for g in &GEOMETRIES {
            store
                .add_reference_reading(
                    r,
                    g.device,
                    g,
                    &values(&scan.reference.as_ref().unwrap().readings, g),
                    b"",
                )
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
        // Each scan by its own (real) pair of instruments, so exports must tell them apart.
        let instrument = |model: &str, serial: String| InstrumentProvenance {
            model: model.into(),
            serial,
            firmware: "2.1.0".into(),
            simulated: Some(false),
            origin: brdfd::store::InstrumentOrigin::Measured,
        };
        store
            .set_scan_provenance(
                id,
                &Provenance {
                    ma_t12: instrument("MA-T12", format!("MT-{i:03}")),
                    sra: instrument("RA-532H", format!("RA-{i:03}")),
                    source: Source::Measured,
                    source_detail: None,
                },
            )
            .await
            .unwrap();
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
                        colorimetry: Default::default(),
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

/// `brdfd ARGS… --all --db DB --out OUT --json`'s answer.
fn all_as_json(args: &[&str], db: &str, out: &std::path::Path) -> Value {
    let mut all = args.to_vec();
    all.extend([
        "--all",
        "--db",
        db,
        "--out",
        out.to_str().unwrap(),
        "--json",
    ]);
    serde_json::from_slice(&brdfd(&all).stdout).unwrap()
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

/// The text of every `<text>` element of an SVG figure, trimmed, with XML entities decoded.
fn svg_texts(path: &Path) -> Vec<String> {
    let svg = std::fs::read_to_string(path).unwrap();
    svg.split("<text")
        .skip(1)
        .map(|t| {
            let body = &t[t.find('>').expect("a <text> tag closes") + 1..];
            let body = &body[..body.find("</text>").expect("a <text> element ends")];
            body.trim()
                .replace("&lt;", "<")
                .replace("&gt;", ">")
                .replace("&quot;", "\"")
                .replace("&#39;", "'")
                .replace("&amp;", "&")
        })
        .collect()
}

/// The numeric labels (axis ticks) among a figure's texts, and their spacing.
fn ticks(texts: &[String]) -> (Vec<f64>, f64) {
    let t: Vec<f64> = texts.iter().filter_map(|s| s.parse().ok()).collect();
    assert!(t.len() >= 3, "too few tick labels in {texts:?}");
    let step = t[1] - t[0];
    for w in t.windows(2) {
        assert!(
            (w[1] - w[0] - step).abs() < 1e-9 * step.abs().max(1.0),
            "{t:?}"
        );
    }
    (t, step)
}

/// Asserts that `value` lies on the axis the tick labels `t` (spacing `step`) describe: no
/// more than one tick spacing outside the first and last label.
fn on_axis(what: &str, value: f64, t: &[f64], step: f64) {
    let (lo, hi) = (t[0].min(t[t.len() - 1]), t[0].max(t[t.len() - 1]));
    assert!(
        value >= lo - step.abs() && value <= hi + step.abs(),
        "{what}: {value} is off the axis {t:?}"
    );
}

/// The figures carry what they claim: titles, axis labels, every sample and geometry name, and
/// axis ranges that hold the values plotted (computed here from the scans and the analysis).
fn check_figure_text(dir: &Path, scans: &[Scan], a: &Analysis) {
    let fig = |stem: &str| svg_texts(&dir.join(format!("{stem}.svg")));
    let has = |texts: &[String], want: &str, stem: &str| {
        assert!(
            texts.iter().any(|t| t == want),
            "{stem}.svg has no text {want:?}: {texts:?}"
        );
    };
    let samples: Vec<&str> = scans.iter().map(|s| s.sample.as_str()).collect();

    let f4 = fig("fig04-measured-swatches");
    assert!(
        f4[0].starts_with("Fig. 4  Measured colour per geometry"),
        "{f4:?}"
    );
    for g in &GEOMETRIES {
        has(&f4, g.name, "fig04");
    }
    for s in &samples {
        has(&f4, s, "fig04");
    }

    // Fig. 5: L* of the MA-T12 readings. The values are recomputed from the readings
    // (reflectance factors, D65/2°); the figure's axis must hold them.
    let f5 = fig("fig05-lightness-diffuse");
    assert!(
        f5[0].starts_with("Fig. 5  Measured lightness L* of the diffuse readings"),
        "{f5:?}"
    );
    has(&f5, "L* (CIELAB, D65, 2°)", "fig05");
    has(
        &f5,
        "geometry (device name; detector° as aspecular°)",
        "fig05",
    );
    for g in GEOMETRIES.iter().filter(|g| g.device == Device::MaT12) {
        has(&f5, g.name, "fig05");
    }
    for s in &samples {
        has(&f5, s, "fig05");
    }
    let (t, step) = ticks(&f5);
    for scan in scans {
        let m = brdfd::processing::process(scan, &Default::default()).unwrap();
        for g in GEOMETRIES.iter().filter(|g| g.device == Device::MaT12) {
            let r = brdfd::colour::brdf_to_reflectance(&m.values[g.index]);
            let l = brdfd::colour::reflectance_to_lab(&r).l;
            on_axis(&format!("fig05 {} {}", scan.sample, g.name), l, &t, step);
        }
    }

    for cf in CostFunction::ALL {
        let f7 = fig(&format!("fig07-swatches-{cf}"));
        assert!(
            f7[0].contains(&format!("cost function {cf}, method separable")),
            "{f7:?}"
        );
        for s in &samples {
            has(&f7, s, "fig07");
        }
    }

    let f8 = fig("fig08-spectra-t-freesia-pink");
    assert!(f8[0].ends_with("sample \"T.Freesia pink\""), "{f8:?}");
    has(&f8, "wavelength (nm)", "fig08");
    has(&f8, "reflectance factor", "fig08");
    for g in GEOMETRIES.iter().filter(|g| g.device == Device::MaT12) {
        has(&f8, &format!("{} (X-Rite MA-T12)", g.name), "fig08");
    }
    for nm in ["400", "500", "600", "700"] {
        has(&f8, nm, "fig08");
    }

    // Fig. 11 and 12: ΔE00 per cost function; the axis must hold every plotted mean.
    let f11 = fig("fig11-delta-e-boxplots");
    has(&f11, "ΔE00 (CIEDE2000)", "fig11");
    let f12 = fig("fig12-mean-delta-e");
    assert!(
        f12[0].starts_with("Fig. 12  Mean ΔE00 per cost function, 95 % CI (n = 2 samples)"),
        "{f12:?}"
    );
    has(&f12, "mean ΔE00 over samples", "fig12");
    has(&f12, "geometries the mean is over", "fig12");
    for label in ["all 14 geometries", "diffuse (MA-T12)", "specular (SRA)"] {
        has(&f12, label, "fig12");
    }
    let (t, step) = ticks(&f12);
    for c in &a.per_cost {
        has(&f12, &format!("{} (separable)", c.cost), "fig12");
        for m in [&c.all, &c.diffuse, &c.specular].into_iter().flatten() {
            on_axis(&format!("fig12 {} mean", c.cost), m.mean, &t, step);
        }
    }
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
        stdout.contains("3 samples, 17 figures (PNG and SVG)"),
        "{stdout}"
    );
    for stem in [
        "fig04-measured-swatches",
        "fig05-lightness-diffuse",
        "fig06-lightness-specular",
        "fig06b-luminance-specular",
        "fig07-swatches-cf1",
        "fig07-swatches-cf2",
        "fig07-swatches-m2",
        "fig08-spectra-t-freesia-pink",
        "fig09-lightness-15deg",
        "fig10-lightness-45deg",
        "fig11-delta-e-boxplots",
        "fig11b-specular-delta-l",
        "fig12-mean-delta-e",
        "fig12b-mean-specular-delta-l",
        "fig13-residual-lightness",
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
    check_figure_text(&out_dir, &scans, &a);
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
    // The provenance table names each scan's instruments.
    assert!(md.contains("Table 5. Provenance"), "{md}");
    assert!(
        md.contains("| measured | MA-T12 serial MT-001 firmware 2.1.0 (measured) | RA-532H serial RA-001 firmware 2.1.0 (measured) |"),
        "{md}"
    );
    // And which scans it pooled.
    assert!(
        md.contains("Pooled: the 3 scans of this study are real — 3 measured on this bench"),
        "{md}"
    );

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
        // Every export says which instruments measured each scan.
        let text = std::fs::read_to_string(&path).unwrap();
        for i in 0..scans.len() {
            for serial in [format!("MT-{i:03}"), format!("RA-{i:03}")] {
                assert!(text.contains(&serial), "{format}: no serial {serial}");
            }
        }
        if format == "csv" {
            let mut r = csv::Reader::from_path(&path).unwrap();
            let head = r.headers().unwrap().clone();
            let col = |name: &str| head.iter().position(|h| h == name).unwrap();
            let first = r.records().next().unwrap().unwrap();
            assert_eq!(&first[col("scan_id")], "1");
            assert_eq!(&first[col("source")], "measured");
            assert_eq!(&first[col("ma_t12_serial")], "MT-000");
            assert_eq!(&first[col("sra_simulated")], "no");
            assert_eq!(&first[col("ma_t12_origin")], "measured");
            assert_eq!(&first[col("sra_origin")], "measured");
            assert!(first[col("measured_at")].ends_with('Z'));
        }
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

    // --json: what was written, as JSON on stdout (the tidy tables and a second report).
    let tidy = dir.path().join("tidy");
    let v = all_as_json(&["export-format", "--format", "tidy"], db_s, &tidy);
    assert_eq!(v["samples"], 3, "{v}");
    assert_eq!(v["format"], "tidy", "{v}");
    for f in v["files"].as_array().unwrap() {
        assert!(std::path::Path::new(f.as_str().unwrap()).exists(), "{f}");
    }
    let spectra = std::fs::read_to_string(tidy.join("spectra.csv")).unwrap();
    assert_eq!(spectra.lines().count(), 1 + 3 * 14 * 31);
    let second = dir.path().join("rep-json");
    let v = all_as_json(&["report"], db_s, &second);
    assert_eq!(v["samples"], 3, "{v}");
    assert!(
        std::path::Path::new(v["html"].as_str().unwrap()).exists(),
        "{v}"
    );
    assert_eq!(v["figures"].as_array().unwrap().len(), 4 + 3 + 3 + 7, "{v}");

    // A simulated scan joins the store (a brdfd.scan/1 file of a replayed scan, imported):
    // `--all` pools the three real scans only, and says so.
    let store = Store::open(&db).await.unwrap();
    let readings = |r: &brdfd::scan::DeviceReadings| -> Vec<NewReading<'static>> {
        GEOMETRIES
            .iter()
            .map(|g| NewReading {
                device: g.device,
                geometry: g,
                values: values(r, g),
                raw_frame: b"",
            })
            .collect()
    };
    let simulated = InstrumentProvenance {
        simulated: Some(true),
        ..InstrumentProvenance::unknown()
    };
    let (_, sim_id) = store
        .import_scan(
            "sim-copy",
            "N9 (imported)",
            &Provenance {
                ma_t12: simulated.clone(),
                sra: simulated,
                source: Source::Imported,
                source_detail: Some("simulated — replayed from a recording".into()),
            },
            &readings(&scans[0].reference.as_ref().unwrap().readings),
            &readings(&scans[0].readings),
        )
        .await
        .unwrap();
    store.close().await;
    let third = dir.path().join("rep-real");
    let out = Command::new(env!("CARGO_BIN_EXE_brdfd"))
        .args(["report", "--all", "--db", db_s, "--out"])
        .arg(&third)
        .output()
        .unwrap();
    let (stdout, stderr) = (
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr),
    );
    assert!(out.status.success(), "{stderr}");
    assert!(stdout.contains("3 samples"), "{stdout}");
    assert!(
        stderr.contains(&format!(
            "pooling the 3 real scans (scan 1, scan 2, scan 3) only; left out 1 scans from \
             simulated instruments (scan {sim_id})"
        )),
        "{stderr}"
    );
    let md = std::fs::read_to_string(third.join("summary.md")).unwrap();
    assert!(md.contains("Pooled: the 3 scans"), "{md}");
    assert!(!md.contains("sim-copy"), "{md}");
}
