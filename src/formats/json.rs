//! The whole study as one JSON document, `brdfd.study/1`: per sample the scan (embedded as a
//! `brdfd.scan/1` object, ARCHITECTURE.md contract 2), the specular strategy, the measured
//! reflectance factor per geometry and every fit (status, method, Fresnel cosine, parameters,
//! estimated reflectance factor and ΔE00 per geometry) and, for a stored scan, its `origin`:
//! station, time and the instruments' provenance. Numbers are serde_json's shortest
//! round-trip form.
//!
//! Import reads the scans back from a `brdfd.study/1` document, or takes a lone
//! `brdfd.scan/1` document as one scan.

use serde::Serialize;
use serde::ser::Serializer;

use super::{ExportOptions, FormatError, reflectance};
use crate::geometry::{GEOMETRIES, GEOMETRY_COUNT};
use crate::scan::Scan;
use crate::spectral::Spectrum;
use crate::study::{FitState, Study};

/// The format tag of the study document.
pub const FORMAT: &str = "brdfd.study/1";

/// One spectrum per geometry, written as an object keyed by geometry name in table order.
struct PerGeometry<'a, T>(&'a [T; GEOMETRY_COUNT]);

impl<T: Serialize> Serialize for PerGeometry<'_, T> {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.collect_map(GEOMETRIES.iter().map(|g| g.name).zip(self.0.iter()))
    }
}

#[derive(Serialize)]
struct Doc<'a> {
    format: &'static str,
    originator: &'a str,
    created: &'a str,
    /// Units, for a reader who opens the file without the docs.
    units: &'static str,
    samples: Vec<SampleDoc<'a>>,
}

#[derive(Serialize)]
struct SampleDoc<'a> {
    name: &'a str,
    scan_id: Option<i64>,
    /// Where, when and by which instruments the scan was measured (stored studies only).
    #[serde(skip_serializing_if = "Option::is_none")]
    origin: Option<OriginDoc<'a>>,
    scan: serde_json::Value,
    specular_strategy: crate::processing::SpecularStrategy,
    /// "absolute" (calibrated reference tile), "relative-to-tile" or "instrument-calibration"
    /// (no tile: the instrument's own calibrated scale; SCIENCE.md §3).
    scale: &'static str,
    /// The tile's calibrated reflectance the readings were normalised with, if any.
    #[serde(skip_serializing_if = "Option::is_none")]
    reference_reflectance: Option<Spectrum>,
    measured_reflectance: PerGeometry<'a, Spectrum>,
    fits: Vec<FitDoc<'a>>,
}

#[derive(Serialize)]
struct OriginDoc<'a> {
    #[serde(skip_serializing_if = "Option::is_none")]
    station: Option<&'a str>,
    /// RFC 3339 UTC.
    measured_at: String,
    /// Per instrument model, serial, firmware and `simulated`; `source` and `source_detail`.
    provenance: &'a crate::store::Provenance,
}

#[derive(Serialize)]
struct FitDoc<'a> {
    cost_function: crate::cost::CostFunction,
    method: &'a str,
    status: &'a str,
    #[serde(skip_serializing_if = "Option::is_none")]
    reason: Option<&'a str>,
    #[serde(skip_serializing_if = "Option::is_none")]
    fresnel: Option<crate::model::FresnelCosine>,
    #[serde(skip_serializing_if = "Option::is_none")]
    params: Option<&'a crate::model::Params>,
    #[serde(skip_serializing_if = "Option::is_none")]
    estimated_reflectance: Option<PerGeometry<'a, Spectrum>>,
    #[serde(skip_serializing_if = "Option::is_none")]
    delta_e00: Option<PerGeometry<'a, f64>>,
    #[serde(skip_serializing_if = "Option::is_none")]
    delta_e00_mean: Option<f64>,
    /// The colorimetry of the ΔE00 values (SCIENCE.md §7.1).
    #[serde(skip_serializing_if = "Option::is_none")]
    colorimetry: Option<crate::colour::Colorimetry>,
    /// The bootstrap intervals, as in `brdfd fit --json` (SCIENCE.md §10).
    #[serde(skip_serializing_if = "Option::is_none")]
    uncertainty: Option<&'a crate::uncertainty::Uncertainty>,
    /// The SRA reading model of the fit's cost (SCIENCE.md §5.1).
    #[serde(skip_serializing_if = "Option::is_none")]
    sra: Option<crate::sra_reading::SraReading>,
    /// Specular |ΔL*| at the SRA geometries, as in `brdfd fit --json` (SCIENCE.md §7.2).
    #[serde(skip_serializing_if = "Option::is_none")]
    specular_delta_l: Option<crate::fit::SpecularDeltaLDocument>,
}

/// The study as a `brdfd.study/1` document.
pub fn write(study: &Study, opts: &ExportOptions) -> Result<String, FormatError> {
    let measured: Vec<[Spectrum; GEOMETRY_COUNT]> = study
        .samples
        .iter()
        .map(|s| s.measured.values.map(|f| reflectance(&f)))
        .collect();
    let estimated: Vec<Vec<Option<[Spectrum; GEOMETRY_COUNT]>>> = study
        .samples
        .iter()
        .map(|s| {
            s.fits
                .iter()
                .map(|f| f.done().map(|d| d.estimated.map(|f| reflectance(&f))))
                .collect()
        })
        .collect();
    let mut samples = Vec::new();
    for (i, s) in study.samples.iter().enumerate() {
        let scan_text = s
            .scan
            .to_json_pretty()
            .map_err(|e| FormatError::Unwritable {
                format: "json",
                message: format!("sample \"{}\": {e}", s.name),
            })?;
        let scan: serde_json::Value =
            serde_json::from_str(&scan_text).expect("a scan document is JSON");
        let fits = s
            .fits
            .iter()
            .zip(&estimated[i])
            .map(|(f, est)| {
                let d = f.done();
                let (status, reason) = match &f.state {
                    FitState::Done(_) => ("done", None),
                    FitState::Failed { reason } => ("failed", Some(reason.as_str())),
                    FitState::Unfinished { status } => (status.as_str(), None),
                };
                FitDoc {
                    cost_function: f.cost,
                    method: &f.method,
                    status,
                    reason,
                    fresnel: d.map(|d| d.fresnel),
                    params: d.map(|d| &d.params),
                    estimated_reflectance: est.as_ref().map(PerGeometry),
                    delta_e00: d.map(|d| PerGeometry(&d.evaluation.per_geometry)),
                    delta_e00_mean: d.map(|d| d.evaluation.all.mean),
                    colorimetry: d.map(|d| d.colorimetry),
                    uncertainty: d.and_then(|d| d.uncertainty.as_ref()),
                    sra: d.map(|d| d.sra),
                    specular_delta_l: d.and_then(|d| d.specular_delta_l.map(Into::into)),
                }
            })
            .collect();
        samples.push(SampleDoc {
            name: &s.name,
            scan_id: s.scan_id,
            origin: s.origin.as_ref().map(|o| OriginDoc {
                station: o.station.as_deref(),
                measured_at: super::rfc3339_utc(o.measured_at_ms.div_euclid(1000)),
                provenance: &o.provenance,
            }),
            scan,
            specular_strategy: s.specular,
            scale: s.scale().name(),
            reference_reflectance: s.reference_reflectance,
            measured_reflectance: PerGeometry(&measured[i]),
            fits,
        });
    }
    let doc = Doc {
        format: FORMAT,
        originator: &opts.originator,
        created: &opts.created,
        units: "readings as in brdfd.scan/1; *_reflectance: reflectance factor pi*f per band, 400-700 nm every 10 nm; params.kd in 1/sr",
        samples,
    };
    let mut text = serde_json::to_string_pretty(&doc).map_err(|e| FormatError::Unwritable {
        format: "json",
        message: e.to_string(),
    })?;
    text.push('\n');
    Ok(text)
}

/// The scans in a `brdfd.study/1` or `brdfd.scan/1` document.
pub(crate) fn parse(file: &str, text: &str) -> Result<Vec<Scan>, FormatError> {
    let syntax = |e: serde_json::Error, field: &str| {
        FormatError::invalid(file, e.line().max(1), field, e.to_string())
    };
    let value: serde_json::Value = serde_json::from_str(text).map_err(|e| syntax(e, "json"))?;
    let scan_of = |v: &serde_json::Value, path: &str, sample: &str| -> Result<Scan, FormatError> {
        let bytes = serde_json::to_vec(v).expect("a JSON value serialises");
        Scan::from_json(&bytes).map_err(|source| match source {
            // The field path inside the scan is in the message; say where the scan is.
            crate::scan::ScanError::Shape { field, message } => FormatError::Missing {
                file: file.to_string(),
                message: format!("{path}: {field}: {message}"),
            },
            source => FormatError::Scan {
                file: file.to_string(),
                sample: sample.to_string(),
                source,
            },
        })
    };
    match value.get("format").and_then(|f| f.as_str()) {
        Some(crate::scan::FORMAT) => Ok(vec![scan_of(&value, "scan", "")?]),
        Some(FORMAT) => {
            let samples = value
                .get("samples")
                .and_then(|s| s.as_array())
                .ok_or_else(|| FormatError::Missing {
                    file: file.to_string(),
                    message: "samples: missing; a brdfd.study/1 document lists its samples".into(),
                })?;
            samples
                .iter()
                .enumerate()
                .map(|(i, s)| {
                    let name = s.get("name").and_then(|n| n.as_str()).unwrap_or("");
                    let scan = s.get("scan").ok_or_else(|| FormatError::Missing {
                        file: file.to_string(),
                        message: format!("samples[{i}].scan: missing"),
                    })?;
                    scan_of(scan, &format!("samples[{i}].scan"), name)
                })
                .collect()
        }
        other => Err(FormatError::Missing {
            file: file.to_string(),
            message: format!(
                "format: {}; expected \"{FORMAT}\" or \"{}\"",
                other.map_or("missing".to_string(), |f| format!("unknown \"{f}\"")),
                crate::scan::FORMAT
            ),
        }),
    }
}

#[cfg(test)]
mod tests {
    use super::super::tests::{fixed, study};
    use super::*;

    #[test]
    fn the_document_carries_fits_and_failures() {
        let text = write(&study(), &fixed()).unwrap();
        let v: serde_json::Value = serde_json::from_str(&text).unwrap();
        assert_eq!(v["format"], FORMAT);
        let s2 = &v["samples"][2];
        assert_eq!(s2["fits"][2]["status"], "failed");
        assert_eq!(s2["fits"][2]["reason"], "cancelled by the operator");
        assert!(s2["fits"][2].get("params").is_none());
        assert_eq!(s2["fits"][0]["params"]["kd"].as_array().unwrap().len(), 31);
        let keys: Vec<&String> = s2["measured_reflectance"]
            .as_object()
            .unwrap()
            .keys()
            .collect();
        assert_eq!(keys.len(), 14);
        assert_eq!(s2["scan"]["format"], crate::scan::FORMAT);
    }

    #[test]
    fn bad_documents_are_rejected_naming_file_line_and_field() {
        let good = write(&study(), &fixed()).unwrap();
        let e = parse("s.json", &good.replacen('{', "[", 1))
            .unwrap_err()
            .to_string();
        assert!(e.starts_with("s.json:"), "{e}");
        let e = parse("s.json", "{\"format\": \"brdfd.study/9\"}")
            .unwrap_err()
            .to_string();
        assert_eq!(
            e,
            "s.json: format: unknown \"brdfd.study/9\"; expected \"brdfd.study/1\" or \"brdfd.scan/1\""
        );
        let bad = good.replacen("\"name\": \"Munsell N9\"", "\"name\": \"\"", 1);
        let e = parse("s.json", &bad).unwrap_err().to_string();
        assert_eq!(
            e,
            "s.json: sample \"T.Freesia pink\": reference.name: must not be empty"
        );
        let mut v: serde_json::Value = serde_json::from_str(&good).unwrap();
        v["samples"][1]["scan"]["readings"]["sra"]["sra-60"] = "high".into();
        let e = parse("s.json", &v.to_string()).unwrap_err().to_string();
        assert!(
            e.starts_with(
                "s.json: samples[1].scan: readings.sra.sra-60: invalid type: string \"high\""
            ),
            "{e}"
        );
    }
}

/// Property tests: whatever text arrives as JSON, the import returns (never panics), an error
/// names a problem, and the scans of an accepted document validate.
#[cfg(test)]
mod proptests {
    use super::super::Format;
    use super::super::proptests::import_properties;

    const PIECES: [&str; 28] = [
        "{",
        "}",
        "[",
        "]",
        ",",
        ":",
        "\"format\"",
        "\"brdfd.study/1\"",
        "\"brdfd.scan/1\"",
        "\"samples\"",
        "\"scan\"",
        "\"name\"",
        "\"sample\"",
        "\"readings\"",
        "\"reference\"",
        "\"ma_t12\"",
        "\"sra\"",
        "\"sra-20\"",
        "\"wavelengths_nm\"",
        "\"\"",
        "null",
        "true",
        "1",
        "-1",
        "0.5",
        "1e999",
        " ",
        "\n",
    ];

    import_properties!(Format::Json, json_pieces_are_rejected_or_valid, &PIECES);
}
