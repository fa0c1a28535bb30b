//! The glTF 2.0 export checked by the Khronos glTF-Validator (npm `gltf-validator`, installed by
//! `.ci/run` into `target/tools/gltf`, or the `node_modules/gltf-validator` directory named by
//! `BRDFD_GLTF_VALIDATOR`): every file of a study's fits has no error and no warning. The test
//! fails, not skips, when node or the validator is missing.

use std::path::PathBuf;
use std::process::Command;

use brdfd::cost::CostFunction;
use brdfd::fit::{FitRequest, fit_scan};
use brdfd::formats::{ExportOptions, gltf};
use brdfd::optimise::Settings;
use brdfd::processing::ProcessingOptions;
use brdfd::report::Study;
use brdfd::scan::Scan;

fn validator() -> PathBuf {
    let p = std::env::var_os("BRDFD_GLTF_VALIDATOR").map_or_else(
        || {
            PathBuf::from(env!("CARGO_MANIFEST_DIR"))
                .join("target/tools/gltf/node_modules/gltf-validator")
        },
        PathBuf::from,
    );
    assert!(
        p.join("package.json").exists(),
        "the Khronos glTF-Validator is needed for this test: run `bash .ci/run` (it runs \
         `npm install gltf-validator` into target/tools/gltf), or set BRDFD_GLTF_VALIDATOR to its \
         node_modules/gltf-validator directory; looked in {}",
        p.display()
    );
    p
}

#[test]
fn every_gltf_file_passes_the_khronos_validator() {
    let validator = validator();
    let dir = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/data");
    let scan =
        Scan::read_file(PathBuf::from(format!("{dir}/t-mandarin-orange.scan.json"))).unwrap();
    // Relative and absolute scale: the scale is named in the asset's extras either way.
    let mut studies = Vec::new();
    for rho in [None, Some([0.77; 31])] {
        let reports: Vec<_> = [CostFunction::Cf1, CostFunction::Cf2]
            .iter()
            .map(|&cost| {
                fit_scan(
                    &scan,
                    &FitRequest {
                        processing: ProcessingOptions {
                            reference_reflectance: rho,
                            ..Default::default()
                        },
                        settings: Settings {
                            cost,
                            ..Settings::default()
                        },
                        ..FitRequest::default()
                    },
                )
                .unwrap()
            })
            .collect();
        studies.push(Study::from_fit_reports(
            std::slice::from_ref(&scan),
            &[reports],
        ));
    }
    let out = tempfile::tempdir().unwrap();
    let mut paths = Vec::new();
    for (i, study) in studies.iter().enumerate() {
        for (name, bytes) in gltf::files(study, &ExportOptions::default()).unwrap() {
            let doc: serde_json::Value = serde_json::from_slice(&bytes).unwrap();
            let scale = doc["asset"]["extras"]["brdfd"]["scale"].as_str().unwrap();
            assert_eq!(
                scale,
                if i == 0 {
                    "relative-to-tile"
                } else {
                    "absolute"
                }
            );
            let p = out.path().join(format!("{i}-{name}"));
            std::fs::write(&p, bytes).unwrap();
            paths.push(p);
        }
    }
    assert_eq!(paths.len(), 4);
    let o = Command::new("node")
        .arg(concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/tests/tools/gltf_validate.js"
        ))
        .arg(&validator)
        .args(&paths)
        .output()
        .expect("node runs (install Node.js: .ci/run does)");
    let report = String::from_utf8_lossy(&o.stdout);
    assert!(
        o.status.success(),
        "{report}{}",
        String::from_utf8_lossy(&o.stderr)
    );
    assert_eq!(
        report.matches("errors 0, warnings 0").count(),
        4,
        "{report}"
    );
}
