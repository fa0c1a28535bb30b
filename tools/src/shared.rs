//! What the study binaries share with brdfd's examples (`examples/common` compiles this same
//! file): a `--name value` option read off the command line, the example scans of
//! `tests/data/` and the real MA-T12 exports of `tests/data/real-mat12/` read and processed as
//! the CLI does. Only `std` and brdfd's library, so that it
//! builds in both packages.

use std::path::{Path, PathBuf};

use brdfd::processing::{MeasuredBrdf, ProcessingOptions, process};
use brdfd::scan::Scan;

/// The value after the option `name` in `args`, else `default`.
pub fn arg<T: std::str::FromStr>(args: &[String], name: &str, default: T) -> T {
    args.iter()
        .position(|a| a == name)
        .and_then(|i| args.get(i + 1))
        .map(|v| {
            v.parse()
                .unwrap_or_else(|_| panic!("{name}: cannot read {v:?}"))
        })
        .unwrap_or(default)
}

/// One example scan, read and processed with the default options.
pub struct ExampleScan {
    /// The scan as its file has it.
    pub scan: Scan,
    /// Whether it is the copy with 1 % noise (`*.noisy.scan.json`).
    pub noisy: bool,
    /// Its measured BRDF.
    pub measured: MeasuredBrdf,
}

/// Every example scan in `dir` (each `*.scan.json` file, in file-name order).
pub fn example_scans(dir: &Path) -> Vec<ExampleScan> {
    let mut files: Vec<_> = std::fs::read_dir(dir)
        .expect("tests/data holds the example scans")
        .map(|e| e.expect("readable tests/data entry").path())
        .filter(|p| p.to_string_lossy().ends_with(".scan.json"))
        .collect();
    files.sort();
    files
        .iter()
        .map(|path| {
            let scan = Scan::read_file(path).expect("example scans are valid");
            let noisy = path.to_string_lossy().ends_with(".noisy.scan.json");
            let measured =
                process(&scan, &ProcessingOptions::default()).expect("example scans process");
            ExampleScan {
                scan,
                noisy,
                measured,
            }
        })
        .collect()
}

/// The real MA-T12 exports (X-Rite's QC `.xlsx` files) under `root` (`tests/data/real-mat12`):
/// `root`'s own files, then those of `root/more`, each folder in file-name order; every
/// measurement a file holds, as (sample name, measured BRDF processed with the default
/// options: 12 geometries, normalised by the instrument's own calibration).
pub fn real_exports(root: &Path) -> Vec<(String, MeasuredBrdf)> {
    let list = |dir: &Path| -> Vec<PathBuf> {
        let mut v: Vec<PathBuf> = std::fs::read_dir(dir)
            .unwrap_or_else(|e| panic!("{} should hold the real exports: {e}", dir.display()))
            .map(|e| e.expect("readable entry").path())
            .filter(|p| p.extension().is_some_and(|e| e == "xlsx"))
            .collect();
        v.sort();
        v
    };
    let mut out = Vec::new();
    for path in list(root).into_iter().chain(list(&root.join("more"))) {
        for x in brdfd::formats::xrite::read_file(&path, &Default::default())
            .unwrap_or_else(|e| panic!("{}: {e}", path.display()))
        {
            let m = process(&x.scan, &ProcessingOptions::default()).expect("real scans process");
            out.push((x.scan.sample.clone(), m));
        }
    }
    out
}
