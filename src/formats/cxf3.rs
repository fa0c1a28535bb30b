//! X-Rite Color Exchange Format 3 (CxF3): written valid against the CxF3 core schema
//! (v3.0.018, kept in `src/formats/data/CxF3_Core.xsd` and checked by the tests), read from
//! brdfd's own files and from an MA-T12's software export.
//!
//! Written layout (element names from the schema):
//! - `ColorSpecificationCollection`: one `ColorSpecification` per geometry, `Id="cs-<name>"`,
//!   whose `MeasurementSpec/GeometryChoice/MultiAngle` holds one `BRDFAngle` with
//!   `Notation="<geometry name>"`, `IlluminationAngle` θi and `Aspecular` (degrees, SCIENCE.md
//!   §2), the 400 nm / 10 nm `WavelengthRange` and the instrument as `Device` (with the
//!   `Model` it reported and its `SerialNumber` when one instrument measured every sample).
//! - `ObjectCollection`: per sample one `Object` per data kind (and per finished fit), its
//!   `ColorValues` holding one spectrum per geometry, and a `TagCollection Name="brdfd"`
//!   saying `data_kind`, `sample`, `reference`, for estimates `cost_function` and `method`, and
//!   for a stored scan its provenance ([`super::PROVENANCE_FIELDS`]: scan id, station, time,
//!   each instrument's model, serial, firmware and whether it was simulated).
//! - A spectrum is a `ReflectanceSpectrum` (`StartWL="400"`) when it is a reflectance factor
//!   inside the schema's `ReflectanceDataType` range (−0.1, 3.0); otherwise — SRA device
//!   intensities, and specular reflectance factors above 3 — a `CustomSpectrum` of 31
//!   `SpectralPoint`s, which the schema leaves unbounded.
//!
//! Read: objects are matched to geometries through their spectra's `ColorSpecification` and its
//! `BRDFAngle/@Notation` (brdfd's geometry names); an object without brdfd's tags is the
//! reference if named like the tile, else a sample. Bands are placed by `StartWL` (the spectrum's,
//! else its specification's `WavelengthRange`, else 400) and the 10 nm increment.

use std::collections::{BTreeMap, HashMap};
use std::fmt::Write as _;

use super::{
    DataKind, ExportOptions, FormatError, ImportOptions, Location, Observation, Owner, Value,
    device_spectrum, geometry_named, parse_number, reflectance,
};
use crate::geometry::{Device, GEOMETRIES, Geometry};
use crate::scan::DeviceReadings;
use crate::spectral::{BANDS, FIRST_NM, STEP_NM, Spectrum, wavelengths_nm};
use crate::study::Study;

/// The CxF3 core namespace.
pub const NAMESPACE: &str = "http://colorexchangeformat.com/CxF3-core";

/// X-Rite's CxF3 core schema, v3.0.018, as distributed in the `colour-cxf` source package
/// (see `src/formats/data/README.md`).
pub const SCHEMA: &str = include_str!("data/CxF3_Core.xsd");

/// The schema's `ReflectanceDataType`: −0.1 < value < 3.0.
fn in_reflectance_range(s: &Spectrum) -> bool {
    s.iter().all(|&v| v > -0.1 && v < 3.0)
}

/// XML text or attribute value with the five predefined entities escaped.
fn esc(s: &str) -> String {
    let mut out = String::with_capacity(s.len());
    for c in s.chars() {
        match c {
            '&' => out.push_str("&amp;"),
            '<' => out.push_str("&lt;"),
            '>' => out.push_str("&gt;"),
            '"' => out.push_str("&quot;"),
            '\'' => out.push_str("&apos;"),
            c => out.push(c),
        }
    }
    out
}

fn spec_id(g: &Geometry) -> String {
    format!("cs-{}", g.name)
}

fn write_spectrum(t: &mut String, g: &Geometry, values: &Spectrum, reflectance_factor: bool) {
    if reflectance_factor && in_reflectance_range(values) {
        let list: Vec<String> = values.iter().map(|v| v.to_string()).collect();
        let _ = writeln!(
            t,
            "          <cc:ReflectanceSpectrum Name=\"{}\" ColorSpecification=\"{}\" StartWL=\"{FIRST_NM}\">{}</cc:ReflectanceSpectrum>",
            g.name,
            spec_id(g),
            list.join(" ")
        );
    } else {
        let _ = writeln!(
            t,
            "          <cc:CustomSpectrum Name=\"{}\" ColorSpecification=\"{}\">",
            g.name,
            spec_id(g)
        );
        for (nm, v) in wavelengths_nm().iter().zip(values) {
            let _ = writeln!(
                t,
                "            <cc:SpectralPoint WL=\"{nm}\">{v}</cc:SpectralPoint>"
            );
        }
        let _ = writeln!(t, "          </cc:CustomSpectrum>");
    }
}

/// The study as a CxF3 document.
pub fn write(study: &Study, opts: &ExportOptions) -> Result<String, FormatError> {
    let mut t = String::new();
    let _ = writeln!(t, "<?xml version=\"1.0\" encoding=\"UTF-8\"?>");
    let _ = writeln!(t, "<cc:CxF xmlns:cc=\"{NAMESPACE}\">");
    let _ = writeln!(t, "  <cc:FileInformation>");
    let _ = writeln!(t, "    <cc:Creator>{}</cc:Creator>", esc(&opts.originator));
    let _ = writeln!(
        t,
        "    <cc:CreationDate>{}</cc:CreationDate>",
        esc(&opts.created)
    );
    let _ = writeln!(
        t,
        "    <cc:Description>Spectral BRDF study: per sample the device readings of the sample and of its reference tile, the measured reflectance factor (pi*M, relative to the tile) and each fit's estimated reflectance factor (pi*f), one spectrum per geometry.</cc:Description>"
    );
    let _ = writeln!(
        t,
        "    <cc:Comment>MA-T12 readings are reflectance factors (0-1 scale); SRA readings (sra-20, sra-60) are the device's single achromatic intensity in its own unit, repeated in every band, written as CustomSpectrum. Geometry names and angles (degrees) per brdfd's geometry table.</cc:Comment>"
    );
    let _ = writeln!(t, "  </cc:FileInformation>");
    let _ = writeln!(t, "  <cc:Resources>");
    let _ = writeln!(t, "    <cc:ObjectCollection>");
    let mut id = 0;
    for s in &study.samples {
        let origin = super::provenance_values(s);
        // (kind, (cost function, method) of an estimate, one spectrum per geometry)
        // (`None` at a geometry the scan did not measure; no reference object without a tile)
        type Object<'a> = (DataKind, Option<(&'a str, &'a str)>, [Option<Spectrum>; 14]);
        let geometries = s.scan.geometries();
        let only_measured = |spectra: [Spectrum; 14]| -> [Option<Spectrum>; 14] {
            std::array::from_fn(|g| geometries.contains(g).then_some(spectra[g]))
        };
        let mut objects: Vec<Object> = vec![(
            DataKind::Reading,
            None,
            GEOMETRIES.map(|g| device_spectrum(&s.scan.readings, &g)),
        )];
        if let Some(reference) = &s.scan.reference {
            objects.push((
                DataKind::Reference,
                None,
                GEOMETRIES.map(|g| {
                    device_spectrum(&reference.readings, &g)
                        .filter(|_| geometries.contains(g.index))
                }),
            ));
        }
        objects.push((
            DataKind::Measured,
            None,
            only_measured(s.measured.values.map(|f| reflectance(&f))),
        ));
        for f in &s.fits {
            if let Some(d) = f.done() {
                objects.push((
                    DataKind::Estimated,
                    Some((f.cost.name(), f.method.as_str())),
                    only_measured(d.estimated.map(|f| reflectance(&f))),
                ));
                if let Some([lo, hi]) = super::estimate_band(d) {
                    let fit = Some((f.cost.name(), f.method.as_str()));
                    objects.push((DataKind::EstimatedLow, fit, only_measured(lo)));
                    objects.push((DataKind::EstimatedHigh, fit, only_measured(hi)));
                }
            }
        }
        for (kind, fit, spectra) in objects {
            id += 1;
            let (object_type, name) = match kind {
                DataKind::Reading => ("Sample", s.name.as_str()),
                DataKind::Reference => ("Reference", s.scan.reference_label()),
                DataKind::Measured => ("Measured", s.name.as_str()),
                DataKind::Estimated => ("Estimated", s.name.as_str()),
                DataKind::EstimatedLow => ("EstimatedLow", s.name.as_str()),
                DataKind::EstimatedHigh => ("EstimatedHigh", s.name.as_str()),
            };
            let _ = writeln!(
                t,
                "      <cc:Object ObjectType=\"{object_type}\" Name=\"{}\" Id=\"o{id}\">",
                esc(name)
            );
            let _ = writeln!(
                t,
                "        <cc:CreationDate>{}</cc:CreationDate>",
                esc(&opts.created)
            );
            let comment = match (kind, fit) {
                (DataKind::Reading, _) => format!("device readings of sample \"{}\"", s.name),
                (DataKind::Reference, _) => format!(
                    "device readings of reference tile \"{}\" for the scan of \"{}\"",
                    s.scan.reference_label(),
                    s.name
                ),
                (DataKind::Measured, _) => format!(
                    "measured reflectance factor of \"{}\" (specular strategy {})",
                    s.name, s.specular
                ),
                (DataKind::Estimated, Some((cost, method))) => format!(
                    "reflectance factor of the model fitted to \"{}\" with cost function {cost}, method {method}",
                    s.name
                ),
                (DataKind::EstimatedLow | DataKind::EstimatedHigh, Some((cost, method))) => {
                    format!(
                        "{} end of the 95 % band of the model fitted to \"{}\" with cost \
                         function {cost}, method {method}: pi*(kd bootstrap interval + specular term)",
                        if kind == DataKind::EstimatedLow {
                            "lower"
                        } else {
                            "upper"
                        },
                        s.name
                    )
                }
                (DataKind::Estimated | DataKind::EstimatedLow | DataKind::EstimatedHigh, None) => {
                    unreachable!("estimates carry their fit")
                }
            };
            let _ = writeln!(t, "        <cc:Comment>{}</cc:Comment>", esc(&comment));
            let _ = writeln!(t, "        <cc:ColorValues>");
            let is_reflectance = matches!(
                kind,
                DataKind::Measured
                    | DataKind::Estimated
                    | DataKind::EstimatedLow
                    | DataKind::EstimatedHigh
            );
            for g in &GEOMETRIES {
                let reflectance_factor = is_reflectance || g.device == Device::MaT12;
                if let Some(spectrum) = &spectra[g.index] {
                    write_spectrum(&mut t, g, spectrum, reflectance_factor);
                }
            }
            let _ = writeln!(t, "        </cc:ColorValues>");
            let _ = writeln!(t, "        <cc:TagCollection Name=\"brdfd\">");
            let mut tags = vec![
                ("data_kind", kind.name().to_string()),
                ("sample", s.name.clone()),
                ("reference", s.scan.reference_label().to_string()),
            ];
            if let Some((cost, method)) = fit {
                tags.push(("cost_function", cost.to_string()));
                tags.push(("method", method.to_string()));
            }
            // Where, when and by which instruments (empty/unknown for in-memory studies).
            for (k, v) in super::PROVENANCE_FIELDS.iter().zip(&origin) {
                if !v.is_empty() {
                    tags.push((k, v.clone()));
                }
            }
            for (k, v) in tags {
                let _ = writeln!(t, "          <cc:Tag Name=\"{k}\" Value=\"{}\"/>", esc(&v));
            }
            let _ = writeln!(t, "        </cc:TagCollection>");
            let _ = writeln!(t, "      </cc:Object>");
        }
    }
    let _ = writeln!(t, "    </cc:ObjectCollection>");
    let _ = writeln!(t, "    <cc:ColorSpecificationCollection>");
    // The instrument behind each device's geometries: its serial (and the model it reported)
    // when one instrument measured every sample of the file; per sample it is in the tags.
    let instrument = |device: Device| -> Option<(String, String)> {
        let mut seen = study.samples.iter().map(|s| {
            s.origin.as_ref().map(|o| match device {
                Device::MaT12 => (
                    o.provenance.ma_t12.model.clone(),
                    o.provenance.ma_t12.serial.clone(),
                ),
                Device::Sra => (
                    o.provenance.sra.model.clone(),
                    o.provenance.sra.serial.clone(),
                ),
            })
        });
        let first = seen.next()??;
        (first.1 != "unknown" && seen.all(|o| o.as_ref() == Some(&first))).then_some(first)
    };
    let instruments = [instrument(Device::MaT12), instrument(Device::Sra)];
    for g in &GEOMETRIES {
        let (manufacturer, model) = match g.device {
            Device::MaT12 => ("X-Rite", "MA-T12"),
            Device::Sra => ("Canon", "RA-532H"),
        };
        let reported = &instruments[match g.device {
            Device::MaT12 => 0,
            Device::Sra => 1,
        }];
        let _ = writeln!(t, "      <cc:ColorSpecification Id=\"{}\">", spec_id(g));
        let _ = writeln!(t, "        <cc:MeasurementSpec>");
        let _ = writeln!(
            t,
            "          <cc:MeasurementType>Spectrum_Reflectance</cc:MeasurementType>"
        );
        let _ = writeln!(t, "          <cc:GeometryChoice>");
        let _ = writeln!(t, "            <cc:MultiAngle>");
        let _ = writeln!(t, "              <cc:BRDFAngle Notation=\"{}\">", g.name);
        let _ = writeln!(
            t,
            "                <cc:IlluminationAngle>{}</cc:IlluminationAngle>",
            g.theta_i_deg
        );
        let _ = writeln!(
            t,
            "                <cc:Aspecular>{}</cc:Aspecular>",
            g.aspecular_deg
        );
        let _ = writeln!(t, "              </cc:BRDFAngle>");
        let _ = writeln!(t, "            </cc:MultiAngle>");
        let _ = writeln!(t, "          </cc:GeometryChoice>");
        let _ = writeln!(
            t,
            "          <cc:WavelengthRange StartWL=\"{FIRST_NM}\" Increment=\"{STEP_NM}\"/>"
        );
        let _ = writeln!(t, "          <cc:Device>");
        let _ = writeln!(
            t,
            "            <cc:Manufacturer>{manufacturer}</cc:Manufacturer>"
        );
        match reported {
            Some((reported_model, serial)) => {
                let _ = writeln!(
                    t,
                    "            <cc:Model>{}</cc:Model>",
                    esc(reported_model)
                );
                let _ = writeln!(
                    t,
                    "            <cc:SerialNumber>{}</cc:SerialNumber>",
                    esc(serial)
                );
            }
            None => {
                let _ = writeln!(t, "            <cc:Model>{model}</cc:Model>");
            }
        }
        let _ = writeln!(t, "          </cc:Device>");
        let _ = writeln!(t, "        </cc:MeasurementSpec>");
        let _ = writeln!(t, "      </cc:ColorSpecification>");
    }
    let _ = writeln!(t, "    </cc:ColorSpecificationCollection>");
    let _ = writeln!(t, "  </cc:Resources>");
    let _ = writeln!(t, "</cc:CxF>");
    Ok(t)
}

/// What a `ColorSpecification` says about the spectra that use it.
struct Spec {
    geometry: &'static Geometry,
    start_wl: Option<f64>,
    increment: Option<f64>,
}

fn is(node: &roxmltree::Node, name: &str) -> bool {
    node.is_element() && node.tag_name().name() == name
}

fn child<'a, 'i>(node: roxmltree::Node<'a, 'i>, name: &str) -> Option<roxmltree::Node<'a, 'i>> {
    node.children().find(|c| is(c, name))
}

/// Line numbers of nodes, as `doc.text_pos_at` counts them, without its scan from the start
/// of the text for every spectrum and point (quadratic in the file's size).
struct Lines(Vec<usize>);

impl Lines {
    fn of_text(text: &str) -> Lines {
        Lines(text.match_indices('\n').map(|(i, _)| i).collect())
    }

    fn of(&self, n: &roxmltree::Node) -> usize {
        self.0.partition_point(|&b| b < n.range().start) + 1
    }
}

/// The readings in a CxF3 document (objects of kind `measured` and `estimated` are skipped).
/// What an instrument's CxF3 export says of where each sample's readings came from, by sample
/// name: the object's `CreationDate` (the measurement time), the file's `Creator` (the
/// software) and the MA-T12 `Device` model and serial its colour specifications name. Objects
/// of brdfd's own exports (tagged `brdfd`) carry their provenance in their tags and get none;
/// a file that does not parse gets none (`observations` says why).
pub(crate) fn origins(file: &str, text: &str) -> BTreeMap<String, crate::scan::Origin> {
    let mut out = BTreeMap::new();
    let Ok(doc) = roxmltree::Document::parse(text) else {
        return out;
    };
    let root = doc.root_element();
    let creator = root
        .descendants()
        .find(|n| is(n, "FileInformation"))
        .and_then(|f| child(f, "Creator"))
        .and_then(|c| c.text())
        .map(|t| t.trim().to_string())
        .filter(|t| !t.is_empty());
    // The MA-T12 named by a MultiAngle colour specification's Device, if any.
    let device = root
        .descendants()
        .filter(|n| is(n, "Device"))
        .find(|d| {
            child(*d, "Model")
                .and_then(|m| m.text())
                .is_some_and(|m| m.contains("MA-T"))
        })
        .map(|d| crate::scan::OriginInstrument {
            model: child(d, "Model")
                .and_then(|m| m.text())
                .unwrap_or("MA-T12")
                .trim()
                .to_string(),
            serial: child(d, "SerialNumber")
                .and_then(|s| s.text())
                .map(|s| s.trim().to_string())
                .filter(|s| !s.is_empty()),
            simulated: false,
        });
    for object in root.descendants().filter(|n| is(n, "Object")) {
        let tagged = object
            .children()
            .any(|c| is(&c, "TagCollection") && c.attribute("Name") == Some("brdfd"));
        let Some(name) = object.attribute("Name").map(str::trim) else {
            continue;
        };
        if tagged || name.is_empty() {
            continue;
        }
        let mut origin = crate::scan::Origin {
            source: Some(format!("CxF3 export {}", super::file_name(file))),
            ma_t12: device.clone(),
            ..Default::default()
        };
        if let Some(created) = child(object, "CreationDate").and_then(|c| c.text()) {
            origin.note_created(created);
        }
        if let Some(c) = &creator {
            origin.notes.insert("originator".into(), c.clone());
        }
        out.insert(name.to_string(), origin);
    }
    out
}

pub(crate) fn observations(
    file: &str,
    text: &str,
    opts: &ImportOptions,
) -> Result<Vec<Observation>, FormatError> {
    let doc = roxmltree::Document::parse(text)
        .map_err(|e| FormatError::invalid(file, e.pos().row as usize, "xml", e.to_string()))?;
    let lines = Lines::of_text(text);
    let root = doc.root_element();
    if root.tag_name().name() != "CxF" {
        return Err(FormatError::invalid(
            file,
            lines.of(&root),
            root.tag_name().name(),
            "not a CxF document (the root element must be CxF)",
        ));
    }
    let specs = color_specifications(file, root, &lines)?;
    let mut out = Vec::new();
    for object in root.descendants().filter(|n| is(n, "Object")) {
        let Some(owner) = owner_of(file, object, &lines, opts)? else {
            continue;
        };
        let Some(values) = child(object, "ColorValues") else {
            continue;
        };
        for sp in values
            .children()
            .filter(|c| is(c, "ReflectanceSpectrum") || is(c, "CustomSpectrum"))
        {
            let at = lines.of(&sp);
            let element = sp.tag_name().name();
            let spec_ref = sp.attribute("ColorSpecification").ok_or_else(|| {
                FormatError::invalid(file, at, element, "no ColorSpecification attribute")
            })?;
            let spec = specs.get(spec_ref).ok_or_else(|| {
                FormatError::invalid(
                    file,
                    at,
                    format!("{element}/@ColorSpecification"),
                    format!("\"{spec_ref}\" names no ColorSpecification with a MultiAngle BRDFAngle; brdfd needs the geometry of every spectrum"),
                )
            })?;
            let spectrum = if element == "ReflectanceSpectrum" {
                reflectance_spectrum(file, at, sp, spec)?
            } else {
                custom_spectrum(file, at, sp, &lines)?
            };
            let value = if spec.geometry.device == Device::Sra
                && spectrum
                    .iter()
                    .all(|v| v.to_bits() == spectrum[0].to_bits())
            {
                Value::Intensity(spectrum[0])
            } else {
                Value::Spectrum(spectrum)
            };
            out.push(Observation {
                owner: owner.clone(),
                geometry: spec.geometry,
                value,
                at: Location {
                    file: file.to_string(),
                    line: at,
                },
                fields: wavelengths_nm()
                    .iter()
                    .map(|nm| format!("{element} ({nm} nm)"))
                    .collect(),
            });
        }
    }
    Ok(out)
}

/// Geometry and wavelength grid per `ColorSpecification` Id (specifications without a
/// multi-angle geometry are left out: only a spectrum that uses one is an error).
fn color_specifications(
    file: &str,
    root: roxmltree::Node,
    lines: &Lines,
) -> Result<HashMap<String, Spec>, FormatError> {
    let line = |n: &roxmltree::Node| lines.of(n);
    let mut specs: HashMap<String, Spec> = HashMap::new();
    for cs in root.descendants().filter(|n| is(n, "ColorSpecification")) {
        let Some(id) = cs.attribute("Id") else {
            return Err(FormatError::invalid(
                file,
                line(&cs),
                "ColorSpecification",
                "no Id attribute",
            ));
        };
        let Some(angle) = cs.descendants().find(|n| is(n, "BRDFAngle")) else {
            // A specification without a multi-angle geometry (e.g. a sphere) cannot be placed;
            // only complain if a spectrum uses it (below).
            continue;
        };
        let notation = angle.attribute("Notation").ok_or_else(|| {
            FormatError::invalid(
                file,
                line(&angle),
                "BRDFAngle",
                "no Notation attribute naming the geometry",
            )
        })?;
        let geometry = geometry_named(file, line(&angle), "BRDFAngle/@Notation", notation)?;
        let range = cs.descendants().find(|n| is(n, "WavelengthRange"));
        let num = |attr: &str| -> Result<Option<f64>, FormatError> {
            match range.and_then(|r| r.attribute(attr)) {
                Some(v) => Ok(Some(parse_number(
                    file,
                    line(&range.expect("attribute came from it")),
                    &format!("WavelengthRange/@{attr}"),
                    v,
                )?)),
                None => Ok(None),
            }
        };
        specs.insert(
            id.to_string(),
            Spec {
                geometry,
                start_wl: num("StartWL")?,
                increment: num("Increment")?,
            },
        );
    }
    Ok(specs)
}

/// Whose readings an `Object` holds, from brdfd's tags or else its name; `None` for the
/// fitted spectra brdfd writes beside the readings (`measured`, `estimated`, …).
fn owner_of(
    file: &str,
    object: roxmltree::Node,
    lines: &Lines,
    opts: &ImportOptions,
) -> Result<Option<Owner>, FormatError> {
    let name = object.attribute("Name").unwrap_or("").trim().to_string();
    let tags: HashMap<&str, &str> = object
        .children()
        .filter(|c| is(c, "TagCollection") && c.attribute("Name") == Some("brdfd"))
        .flat_map(|c| c.children().filter(|t| is(t, "Tag")))
        .filter_map(|t| Some((t.attribute("Name")?, t.attribute("Value")?)))
        .collect();
    let owner = match tags.get("data_kind") {
        Some(kind) => {
            let kind: DataKind = kind.parse().map_err(|e: String| {
                FormatError::invalid(file, lines.of(&object), "Tag data_kind", e)
            })?;
            let sample = tags.get("sample").map_or(name.clone(), |s| s.to_string());
            match kind {
                DataKind::Measured
                | DataKind::Estimated
                | DataKind::EstimatedLow
                | DataKind::EstimatedHigh => return Ok(None),
                DataKind::Reading => Owner::Sample(sample),
                DataKind::Reference => Owner::ReferenceOf {
                    sample,
                    tile: tags
                        .get("reference")
                        .map_or(name.clone(), |s| s.to_string()),
                },
            }
        }
        None if name == opts.reference => Owner::SharedReference,
        None => Owner::Sample(name.clone()),
    };
    if let Owner::Sample(s) = &owner
        && s.is_empty()
    {
        return Err(FormatError::invalid(
            file,
            lines.of(&object),
            "Object/@Name",
            "an object with readings needs a name (the sample's)",
        ));
    }
    Ok(Some(owner))
}

/// A `ReflectanceSpectrum`: a list of values from a start wavelength on the MA-T12's 10 nm
/// grid, of which the 31 bands 400–700 nm are read.
fn reflectance_spectrum(
    file: &str,
    at: usize,
    sp: roxmltree::Node,
    spec: &Spec,
) -> Result<Spectrum, FormatError> {
    let element = "ReflectanceSpectrum";
    let start = match sp.attribute("StartWL") {
        Some(v) => parse_number(file, at, "ReflectanceSpectrum/@StartWL", v)?,
        None => spec.start_wl.unwrap_or(f64::from(FIRST_NM)),
    };
    let step = spec.increment.unwrap_or(f64::from(STEP_NM));
    if step != f64::from(STEP_NM) {
        return Err(FormatError::invalid(
            file,
            at,
            element,
            format!("wavelength increment {step} nm; brdfd reads the MA-T12's 10 nm grid"),
        ));
    }
    let list: Vec<&str> = sp.text().unwrap_or("").split_whitespace().collect();
    let offset = (f64::from(FIRST_NM) - start) / step;
    // A negative start is no wavelength (and, far enough below 0, would put 400 nm past the
    // end of the index range).
    if start < 0.0 || offset < 0.0 || offset.fract() != 0.0 {
        return Err(FormatError::invalid(
            file,
            at,
            element,
            format!("starts at {start} nm; brdfd needs 400–700 nm every 10 nm"),
        ));
    }
    let offset = offset as usize;
    if list.len() < offset + BANDS {
        return Err(FormatError::invalid(
            file,
            at,
            element,
            format!(
                "{} values from {start} nm do not reach 700 nm (need {})",
                list.len(),
                offset + BANDS
            ),
        ));
    }
    let mut s = [0.0; BANDS];
    for (b, v) in s.iter_mut().enumerate() {
        *v = parse_number(
            file,
            at,
            &format!("ReflectanceSpectrum ({} nm)", wavelengths_nm()[b]),
            list[offset + b],
        )?;
    }
    Ok(s)
}

/// A `CustomSpectrum`: `SpectralPoint`s by wavelength, one needed at each of the 31 bands.
fn custom_spectrum(
    file: &str,
    at: usize,
    sp: roxmltree::Node,
    lines: &Lines,
) -> Result<Spectrum, FormatError> {
    let mut s = [None; BANDS];
    for p in sp.children().filter(|c| is(c, "SpectralPoint")) {
        let pl = lines.of(&p);
        let wl = parse_number(
            file,
            pl,
            "SpectralPoint/@WL",
            p.attribute("WL").unwrap_or(""),
        )?;
        let v = parse_number(file, pl, "SpectralPoint", p.text().unwrap_or(""))?;
        if let Some(b) = wavelengths_nm().iter().position(|&nm| f64::from(nm) == wl) {
            s[b] = Some(v);
        }
    }
    let mut full = [0.0; BANDS];
    for (b, v) in s.iter().enumerate() {
        full[b] = v.ok_or_else(|| {
            FormatError::invalid(
                file,
                at,
                "CustomSpectrum",
                format!("no SpectralPoint at {} nm", wavelengths_nm()[b]),
            )
        })?;
    }
    Ok(full)
}

/// A fixture for tests of the import by object name: what an MA-T12's software writes for one
/// session, each of `objects` (name, device readings) as an `Object` created 2024-05-01 with
/// no brdfd tags, its spectra 390–710 nm (the bands outside 400–700 nm at 0.5) on the grid
/// the specifications give.
pub fn instrument_export(objects: &[(&str, &DeviceReadings)]) -> String {
    let mut xml = format!(
        "<?xml version=\"1.0\"?>\n<CxF xmlns=\"{NAMESPACE}\"><Resources><ObjectCollection>\n"
    );
    for (i, (name, r)) in objects.iter().enumerate() {
        let _ = writeln!(
            xml,
            "<Object ObjectType=\"Standard\" Name=\"{name}\" Id=\"x{i}\"><CreationDate>2024-05-01T12:00:00Z</CreationDate><ColorValues>"
        );
        for g in crate::geometry::ma_t12() {
            let vals: Vec<String> = std::iter::once("0.5".to_string())
                .chain(r.ma_t12[g.index].iter().map(|v| v.to_string()))
                .chain(std::iter::once("0.5".to_string()))
                .collect();
            let _ = writeln!(
                xml,
                "<ReflectanceSpectrum ColorSpecification=\"m{}\">{}</ReflectanceSpectrum>",
                g.index,
                vals.join(" ")
            );
        }
        xml += "</ColorValues></Object>\n";
    }
    xml += "</ObjectCollection><ColorSpecificationCollection>";
    for g in crate::geometry::ma_t12() {
        let _ = write!(
            xml,
            "<ColorSpecification Id=\"m{}\"><MeasurementSpec><MeasurementType>Spectrum_Reflectance</MeasurementType><GeometryChoice><MultiAngle><BRDFAngle Notation=\"{}\"><IlluminationAngle>{}</IlluminationAngle><Aspecular>{}</Aspecular></BRDFAngle></MultiAngle></GeometryChoice><WavelengthRange StartWL=\"390\" Increment=\"10\"/></MeasurementSpec></ColorSpecification>",
            g.index, g.name, g.theta_i_deg, g.aspecular_deg
        );
    }
    xml += "</ColorSpecificationCollection></Resources></CxF>\n";
    xml
}

#[cfg(test)]
pub(crate) mod tests {
    use super::super::tests::{fixed, study};
    use super::super::{Format, ImportOptions, import};
    use super::*;

    fn err(text: &str) -> String {
        import(Format::Cxf3, "m.cxf", text, None, &ImportOptions::default())
            .unwrap_err()
            .to_string()
    }

    /// Runs `xmllint` (libxml2) on `xml` against the embedded CxF3 core schema: `Ok` if it
    /// validates, `Err(xmllint's report)` if not. No well-kept pure-Rust crate validates XSD;
    /// a missing `xmllint` panics, so that the positive and the negative test both fail (not
    /// skip, and not pass) without it.
    fn xmllint(xml: &str) -> Result<(), String> {
        let dir = tempfile::tempdir().unwrap();
        let xsd = dir.path().join("CxF3_Core.xsd");
        let doc = dir.path().join("export.cxf");
        std::fs::write(&xsd, SCHEMA).unwrap();
        std::fs::write(&doc, xml).unwrap();
        let out = std::process::Command::new("xmllint")
            .arg("--noout")
            .arg("--schema")
            .arg(&xsd)
            .arg(&doc)
            .output()
            .unwrap_or_else(|e| {
                panic!(
                    "cannot run xmllint ({e}); install it with `apt-get install -y libxml2-utils` (.ci/run does)"
                )
            });
        let report = String::from_utf8_lossy(&out.stderr).into_owned();
        // xmllint's exit status 3 is "validation error"; anything else but 0 means it did
        // not get as far as validating (bad schema, unreadable file), which is not a verdict.
        match out.status.code() {
            Some(0) => Ok(()),
            Some(3) => Err(report),
            other => panic!("xmllint did not validate (exit {other:?}):\n{report}"),
        }
    }

    /// Asserts that `xml` validates against the CxF3 core schema.
    pub(crate) fn validate_with_xmllint(xml: &str) {
        if let Err(report) = xmllint(xml) {
            panic!("the CxF3 export does not validate against CxF3_Core.xsd:\n{report}");
        }
    }

    #[test]
    fn the_export_validates_against_the_cxf3_core_schema() {
        let mut s = study();
        // A name needing escapes, and a specular estimate above the schema's reflectance range.
        s.samples[0].name = "Tile <A> & \"B\"".into();
        let xml = write(&s, &fixed()).unwrap();
        assert!(xml.contains("<cc:BRDFAngle Notation=\"45as110\">"));
        assert!(xml.contains("<cc:CustomSpectrum Name=\"sra-20\""));
        validate_with_xmllint(&xml);
    }

    #[test]
    fn the_export_names_the_instruments_and_stays_valid() {
        let xml = write(&super::super::tests::stored_study(), &fixed()).unwrap();
        // One MA-T12 measured every sample: its serial is the device's, per geometry.
        assert_eq!(
            xml.matches("<cc:SerialNumber>MT-7</cc:SerialNumber>")
                .count(),
            12
        );
        assert_eq!(
            xml.matches("<cc:SerialNumber>SIM-RA</cc:SerialNumber>")
                .count(),
            2
        );
        // Per object, every provenance field as a tag.
        assert!(xml.contains("<cc:Tag Name=\"ma_t12_serial\" Value=\"MT-7\"/>"));
        assert!(xml.contains("<cc:Tag Name=\"sra_simulated\" Value=\"yes\"/>"));
        assert!(xml.contains("<cc:Tag Name=\"scan_id\" Value=\"12\"/>"));
        assert!(xml.contains("<cc:Tag Name=\"station\" Value=\"bench-2\"/>"));
        validate_with_xmllint(&xml);
        // Two instruments in one file: no single serial is claimed for the device.
        let mut mixed = super::super::tests::stored_study();
        mixed.samples[1]
            .origin
            .as_mut()
            .unwrap()
            .provenance
            .ma_t12
            .serial = "MT-8".into();
        let xml = write(&mixed, &fixed()).unwrap();
        assert!(!xml.contains("<cc:SerialNumber>MT-"), "{xml}");
        assert!(xml.contains("<cc:Tag Name=\"ma_t12_serial\" Value=\"MT-8\"/>"));
    }

    #[test]
    fn the_validator_catches_a_schema_violation() {
        // Guard against a validation that passes anything: an element out of order fails.
        let xml =
            write(&study(), &fixed())
                .unwrap()
                .replacen("<cc:Aspecular>-45</cc:Aspecular>", "", 1);
        let report = xmllint(&xml).expect_err("xmllint accepted an out-of-order export");
        assert!(report.contains("Aspecular"), "xmllint's report: {report}");
    }

    #[test]
    fn an_instrument_export_reads_by_object_name() {
        let s = study().samples[1].clone();
        // The MA-T12 software's shape: objects named after what was measured, no brdfd tags,
        // the grid given once in the specification, extra bands outside 400-700 nm.
        let xml = instrument_export(&[
            ("Munsell N9", &s.scan.reference.as_ref().unwrap().readings),
            (s.name.as_str(), &s.scan.readings),
        ]);
        validate_with_xmllint(&xml);
        let sra = super::super::sra::write_scans(std::slice::from_ref(&s.scan));
        let got = import(
            Format::Cxf3,
            "m.cxf",
            &xml,
            Some(("s.csv", &sra)),
            &ImportOptions::default(),
        )
        .unwrap();
        // The readings as written, and what the export says of them: the object's creation
        // time as the measurement time.
        let mut got = got;
        let origin = got[0].origin.take().expect("an instrument export's origin");
        assert_eq!(got, vec![s.scan]);
        assert_eq!(origin.measured_at.as_deref(), Some("2024-05-01T12:00:00Z"));
        assert_eq!(origin.source.as_deref(), Some("CxF3 export m.cxf"));
    }

    #[test]
    fn a_start_wavelength_far_below_400_nm_is_rejected_not_overflowed() {
        // StartWL="-1e300" made the band offset saturate to usize::MAX: adding the 31 bands
        // overflowed (debug builds), or wrapped and indexed past the values (release). The
        // mutated-export property found it in a 30 000-case run; this keeps it found.
        let good = write(&study(), &fixed()).unwrap();
        let bad = good.replacen("StartWL=\"400\">", "StartWL=\"-1e300\">", 1);
        let line = bad.lines().position(|l| l.contains("-1e300")).unwrap() + 1;
        let e = err(&bad);
        assert!(
            e.starts_with(&format!(
                "m.cxf:{line}: ReflectanceSpectrum: starts at -1000"
            )),
            "{e}"
        );
        assert!(
            e.ends_with(" nm; brdfd needs 400–700 nm every 10 nm"),
            "{e}"
        );
        let e = err(&good.replacen("StartWL=\"400\">", "StartWL=\"-10\">", 1));
        assert!(e.contains("ReflectanceSpectrum: starts at -10 nm"), "{e}");
    }

    #[test]
    fn bad_files_are_rejected_naming_file_line_and_field() {
        let good = write(&study(), &fixed()).unwrap();
        let e = err(&good.replacen("</cc:Object>", "", 1));
        assert!(e.starts_with("m.cxf:"), "{e}");
        assert!(e.contains(": xml: "), "{e}");
        let e = err(&good.replacen("Notation=\"45as25\"", "Notation=\"45as26\"", 1));
        assert!(
            e.contains(": BRDFAngle/@Notation: unknown geometry \"45as26\""),
            "{e}"
        );
        let bad = good.replacen("StartWL=\"400\">0.", "StartWL=\"400\">x.", 1);
        let line = bad.lines().position(|l| l.contains(">x.")).unwrap() + 1;
        let e = err(&bad);
        assert!(
            e.starts_with(&format!("m.cxf:{line}: ReflectanceSpectrum (400 nm): \"x.")),
            "{e}"
        );
        let e = err(&good.replacen(
            "ColorSpecification=\"cs-15as15\"",
            "ColorSpecification=\"cs-none\"",
            1,
        ));
        assert!(
            e.contains(
                "ReflectanceSpectrum/@ColorSpecification: \"cs-none\" names no ColorSpecification"
            ),
            "{e}"
        );
        let e = err("<Other/>");
        assert_eq!(
            e,
            "m.cxf:1: Other: not a CxF document (the root element must be CxF)"
        );
    }
}

/// Property tests: whatever text arrives as CxF3, the import returns (never panics), an error
/// names a problem, and the scans of an accepted file validate.
#[cfg(test)]
mod proptests {
    use super::super::Format;
    use super::super::proptests::import_properties;

    const PIECES: [&str; 30] = [
        "<CxF>",
        "</CxF>",
        "<Object Name=\"A\">",
        "<Object Name=\"Munsell N9\">",
        "<Object>",
        "</Object>",
        "<ColorValues>",
        "</ColorValues>",
        "<ReflectanceSpectrum ColorSpecification=\"s\">",
        "<ReflectanceSpectrum ColorSpecification=\"s\" StartWL=\"-1e300\">",
        "</ReflectanceSpectrum>",
        "<CustomSpectrum ColorSpecification=\"s\">",
        "</CustomSpectrum>",
        "<SpectralPoint WL=\"400\">",
        "</SpectralPoint>",
        "<ColorSpecification Id=\"s\">",
        "</ColorSpecification>",
        "<BRDFAngle Notation=\"sra-20\"/>",
        "<BRDFAngle Notation=\"45as45\"/>",
        "<WavelengthRange StartWL=\"390\" Increment=\"10\"/>",
        "<TagCollection Name=\"brdfd\">",
        "</TagCollection>",
        "<Tag Name=\"data_kind\" Value=\"reference\"/>",
        "0.5 ",
        "1 ",
        "-1 ",
        "1e999 ",
        "&amp;",
        "\n",
        "é",
    ];

    import_properties!(Format::Cxf3, cxf3_pieces_are_rejected_or_valid, &PIECES);
}
