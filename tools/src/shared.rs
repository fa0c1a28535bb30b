//! What the study binaries share with brdfd's examples (`examples/common` compiles this same
//! file): a `--name value` option read off the command line, and the example scans of
//! `tests/data/` read and processed as the CLI does. Only `std` and brdfd's library, so that it
//! builds in both packages.

use std::path::Path;

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
