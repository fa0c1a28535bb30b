//! Import assembly: the observations a parser reads from a file (whose reading, at which
//! geometry, where in the file), checked and built into one scan per sample, and what an
//! instrument's export says of where its readings came from.

use std::collections::BTreeMap;

use crate::geometry::{Device, GEOMETRIES, GEOMETRY_COUNT, Geometry, MA_T12_COUNT};
use crate::scan::{DeviceReadings, Origin, OriginInstrument, Reference, Scan};
use crate::spectral::{BANDS, Spectrum};

use super::time::export_time;
use super::{FormatError, ImportOptions, file_name, table};

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
pub(super) fn cgats_origin(file: &str, t: &table::Table) -> Option<Origin> {
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

/// A row's sample name, trimmed; an empty one is an error naming the row's `field`.
pub(crate) fn sample_name<'a>(
    file: &str,
    line: usize,
    field: &str,
    text: &'a str,
) -> Result<&'a str, FormatError> {
    let name = text.trim();
    if name.is_empty() {
        return Err(FormatError::invalid(
            file,
            line,
            field,
            "sample name must not be empty",
        ));
    }
    Ok(name)
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
                if g.device == Device::MaT12 && !crate::scan::physical_reflectance_factor(v) {
                    return Err(FormatError::invalid(
                        &at.file,
                        at.line,
                        field_name(fields, band),
                        format!(
                            "{who} at {}: {v:e} is beyond any reflectance factor an instrument \
                             reads (at most {}); the value is corrupt",
                            g.name,
                            crate::scan::MAX_REFLECTANCE_FACTOR
                        ),
                    ));
                }
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
        // The readings against the tile's, naming the sample's line: what `Scan::validate`
        // checks, with the place in the file.
        if let Some((geo, band, value, tile_value)) = readings.beyond_reference(&ref_readings) {
            let (_, at, fields) = samples[&name].values[geo.index]
                .as_ref()
                .expect("every geometry was read");
            let at_band = band
                .map(|b| format!(" at {} nm", crate::spectral::wavelengths_nm()[b]))
                .unwrap_or_default();
            return Err(FormatError::invalid(
                &at.file,
                at.line,
                field_name(fields, band),
                format!(
                    "sample \"{name}\" at {}{at_band}: {value:e} is {:e} times the reference \
                     tile \"{tile}\"'s {tile_value:e}; no reflectance factor is above {} times \
                     a diffuse tile's, so one of the two values is corrupt",
                    geo.name,
                    value / tile_value,
                    crate::scan::MAX_REFLECTANCE_FACTOR
                ),
            ));
        }
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
