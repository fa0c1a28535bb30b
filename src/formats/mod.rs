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

pub mod certificate;
pub mod cgats;
pub mod csv;
pub mod cxf3;
pub mod gltf;
pub mod json;
pub mod mitsuba;
pub mod sra;
mod table;
pub mod tidy;
pub mod xrite;
pub mod xrite_xlsx;

use std::collections::BTreeMap;
use std::fmt;
use std::path::{Path, PathBuf};
use std::str::FromStr;

use crate::cost::CostFunction;
use crate::geometry::{Device, GEOMETRIES, GEOMETRY_COUNT, Geometry, MA_T12_COUNT};
use crate::scan::{DeviceReadings, Origin, OriginInstrument, Reference, Scan, ScanError};
use crate::spectral::{BANDS, Spectrum};
use crate::store::Provenance;
use crate::study::{DoneFit, SampleStudy, Study};

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
    #[error("cannot write {}: {source}", path.display())]
    Write {
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
}

impl Default for ImportOptions {
    fn default() -> Self {
        ImportOptions {
            reference: DEFAULT_REFERENCE.to_string(),
        }
    }
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
    let mut obs = match format {
        Format::Cgats => {
            let t = cgats::parse(file, text)?;
            file_origin = cgats_origin(file, &t);
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

/// A time as an instrument's export writes it, as RFC 3339 UTC: RFC 3339 itself, or a civil
/// ISO 8601 date and time without an offset, which is taken as UTC (`None` otherwise).
pub(crate) fn export_time(text: &str) -> Option<(String, bool)> {
    let text = text.trim();
    if let Ok(t) = text.parse::<jiff::Timestamp>() {
        return Some((t.to_string(), true));
    }
    let civil: jiff::civil::DateTime = text.parse().ok()?;
    let t = jiff::tz::TimeZone::UTC.to_timestamp(civil).ok()?;
    Some((t.to_string(), false))
}

impl Origin {
    /// Keeps an export's creation time as the measurement time (RFC 3339 UTC; a time without
    /// an offset is taken as UTC and the notes say so), or, when it is no time brdfd reads, as
    /// a note.
    pub(crate) fn note_created(&mut self, created: &str) {
        match export_time(created) {
            Some((at, offset)) => {
                self.measured_at = Some(at);
                if !offset {
                    self.notes
                        .insert("time zone".into(), "none stated; taken as UTC".into());
                }
            }
            None => {
                self.notes
                    .insert("created".into(), created.trim().to_string());
            }
        }
    }
}

/// What an instrument's CGATS export says in its header of where its readings came from:
/// `CREATED` (when it was written, as the measurement time), `INSTRUMENTATION` (the
/// instrument: a real one) and `ORIGINATOR` (the software). brdfd's own exports (with a
/// `DATA_KIND` column) carry their provenance per row and get none.
fn cgats_origin(file: &str, t: &table::Table) -> Option<Origin> {
    if t.is_brdfd_export() {
        return None;
    }
    let mut origin = Origin {
        source: Some(format!("CGATS export {}", file_name(file))),
        ..Origin::default()
    };
    if let Some(created) = t.keyword("CREATED") {
        origin.note_created(created);
    }
    if let Some(instrument) = t
        .keyword("INSTRUMENTATION")
        .filter(|i| !i.trim().is_empty())
    {
        origin.ma_t12 = Some(OriginInstrument {
            model: instrument.trim().to_string(),
            serial: t
                .keyword("SERIAL_NUMBER")
                .map(|s| s.trim().to_string())
                .filter(|s| !s.is_empty()),
            simulated: false,
        });
    }
    if let Some(originator) = t.keyword("ORIGINATOR") {
        origin
            .notes
            .insert("originator".into(), originator.to_string());
    }
    Some(origin)
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
/// `unknown`). A study made in memory (`brdfd demo`) has no scan id, station or time (empty)
/// and `unknown` instruments.
pub const PROVENANCE_FIELDS: [&str; 12] = [
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

/// Where a value was read.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Location {
    pub file: String,
    pub line: usize,
}

/// Whose reading an imported value is.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Owner {
    /// A sample's own reading.
    Sample(String),
    /// The reference reading taken for one sample's scan (brdfd's exports), with the tile's name.
    ReferenceOf { sample: String, tile: String },
    /// The reference tile of every sample in the file (an instrument's export).
    SharedReference,
}

/// An imported value.
// 248 bytes against 8: kept inline, as the store's `ReadingValues` is; most values are spectra.
#[allow(clippy::large_enum_variant)]
#[derive(Debug, Clone, PartialEq)]
pub enum Value {
    Spectrum(Spectrum),
    Intensity(f64),
}

/// One imported reading, before the scans are assembled.
#[derive(Debug, Clone, PartialEq)]
pub struct Observation {
    pub owner: Owner,
    pub geometry: &'static Geometry,
    pub value: Value,
    pub at: Location,
    /// How to name the value in an error: one name for the whole value (`ReflectanceSpectrum`,
    /// `intensity`), or one per band (`SPECTRAL_NM400` … `SPECTRAL_NM700`).
    pub fields: Vec<String>,
}

/// Parses a number as a field value, naming the field and line if it is not one.
pub(crate) fn parse_number(
    file: &str,
    line: usize,
    field: &str,
    text: &str,
) -> Result<f64, FormatError> {
    let t = text.trim();
    match t.parse::<f64>() {
        Ok(v) if v.is_finite() => Ok(v),
        Ok(v) => Err(FormatError::invalid(
            file,
            line,
            field,
            format!("{v} is not a finite number"),
        )),
        Err(_) => Err(FormatError::invalid(
            file,
            line,
            field,
            format!("\"{t}\" is not a number"),
        )),
    }
}

/// Looks a geometry name up (SCIENCE.md §2), or says which names are valid.
pub(crate) fn geometry_named(
    file: &str,
    line: usize,
    field: &str,
    name: &str,
) -> Result<&'static Geometry, FormatError> {
    crate::geometry::by_name(name.trim()).ok_or_else(|| {
        let valid: Vec<&str> = GEOMETRIES.iter().map(|g| g.name).collect();
        FormatError::invalid(
            file,
            line,
            field,
            format!(
                "unknown geometry \"{}\"; brdfd's geometry names are {}",
                name.trim(),
                valid.join(", ")
            ),
        )
    })
}

/// Slots for the 14 readings of one surface, with where each came from.
struct Slots {
    values: Vec<Option<(Value, Location, Vec<String>)>>,
}

impl Slots {
    fn new() -> Slots {
        Slots {
            values: vec![None; GEOMETRY_COUNT],
        }
    }

    fn put(&mut self, who: &str, o: Observation) -> Result<(), FormatError> {
        let slot = &mut self.values[o.geometry.index];
        if let Some((_, first, _)) = slot {
            return Err(FormatError::invalid(
                &o.at.file,
                o.at.line,
                field_name(&o.fields, None),
                format!(
                    "{who} at geometry {} given twice (first at {}:{})",
                    o.geometry.name, first.file, first.line
                ),
            ));
        }
        *slot = Some((o.value, o.at, o.fields));
        Ok(())
    }

    /// The readings, checked value by value against `role`'s rule, or what is missing.
    fn readings(
        &self,
        file: &str,
        who: &str,
        reference: bool,
    ) -> Result<DeviceReadings, FormatError> {
        let mut ma_t12 = [[0.0; BANDS]; MA_T12_COUNT];
        let mut sra = [0.0; crate::geometry::SRA_COUNT];
        for g in &GEOMETRIES {
            let Some((value, at, fields)) = &self.values[g.index] else {
                let source = match g.device {
                    Device::MaT12 => "the MA-T12 file",
                    Device::Sra => "the file or the SRA CSV (--sra)",
                };
                return Err(FormatError::Missing {
                    file: file.to_string(),
                    message: format!(
                        "{who}: no reading at geometry {} ({}); expected in {source}",
                        g.name, g.device
                    ),
                });
            };
            let check = |v: f64, band: Option<usize>| -> Result<f64, FormatError> {
                let ok = if reference { v > 0.0 } else { v >= 0.0 };
                if ok {
                    return Ok(v);
                }
                let at_band = band
                    .map(|b| format!(" at {} nm", crate::spectral::wavelengths_nm()[b]))
                    .unwrap_or_default();
                let rule = if reference {
                    "a reference reading must be positive; re-measure the reference tile"
                } else {
                    "a device reading cannot be negative"
                };
                Err(FormatError::invalid(
                    &at.file,
                    at.line,
                    field_name(fields, band),
                    format!("{who} at {}{at_band}: {v}: {rule}", g.name),
                ))
            };
            match (g.device, value) {
                (Device::MaT12, Value::Spectrum(s)) => {
                    for (b, &v) in s.iter().enumerate() {
                        check(v, Some(b))?;
                    }
                    ma_t12[g.index] = *s;
                }
                (Device::MaT12, Value::Intensity(_)) => {
                    return Err(FormatError::invalid(
                        &at.file,
                        at.line,
                        field_name(fields, None),
                        format!(
                            "{who} at {}: the MA-T12 reports a 31-band spectrum, not a single value",
                            g.name
                        ),
                    ));
                }
                (Device::Sra, Value::Intensity(v)) => {
                    sra[g.index - MA_T12_COUNT] = check(*v, None)?;
                }
                (Device::Sra, Value::Spectrum(s)) => {
                    // The SRA is achromatic: brdfd writes its value in every band.
                    if s.iter().any(|v| v.to_bits() != s[0].to_bits()) {
                        return Err(FormatError::invalid(
                            &at.file,
                            at.line,
                            field_name(fields, None),
                            format!(
                                "{who} at {}: the SRA reports one achromatic value; the 31 bands must be equal",
                                g.name
                            ),
                        ));
                    }
                    sra[g.index - MA_T12_COUNT] = check(s[0], None)?;
                }
            }
        }
        Ok(DeviceReadings {
            ma_t12,
            sra: Some(sra),
        })
    }
}

/// The name of band `band`'s field, or of the whole value.
fn field_name(fields: &[String], band: Option<usize>) -> String {
    band.and_then(|b| fields.get(b))
        .or(fields.first())
        .cloned()
        .unwrap_or_else(|| "value".into())
}

/// Builds one scan per sample from the observations of a file (and its SRA CSV), in order of
/// each sample's first appearance.
pub fn assemble(
    file: &str,
    obs: Vec<Observation>,
    opts: &ImportOptions,
) -> Result<Vec<Scan>, FormatError> {
    let mut order: Vec<String> = Vec::new();
    let mut samples: BTreeMap<String, Slots> = BTreeMap::new();
    let mut own_refs: BTreeMap<String, (Slots, String)> = BTreeMap::new();
    let mut shared = Slots::new();
    for o in obs {
        match o.owner.clone() {
            Owner::Sample(name) => {
                if !samples.contains_key(&name) {
                    order.push(name.clone());
                }
                let who = format!("sample \"{name}\"");
                samples
                    .entry(name)
                    .or_insert_with(Slots::new)
                    .put(&who, o)?;
            }
            Owner::ReferenceOf { sample, tile } => {
                let who = format!("reference \"{tile}\" of sample \"{sample}\"");
                let entry = own_refs
                    .entry(sample)
                    .or_insert_with(|| (Slots::new(), tile.clone()));
                if entry.1 != tile {
                    return Err(FormatError::invalid(
                        &o.at.file,
                        o.at.line,
                        field_name(&o.fields, None),
                        format!(
                            "reference tile \"{tile}\" differs from \"{}\" named before for the same sample",
                            entry.1
                        ),
                    ));
                }
                entry.0.put(&who, o)?;
            }
            Owner::SharedReference => {
                let who = format!("reference \"{}\"", opts.reference);
                shared.put(&who, o)?;
            }
        }
    }
    if order.is_empty() {
        return Err(FormatError::Missing {
            file: file.to_string(),
            message: format!(
                "no sample readings found (an instrument export needs objects other than the reference \"{}\")",
                opts.reference
            ),
        });
    }
    if let Some(orphan) = own_refs.keys().find(|s| !samples.contains_key(*s)) {
        return Err(FormatError::Missing {
            file: file.to_string(),
            message: format!("reference readings for sample \"{orphan}\" but no readings of it"),
        });
    }
    let mut scans = Vec::new();
    for name in order {
        let readings = samples[&name].readings(file, &format!("sample \"{name}\""), false)?;
        let (ref_slots, tile) = match own_refs.get(&name) {
            Some((slots, tile)) => (slots, tile.clone()),
            None => (&shared, opts.reference.clone()),
        };
        let ref_readings = ref_slots.readings(
            file,
            &format!("reference \"{tile}\" for sample \"{name}\""),
            true,
        )?;
        let scan = Scan {
            sample: name.clone(),
            reference: Some(Reference {
                name: tile,
                readings: ref_readings,
            }),
            readings,
            origin: None,
        };
        scan.validate().map_err(|source| FormatError::Scan {
            file: file.to_string(),
            sample: name,
            source,
        })?;
        scans.push(scan);
    }
    Ok(scans)
}

/// The current time as RFC 3339 UTC, whole seconds (`2024-05-01T12:00:00Z`).
pub fn rfc3339_utc_now() -> String {
    rfc3339_utc(crate::store::now_ms() / 1000)
}

/// Seconds since the Unix epoch → RFC 3339 UTC, whole seconds (e.g. `2024-05-01T12:00:00Z`).
pub fn rfc3339_utc(secs: i64) -> String {
    let format =
        time::macros::format_description!("[year]-[month]-[day]T[hour]:[minute]:[second]Z");
    time::OffsetDateTime::from_unix_timestamp(secs)
        .ok()
        .and_then(|t| t.format(&format).ok())
        .unwrap_or_else(|| format!("{secs} s after 1970-01-01T00:00:00Z"))
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
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
                    },
                    sra: InstrumentProvenance {
                        model: "RA-532H".into(),
                        serial: "SIM-RA".into(),
                        firmware: "sim".into(),
                        simulated: Some(true),
                    },
                    source: Source::Measured,
                    source_detail: None,
                },
            });
        }
        s
    }

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
                "yes"
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
    }

    fn rows_of_memory() -> Vec<SpectralRow> {
        rows(&study())
    }

    #[test]
    fn dates_are_rfc3339() {
        assert_eq!(rfc3339_utc(0), "1970-01-01T00:00:00Z");
        assert_eq!(rfc3339_utc(951_782_400), "2000-02-29T00:00:00Z");
        assert_eq!(rfc3339_utc(1_714_564_800), "2024-05-01T12:00:00Z");
        assert_eq!(rfc3339_utc(4_107_542_399), "2100-02-28T23:59:59Z");
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

    /// The test study with made-up intervals on its first fit: kd ± 10 %.
    fn study_with_intervals() -> Study {
        let mut study = study();
        let crate::study::FitState::Done(d) = &mut study.samples[0].fits[0].state else {
            panic!("the first fit is done");
        };
        let p = d.params;
        d.uncertainty = Some(crate::uncertainty::Uncertainty {
            method: crate::uncertainty::METHOD.into(),
            resamples: 200,
            noise: 0.014,
            seed: 1,
            ks: [p.ks * 0.8, p.ks * 1.2],
            alpha: [p.alpha * 0.8, p.alpha * 1.2],
            ior: [p.ior * 0.9, p.ior * 1.1],
            kd: p.kd.iter().map(|k| [k * 0.9, k * 1.1]).collect(),
            delta_e00_mean: [0.1, 0.2],
            delta_e00_diffuse_mean: [0.1, 0.2],
            delta_e00_specular_mean: Some([1.0, 2.0]),
            calibrated: true,
            note: None,
        });
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

    #[test]
    fn the_valid_exports_import() {
        for format in Format::ALL {
            let got = import(format, "x", valid(format), None, &ImportOptions::default())
                .unwrap_or_else(|e| panic!("{format}: {e}"));
            assert_eq!(got, *SCANS, "{format}");
        }
    }
}
