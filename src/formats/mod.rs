//! Exchange formats: exports of scans and fits that colour tools read, and imports of the
//! instruments' own software exports, so a lab can use brdfd without the wire protocols.
//!
//! - [`cgats`]: CGATS.17 text (one row per sample, data kind and geometry, `SPECTRAL_NM400` …
//!   `SPECTRAL_NM700`, custom fields declared with `KEYWORD`).
//! - [`csv`](mod@csv): the same rows as comma-separated values.
//! - [`cxf3`]: X-Rite Color Exchange Format 3 (one `ColorSpecification` with a `MultiAngle`
//!   `BRDFAngle` per geometry; one `Object` per sample and data kind), valid against the CxF3
//!   core schema kept in `src/formats/data/`.
//! - [`json`]: everything, including the fitted parameters, as one JSON document.
//! - [`tidy`]: two tidy CSV tables for analysis (spectra per scan × geometry × band; fits).
//! - [`sra`]: the Canon SRA's values as CSV (`sample,geometry,intensity`).
//! - [`gltf`]: glTF 2.0 materials of fitted BRDFs on a sphere (one per fit; RGB approximation).
//! - [`mitsuba`]: Mitsuba 3 scenes of fitted materials (one per fit; SCIENCE.md §10).
//! - [`certificate`]: the reference tile's calibration (CGATS or CxF3), for `[reference]`.
//! - [`xrite_xlsx`]: X-Rite's quality-control `.xlsx` export of MA-T12 measurements (read
//!   only), and the check of its L*a*b* against brdfd's colorimetry; [`xrite`]: its
//!   measurements as scans (reference: instrument calibration, no SRA readings).
//!
//! What an export holds, per sample of a [`Study`]: the device readings of the sample and of
//! the reference tile they are normalised by (`reading`, `reference`), the measured
//! reflectance factor `R = π·M` (`measured`) and, per finished fit, the model's reflectance
//! factor `π·f` (`estimated`, with cost function and method). MA-T12 readings are the device's
//! reflectance factor (0–1 scale); an SRA reading is the device's one achromatic intensity, in its
//! own unit, written in every band (the flat spread processing applies, SCIENCE.md §3).
//!
//! Imports turn such files back into [`Scan`]s. Two shapes are read:
//! - brdfd's own exports, which say per row (or per CxF3 object) whose reading it is;
//! - an instrument's software export, which only names the measured objects: the object
//!   named like the reference tile (`--reference`, default "Munsell N9") is the reference of
//!   every other object in the file, and the SRA values come from a separate [`sra`] CSV.
//!
//! Every number is written with Rust's shortest round-trip `Display` and read with the
//! correctly rounded `str::parse`, so export → import gives the same scan to the last bit in
//! every format. Every error names the file, the line and the field.

pub mod budget;
pub mod certificate;
pub mod cgats;
pub mod csv;
pub mod cxf3;
mod export;
pub mod gltf;
mod import;
pub mod json;
pub mod mitsuba;
pub mod sra;
mod table;
pub mod tidy;
mod time;
pub mod xrite;
pub mod xrite_xlsx;

use std::collections::BTreeMap;
use std::fmt;
use std::path::{Path, PathBuf};
use std::str::FromStr;

use crate::scan::{Scan, ScanError};
use crate::study::Study;

pub use self::time::{rfc3339_utc, rfc3339_utc_now};
pub use export::{
    PROVENANCE_FIELDS, SpectralRow, device_spectrum, estimate_band, provenance_values, reflectance,
    rows,
};
pub use import::{Location, Observation, Owner, Value, assemble};
pub(crate) use import::{geometry_named, parse_number, sample_name};

/// The reference tile's name when an instrument file does not say.
pub const DEFAULT_REFERENCE: &str = "Munsell N9";

/// Everything that can be wrong with reading or writing an exchange file.
#[derive(Debug, thiserror::Error)]
pub enum FormatError {
    #[error("cannot read {}: {source}", path.display())]
    Read {
        path: PathBuf,
        source: std::io::Error,
    },
    /// A value or a line of the file is wrong; fix the file at that line.
    #[error("{file}:{line}: {field}: {message}")]
    Invalid {
        file: String,
        line: usize,
        field: String,
        message: String,
    },
    /// Something the file should hold is not there (no line to point at).
    #[error("{file}: {message}")]
    Missing { file: String, message: String },
    /// The assembled scan does not validate (a last check; the per-value checks above
    /// normally catch the problem first, with its line).
    #[error("{file}: sample \"{sample}\": {source}")]
    Scan {
        file: String,
        sample: String,
        #[source]
        source: ScanError,
    },
    /// A part of the file is beyond the import budget.
    #[error(transparent)]
    Budget(#[from] budget::OverBudget),
    /// The study cannot be written in this format.
    #[error("{format}: {message}")]
    Unwritable {
        format: &'static str,
        message: String,
    },
}

impl FormatError {
    pub(crate) fn invalid(
        file: &str,
        line: usize,
        field: impl Into<String>,
        message: impl Into<String>,
    ) -> FormatError {
        FormatError::Invalid {
            file: file.to_string(),
            line,
            field: field.into(),
            message: message.into(),
        }
    }
}

/// The exchange formats.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Format {
    Cgats,
    Cxf3,
    Csv,
    Json,
}

impl Format {
    pub const ALL: [Format; 4] = [Format::Cgats, Format::Cxf3, Format::Csv, Format::Json];

    /// The name used on the command line.
    pub const fn name(self) -> &'static str {
        match self {
            Format::Cgats => "cgats",
            Format::Cxf3 => "cxf3",
            Format::Csv => "csv",
            Format::Json => "json",
        }
    }

    /// The file extension brdfd writes.
    pub const fn extension(self) -> &'static str {
        match self {
            Format::Cgats => "cgats.txt",
            Format::Cxf3 => "cxf",
            Format::Csv => "csv",
            Format::Json => "json",
        }
    }
}

impl fmt::Display for Format {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for Format {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        Format::ALL
            .into_iter()
            .find(|f| f.name() == s)
            .ok_or_else(|| format!("unknown format \"{s}\"; valid: cgats, cxf3, csv, json"))
    }
}

/// Options of an export.
#[derive(Debug, Clone, PartialEq)]
pub struct ExportOptions {
    /// Creation time written into the file (RFC 3339, UTC); CxF3 requires one per object.
    pub created: String,
    /// The program and version named as the file's originator.
    pub originator: String,
}

impl Default for ExportOptions {
    fn default() -> Self {
        ExportOptions {
            created: rfc3339_utc_now(),
            originator: format!("brdfd {}", env!("CARGO_PKG_VERSION")),
        }
    }
}

/// Writes `study` in `format`.
pub fn export(study: &Study, format: Format, opts: &ExportOptions) -> Result<String, FormatError> {
    match format {
        Format::Cgats => cgats::write(study, opts),
        Format::Cxf3 => cxf3::write(study, opts),
        Format::Csv => csv::write(study),
        Format::Json => json::write(study, opts),
    }
}

/// Options of an import.
#[derive(Debug, Clone, PartialEq)]
pub struct ImportOptions {
    /// In an instrument's export, the object with this name is the reference tile.
    pub reference: String,
    /// The limits the reader works within.
    pub budget: budget::Budget,
}

impl Default for ImportOptions {
    fn default() -> Self {
        ImportOptions {
            reference: DEFAULT_REFERENCE.to_string(),
            budget: budget::Budget::default(),
        }
    }
}

/// Reads `path` as UTF-8 text within `budget`'s file size (a larger file is refused unread).
pub fn read_text_within(path: &Path, budget: &budget::Budget) -> Result<String, FormatError> {
    let io = |source| FormatError::Read {
        path: path.to_path_buf(),
        source,
    };
    let bytes = budget
        .read_file(path, &path.display().to_string())
        .map_err(|e| match e {
            budget::ReadError::Io(e) => io(e),
            budget::ReadError::Over(e) => FormatError::Budget(e),
        })?;
    String::from_utf8(bytes).map_err(|e| {
        io(std::io::Error::new(
            std::io::ErrorKind::InvalidData,
            format!(
                "not UTF-8 text (byte {}): export it as UTF-8",
                e.utf8_error().valid_up_to()
            ),
        ))
    })
}

/// Reads the scans in `text` (the contents of `file`, named in errors) in `format`, taking the
/// SRA values from `sra` (an [`sra`] CSV: name and contents) when the file has none.
pub fn import(
    format: Format,
    file: &str,
    text: &str,
    sra: Option<(&str, &str)>,
    opts: &ImportOptions,
) -> Result<Vec<Scan>, FormatError> {
    // What an instrument's export says of where its readings came from: one account for the
    // whole file (a CGATS header), or one per sample (CxF3 objects).
    let mut file_origin = None;
    let mut sample_origins = BTreeMap::new();
    if matches!(format, Format::Cgats | Format::Csv) {
        // What the parsers hold grows with the lines (a few kB each): bounded before parsing.
        let lines = text.lines().count() as u64;
        opts.budget
            .check(budget::Limit::Records, file, "the whole file", lines)?;
    }
    let mut obs = match format {
        Format::Cgats => {
            let t = cgats::parse(file, text)?;
            file_origin = import::cgats_origin(file, &t);
            table::observations(&t, opts)?
        }
        Format::Csv => table::observations(&csv::parse(file, text)?, opts)?,
        Format::Cxf3 => {
            sample_origins = cxf3::origins(file, text);
            cxf3::observations(file, text, opts)?
        }
        Format::Json => return json::parse(file, text),
    };
    if let Some((sra_file, sra_text)) = sra {
        obs.extend(sra::observations(sra_file, sra_text, opts)?);
    }
    let mut scans = assemble(file, obs, opts)?;
    for scan in &mut scans {
        if scan.origin.is_none() {
            scan.origin = sample_origins
                .get(&scan.sample)
                .cloned()
                .or_else(|| file_origin.clone());
        }
    }
    Ok(scans)
}

/// The last component of a file's path as given (provenance names the file, not where it was).
pub(crate) fn file_name(file: &str) -> &str {
    Path::new(file)
        .file_name()
        .and_then(|n| n.to_str())
        .unwrap_or(file)
}

/// Reads a file into a string, naming it on failure.
pub fn read_text(path: &Path) -> Result<String, FormatError> {
    std::fs::read_to_string(path).map_err(|source| FormatError::Read {
        path: path.to_path_buf(),
        source,
    })
}

/// Whose reading a data row or object is.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum DataKind {
    /// The sample's device reading.
    Reading,
    /// The reference tile's device reading, taken for this sample's scan.
    Reference,
    /// Measured reflectance factor `R = π·M`, relative to the reference tile.
    Measured,
    /// The fitted model's reflectance factor `π·f`.
    Estimated,
    /// Lower end of the estimate's 95 % band: `π·(kd_lo(λ) + s_g)`, the bootstrap interval of
    /// kd plus the point fit's specular term (SCIENCE.md §11). Only for fits with intervals.
    EstimatedLow,
    /// Upper end, `π·(kd_hi(λ) + s_g)`.
    EstimatedHigh,
}

impl DataKind {
    pub const ALL: [DataKind; 6] = [
        DataKind::Reading,
        DataKind::Reference,
        DataKind::Measured,
        DataKind::Estimated,
        DataKind::EstimatedLow,
        DataKind::EstimatedHigh,
    ];

    pub const fn name(self) -> &'static str {
        match self {
            DataKind::Reading => "reading",
            DataKind::Reference => "reference",
            DataKind::Measured => "measured",
            DataKind::Estimated => "estimated",
            DataKind::EstimatedLow => "estimated_lo",
            DataKind::EstimatedHigh => "estimated_hi",
        }
    }
}

impl FromStr for DataKind {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        DataKind::ALL
            .into_iter()
            .find(|k| k.name() == s)
            .ok_or_else(|| {
                format!(
                    "unknown data kind \"{s}\"; valid: reading, reference, measured, estimated, \
                     estimated_lo, estimated_hi"
                )
            })
    }
}
#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::scan::DeviceReadings;
    use crate::spectral::BANDS;
    use crate::store::Provenance;
    use crate::study::tests::study_from_truth;

    /// Options with a fixed time, so exports are reproducible.
    pub(crate) fn fixed() -> ExportOptions {
        ExportOptions {
            created: "2024-05-01T12:00:00Z".into(),
            originator: "brdfd test".into(),
        }
    }

    pub(crate) fn study() -> Study {
        study_from_truth(3, Some(2))
    }

    /// [`study`] as loaded from a store: scan ids 11, 12, 13, measured by one real MA-T12
    /// (serial MT-7) and a simulated SRA, on station "bench-2".
    pub(crate) fn stored_study() -> Study {
        use crate::store::{InstrumentProvenance, Source};
        use crate::study::Origin;
        let mut s = study();
        for (i, sample) in s.samples.iter_mut().enumerate() {
            sample.scan_id = Some(11 + i as i64);
            sample.origin = Some(Origin {
                station: Some("bench-2".into()),
                measured_at_ms: 1_714_564_800_000 + 60_000 * i as i64,
                provenance: Provenance {
                    ma_t12: InstrumentProvenance {
                        model: "MA-T12".into(),
                        serial: "MT-7".into(),
                        firmware: "2.1.0".into(),
                        simulated: Some(false),
                        origin: crate::store::InstrumentOrigin::Measured,
                    },
                    sra: InstrumentProvenance {
                        model: "RA-532H".into(),
                        serial: "SIM-RA".into(),
                        firmware: "sim".into(),
                        simulated: Some(true),
                        origin: crate::store::InstrumentOrigin::Simulated,
                    },
                    source: Source::Measured,
                    source_detail: None,
                },
            });
        }
        s
    }

    /// The test study with made-up intervals on its first fit: kd ± 10 %.
    fn study_with_intervals() -> Study {
        let mut study = study();
        let crate::study::FitState::Done(d) = &mut study.samples[0].fits[0].state else {
            panic!("the first fit is done");
        };
        d.uncertainty = Some(crate::test_support::made_up_uncertainty(&d.params, true));
        study
    }

    #[test]
    fn intervals_travel_in_every_format_and_imports_skip_them() {
        let with = study_with_intervals();
        let r = rows(&with);
        let at = |kind: DataKind| {
            r.iter()
                .find(|x| x.kind == kind && x.geometry.name == "15as15")
                .unwrap()
                .values
        };
        let (lo, est, hi) = (
            at(DataKind::EstimatedLow),
            at(DataKind::Estimated),
            at(DataKind::EstimatedHigh),
        );
        let d = with.samples[0].fits[0].done().unwrap();
        let s = d.estimated[3][0] - d.params.kd[0];
        assert!((lo[0] - std::f64::consts::PI * (0.9 * d.params.kd[0] + s)).abs() < 1e-12);
        assert!((0..BANDS).all(|b| lo[b] < est[b] && est[b] < hi[b]));
        assert_eq!(r.len(), rows(&study()).len() + 2 * 14);
        let want: Vec<Scan> = with.samples.iter().map(|s| s.scan.clone()).collect();
        for format in Format::ALL {
            let text = export(&with, format, &fixed()).unwrap();
            if format == Format::Json {
                assert!(text.contains("\"uncertainty\"") && text.contains("\"colorimetry\""));
            } else if format == Format::Cxf3 {
                assert!(text.contains("EstimatedLow"));
                cxf3::tests::validate_with_xmllint(&text);
            } else {
                assert!(
                    text.contains("estimated_lo") || text.contains("EstimatedLow"),
                    "{format}"
                );
            }
            let got = import(format, "x", &text, None, &ImportOptions::default()).unwrap();
            assert_eq!(got.len(), want.len(), "{format}");
        }
    }

    #[test]
    fn every_format_round_trips_the_scans_bit_for_bit() {
        let study = study();
        let want: Vec<Scan> = study.samples.iter().map(|s| s.scan.clone()).collect();
        for format in Format::ALL {
            let text = export(&study, format, &fixed()).unwrap();
            let got = import(format, "x", &text, None, &ImportOptions::default())
                .unwrap_or_else(|e| panic!("{format}: {e}"));
            assert_eq!(got.len(), want.len(), "{format}");
            for (g, w) in got.iter().zip(&want) {
                // PartialEq on f64 would let -0.0 == 0.0 slip; compare bits.
                let bits = |s: &Scan| -> Vec<u64> {
                    let r = |d: &DeviceReadings| {
                        d.ma_t12
                            .iter()
                            .flatten()
                            .chain(d.sra.iter().flatten())
                            .map(|v| v.to_bits())
                            .collect::<Vec<_>>()
                    };
                    [r(&s.readings), r(&s.reference.as_ref().unwrap().readings)].concat()
                };
                assert_eq!(g, w, "{format}");
                assert_eq!(bits(g), bits(w), "{format}");
            }
        }
    }
}

/// What the property tests of each format share: the valid exports they mutate, and the check
/// that an import either names a problem or returns scans that validate.
#[cfg(test)]
pub(crate) mod proptests {
    use std::sync::LazyLock;

    use super::*;
    use crate::scan::proptests::assert_names_a_problem;
    use crate::study::tests::study_from_truth;
    use proptest::prelude::*;

    /// A two-sample study (the second with a failed fit) exported in every format, made once:
    /// small enough that a few edits often land somewhere that matters.
    static EXPORTS: LazyLock<Vec<(Format, String)>> = LazyLock::new(|| {
        let study = study_from_truth(2, Some(1));
        Format::ALL
            .into_iter()
            .map(|f| (f, export(&study, f, &tests::fixed()).unwrap()))
            .collect()
    });

    /// The scans of that study.
    pub(crate) static SCANS: LazyLock<Vec<Scan>> = LazyLock::new(|| {
        study_from_truth(2, Some(1))
            .samples
            .into_iter()
            .map(|s| s.scan)
            .collect()
    });

    /// The export of the study in `format`.
    pub(crate) fn valid(format: Format) -> &'static str {
        let (_, text) = EXPORTS
            .iter()
            .find(|(f, _)| *f == format)
            .expect("every format is exported");
        text
    }

    /// Imports `text` (with `sra` as the SRA CSV, if given): an error must name a problem, and
    /// every scan of an accepted file must validate.
    pub(crate) fn check_import(
        format: Format,
        text: &str,
        sra: Option<&str>,
    ) -> Result<(), TestCaseError> {
        let sra = sra.map(|s| ("s.csv", s));
        match import(format, "x", text, sra, &ImportOptions::default()) {
            Err(e) => assert_names_a_problem(&e)?,
            Ok(scans) => {
                for s in scans {
                    if let Err(e) = s.validate() {
                        return Err(TestCaseError::fail(format!(
                            "{format}: accepted sample \"{}\" that does not validate: {e}",
                            s.sample
                        )));
                    }
                }
            }
        }
        Ok(())
    }

    /// Text made of `pieces` (a format's keywords, names, numbers and punctuation), which gets
    /// further into a parser than arbitrary characters do.
    pub(crate) fn soup(pieces: &'static [&'static str]) -> impl Strategy<Value = String> {
        proptest::collection::vec(proptest::sample::select(pieces), 0..64).prop_map(|p| p.concat())
    }

    /// The import properties of a text format: arbitrary text, text made of the format's
    /// `pieces` (the test `$pieces_test`) and mutations of its valid export are each rejected
    /// naming a problem or read into scans that validate.
    macro_rules! import_properties {
        ($format:expr, $pieces_test:ident, $pieces:expr) => {
            proptest::proptest! {
                #![proptest_config(crate::test_support::proptest_config())]

                #[test]
                fn arbitrary_text_is_rejected_or_valid(
                    text in proptest::prelude::any::<String>()
                ) {
                    $crate::formats::proptests::check_import($format, &text, None)?;
                }

                #[test]
                fn $pieces_test(text in $crate::formats::proptests::soup($pieces)) {
                    $crate::formats::proptests::check_import($format, &text, None)?;
                }

                #[test]
                fn a_mutated_export_is_rejected_or_valid(
                    ms in $crate::scan::proptests::mutations()
                ) {
                    let text = $crate::scan::proptests::apply(
                        $crate::formats::proptests::valid($format),
                        &ms,
                    );
                    $crate::formats::proptests::check_import($format, &text, None)?;
                }
            }
        };
    }
    pub(crate) use import_properties;

    #[test]
    fn the_valid_exports_import() {
        for format in Format::ALL {
            let got = import(format, "x", valid(format), None, &ImportOptions::default())
                .unwrap_or_else(|e| panic!("{format}: {e}"));
            assert_eq!(got, *SCANS, "{format}");
        }
    }
}
