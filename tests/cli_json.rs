//! `--json` on the commands that print results without a daemon: stdout is JSON (one object,
//! or one per line) naming what was written, and every file named exists. The daemon commands'
//! `--json` is tested against a live daemon in `tests/daemon_operator.rs`.

use std::process::Command;

use serde_json::Value;

fn brdfd_json(args: &[&str]) -> Vec<Value> {
    let mut all = args.to_vec();
    all.push("--json");
    let out = Command::new(env!("CARGO_BIN_EXE_brdfd"))
        .args(&all)
        .env_remove("BRDFD_CONFIG")
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "brdfd {all:?}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let text = String::from_utf8(out.stdout).unwrap();
    text.lines()
        .map(|l| serde_json::from_str(l).unwrap_or_else(|e| panic!("{all:?}: {e}: {l}")))
        .collect()
}

fn exists(v: &Value) {
    let p = v.as_str().unwrap_or_else(|| panic!("not a path: {v}"));
    assert!(std::path::Path::new(p).exists(), "{p}");
}

#[test]
fn offline_commands_print_json_naming_what_they_wrote() {
    let dir = tempfile::tempdir().unwrap();
    let d = |name: &str| dir.path().join(name).display().to_string();

    // synth: one object per sample.
    let synth = brdfd_json(&["synth", "--out", &d("synth")]);
    assert_eq!(synth.len(), 8);
    for v in &synth {
        exists(&v["scan"]);
        exists(&v["truth"]);
    }
    let first = synth[0]["scan"].as_str().unwrap().to_string();

    // render: the file and what it shows.
    let render = brdfd_json(&[
        "render",
        "--input",
        &first,
        "--cost",
        "cf1",
        "--out",
        &d("s.png"),
    ]);
    assert_eq!(render.len(), 1);
    assert_eq!(render[0]["sample"], synth[0]["sample"]);
    assert_eq!(render[0]["costs"], serde_json::json!(["cf1"]));
    exists(&render[0]["file"]);

    // import-format of a brdfd export → one object per scan.
    let csv = dir.path().join("x.csv");
    let scan = brdfd::scan::Scan::read_file(std::path::Path::new(&first)).unwrap();
    let study = brdfd::report::Study {
        samples: vec![brdfd::report::study::SampleStudy {
            name: scan.sample.clone(),
            scan_id: None,
            origin: None,
            measured: brdfd::processing::process(&scan, &Default::default()).unwrap(),
            scan,
            specular: Default::default(),
            reference_reflectance: None,
            fits: Vec::new(),
        }],
    };
    let text = brdfd::formats::export(
        &study,
        brdfd::formats::Format::Csv,
        &brdfd::formats::ExportOptions::default(),
    )
    .unwrap();
    std::fs::write(&csv, text).unwrap();
    let imported = brdfd_json(&["import-format", csv.to_str().unwrap(), "--out", &d("back")]);
    assert_eq!(imported.len(), 1);
    assert_eq!(imported[0]["sample"], synth[0]["sample"]);
    exists(&imported[0]["file"]);
}

/// `import-format --help` shows a CGATS and a CxF3 export and names the committed examples;
/// each example command in it runs from the source tree, and the scan it writes keeps what the
/// file says of its origin: the creation time as the measurement time, and the instrument.
#[test]
fn the_import_help_examples_run_and_keep_the_exports_time_and_instrument() {
    let root = env!("CARGO_MANIFEST_DIR");
    let help = Command::new(env!("CARGO_BIN_EXE_brdfd"))
        .args(["import-format", "--help"])
        .output()
        .unwrap();
    let help = String::from_utf8(help.stdout).unwrap();
    assert!(
        help.contains("BEGIN_DATA_FORMAT") && help.contains("ReflectanceSpectrum"),
        "{help}"
    );
    let examples: Vec<&str> = help
        .lines()
        .map(str::trim)
        .filter(|l| l.starts_with("brdfd import-format tests/data/instrument-exports/"))
        .collect();
    assert_eq!(examples.len(), 2, "a CGATS and a CxF3 example:\n{help}");
    for example in examples {
        let out = tempfile::tempdir().unwrap();
        let mut args: Vec<String> = example
            .split_whitespace()
            .skip(1)
            .map(|a| {
                if a == "scans/" {
                    out.path().display().to_string()
                } else {
                    a.to_string()
                }
            })
            .collect();
        args.push("--json".into());
        let run = Command::new(env!("CARGO_BIN_EXE_brdfd"))
            .args(&args)
            .current_dir(root)
            .env_remove("BRDFD_CONFIG")
            .output()
            .unwrap();
        assert!(
            run.status.success(),
            "{example}: {}",
            String::from_utf8_lossy(&run.stderr)
        );
        let written: Value =
            serde_json::from_slice(run.stdout.split(|b| *b == b'\n').next().unwrap()).unwrap();
        let file = std::fs::read(written["file"].as_str().unwrap()).unwrap();
        let scan = brdfd::scan::Scan::from_json(&file).unwrap();
        assert_eq!(scan.sample, "T.Sky blue");
        assert!(
            scan.readings.sra.is_some(),
            "{example}: the SRA CSV's readings"
        );
        let origin = scan
            .origin
            .unwrap_or_else(|| panic!("{example}: no origin"));
        assert_eq!(
            origin.measured_at.as_deref(),
            Some("2024-05-29T16:37:15Z"),
            "{example}"
        );
        let mat12 = origin.ma_t12.unwrap();
        assert_eq!(
            (mat12.model.as_str(), mat12.serial.as_deref()),
            ("MA-T12", Some("12345"))
        );
        assert!(!mat12.simulated);
        assert_eq!(
            origin.notes.get("originator").map(String::as_str),
            Some("MA-T12 software")
        );
    }
}
