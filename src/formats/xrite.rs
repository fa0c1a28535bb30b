//! X-Rite's QC `.xlsx` export → scans ([`xrite_xlsx`] reads the file; this module owns what
//! brdfd makes of it).
//!
//! Each measurement becomes one scan (SCIENCE.md §3): the MA-T12's 12 readings as the
//! reflectance factor they are, relative to the instrument's own calibrated white standard
//! (reference "instrument calibration", `R = S`), no SRA readings, and an `origin` that keeps
//! what the file says — the measurement time, the MA-T12 (serial unknown unless the file states
//! one; never simulated), the job and standard names, the illuminant/observer, the file's
//! SHA-256 — and the result of the colorimetry check: brdfd recomputes X-Rite's L*a*b* from
//! the spectra (ASTM E308 weighting under the file's illuminant/observer) and records the
//! largest ΔE00; a geometry more than [`COLORIMETRY_THRESHOLD`] apart is a warning naming it
//! (the importer read the wrong column, or the file was edited).
//!
//! The file states no time zone: `Date/Time` is taken as UTC, and the notes say so.

use std::collections::BTreeMap;
use std::path::Path;

use super::budget::Budget;

use super::xrite_xlsx::{
    self, COLORIMETRY_THRESHOLD, ColorimetryCheck, TextureImage, XlsxError, XriteExport,
    XriteMeasurement,
};
use crate::scan::{DeviceReadings, Origin, OriginInstrument, Scan};

/// One measurement of an X-Rite export as a scan, with what the import found.
#[derive(Debug, Clone, PartialEq)]
pub struct XriteScan {
    /// The scan (no tile, no SRA readings, `origin` filled in).
    pub scan: Scan,
    /// brdfd's L*a*b* against the file's.
    pub check: ColorimetryCheck,
    /// The instrument camera's images of the measurement.
    pub textures: Vec<TextureImage>,
}

impl XriteScan {
    /// The warning for the operator when a geometry disagrees with the file's L*a*b*.
    pub fn warning(&self) -> Option<String> {
        (!self.check.flagged.is_empty()).then(|| {
            format!(
                "\"{}\": brdfd's L*a*b* differ from the file's by more than ΔE00 {COLORIMETRY_THRESHOLD} at {} (largest {:.4} at {}): the file may have been edited, or a column read wrongly",
                self.scan.sample,
                self.check.flagged.join(", "),
                self.check.largest,
                self.check.largest_at
            )
        })
    }
}

/// The scans of an export, one per measurement, in file order.
pub fn scans(export: &XriteExport) -> Result<Vec<XriteScan>, XlsxError> {
    export
        .measurements
        .iter()
        .map(|m| {
            let check = xrite_xlsx::check_colorimetry(m)?;
            Ok(XriteScan {
                scan: scan_of(export, m, &check),
                check,
                textures: m.textures.clone(),
            })
        })
        .collect()
}

/// Reads an export file within `budget` and turns it into scans.
pub fn read_file(path: &Path, budget: &Budget) -> Result<Vec<XriteScan>, XlsxError> {
    scans(&xrite_xlsx::read_file(path, budget)?)
}

/// Reads an export from its bytes within `budget` (`file_name` is named in errors) and turns
/// it into scans.
pub fn read(bytes: &[u8], file_name: &str, budget: &Budget) -> Result<Vec<XriteScan>, XlsxError> {
    scans(&xrite_xlsx::read(bytes, file_name, budget)?)
}

fn scan_of(export: &XriteExport, m: &XriteMeasurement, check: &ColorimetryCheck) -> Scan {
    let mut notes = BTreeMap::new();
    notes.insert("job".to_string(), m.job.clone());
    notes.insert("standard".to_string(), m.standard.clone());
    notes.insert(
        "illuminant/observer".to_string(),
        format!("{}/{}", m.illuminant, m.observer_deg),
    );
    notes.insert("sha256".to_string(), export.sha256_hex.clone());
    notes.insert(
        "date/time".to_string(),
        format!(
            "{} as the file states it ({}); no time zone stated, taken as UTC",
            m.measured_at, m.measured_at_text
        ),
    );
    notes.insert(
        "colorimetry check".to_string(),
        format!(
            "largest ΔE00 {:.2e} at {} against the file's L*a*b* ({}, ASTM E308){}",
            check.largest,
            check.largest_at,
            check.colorimetry,
            if check.flagged.is_empty() {
                String::new()
            } else {
                format!(
                    "; above {COLORIMETRY_THRESHOLD} at {}",
                    check.flagged.join(", ")
                )
            }
        ),
    );
    if let Some(color_name) = &m.color_data_name {
        notes.insert("color data name".to_string(), color_name.clone());
    }
    let measured_at = jiff::tz::TimeZone::UTC
        .to_timestamp(m.measured_at)
        .ok()
        .map(|t| t.to_string());
    Scan {
        sample: m.name.clone(),
        reference: None,
        readings: DeviceReadings {
            ma_t12: m.spectra,
            sra: None,
        },
        origin: Some(Origin {
            measured_at,
            ma_t12: Some(OriginInstrument {
                model: "MA-T12".to_string(),
                serial: m.instrument_serial.clone(),
                simulated: false,
            }),
            sra: None,
            source: Some(format!("X-Rite QC export {}", export.file_name)),
            notes,
        }),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::GeometrySet;

    fn real(name: &str) -> Vec<u8> {
        std::fs::read(
            Path::new(env!("CARGO_MANIFEST_DIR"))
                .join(super::super::xrite_xlsx::REAL_EXPORTS_DIR)
                .join(name),
        )
        .unwrap()
    }

    #[test]
    fn a_real_export_becomes_an_instrument_calibration_scan_that_round_trips() {
        let scans = read(
            &real("PAR_PW_RO_NG_1.xlsx"),
            "PAR_PW_RO_NG_1.xlsx",
            &Budget::default(),
        )
        .unwrap();
        assert_eq!(scans.len(), 1);
        let s = &scans[0];
        assert!(s.scan.reference.is_none());
        assert_eq!(s.scan.geometries(), GeometrySet::MA_T12);
        assert!(s.check.largest <= 1e-3, "{:?}", s.check);
        assert!(s.warning().is_none());
        let origin = s.scan.origin.as_ref().unwrap();
        assert_eq!(origin.ma_t12.as_ref().unwrap().model, "MA-T12");
        assert!(!origin.ma_t12.as_ref().unwrap().simulated);
        assert_eq!(origin.notes["illuminant/observer"], "D65/10");
        assert_eq!(origin.notes["sha256"].len(), 64);
        let ms = origin.measured_at_ms().unwrap().unwrap();
        // August 2024, as the database says.
        let t = jiff::Timestamp::from_millisecond(ms).unwrap().to_string();
        assert!(t.starts_with("2024-08"), "{t}");
        // The scan file carries all of it, and reads back the same.
        let text = s.scan.to_json_pretty().unwrap();
        assert_eq!(Scan::from_json(text.as_bytes()).unwrap(), s.scan);
    }
}
