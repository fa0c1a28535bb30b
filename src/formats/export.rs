//! What an export holds: the spectral rows of a study (readings, reference, measured, and each
//! finished fit's estimate with its 95 % band) and the provenance every row carries.

use crate::cost::CostFunction;
use crate::geometry::{Device, GEOMETRIES, GEOMETRY_COUNT, Geometry};
use crate::scan::DeviceReadings;
use crate::spectral::{BANDS, Spectrum};
use crate::store::Provenance;
use crate::study::{DoneFit, SampleStudy, Study};

use super::DataKind;
use super::time::rfc3339_utc;

/// One spectrum of an export: a sample's data of one kind at one geometry.
#[derive(Debug, Clone, PartialEq)]
pub struct SpectralRow {
    pub sample: String,
    pub kind: DataKind,
    /// The reference tile's name.
    pub reference: String,
    /// Set for `estimated` rows.
    pub cost_function: Option<CostFunction>,
    /// Set for `estimated` rows.
    pub method: Option<String>,
    pub geometry: &'static Geometry,
    /// The sample's provenance, in [`PROVENANCE_FIELDS`] order.
    pub origin: [String; PROVENANCE_FIELDS.len()],
    pub values: Spectrum,
}

/// The provenance every spectral export carries per sample, by column name (CSV; CGATS upper-
/// cases them): the store's scan id, the station (central database only), when the scan was
/// measured (RFC 3339 UTC), how its readings came in (`measured`, `imported`, `replay`), and per
/// instrument its model, serial, firmware and whether it was simulated (`yes`, `no`,
/// `unknown`), then each instrument's origin (`measured`, `imported`, `simulated`, `absent`).
/// A study made in memory (`brdfd demo`) has no scan id, station or time (empty), `unknown`
/// instruments and an empty origin.
pub const PROVENANCE_FIELDS: [&str; 14] = [
    "scan_id",
    "station",
    "measured_at",
    "source",
    "ma_t12_model",
    "ma_t12_serial",
    "ma_t12_firmware",
    "ma_t12_simulated",
    "sra_model",
    "sra_serial",
    "sra_firmware",
    "sra_simulated",
    "ma_t12_origin",
    "sra_origin",
];

/// One sample's [`PROVENANCE_FIELDS`] values.
pub fn provenance_values(s: &SampleStudy) -> [String; PROVENANCE_FIELDS.len()] {
    let unknown = Provenance::unknown();
    let (station, measured_at, p) = match &s.origin {
        Some(o) => (
            o.station.clone().unwrap_or_default(),
            rfc3339_utc(o.measured_at_ms.div_euclid(1000)),
            &o.provenance,
        ),
        None => (String::new(), String::new(), &unknown),
    };
    let origin = |i: &crate::store::InstrumentProvenance| match &s.origin {
        Some(_) => i.origin.to_string(),
        None => String::new(),
    };
    let simulated = |v: Option<bool>| match v {
        Some(true) => "yes",
        Some(false) => "no",
        None => "unknown",
    };
    [
        s.scan_id.map_or(String::new(), |id| id.to_string()),
        station,
        measured_at,
        p.source.to_string(),
        p.ma_t12.model.clone(),
        p.ma_t12.serial.clone(),
        p.ma_t12.firmware.clone(),
        simulated(p.ma_t12.simulated).into(),
        p.sra.model.clone(),
        p.sra.serial.clone(),
        p.sra.firmware.clone(),
        simulated(p.sra.simulated).into(),
        origin(&p.ma_t12),
        origin(&p.sra),
    ]
}

/// Every spectrum of a study, per sample: readings, reference, measured, then each finished
/// fit's estimate, each over the 14 geometries in table order.
pub fn rows(study: &Study) -> Vec<SpectralRow> {
    let mut out = Vec::new();
    for s in &study.samples {
        let origin = provenance_values(s);
        // Rows only at the geometries the scan measured, and reference rows only for a tile.
        let geometries = s.scan.geometries();
        let mut push = |kind,
                        fit: Option<(CostFunction, &str)>,
                        spectra: [Option<Spectrum>; GEOMETRY_COUNT]| {
            for g in geometries.iter() {
                let Some(values) = spectra[g.index] else {
                    continue;
                };
                out.push(SpectralRow {
                    sample: s.name.clone(),
                    kind,
                    reference: s.scan.reference_label().to_string(),
                    cost_function: fit.map(|f| f.0),
                    method: fit.map(|f| f.1.to_string()),
                    geometry: g,
                    origin: origin.clone(),
                    values,
                });
            }
        };
        push(
            DataKind::Reading,
            None,
            GEOMETRIES.map(|g| device_spectrum(&s.scan.readings, &g)),
        );
        if let Some(reference) = &s.scan.reference {
            push(
                DataKind::Reference,
                None,
                GEOMETRIES.map(|g| device_spectrum(&reference.readings, &g)),
            );
        }
        push(
            DataKind::Measured,
            None,
            s.measured.values.map(|f| Some(reflectance(&f))),
        );
        for f in &s.fits {
            if let Some(d) = f.done() {
                push(
                    DataKind::Estimated,
                    Some((f.cost, f.method.as_str())),
                    d.estimated.map(|f| Some(reflectance(&f))),
                );
                if let Some([lo, hi]) = estimate_band(d) {
                    push(
                        DataKind::EstimatedLow,
                        Some((f.cost, f.method.as_str())),
                        lo.map(Some),
                    );
                    push(
                        DataKind::EstimatedHigh,
                        Some((f.cost, f.method.as_str())),
                        hi.map(Some),
                    );
                }
            }
        }
    }
    out
}

/// The 95 % band of a fit's estimated reflectance factor at each geometry, from its bootstrap
/// interval of kd and its point specular term: `π·(kd_lo + s_g)`, `π·(kd_hi + s_g)`.
/// `None` without intervals.
pub fn estimate_band(d: &DoneFit) -> Option<[[Spectrum; GEOMETRY_COUNT]; 2]> {
    let u = d.uncertainty.as_ref()?;
    if u.kd.len() != BANDS {
        return None;
    }
    // The point estimate minus kd is the specular term, the same in every band.
    let band = |end: usize| -> [Spectrum; GEOMETRY_COUNT] {
        std::array::from_fn(|g| {
            std::array::from_fn(|b| {
                let s = d.estimated[g][b] - d.params.kd[b];
                std::f64::consts::PI * (u.kd[b][end] + s)
            })
        })
    };
    Some([band(0), band(1)])
}

/// A device reading as a spectrum: the MA-T12's 31 bands, or the SRA's intensity in every band;
/// `None` at an SRA geometry of readings without SRA values.
pub fn device_spectrum(readings: &DeviceReadings, g: &Geometry) -> Option<Spectrum> {
    match g.device {
        Device::MaT12 => Some(readings.ma_t12[g.index]),
        Device::Sra => readings.intensity(g).map(|v| [v; BANDS]),
    }
}

/// BRDF (sr⁻¹) → reflectance factor, `R = π·f` (SCIENCE.md §7).
pub fn reflectance(f: &Spectrum) -> Spectrum {
    crate::colour::brdf_to_reflectance(f)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::formats::tests::{stored_study, study};

    #[test]
    fn every_spectral_row_carries_its_samples_provenance() {
        let rows = rows(&stored_study());
        let first = &rows[0];
        assert_eq!(
            first.origin,
            [
                "11",
                "bench-2",
                "2024-05-01T12:00:00Z",
                "measured",
                "MA-T12",
                "MT-7",
                "2.1.0",
                "no",
                "RA-532H",
                "SIM-RA",
                "sim",
                "yes",
                "measured",
                "simulated"
            ]
            .map(String::from)
        );
        let last = rows.last().unwrap();
        assert_eq!(last.origin[0], "13");
        assert_eq!(last.origin[2], "2024-05-01T12:02:00Z");
        // A study made in memory says it does not know.
        let mem = rows_of_memory();
        assert_eq!(mem[0].origin[0], "");
        assert_eq!(mem[0].origin[3], "unknown");
        assert_eq!(mem[0].origin[7], "unknown");
        assert_eq!(mem[0].origin[12], "");
    }

    fn rows_of_memory() -> Vec<SpectralRow> {
        rows(&study())
    }

    #[test]
    fn rows_cover_every_kind_and_geometry() {
        let study = study();
        let rows = rows(&study);
        // 3 samples × (reading + reference + measured) × 14, plus 8 finished fits × 14.
        assert_eq!(rows.len(), (3 * 3 + 8) * 14);
        let s = &study.samples[0];
        let r = &rows[12];
        assert_eq!((r.kind, r.geometry.name), (DataKind::Reading, "sra-20"));
        assert_eq!(r.values, [s.scan.readings.sra.unwrap()[0]; BANDS]);
        let m = rows
            .iter()
            .find(|r| r.kind == DataKind::Measured && r.geometry.name == "45as45")
            .unwrap();
        assert_eq!(m.values, reflectance(&s.measured.values[9]));
    }
}
