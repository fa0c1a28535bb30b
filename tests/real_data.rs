//! Real MA-T12 measurements end to end: X-Rite's own QC `.xlsx` exports (copies in
//! `tests/data/real-mat12/`, source in its README) come in through `import-format`, the watch
//! folder and `POST /scans/import`, and are fitted under all three cost functions over the 12
//! MA-T12 geometries, normalised by the instrument's own white calibration.

mod common;

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use brdfd::formats::xrite_xlsx::{REAL_EXPORTS, REAL_EXPORTS_DIR};
use serde_json::Value;

use common::*;

fn real(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join(REAL_EXPORTS_DIR)
        .join(name)
}

fn wait_for(what: &str, mut cond: impl FnMut() -> bool) {
    let start = Instant::now();
    while !cond() {
        assert!(
            start.elapsed() < Duration::from_secs(120),
            "timed out waiting for {what}"
        );
        std::thread::sleep(Duration::from_millis(50));
    }
}

/// `import-format` writes one scan file per export; each fits under cf1, cf2 and m2 with
/// `brdfd fit`, over the 12 MA-T12 geometries, and says so.
#[test]
fn import_format_then_fit_every_real_export_under_every_cost_function() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("scans");
    let mut args = vec!["import-format".to_string()];
    args.extend(REAL_EXPORTS.iter().map(|f| real(f).display().to_string()));
    args.extend(["--out".into(), out.display().to_string(), "--json".into()]);
    let args: Vec<&str> = args.iter().map(String::as_str).collect();
    let o = run_brdfd(&args, None);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let lines: Vec<Value> = String::from_utf8_lossy(&o.stdout)
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    assert_eq!(lines.len(), 6);
    for line in &lines {
        // X-Rite's L*a*b* reproduced from the spectra.
        let largest = line["colorimetry_check"]["largest_delta_e00"]
            .as_f64()
            .unwrap();
        assert!(largest <= 1e-3, "{line}");
        assert!(line["colorimetry_check"]["warning"].is_null(), "{line}");
    }
    // One file under each cost function (all six are fitted by the daemon test below).
    let file = lines[4]["file"].as_str().unwrap();
    for cost in ["cf1", "cf2", "m2"] {
        let o = run_brdfd(&["fit", "--input", file, "--cost", cost, "--json"], None);
        assert!(
            o.status.success(),
            "{cost}: {}",
            String::from_utf8_lossy(&o.stderr)
        );
        let v: Value = serde_json::from_slice(&o.stdout).unwrap();
        assert_eq!(v["reference"], "instrument calibration");
        assert_eq!(v["specular_readings"], false);
        assert_eq!(v["delta_e00"].as_object().unwrap().len(), 12, "{cost}");
        assert_eq!(v["lab"].as_object().unwrap().len(), 12, "{cost}");
        assert!(v["delta_e00_specular_mean"].is_null());
        let mean = v["delta_e00_mean"].as_f64().unwrap();
        // Real paint leaves a residual the model cannot fit, but nothing absurd.
        assert!(mean > 0.0 && mean < 10.0, "{cost}: mean ΔE00 {mean}");
    }
    // The table form says it too.
    let o = run_brdfd(&["fit", "--input", file, "--cost", "cf2"], None);
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(
        text.contains("reference        instrument calibration; no specular readings"),
        "{text}"
    );
}

/// A bad file writes nothing and names itself.
#[test]
fn a_broken_xlsx_is_refused_naming_it() {
    let dir = tempfile::tempdir().unwrap();
    let bad = dir.path().join("broken.xlsx");
    std::fs::write(&bad, b"PK\x03\x04 not really a zip").unwrap();
    let out = dir.path().join("scans");
    let o = run_brdfd(
        &[
            "import-format",
            &real(REAL_EXPORTS[0]).display().to_string(),
            &bad.display().to_string(),
            "--out",
            &out.display().to_string(),
        ],
        None,
    );
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("broken.xlsx"), "{err}");
    assert!(!out.exists() || std::fs::read_dir(&out).unwrap().next().is_none());
}

/// The daemon takes the exports through its watch folder and over HTTP: each is one scan,
/// reference "instrument calibration", no SRA readings, the MA-T12 (not simulated) and the
/// measurement time as the file says, fitted under all three cost functions.
#[test]
fn the_daemon_imports_real_exports_by_watch_folder_and_http_and_fits_them() {
    let _serial = serial();
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let inbox = dir.join("inbox");
    std::fs::create_dir(&inbox).unwrap();
    write_simulated_config(
        dir,
        "",
        &format!(
            "[fit]\ncost_functions = [\"cf1\", \"cf2\", \"m2\"]\nbootstrap = 0\n\n\
             [ingest]\nwatch = \"{}\"\nsettle_ms = 100\npoll_ms = 20\n\n",
            inbox.display()
        ),
    );
    let daemon = spawn_serve(&dir.join("brdfd.toml"), &[]);
    for f in &REAL_EXPORTS[..3] {
        std::fs::copy(real(f), inbox.join(f)).unwrap();
    }
    wait_for("three exports in done/", || {
        std::fs::read_dir(inbox.join("done"))
            .map(|d| d.count() == 3)
            .unwrap_or(false)
    });
    for f in &REAL_EXPORTS[3..] {
        let bytes = std::fs::read(real(f)).unwrap();
        let v = daemon.client.post_bytes("/scans/import", &bytes).unwrap();
        assert_eq!(v["scans"].as_array().unwrap().len(), 1, "{v}");
        assert_eq!(v["fits"].as_array().unwrap().len(), 3, "{v}");
        let check = &v["colorimetry_checks"][0];
        assert!(check["largest_delta_e00"].as_f64().unwrap() <= 1e-3, "{v}");
    }
    let list = daemon.client.get("/scans").unwrap();
    let scans = list.as_array().unwrap();
    assert_eq!(scans.len(), 6, "{list}");
    let expected_textures: Vec<(String, Vec<(String, Vec<u8>)>)> = REAL_EXPORTS
        .iter()
        .flat_map(|f| brdfd::formats::xrite::read_file(&real(f), &Default::default()).unwrap())
        .map(|x| {
            let t = x
                .textures
                .into_iter()
                .map(|t| (t.geometry, t.png))
                .collect();
            (x.scan.sample, t)
        })
        .collect();
    let mut any_texture = false;
    // Every fit of every scan ended, as the store says (the status counters may run ahead of
    // the fit's last commit).
    wait_for("every fit done", || {
        scans.iter().all(|s| {
            let d = daemon.client.get(&format!("/scans/{}", s["id"])).unwrap();
            let fits = d["fits"].as_array().cloned().unwrap_or_default();
            fits.len() == 3
                && fits
                    .iter()
                    .all(|f| f["run"]["status"] != "queued" && f["run"]["status"] != "running")
        })
    });
    for s in scans {
        let id = s["id"].as_i64().unwrap();
        let d = daemon.client.get(&format!("/scans/{id}")).unwrap();
        assert_eq!(d["scan"]["specular_readings"], false, "{d}");
        assert_eq!(
            d["reference"]["reference"]["instrument_calibration"], true,
            "{d}"
        );
        assert_eq!(d["readings"].as_array().unwrap().len(), 12);
        let p = &d["scan"]["provenance"];
        assert_eq!(p["ma_t12"]["model"], "MA-T12", "{p}");
        assert_eq!(p["ma_t12"]["simulated"], false, "{p}");
        assert!(
            p["source_detail"].as_str().unwrap().contains("sha256"),
            "{p}"
        );
        // The measurement time the file states (2024), not the import time.
        let t = d["scan"]["requested_at_ms"].as_i64().unwrap();
        assert!((1_704_067_200_000..1_735_689_600_000).contains(&t), "{t}");
        let fits = d["fits"].as_array().unwrap();
        assert_eq!(fits.len(), 3, "{d}");
        for f in fits {
            assert_eq!(f["run"]["status"], "done", "{f}");
            assert!(f["evaluation"]["specular"].is_null(), "{f}");
            let mean = f["evaluation"]["all"]["mean"].as_f64().unwrap();
            assert!(mean > 0.0 && mean < 10.0, "{f}");
        }
        // The instrument camera's images are kept with the scan, byte for byte as the file
        // holds them, in its order, by either path.
        let sample = d["scan"]["sample"].as_str().unwrap();
        let textures = d["textures"].as_array().unwrap();
        let want = &expected_textures
            .iter()
            .find(|(name, _)| name == sample)
            .unwrap_or_else(|| panic!("no file measured {sample}"))
            .1;
        assert_eq!(textures.len(), want.len(), "{sample}: {d}");
        for (t, (label, png)) in textures.iter().zip(want) {
            assert_eq!(t["label"], label.as_str(), "{t}");
            let n = t["position"].as_u64().unwrap();
            let got = daemon
                .client
                .get_bytes(&format!("/scans/{id}/textures/{n}.png"))
                .unwrap();
            assert!(&got == png, "{sample} texture {n} differs from the file's");
        }
        any_texture |= !textures.is_empty();
    }
    assert!(any_texture, "the shared exports carry texture images");
    let e = daemon
        .client
        .get_bytes(&format!("/scans/{}/textures/99.png", scans[0]["id"]))
        .unwrap_err();
    assert!(e.to_string().contains("texture image"), "{e}");
}
