//! The scan file, `brdfd.scan/1` (ARCHITECTURE.md contract 2): how one scan — a sample's 14
//! readings and the Munsell N9 reference readings they are normalised by — leaves and enters
//! brdfd outside the store.
//!
//! A scan from an instrument's own software may lack parts, and the file says so explicitly
//! (never by zeros or NaN): `"reference": "instrument-calibration"` when there is no N9 reading
//! (the MA-T12's reflectance factor is then relative to the instrument's own calibrated white
//! standard, absolute scale), and `"sra": "not-measured"` when there are no SRA readings (the
//! scan has the 12 MA-T12 geometries only). Files without these keep reading as they always did.
//!
//! On disk the readings are JSON maps keyed by the devices' geometry names (SCIENCE.md §2), with
//! the 31-band grid spelled out in `wavelengths_nm`. In memory they are fixed-size arrays in
//! [`GEOMETRIES`] table order, so nothing downstream looks a name up again.
//!
//! Reading is two-staged (raw serde structs → checked [`Scan`]): the raw stage reports JSON shape
//! errors with the path of the offending field, the checked stage reports every semantic problem
//! (format version, geometry set, lengths, grid, non-finite or non-physical values) with the field
//! named as `readings.ma_t12.15as-45[3] (430 nm)`. Writing goes through the same validation, so a
//! NaN can never be written as `null`, and reproduces every `f64` bit for bit (shortest round-trip
//! decimal out, correctly rounded parse in: serde_json's `float_roundtrip`).

use std::fmt;
use std::io::{self, Read};
use std::path::{Path, PathBuf};

use serde::de::{Deserializer, MapAccess, Visitor};
use serde::ser::Serializer;
use serde::{Deserialize, Serialize};

use crate::geometry::{self, Device, GEOMETRIES, Geometry, GeometrySet, MA_T12_COUNT, SRA_COUNT};
use crate::spectral::{BANDS, Spectrum, wavelengths_nm};

/// The format tag this build reads and writes.
pub const FORMAT: &str = "brdfd.scan/1";

/// The value of `"reference"` for a scan normalised by the instrument's own white calibration.
pub const INSTRUMENT_CALIBRATION: &str = "instrument-calibration";

/// The value of an `"sra"` field when the scan has no SRA readings.
pub const SRA_NOT_MEASURED: &str = "not-measured";

/// How the reference of a scan reads for people: the tile's name, or "instrument calibration".
pub const INSTRUMENT_CALIBRATION_LABEL: &str = "instrument calibration";

/// One scan: the sample's readings and the reference readings in force when it was taken.
#[derive(Debug, Clone, PartialEq)]
pub struct Scan {
    /// The sample's name, e.g. "T.Freesia pink".
    pub sample: String,
    /// The white reference (Munsell N9) the readings are normalised by; `None` when the MA-T12
    /// values are already the reflectance factor relative to the instrument's own calibrated
    /// white standard (an instrument-software export: `R = S`, absolute scale).
    pub reference: Option<Reference>,
    /// The sample's own readings.
    pub readings: DeviceReadings,
    /// Where the readings came from, when the file that brought them says (`"origin"`):
    /// an instrument-software export's measurement time, instrument and source file.
    pub origin: Option<Origin>,
}

/// What a scan file says of where its readings came from (`"origin"`, optional). Imports
/// keep it: the measurement time becomes the scan's time, the instrument its provenance.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Origin {
    /// When the instrument took the readings, RFC 3339 (e.g. `2024-08-12T10:31:07Z`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub measured_at: Option<String>,
    /// The MA-T12 that measured it, as the file names it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub ma_t12: Option<OriginInstrument>,
    /// The SRA that measured it, as the file names it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sra: Option<OriginInstrument>,
    /// What brought the readings in, e.g. `X-Rite QC export PAR_EW_RL_NG_3.xlsx`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub source: Option<String>,
    /// What else the source file states, by name (job, standard, illuminant/observer, the
    /// file's SHA-256, the colorimetry check), in name order.
    #[serde(default, skip_serializing_if = "std::collections::BTreeMap::is_empty")]
    pub notes: std::collections::BTreeMap<String, String>,
}

/// An instrument as a file names it.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct OriginInstrument {
    /// e.g. "MA-T12".
    pub model: String,
    /// `None` when the file does not say.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub serial: Option<String>,
    /// A simulated instrument (a replayed recording).
    #[serde(default)]
    pub simulated: bool,
}

impl Origin {
    /// `measured_at` as milliseconds since the epoch, or an error naming the field.
    pub fn measured_at_ms(&self) -> Result<Option<i64>, ScanError> {
        let Some(text) = &self.measured_at else {
            return Ok(None);
        };
        let t: jiff::Timestamp = text.parse().map_err(|e| ScanError::Shape {
            field: "origin.measured_at".into(),
            message: format!("\"{text}\" is not an RFC 3339 time ({e})"),
        })?;
        Ok(Some(t.as_millisecond()))
    }

    /// The notes as one line, `key value; key value`, for a provenance detail.
    pub fn describe(&self) -> String {
        let mut parts: Vec<String> = self.source.iter().cloned().collect();
        parts.extend(self.notes.iter().map(|(k, v)| format!("{k} {v}")));
        parts.join("; ")
    }
}

/// A white reference tile and its readings on both devices at all 14 geometries.
#[derive(Debug, Clone, PartialEq)]
pub struct Reference {
    /// The tile's name, e.g. "Munsell N9".
    pub name: String,
    /// Its readings; every value must be positive and finite (SCIENCE.md §3).
    pub readings: DeviceReadings,
}

/// Readings of one surface on both instruments, in [`GEOMETRIES`] table order.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DeviceReadings {
    /// X-Rite MA-T12: reflectance factor as the device reports it (0–1 scale), 31 bands each,
    /// for `GEOMETRIES[0..12]`.
    pub ma_t12: [Spectrum; MA_T12_COUNT],
    /// Canon RA-532H: one achromatic 1D-BRDF intensity each, for `GEOMETRIES[12..14]`;
    /// `None` when the SRA was not measured.
    pub sra: Option<[f64; SRA_COUNT]>,
}

impl Scan {
    /// The geometries this scan measured: all 14, or the 12 MA-T12 ones without SRA readings.
    pub fn geometries(&self) -> GeometrySet {
        self.readings.geometries()
    }

    /// The reference as people read it: the tile's name, or "instrument calibration".
    pub fn reference_label(&self) -> &str {
        self.reference
            .as_ref()
            .map_or(INSTRUMENT_CALIBRATION_LABEL, |r| r.name.as_str())
    }
}

impl DeviceReadings {
    /// The MA-T12 spectrum at a geometry of that device (`None` for an SRA geometry).
    pub fn spectrum(&self, geo: &Geometry) -> Option<&Spectrum> {
        match geo.device {
            Device::MaT12 => self.ma_t12.get(geo.index),
            Device::Sra => None,
        }
    }

    /// The SRA intensity at a geometry of that device (`None` for an MA-T12 geometry).
    pub fn intensity(&self, geo: &Geometry) -> Option<f64> {
        match geo.device {
            Device::MaT12 => None,
            Device::Sra => self
                .sra
                .and_then(|sra| sra.get(geo.index - MA_T12_COUNT).copied()),
        }
    }

    /// The geometries these readings cover.
    pub fn geometries(&self) -> GeometrySet {
        if self.sra.is_some() {
            GeometrySet::ALL
        } else {
            GeometrySet::MA_T12
        }
    }
}

/// Everything that can be wrong with a scan file or an in-memory [`Scan`].
#[derive(Debug, thiserror::Error)]
pub enum ScanError {
    #[error("cannot read scan file {}: {source}", path.display())]
    Read { path: PathBuf, source: io::Error },
    #[error("cannot write scan file {}: {source}", path.display())]
    Write { path: PathBuf, source: io::Error },
    #[error("scan file is not valid JSON: {0}")]
    Syntax(#[source] serde_json::Error),
    /// The JSON is well formed but a field has the wrong shape or type (or a number is out of
    /// the f64 range, which serde_json refuses at parse time).
    #[error("{field}: {message}")]
    Shape { field: String, message: String },
    #[error("format: missing; a scan file must say \"format\": \"{FORMAT}\"")]
    MissingFormat,
    #[error(
        "format: unknown version {found}; this brdfd reads \"{FORMAT}\" (convert the file or use a brdfd that reads it)"
    )]
    UnknownFormat { found: String },
    #[error("{field}: must not be empty")]
    EmptyName { field: &'static str },
    #[error("wavelengths_nm: expected the 31 bands 400, 410, …, 700 nm, got {found}")]
    WavelengthGrid { found: String },
    #[error("{field}: missing geometry \"{geometry}\"")]
    MissingGeometry {
        field: String,
        geometry: &'static str,
    },
    #[error("{field}: unknown geometry \"{name}\" (this device's geometries are {expected})")]
    UnknownGeometry {
        field: String,
        name: String,
        expected: String,
    },
    #[error("{field}: geometry \"{name}\" given twice")]
    DuplicateGeometry { field: String, name: String },
    #[error("{field}: expected {expected} values, got {got}")]
    WrongLength {
        field: String,
        expected: usize,
        got: usize,
    },
    #[error("{field}: {value} is not a finite number")]
    NonFinite { field: String, value: f64 },
    #[error("{field}: reference reading {value} must be positive; re-measure the reference tile")]
    BadReference { field: String, value: f64 },
    #[error("{field}: reading {value} is negative; a device reading cannot be")]
    NegativeReading { field: String, value: f64 },
    #[error(
        "{field}: reading {value:e} is beyond any reflectance factor an instrument reads (at most \
         {MAX_REFLECTANCE_FACTOR}); the value is corrupt"
    )]
    Unphysical { field: String, value: f64 },
    #[error(
        "{field}: reading {value:e} is {ratio:e} times the reference tile's {reference:e} \
         ({reference_field}); no reflectance factor is above {MAX_REFLECTANCE_FACTOR} times a \
         diffuse tile's, so one of the two values is corrupt"
    )]
    BeyondReference {
        field: String,
        value: f64,
        reference_field: String,
        reference: f64,
        ratio: f64,
    },
    #[error("{field}: expected an object of readings or \"{expected}\", got \"{found}\"")]
    UnknownTag {
        field: &'static str,
        expected: &'static str,
        found: String,
    },
    /// SRA readings are normalised by the tile's SRA readings: without them they cannot be used.
    #[error(
        "readings.sra: SRA readings need an N9 reference with SRA readings to be normalised by; \
         give the reference's \"sra\" readings, or mark the scan's \"sra\" as \"{SRA_NOT_MEASURED}\""
    )]
    SraWithoutReference,
}

/// Whose readings a value belongs to; the reference must be strictly positive, the sample only
/// non-negative (a black sample may read exactly 0).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Role {
    Reference,
    Sample,
}

impl Role {
    const fn prefix(self) -> &'static str {
        match self {
            Role::Reference => "reference",
            Role::Sample => "readings",
        }
    }
}

/// `readings.ma_t12.15as-45`
fn geometry_field(role: Role, geo: &Geometry) -> String {
    format!("{}.{}.{}", role.prefix(), geo.device.key(), geo.name)
}

/// `readings.ma_t12.15as-45[3] (430 nm)`
fn band_field(role: Role, geo: &Geometry, band: usize) -> String {
    format!(
        "{}[{band}] ({} nm)",
        geometry_field(role, geo),
        wavelengths_nm()[band]
    )
}

/// The largest MA-T12 reading accepted, as a reflectance factor (0–1 scale). A reflectance
/// factor is the sample's radiance over a perfect diffuser's, `R = π·L/E`; it exceeds 1 only
/// near the mirror direction, and is largest for a perfect mirror (reflectance 1) seen within
/// the illuminating beam: `R = π / Ω`, with `Ω` the beam's solid angle. 10⁴ is a beam of
/// 0.57° half-angle, narrower than any goniospectrophotometer's, so no instrument reads more;
/// a glossy sample near specular reads in the hundreds at most. The SRA's readings are in the
/// device's own unit and are only required to be finite.
pub const MAX_REFLECTANCE_FACTOR: f64 = 1e4;

/// Whether `value` can be an MA-T12 reading (a reflectance factor at most
/// [`MAX_REFLECTANCE_FACTOR`]); the one check every reader applies.
pub fn physical_reflectance_factor(value: f64) -> bool {
    value.is_finite() && value <= MAX_REFLECTANCE_FACTOR
}

/// Whether a sample's reading `sample` can be one, against the reference tile's `reference` at
/// the same geometry (and band): the processed value is their ratio times the tile's
/// reflectance (at most 1), so a ratio above [`MAX_REFLECTANCE_FACTOR`] is beyond any
/// reflectance factor. This bounds the SRA's readings, which are in the device's own unit,
/// and a tile reading so small that the ratio overflows what the fit can use; the one check
/// of a reading against its tile every reader applies.
pub fn physical_against_reference(sample: f64, reference: f64) -> bool {
    sample / reference <= MAX_REFLECTANCE_FACTOR
}

fn check_value(role: Role, field: impl FnOnce() -> String, value: f64) -> Result<(), ScanError> {
    if !value.is_finite() {
        return Err(ScanError::NonFinite {
            field: field(),
            value,
        });
    }
    match role {
        Role::Reference if value <= 0.0 => Err(ScanError::BadReference {
            field: field(),
            value,
        }),
        Role::Sample if value < 0.0 => Err(ScanError::NegativeReading {
            field: field(),
            value,
        }),
        _ => Ok(()),
    }
}

impl DeviceReadings {
    /// The first of these sample readings beyond [`physical_against_reference`] against
    /// `tile`'s, as (geometry, band for the MA-T12, value, the tile's value).
    pub fn beyond_reference(
        &self,
        tile: &DeviceReadings,
    ) -> Option<(&'static Geometry, Option<usize>, f64, f64)> {
        for geo in &GEOMETRIES {
            match geo.device {
                Device::MaT12 => {
                    let (s, w) = (&self.ma_t12[geo.index], &tile.ma_t12[geo.index]);
                    if let Some(b) = (0..BANDS).find(|&b| !physical_against_reference(s[b], w[b])) {
                        return Some((geo, Some(b), s[b], w[b]));
                    }
                }
                Device::Sra => {
                    if let (Some(s), Some(w)) = (&self.sra, &tile.sra) {
                        let k = geo.index - MA_T12_COUNT;
                        if !physical_against_reference(s[k], w[k]) {
                            return Some((geo, None, s[k], w[k]));
                        }
                    }
                }
            }
        }
        None
    }

    fn validate(&self, role: Role) -> Result<(), ScanError> {
        for geo in &GEOMETRIES {
            match geo.device {
                Device::MaT12 => {
                    for (band, &v) in self.ma_t12[geo.index].iter().enumerate() {
                        check_value(role, || band_field(role, geo, band), v)?;
                        if !physical_reflectance_factor(v) {
                            return Err(ScanError::Unphysical {
                                field: band_field(role, geo, band),
                                value: v,
                            });
                        }
                    }
                }
                Device::Sra => {
                    if let Some(sra) = &self.sra {
                        let v = sra[geo.index - MA_T12_COUNT];
                        check_value(role, || geometry_field(role, geo), v)?;
                    }
                }
            }
        }
        Ok(())
    }
}

impl Scan {
    /// Checks what the type system cannot: non-empty names, finite non-negative readings and a
    /// strictly positive reference (SCIENCE.md §3). Reading and writing both call it.
    pub fn validate(&self) -> Result<(), ScanError> {
        if self.sample.trim().is_empty() {
            return Err(ScanError::EmptyName { field: "sample" });
        }
        if let Some(reference) = &self.reference {
            if reference.name.trim().is_empty() {
                return Err(ScanError::EmptyName {
                    field: "reference.name",
                });
            }
            reference.readings.validate(Role::Reference)?;
        }
        let sra_reference = self.reference.as_ref().and_then(|r| r.readings.sra);
        if self.readings.sra.is_some() && sra_reference.is_none() {
            return Err(ScanError::SraWithoutReference);
        }
        if let Some(origin) = &self.origin {
            origin.measured_at_ms()?;
        }
        self.readings.validate(Role::Sample)?;
        if let Some(reference) = &self.reference
            && let Some((geo, band, value, tile)) =
                self.readings.beyond_reference(&reference.readings)
        {
            let field = |role| match band {
                Some(b) => band_field(role, geo, b),
                None => geometry_field(role, geo),
            };
            return Err(ScanError::BeyondReference {
                field: field(Role::Sample),
                value,
                reference_field: field(Role::Reference),
                reference: tile,
                ratio: value / tile,
            });
        }
        Ok(())
    }

    /// Parses and checks a `brdfd.scan/1` document.
    pub fn from_json(bytes: &[u8]) -> Result<Scan, ScanError> {
        // Stage 0: the format tag decides how to read the rest, so look at it first; a document
        // of another version may legitimately have another shape.
        #[derive(Deserialize)]
        struct Probe {
            format: Option<serde_json::Value>,
        }
        let probe: Probe = serde_json::from_slice(bytes).map_err(ScanError::Syntax)?;
        match probe.format {
            None => return Err(ScanError::MissingFormat),
            Some(serde_json::Value::String(s)) if s == FORMAT => {}
            Some(other) => {
                return Err(ScanError::UnknownFormat {
                    found: other.to_string(),
                });
            }
        }

        // Stage 1: shape, with the JSON path of whatever does not fit.
        let mut de = serde_json::Deserializer::from_slice(bytes);
        let raw: RawScan = serde_path_to_error::deserialize(&mut de).map_err(|e| {
            let path = e.path().to_string();
            let field = if path == "." {
                "scan".to_string()
            } else {
                path
            };
            ScanError::Shape {
                field,
                message: e.into_inner().to_string(),
            }
        })?;

        // Stage 2: semantics.
        raw.check()
    }

    /// Reads a whole document from `reader` and parses it.
    pub fn from_reader(mut reader: impl Read) -> Result<Scan, ScanError> {
        let mut bytes = Vec::new();
        reader
            .read_to_end(&mut bytes)
            .map_err(|source| ScanError::Read {
                path: PathBuf::from("<reader>"),
                source,
            })?;
        Scan::from_json(&bytes)
    }

    /// Reads and parses a scan file.
    pub fn read_file(path: impl AsRef<Path>) -> Result<Scan, ScanError> {
        let path = path.as_ref();
        let bytes = std::fs::read(path).map_err(|source| ScanError::Read {
            path: path.to_path_buf(),
            source,
        })?;
        Scan::from_json(&bytes)
    }

    /// The document, pretty-printed with one line per geometry. Fails only if the scan does
    /// not [`validate`](Scan::validate).
    pub fn to_json_pretty(&self) -> Result<String, ScanError> {
        self.validate()?;
        let out = OutScan {
            format: FORMAT,
            sample: &self.sample,
            wavelengths_nm: wavelengths_nm(),
            reference: match &self.reference {
                Some(reference) => OrTag::Value(OutReference {
                    name: &reference.name,
                    ma_t12: OutMaT12(&reference.readings.ma_t12),
                    sra: OutSra::of(&reference.readings.sra),
                }),
                None => OrTag::Tag(INSTRUMENT_CALIBRATION.to_string()),
            },
            readings: OutReadings {
                ma_t12: OutMaT12(&self.readings.ma_t12),
                sra: OutSra::of(&self.readings.sra),
            },
            origin: self.origin.as_ref(),
        };
        let mut buf = Vec::new();
        let mut ser = serde_json::Serializer::with_formatter(&mut buf, ScanFormatter::new());
        out.serialize(&mut ser)
            .expect("serialising into memory cannot fail");
        buf.push(b'\n');
        Ok(String::from_utf8(buf).expect("serde_json writes UTF-8"))
    }

    /// Writes the document to `path` (created or truncated).
    pub fn write_file(&self, path: impl AsRef<Path>) -> Result<(), ScanError> {
        let path = path.as_ref();
        let text = self.to_json_pretty()?;
        std::fs::write(path, text).map_err(|source| ScanError::Write {
            path: path.to_path_buf(),
            source,
        })
    }
}

// ---------------------------------------------------------------------------------------------
// Raw (as parsed) stage.

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawScan {
    #[allow(dead_code)] // checked by the probe
    format: String,
    sample: String,
    wavelengths_nm: Vec<f64>,
    reference: OrTag<RawReference>,
    readings: RawReadings,
    #[serde(default)]
    origin: Option<Origin>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawReference {
    name: String,
    ma_t12: Entries<Vec<f64>>,
    sra: OrTag<Entries<f64>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawReadings {
    ma_t12: Entries<Vec<f64>>,
    sra: OrTag<Entries<f64>>,
}

/// A field that holds either its object or a string tag that stands for its absence
/// (`"instrument-calibration"`, `"not-measured"`). A custom visitor rather than an untagged
/// enum, so that an error inside the object keeps its JSON path.
enum OrTag<T> {
    Tag(String),
    Value(T),
}

impl<'de, T: Deserialize<'de>> Deserialize<'de> for OrTag<T> {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct V_<T>(std::marker::PhantomData<T>);
        impl<'de, T: Deserialize<'de>> Visitor<'de> for V_<T> {
            type Value = OrTag<T>;
            fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
                f.write_str("an object, or a string that says why it is absent")
            }
            fn visit_str<E: serde::de::Error>(self, v: &str) -> Result<Self::Value, E> {
                Ok(OrTag::Tag(v.to_string()))
            }
            fn visit_map<A: MapAccess<'de>>(self, map: A) -> Result<Self::Value, A::Error> {
                T::deserialize(serde::de::value::MapAccessDeserializer::new(map)).map(OrTag::Value)
            }
        }
        d.deserialize_any(V_(std::marker::PhantomData))
    }
}

impl<T: Serialize> Serialize for OrTag<T> {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        match self {
            OrTag::Tag(tag) => s.serialize_str(tag),
            OrTag::Value(v) => v.serialize(s),
        }
    }
}

impl<T> OrTag<T> {
    /// The object, `None` for the one tag allowed here, an error naming `field` for another.
    fn expect(self, field: &'static str, tag: &'static str) -> Result<Option<T>, ScanError> {
        match self {
            OrTag::Value(v) => Ok(Some(v)),
            OrTag::Tag(t) if t == tag => Ok(None),
            OrTag::Tag(found) => Err(ScanError::UnknownTag {
                field,
                expected: tag,
                found,
            }),
        }
    }
}

/// A JSON object read as its entries in document order, duplicates kept (a `BTreeMap` would
/// silently keep the last of two readings for one geometry).
struct Entries<V>(Vec<(String, V)>);

impl<'de, V: Deserialize<'de>> Deserialize<'de> for Entries<V> {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct V_<V>(std::marker::PhantomData<V>);
        impl<'de, V: Deserialize<'de>> Visitor<'de> for V_<V> {
            type Value = Entries<V>;
            fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
                f.write_str("an object keyed by geometry name")
            }
            fn visit_map<A: MapAccess<'de>>(self, mut map: A) -> Result<Self::Value, A::Error> {
                let mut out = Vec::new();
                while let Some((k, v)) = map.next_entry::<String, V>()? {
                    out.push((k, v));
                }
                Ok(Entries(out))
            }
        }
        d.deserialize_map(V_(std::marker::PhantomData))
    }
}

/// Puts one device's entries into table order, or names what is unknown, doubled or missing.
fn arrange<V, T: Copy>(
    entries: Entries<V>,
    role: Role,
    device: Device,
    mut convert: impl FnMut(&Geometry, V) -> Result<T, ScanError>,
    fill: T,
) -> Result<Vec<T>, ScanError> {
    let field = format!("{}.{}", role.prefix(), device.key());
    let geos = geometry::of_device(device);
    let first = geos[0].index;
    let mut slots: Vec<Option<T>> = vec![None; geos.len()];
    for (name, value) in entries.0 {
        let Some(geo) = geos.iter().find(|g| g.name == name) else {
            let expected = geos
                .iter()
                .map(|g| format!("\"{}\"", g.name))
                .collect::<Vec<_>>()
                .join(", ");
            return Err(ScanError::UnknownGeometry {
                field,
                name,
                expected,
            });
        };
        let slot = &mut slots[geo.index - first];
        if slot.is_some() {
            return Err(ScanError::DuplicateGeometry { field, name });
        }
        *slot = Some(convert(geo, value)?);
    }
    if let Some(i) = slots.iter().position(Option::is_none) {
        return Err(ScanError::MissingGeometry {
            field,
            geometry: geos[i].name,
        });
    }
    Ok(slots.into_iter().map(|s| s.unwrap_or(fill)).collect())
}

fn arrange_readings(
    ma_t12: Entries<Vec<f64>>,
    sra: OrTag<Entries<f64>>,
    role: Role,
) -> Result<DeviceReadings, ScanError> {
    let sra_field = match role {
        Role::Reference => "reference.sra",
        Role::Sample => "readings.sra",
    };
    let sra = sra.expect(sra_field, SRA_NOT_MEASURED)?;
    let spectra = arrange(
        ma_t12,
        role,
        Device::MaT12,
        |geo, values: Vec<f64>| {
            let spectrum: Spectrum =
                values
                    .as_slice()
                    .try_into()
                    .map_err(|_| ScanError::WrongLength {
                        field: geometry_field(role, geo),
                        expected: BANDS,
                        got: values.len(),
                    })?;
            for (band, &v) in spectrum.iter().enumerate() {
                check_value(role, || band_field(role, geo, band), v)?;
            }
            Ok(spectrum)
        },
        [0.0; BANDS],
    )?;
    let intensities = sra
        .map(|sra| {
            arrange(
                sra,
                role,
                Device::Sra,
                |geo, v: f64| {
                    check_value(role, || geometry_field(role, geo), v)?;
                    Ok(v)
                },
                0.0,
            )
        })
        .transpose()?;
    Ok(DeviceReadings {
        ma_t12: spectra
            .try_into()
            .expect("arrange returns one slot per MA-T12 geometry"),
        sra: intensities.map(|v| {
            v.try_into()
                .expect("arrange returns one slot per SRA geometry")
        }),
    })
}

impl RawScan {
    fn check(self) -> Result<Scan, ScanError> {
        if self.sample.trim().is_empty() {
            return Err(ScanError::EmptyName { field: "sample" });
        }
        let grid = wavelengths_nm();
        let grid_ok = self.wavelengths_nm.len() == BANDS
            && self
                .wavelengths_nm
                .iter()
                .zip(grid)
                .all(|(&got, want)| got == f64::from(want));
        if !grid_ok {
            let found = if self.wavelengths_nm.len() == BANDS {
                let (i, got) = self
                    .wavelengths_nm
                    .iter()
                    .enumerate()
                    .find(|&(i, &got)| got != f64::from(grid[i]))
                    .expect("some band differs");
                format!("{got} nm at position {i} (expected {} nm)", grid[i])
            } else {
                format!("{} values", self.wavelengths_nm.len())
            };
            return Err(ScanError::WavelengthGrid { found });
        }
        let reference = match self.reference.expect("reference", INSTRUMENT_CALIBRATION)? {
            Some(raw) => {
                if raw.name.trim().is_empty() {
                    return Err(ScanError::EmptyName {
                        field: "reference.name",
                    });
                }
                let readings = arrange_readings(raw.ma_t12, raw.sra, Role::Reference)?;
                Some(Reference {
                    name: raw.name,
                    readings,
                })
            }
            None => None,
        };
        let readings = arrange_readings(self.readings.ma_t12, self.readings.sra, Role::Sample)?;
        let scan = Scan {
            sample: self.sample,
            reference,
            readings,
            origin: self.origin,
        };
        // The checks across parts (SRA readings need the tile's) are the in-memory ones.
        scan.validate()?;
        Ok(scan)
    }
}

// ---------------------------------------------------------------------------------------------
// Output stage: borrowed views serialised in table order.

#[derive(Serialize)]
struct OutScan<'a> {
    format: &'static str,
    sample: &'a str,
    wavelengths_nm: [u32; BANDS],
    reference: OrTag<OutReference<'a>>,
    readings: OutReadings<'a>,
    #[serde(skip_serializing_if = "Option::is_none")]
    origin: Option<&'a Origin>,
}

#[derive(Serialize)]
struct OutReference<'a> {
    name: &'a str,
    ma_t12: OutMaT12<'a>,
    sra: OrTag<OutSra<'a>>,
}

#[derive(Serialize)]
struct OutReadings<'a> {
    ma_t12: OutMaT12<'a>,
    sra: OrTag<OutSra<'a>>,
}

struct OutMaT12<'a>(&'a [Spectrum; MA_T12_COUNT]);
struct OutSra<'a>(&'a [f64; SRA_COUNT]);

impl<'a> OutSra<'a> {
    fn of(sra: &'a Option<[f64; SRA_COUNT]>) -> OrTag<OutSra<'a>> {
        match sra {
            Some(values) => OrTag::Value(OutSra(values)),
            None => OrTag::Tag(SRA_NOT_MEASURED.to_string()),
        }
    }
}

impl Serialize for OutMaT12<'_> {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.collect_map(geometry::ma_t12().iter().map(|g| g.name).zip(self.0.iter()))
    }
}

impl Serialize for OutSra<'_> {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.collect_map(geometry::sra().iter().map(|g| g.name).zip(self.0.iter()))
    }
}

/// Pretty objects, but every array on one line: one geometry per line reads and diffs well.
struct ScanFormatter {
    pretty: serde_json::ser::PrettyFormatter<'static>,
}

impl ScanFormatter {
    fn new() -> Self {
        ScanFormatter {
            pretty: serde_json::ser::PrettyFormatter::with_indent(b"  "),
        }
    }
}

impl serde_json::ser::Formatter for ScanFormatter {
    fn begin_array<W: ?Sized + io::Write>(&mut self, w: &mut W) -> io::Result<()> {
        w.write_all(b"[")
    }
    fn end_array<W: ?Sized + io::Write>(&mut self, w: &mut W) -> io::Result<()> {
        w.write_all(b"]")
    }
    fn begin_array_value<W: ?Sized + io::Write>(
        &mut self,
        w: &mut W,
        first: bool,
    ) -> io::Result<()> {
        if first { Ok(()) } else { w.write_all(b", ") }
    }
    fn end_array_value<W: ?Sized + io::Write>(&mut self, _w: &mut W) -> io::Result<()> {
        Ok(())
    }
    fn begin_object<W: ?Sized + io::Write>(&mut self, w: &mut W) -> io::Result<()> {
        self.pretty.begin_object(w)
    }
    fn end_object<W: ?Sized + io::Write>(&mut self, w: &mut W) -> io::Result<()> {
        self.pretty.end_object(w)
    }
    fn begin_object_key<W: ?Sized + io::Write>(
        &mut self,
        w: &mut W,
        first: bool,
    ) -> io::Result<()> {
        self.pretty.begin_object_key(w, first)
    }
    fn end_object_key<W: ?Sized + io::Write>(&mut self, w: &mut W) -> io::Result<()> {
        self.pretty.end_object_key(w)
    }
    fn begin_object_value<W: ?Sized + io::Write>(&mut self, w: &mut W) -> io::Result<()> {
        self.pretty.begin_object_value(w)
    }
    fn end_object_value<W: ?Sized + io::Write>(&mut self, w: &mut W) -> io::Result<()> {
        self.pretty.end_object_value(w)
    }
}

#[cfg(test)]
impl Scan {
    /// The reference tile's SRA readings, for tests that spoil one; panics on a scan without them.
    pub(crate) fn reference_sra_mut(&mut self) -> &mut [f64; SRA_COUNT] {
        self.reference
            .as_mut()
            .unwrap()
            .readings
            .sra
            .as_mut()
            .unwrap()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    /// A valid scan with distinct values everywhere, so a mix-up of geometries would show.
    fn example() -> Scan {
        let spectra = |base: f64| -> [Spectrum; MA_T12_COUNT] {
            std::array::from_fn(|g| {
                std::array::from_fn(|b| base + 0.01 * g as f64 + 0.001 * b as f64)
            })
        };
        Scan {
            sample: "T.Freesia pink".into(),
            reference: Some(Reference {
                name: "Munsell N9".into(),
                readings: DeviceReadings {
                    ma_t12: spectra(0.7),
                    sra: Some([0.245, 0.25]),
                },
            }),
            readings: DeviceReadings {
                ma_t12: spectra(0.3),
                sra: Some([3.1, 7.9]),
            },
            origin: None,
        }
    }

    #[test]
    fn readings_beyond_any_reflectance_factor_against_the_tile_are_refused_naming_both() {
        // An SRA reading of 1e308 (the device's unit: only the tile's bounds it).
        let mut s = example();
        s.readings.sra = Some([1e308, 7.9]);
        let e = s.validate().unwrap_err().to_string();
        assert!(
            e.starts_with("readings.sra.sra-20: reading 1e308 is inf times")
                && e.contains("(reference.sra.sra-20)")
                && e.contains("above 10000 times"),
            "{e}"
        );
        // Hundreds of times the tile's, as near the specular direction of a glossy sample.
        s.readings.sra = Some([0.245 * 400.0, 0.25 * 900.0]);
        s.validate().unwrap();
        // A tile reading so small that the MA-T12's ratio overflows what the fit can use.
        let mut s = example();
        s.reference.as_mut().unwrap().readings.ma_t12[2][5] = 1e-300;
        let e = s.validate().unwrap_err().to_string();
        assert!(
            e.starts_with("readings.ma_t12.15as-15[5] (450 nm): reading 3.25e-1 is 3.25e299")
                && e.contains("(reference.ma_t12.15as-15[5] (450 nm))"),
            "{e}"
        );
        // At the bound itself: accepted.
        let mut s = example();
        s.readings.sra = Some([0.245 * MAX_REFLECTANCE_FACTOR, 7.9]);
        s.validate().unwrap();
    }

    fn example_value() -> serde_json::Value {
        serde_json::from_str(&example().to_json_pretty().unwrap()).unwrap()
    }

    /// Parses a modified copy of the example document and returns the error message.
    fn error_after(edit: impl FnOnce(&mut serde_json::Value)) -> String {
        let mut v = example_value();
        edit(&mut v);
        let text = serde_json::to_vec(&v).unwrap();
        Scan::from_json(&text)
            .expect_err("the edited document must be rejected")
            .to_string()
    }

    #[test]
    fn round_trips_exactly() {
        let scan = example();
        let text = scan.to_json_pretty().unwrap();
        assert_eq!(Scan::from_json(text.as_bytes()).unwrap(), scan);
        assert!(text.contains("\"format\": \"brdfd.scan/1\""));
        // One line per geometry, arrays inline.
        assert!(
            text.lines()
                .any(|l| l.trim_start().starts_with("\"15as-45\": [0.7, "))
        );
        assert!(text.contains("\"wavelengths_nm\": [400, 410, 420,"));
    }

    #[test]
    fn round_trips_awkward_floats_bit_for_bit() {
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        let mut scan = example();
        for s in scan.readings.ma_t12.iter_mut() {
            for v in s.iter_mut() {
                // Full-precision mantissas over many decades, plus subnormal-ish extremes.
                *v = rng.random::<f64>() * 10f64.powi(rng.random_range(-12..4)) + f64::MIN_POSITIVE;
            }
        }
        // The tile's: full-precision mantissas within a tile's range, so that every sample
        // reading stays a reflectance factor against it.
        for s in scan.reference.as_mut().unwrap().readings.ma_t12.iter_mut() {
            for v in s.iter_mut() {
                *v = 0.5 + 0.5 * rng.random::<f64>();
            }
        }
        scan.readings.sra = Some([0.1 + 0.2, 1e-300]);
        scan.readings.ma_t12[0][0] = 0.0;
        let back = Scan::from_json(scan.to_json_pretty().unwrap().as_bytes()).unwrap();
        for (a, b) in back
            .readings
            .ma_t12
            .iter()
            .flatten()
            .zip(scan.readings.ma_t12.iter().flatten())
        {
            assert_eq!(a.to_bits(), b.to_bits());
        }
        assert_eq!(back, scan);
    }

    #[test]
    fn file_round_trip() {
        let dir = std::env::temp_dir().join(format!("brdfd-scan-test-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("x.scan.json");
        example().write_file(&path).unwrap();
        assert_eq!(Scan::read_file(&path).unwrap(), example());
        assert_eq!(
            Scan::from_reader(std::fs::File::open(&path).unwrap()).unwrap(),
            example()
        );
        std::fs::remove_dir_all(&dir).unwrap();
        let err = Scan::read_file(dir.join("nope.json"))
            .unwrap_err()
            .to_string();
        assert!(
            err.starts_with("cannot read scan file") && err.contains("nope.json"),
            "{err}"
        );
    }

    #[test]
    fn geometries_are_put_in_table_order_whatever_the_file_order() {
        let mut v = example_value();
        let map = v["readings"]["ma_t12"].as_object_mut().unwrap();
        let entries: Vec<_> = std::mem::take(map).into_iter().rev().collect();
        map.extend(entries);
        let scan = Scan::from_json(&serde_json::to_vec(&v).unwrap()).unwrap();
        assert_eq!(scan, example());
    }

    #[test]
    fn rejects_unknown_and_missing_format() {
        let e = error_after(|v| v["format"] = "brdfd.scan/2".into());
        assert_eq!(
            e,
            "format: unknown version \"brdfd.scan/2\"; this brdfd reads \"brdfd.scan/1\" \
             (convert the file or use a brdfd that reads it)"
        );
        let e = error_after(|v| v["format"] = 1.into());
        assert!(e.starts_with("format: unknown version 1;"), "{e}");
        let e = error_after(|v| {
            v.as_object_mut().unwrap().remove("format");
        });
        assert!(e.starts_with("format: missing"), "{e}");
    }

    #[test]
    fn rejects_bad_json() {
        let e = Scan::from_json(b"{\"format\": \"brdfd.scan/1\",")
            .unwrap_err()
            .to_string();
        assert!(e.starts_with("scan file is not valid JSON: "), "{e}");
    }

    #[test]
    fn rejects_missing_geometry() {
        let e = error_after(|v| {
            v["readings"]["ma_t12"]
                .as_object_mut()
                .unwrap()
                .remove("45as110");
        });
        assert_eq!(e, "readings.ma_t12: missing geometry \"45as110\"");
        let e = error_after(|v| {
            v["reference"]["sra"]
                .as_object_mut()
                .unwrap()
                .remove("sra-20");
        });
        assert_eq!(e, "reference.sra: missing geometry \"sra-20\"");
    }

    #[test]
    fn rejects_unknown_geometry() {
        let e = error_after(|v| {
            let m = v["readings"]["ma_t12"].as_object_mut().unwrap();
            let x = m["15as-45"].clone();
            m.insert("15as99".into(), x);
        });
        assert!(e.starts_with("readings.ma_t12: unknown geometry \"15as99\" (this device's geometries are \"15as-45\","), "{e}");
        // A geometry of the other device is unknown here too.
        let e = error_after(|v| {
            v["readings"]["sra"]["45as15"] = 1.0.into();
        });
        assert!(
            e.starts_with("readings.sra: unknown geometry \"45as15\""),
            "{e}"
        );
    }

    #[test]
    fn rejects_duplicate_geometry() {
        let mut text = example().to_json_pretty().unwrap();
        text = text.replacen("\"sra-60\": 7.9", "\"sra-60\": 7.9, \"sra-60\": 8.0", 1);
        let e = Scan::from_json(text.as_bytes()).unwrap_err().to_string();
        assert_eq!(e, "readings.sra: geometry \"sra-60\" given twice");
    }

    #[test]
    fn rejects_wrong_length() {
        let e = error_after(|v| {
            v["readings"]["ma_t12"]["15as-45"]
                .as_array_mut()
                .unwrap()
                .pop();
        });
        assert_eq!(e, "readings.ma_t12.15as-45: expected 31 values, got 30");
        let e = error_after(|v| {
            v["reference"]["ma_t12"]["45as45"]
                .as_array_mut()
                .unwrap()
                .push(0.5.into());
        });
        assert_eq!(e, "reference.ma_t12.45as45: expected 31 values, got 32");
    }

    #[test]
    fn rejects_wrong_wavelength_grid() {
        let e = error_after(|v| v["wavelengths_nm"][3] = 435.into());
        assert_eq!(
            e,
            "wavelengths_nm: expected the 31 bands 400, 410, …, 700 nm, got 435 nm at position 3 (expected 430 nm)"
        );
        let e = error_after(|v| {
            v["wavelengths_nm"].as_array_mut().unwrap().push(710.into());
        });
        assert!(e.ends_with("got 32 values"), "{e}");
        // 400.0 is the same wavelength as 400.
        let mut v = example_value();
        v["wavelengths_nm"][0] = 400.0.into();
        Scan::from_json(&serde_json::to_vec(&v).unwrap()).unwrap();
    }

    #[test]
    fn rejects_out_of_range_numbers_naming_the_field() {
        // JSON has no NaN or infinity; a literal past f64::MAX is the way one sneaks in.
        let text = example()
            .to_json_pretty()
            .unwrap()
            .replacen("[0.3, ", "[0.3, 1e999, ", 1);
        let text = text.replacen("0.301, ", "", 1);
        let e = Scan::from_json(text.as_bytes()).unwrap_err().to_string();
        assert!(e.starts_with("readings.ma_t12.15as-45[1]: "), "{e}");
        assert!(e.contains("number out of range"), "{e}");
        // null where a number belongs.
        let e = error_after(|v| v["readings"]["sra"]["sra-20"] = serde_json::Value::Null);
        assert!(
            e.starts_with("readings.sra.sra-20: invalid type: null"),
            "{e}"
        );
    }

    #[test]
    fn rejects_non_finite_values_in_memory_before_writing() {
        let mut scan = example();
        scan.readings.ma_t12[2][5] = f64::NAN;
        let e = scan.to_json_pretty().unwrap_err().to_string();
        assert_eq!(
            e,
            "readings.ma_t12.15as-15[5] (450 nm): NaN is not a finite number"
        );
        let mut scan = example();
        scan.reference_sra_mut()[1] = f64::INFINITY;
        let e = scan.validate().unwrap_err().to_string();
        assert_eq!(e, "reference.sra.sra-60: inf is not a finite number");
    }

    #[test]
    fn rejects_zero_or_negative_reference_but_accepts_a_zero_sample() {
        let e = error_after(|v| v["reference"]["ma_t12"]["15as80"][30] = 0.into());
        assert_eq!(
            e,
            "reference.ma_t12.15as80[30] (700 nm): reference reading 0 must be positive; re-measure the reference tile"
        );
        let e = error_after(|v| v["reference"]["sra"]["sra-60"] = (-0.2).into());
        assert!(
            e.starts_with("reference.sra.sra-60: reference reading -0.2 must be positive"),
            "{e}"
        );
        let e = error_after(|v| v["readings"]["ma_t12"]["45as25"][0] = (-0.01).into());
        assert_eq!(
            e,
            "readings.ma_t12.45as25[0] (400 nm): reading -0.01 is negative; a device reading cannot be"
        );

        let mut v = example_value();
        v["readings"]["ma_t12"]["45as25"][0] = 0.into();
        v["readings"]["sra"]["sra-20"] = 0.into();
        let scan = Scan::from_json(&serde_json::to_vec(&v).unwrap()).unwrap();
        assert_eq!(scan.readings.ma_t12[8][0], 0.0);
        assert_eq!(scan.readings.sra.unwrap()[0], 0.0);
    }

    #[test]
    fn instrument_calibration_and_no_sra_round_trip_explicitly() {
        let mut scan = example();
        scan.reference = None;
        scan.readings.sra = None;
        let text = scan.to_json_pretty().unwrap();
        assert!(
            text.contains("\"reference\": \"instrument-calibration\""),
            "{text}"
        );
        assert!(text.contains("\"sra\": \"not-measured\""), "{text}");
        let back = Scan::from_json(text.as_bytes()).unwrap();
        assert_eq!(back, scan);
        assert_eq!(back.geometries(), GeometrySet::MA_T12);
        assert_eq!(back.reference_label(), "instrument calibration");
        assert_eq!(example().geometries(), GeometrySet::ALL);

        // A tile reference without SRA readings, and a scan without them: fine.
        let mut v = example_value();
        v["reference"]["sra"] = "not-measured".into();
        v["readings"]["sra"] = "not-measured".into();
        let scan = Scan::from_json(&serde_json::to_vec(&v).unwrap()).unwrap();
        assert_eq!(scan.reference_label(), "Munsell N9");
        assert!(scan.readings.sra.is_none());

        // SRA readings need the tile's SRA readings.
        let e = error_after(|v| v["reference"] = "instrument-calibration".into());
        assert!(
            e.starts_with("readings.sra: SRA readings need an N9 reference"),
            "{e}"
        );
        let e = error_after(|v| v["reference"]["sra"] = "not-measured".into());
        assert!(e.starts_with("readings.sra: SRA readings need"), "{e}");
        // Unknown tags are named, and errors inside an object keep their path.
        let e = error_after(|v| v["reference"] = "none".into());
        assert_eq!(
            e,
            "reference: expected an object of readings or \"instrument-calibration\", got \"none\""
        );
        let e = error_after(|v| v["readings"]["sra"] = "missing".into());
        assert!(
            e.starts_with("readings.sra: expected an object of readings or \"not-measured\""),
            "{e}"
        );
        let e = error_after(|v| v["reference"]["ma_t12"]["15as80"] = "x".into());
        assert!(
            e.starts_with("reference.ma_t12.15as80: invalid type"),
            "{e}"
        );
    }

    #[test]
    fn rejects_empty_names_and_unknown_fields() {
        let e = error_after(|v| v["sample"] = " ".into());
        assert_eq!(e, "sample: must not be empty");
        let e = error_after(|v| v["reference"]["name"] = "".into());
        assert_eq!(e, "reference.name: must not be empty");
        let e = error_after(|v| v["operator"] = "ann".into());
        assert!(
            e.starts_with("operator: unknown field `operator`, expected one of"),
            "{e}"
        );
        let e = error_after(|v| {
            v["readings"].as_object_mut().unwrap().remove("sra");
        });
        assert!(e.starts_with("readings: missing field `sra`"), "{e}");
    }

    #[test]
    fn accessors_follow_the_table() {
        let scan = example();
        let g = geometry::by_name("45as110").unwrap();
        assert_eq!(scan.readings.spectrum(g).unwrap()[0], 0.3 + 0.11);
        assert_eq!(scan.readings.intensity(g), None);
        let s = geometry::by_name("sra-60").unwrap();
        assert_eq!(scan.readings.intensity(s), Some(7.9));
        assert!(scan.readings.spectrum(s).is_none());
    }
}

/// Property tests: whatever bytes arrive, [`Scan::from_json`] returns (never panics), an error
/// names a problem, and a document it accepts validates and writes back to itself.
///
/// The mutations of a valid file live here and are shared by the property tests of the other
/// parsers of outside input ([`crate::config`], [`crate::formats`]): a mutation is a small
/// edit (delete, insert, truncate, swap a number for an awkward literal, drop or repeat a line,
/// splice in a few characters) and a case is one to three of them, so a failing case is
/// reported as the edits, not as the whole mutated file.
#[cfg(test)]
pub(crate) mod proptests {
    use super::*;
    use proptest::prelude::*;
    use proptest::sample::Index;

    /// What a mutation puts where a number was: out of f64 range, negative, zero, past the
    /// integer types, not a number, another JSON type, nothing.
    const NUMBER_SWAPS: [&str; 24] = [
        "1e999",
        "-1e999",
        "1e-400",
        "-1",
        "-0",
        "0",
        "0.0",
        "1e308",
        "-1e300",
        "1e20",
        "4294967296",
        "18446744073709551616",
        "-9223372036854775809",
        "99999999999999999999999999",
        "NaN",
        "inf",
        "-inf",
        "0x10",
        "x",
        "\"x\"",
        "null",
        "[]",
        "{}",
        "",
    ];

    /// Characters that mean something to one of the formats (JSON, TOML, CGATS, CSV, XML).
    const STRUCTURAL: [char; 22] = [
        '{', '}', '[', ']', '"', '\'', ',', ':', '=', '#', '\n', '\r', '\t', ' ', '\\', '<', '>',
        '/', '&', ';', '.', '\u{e9}',
    ];

    /// One small edit of a text.
    #[derive(Debug, Clone)]
    pub(crate) enum Mutation {
        Delete(Index),
        Insert(Index, char),
        Truncate(Index),
        /// Replace a number token by a literal of [`NUMBER_SWAPS`].
        Number(Index, &'static str),
        DropLine(Index),
        /// Insert a copy of one line before another.
        RepeatLine(Index, Index),
        /// Replace up to `.1` characters at `.0` by `.2`.
        Splice(Index, usize, String),
    }

    fn mutation() -> impl Strategy<Value = Mutation> {
        let ch = prop_oneof![
            3 => proptest::sample::select(STRUCTURAL.to_vec()),
            1 => any::<char>(),
        ];
        // A number swapped is the edit most likely to get past the syntax to the checks.
        prop_oneof![
            2 => any::<Index>().prop_map(Mutation::Delete),
            2 => (any::<Index>(), ch).prop_map(|(i, c)| Mutation::Insert(i, c)),
            1 => any::<Index>().prop_map(Mutation::Truncate),
            6 => (any::<Index>(), proptest::sample::select(NUMBER_SWAPS.to_vec()))
                .prop_map(|(i, s)| Mutation::Number(i, s)),
            1 => any::<Index>().prop_map(Mutation::DropLine),
            1 => (any::<Index>(), any::<Index>()).prop_map(|(a, b)| Mutation::RepeatLine(a, b)),
            2 => (any::<Index>(), 0..16usize, ".{0,8}")
                .prop_map(|(i, n, s)| Mutation::Splice(i, n, s)),
        ]
    }

    /// One to three mutations, applied in order by [`apply`].
    pub(crate) fn mutations() -> impl Strategy<Value = Vec<Mutation>> {
        proptest::collection::vec(mutation(), 1..4)
    }

    /// The byte offset of a char boundary picked by `i` (the end of the text included).
    fn boundary(text: &str, i: &Index) -> usize {
        let count = text.chars().count();
        let k = i.index(count + 1);
        text.char_indices().nth(k).map_or(text.len(), |(at, _)| at)
    }

    /// Byte ranges of the number tokens of `text`: runs of `[0-9.eE+-]` holding a digit that
    /// are not part of a word (so `SPECTRAL_NM400` and `15as-45` stay whole).
    fn numbers(text: &str) -> Vec<std::ops::Range<usize>> {
        let b = text.as_bytes();
        let numeric = |c: u8| c.is_ascii_digit() || matches!(c, b'.' | b'e' | b'E' | b'+' | b'-');
        let word = |c: u8| c.is_ascii_alphanumeric() || c == b'_' || c >= 0x80;
        let mut out = Vec::new();
        let mut i = 0;
        while i < b.len() {
            if !numeric(b[i]) {
                i += 1;
                continue;
            }
            let start = i;
            while i < b.len() && numeric(b[i]) {
                i += 1;
            }
            let run = &b[start..i];
            let before_ok = start == 0 || !word(b[start - 1]);
            let after_ok = i == b.len() || !word(b[i]);
            if run.iter().any(u8::is_ascii_digit) && before_ok && after_ok {
                out.push(start..i);
            }
        }
        out
    }

    /// Byte ranges of the lines of `text`, each with its line break.
    fn lines(text: &str) -> Vec<std::ops::Range<usize>> {
        let mut out = Vec::new();
        let mut start = 0;
        for (i, c) in text.char_indices() {
            if c == '\n' {
                out.push(start..i + 1);
                start = i + 1;
            }
        }
        if start < text.len() {
            out.push(start..text.len());
        }
        out
    }

    impl Mutation {
        fn apply(&self, t: &mut String) {
            match self {
                Mutation::Delete(i) => {
                    let at = boundary(t, i);
                    if at < t.len() {
                        t.remove(at);
                    }
                }
                Mutation::Insert(i, c) => {
                    let at = boundary(t, i);
                    t.insert(at, *c);
                }
                Mutation::Truncate(i) => {
                    let at = boundary(t, i);
                    t.truncate(at);
                }
                Mutation::Number(i, with) => {
                    let spans = numbers(t);
                    if !spans.is_empty() {
                        t.replace_range(spans[i.index(spans.len())].clone(), with);
                    }
                }
                Mutation::DropLine(i) => {
                    let ls = lines(t);
                    if !ls.is_empty() {
                        t.replace_range(ls[i.index(ls.len())].clone(), "");
                    }
                }
                Mutation::RepeatLine(from, to) => {
                    let ls = lines(t);
                    if !ls.is_empty() {
                        let mut line = t[ls[from.index(ls.len())].clone()].to_string();
                        if !line.ends_with('\n') {
                            line.push('\n');
                        }
                        t.insert_str(ls[to.index(ls.len())].start, &line);
                    }
                }
                Mutation::Splice(i, n, with) => {
                    let at = boundary(t, i);
                    let end = t[at..]
                        .char_indices()
                        .nth(*n)
                        .map_or(t.len(), |(k, _)| at + k);
                    t.replace_range(at..end, with);
                }
            }
        }
    }

    /// `valid` with `ms` applied in order.
    pub(crate) fn apply(valid: &str, ms: &[Mutation]) -> String {
        let mut t = valid.to_string();
        for m in ms {
            m.apply(&mut t);
        }
        t
    }

    /// Checks that an error names a problem: some text, and not only a location (`file:3: `).
    pub(crate) fn assert_names_a_problem(e: &dyn std::error::Error) -> Result<(), TestCaseError> {
        let shown = e.to_string();
        prop_assert!(
            !shown.trim().is_empty() && !shown.trim_end().ends_with(':'),
            "error without a message: {shown:?} ({e:?})"
        );
        Ok(())
    }

    const VALID: &str = include_str!("../tests/data/t-sky-blue.scan.json");

    /// Parses `bytes`: an error must name a problem; an accepted scan must validate and write a
    /// document that reads back equal.
    fn check(bytes: &[u8]) -> Result<(), TestCaseError> {
        match Scan::from_json(bytes) {
            Err(e) => assert_names_a_problem(&e)?,
            Ok(scan) => {
                if let Err(e) = scan.validate() {
                    return Err(TestCaseError::fail(format!(
                        "accepted a scan that does not validate: {e}"
                    )));
                }
                let text = scan
                    .to_json_pretty()
                    .map_err(|e| TestCaseError::fail(format!("cannot write it back: {e}")))?;
                let back = Scan::from_json(text.as_bytes())
                    .map_err(|e| TestCaseError::fail(format!("cannot read it back: {e}")))?;
                prop_assert_eq!(back, scan);
            }
        }
        Ok(())
    }

    #[test]
    fn number_tokens_are_numbers_outside_words() {
        let text = "\"15as-45\": [0.5, -1e-3], SPECTRAL_NM400 = 7\n2,x3";
        let found: Vec<&str> = numbers(text).into_iter().map(|r| &text[r]).collect();
        assert_eq!(found, ["0.5", "-1e-3", "7", "2"]);
        Scan::from_json(VALID.as_bytes()).unwrap();
    }

    proptest! {
        #![proptest_config(crate::test_support::proptest_config())]

        #[test]
        fn arbitrary_bytes_are_rejected_or_valid(
            bytes in proptest::collection::vec(any::<u8>(), 0..512)
        ) {
            check(&bytes)?;
        }

        #[test]
        fn json_like_text_after_the_format_tag_is_rejected_or_valid(
            body in "[{}\\[\\]\",: 0-9a-z_.\\-]{0,200}"
        ) {
            check(format!("{{\"format\": \"{FORMAT}\", {body}").as_bytes())?;
        }

        #[test]
        fn a_mutated_valid_file_is_rejected_or_valid(ms in mutations()) {
            check(apply(VALID, &ms).as_bytes())?;
        }

        #[test]
        fn a_valid_file_with_a_byte_changed_is_rejected_or_valid(
            at in any::<Index>(),
            byte in any::<u8>(),
        ) {
            let mut bytes = VALID.as_bytes().to_vec();
            let i = at.index(bytes.len());
            bytes[i] = byte;
            check(&bytes)?;
        }
    }
}
