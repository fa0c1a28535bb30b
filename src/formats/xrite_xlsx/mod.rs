//! X-Rite's quality-control `.xlsx` export of MA-T12 measurements: the reader, and the check of
//! the file's own L*a*b* against brdfd's colorimetry.
//!
//! The workbook (read with `calamine`; the image anchors, which calamine does not expose, from the
//! drawing parts with `zip` and `roxmltree`) has these sheets:
//!
//! | sheet | content |
//! |---|---|
//! | `Color Data` | `QC JOB:`, `STANDARD:` and `ILLUMINANT/OBSERVER:` (e.g. `D65/10`) rows, then a header `Name, Date/Time, Geometry, L* (D65/10), a* (D65/10), b* (D65/10)` and one row per measurement and geometry |
//! | `Spectral Data` | `QC JOB:` and `STANDARD:` rows, then a header `Name, Date/Time, Geometry, 400, 410, …, 700` and one row per measurement and geometry: reflectance factor, 0–1 scale, relative to the instrument's calibrated white (values above 1 occur near the specular direction) |
//! | `Texture Data` | the instrument's texture indices when measured; not read |
//! | `Texture Images` | a heading row naming the sample in column B, then one row per 15° geometry (and `15d`) with its name in column A and the camera's PNG anchored in column B of that row |
//!
//! `Color Data` and `Spectral Data` are required, the texture sheets are optional. Columns are
//! found by their header text, not their position; rows whose cells are all empty are skipped
//! (some exports pad every sheet to 1,000 rows).
//!
//! A measurement is the rows of `Spectral Data` that share `Date/Time` and `Name`; it must hold
//! each of the 12 MA-T12 geometries ([`crate::geometry::ma_t12`], named as there) exactly once.
//! A `Color Data` row belongs to the measurement with its `Date/Time` and `Geometry` (its `Name`
//! may differ from the spectral one; when several measurements share the time, the one with the
//! same name). `Date/Time` is the Excel serial day number the file stores (or ISO 8601 text), read
//! as the instrument's local time: the file does not say its time zone.
//!
//! Texture images are given to the measurement the sheet's heading row above them names (by its
//! `Spectral Data` or `Color Data` name); in a file with one measurement all of them are its own.
//! An image whose heading names no single measurement of a multi-measurement file is kept in
//! [`XriteExport::unassigned_textures`]. Each image keeps the geometry written in column A of
//! the row it is anchored in, and that anchor cell.
//!
//! Every error names the file, the sheet and the cell (or the measurement, when something is
//! missing); a file with any error gives no measurements at all.
//!
//! The reader is split by what it reads, each file owning the import-budget limits of its data
//! ([`super::budget`]): `archive` (the zip archive's parts, each read within its size limit, and
//! the workbook's sheet list), `cells` (the sheets' cells and shared strings: a sheet's
//! bounding box and the shared strings' count and length checked before calamine builds its
//! grid, then the measurements read from the cells), `markup` (the tag scanner those checks
//! use), `images` (the texture images: anchors, each image part read once, bytes and PNG
//! pixels) and `colorimetry` ([`check_colorimetry`]).

use std::collections::BTreeMap;
use std::io::Cursor;
use std::panic::{AssertUnwindSafe, catch_unwind};
use std::path::Path;

use calamine::{Reader, Xlsx};
use sha2::{Digest, Sha256};

use super::budget::{Budget, Limit, OverBudget};
use crate::colour::Lab;
use crate::geometry::MA_T12_COUNT;
use crate::spectral::Spectrum;

use archive::Parts;
use cells::Sheet;
pub use colorimetry::{COLORIMETRY_THRESHOLD, ColorimetryCheck, check_colorimetry};

mod archive;
mod cells;
mod colorimetry;
mod images;
mod markup;
mod proptests;

/// The sheet of L*a*b* values.
pub const COLOR_SHEET: &str = "Color Data";
/// The sheet of reflectance spectra.
pub const SPECTRAL_SHEET: &str = "Spectral Data";
/// The sheet of camera images.
pub const TEXTURE_IMAGES_SHEET: &str = "Texture Images";

/// One `.xlsx` file as read.
#[derive(Debug, Clone, PartialEq)]
pub struct XriteExport {
    /// The file name as given to [`read`] (used in every error).
    pub file_name: String,
    /// SHA-256 of the file's bytes, lower-case hex.
    pub sha256_hex: String,
    /// The measurements, in the order their first `Spectral Data` row appears.
    pub measurements: Vec<XriteMeasurement>,
    /// Texture images that no measurement could be given (see the module docs); empty for a
    /// file with one measurement.
    pub unassigned_textures: Vec<TextureImage>,
}

/// One MA-T12 measurement of a sample: 12 geometries.
#[derive(Debug, Clone, PartialEq)]
pub struct XriteMeasurement {
    /// The `Name` of its `Spectral Data` rows.
    pub name: String,
    /// The `Name` of its `Color Data` rows, when it differs from [`XriteMeasurement::name`].
    pub color_data_name: Option<String>,
    /// `Date/Time`, as the instrument's local time (the file states no time zone).
    pub measured_at: jiff::civil::DateTime,
    /// `Date/Time` as the file stores it: the Excel serial day number (shortest round-trip
    /// decimal) or the cell's text.
    pub measured_at_text: String,
    /// The `QC JOB:` name.
    pub job: String,
    /// The `STANDARD:` name.
    pub standard: String,
    /// The illuminant of `ILLUMINANT/OBSERVER:`, as written (e.g. `D65`).
    pub illuminant: String,
    /// The observer of `ILLUMINANT/OBSERVER:` in degrees (e.g. 10).
    pub observer_deg: u32,
    /// The instrument's serial number, when the file states one (the known exports do not).
    pub instrument_serial: Option<String>,
    /// Reflectance factor (0–1 scale) per MA-T12 geometry, in [`crate::geometry::GEOMETRIES`]
    /// order, 400–700 nm at 10 nm.
    pub spectra: [Spectrum; MA_T12_COUNT],
    /// X-Rite's own L*a*b* per geometry, same order, under the stated illuminant/observer.
    pub lab: [Lab; MA_T12_COUNT],
    /// The instrument camera's images of this measurement, in the drawing's order.
    pub textures: Vec<TextureImage>,
}

/// One camera image of the `Texture Images` sheet.
#[derive(Debug, Clone, PartialEq)]
pub struct TextureImage {
    /// The text in column A of the row the image is anchored in: a 15° geometry (`15as-45` …
    /// `15as80`) or `15d`, as the file writes it.
    pub geometry: String,
    /// The cell the image's top-left corner is anchored in, e.g. `B2`.
    pub anchor: String,
    /// The PNG file, as stored.
    pub png: Vec<u8>,
}

/// Everything that can be wrong with an X-Rite `.xlsx` export.
#[derive(Debug, thiserror::Error)]
pub enum XlsxError {
    #[error("cannot read {}: {source}", path.display())]
    Read {
        path: std::path::PathBuf,
        source: std::io::Error,
    },
    /// A part of the file is beyond the import budget.
    #[error(transparent)]
    Budget(#[from] OverBudget),
    #[error("{file}: not a zip archive, so not an .xlsx file ({message})")]
    NotZip { file: String, message: String },
    #[error("{file}: a zip archive but not a readable .xlsx workbook: {message}")]
    NotXlsx { file: String, message: String },
    #[error("{file}: no sheet \"{sheet}\" (the workbook has: {found}); export the QC job again")]
    MissingSheet {
        file: String,
        sheet: &'static str,
        found: String,
    },
    #[error("{file}: sheet \"{sheet}\": {message}")]
    Sheet {
        file: String,
        sheet: &'static str,
        message: String,
    },
    #[error("{file}: sheet \"{sheet}\", cell {cell}: {message}")]
    Cell {
        file: String,
        sheet: &'static str,
        cell: String,
        message: String,
    },
    #[error("{file}: sheet \"{sheet}\", cell {cell}: empty; {what} expected")]
    EmptyCell {
        file: String,
        sheet: &'static str,
        cell: String,
        what: String,
    },
    #[error("{file}: sheet \"{sheet}\", cell {cell}: {text:?} is not a number")]
    NotANumber {
        file: String,
        sheet: &'static str,
        cell: String,
        text: String,
    },
    #[error(
        "{file}: sheet \"{sheet}\", cell {cell}: {value} is negative; a reflectance factor is \
         at least 0"
    )]
    Negative {
        file: String,
        sheet: &'static str,
        cell: String,
        value: f64,
    },
    #[error(
        "{file}: sheet \"{sheet}\", cell {cell}: {value:e} is beyond any reflectance factor an \
         instrument reads (at most {}); the cell is corrupt",
        crate::scan::MAX_REFLECTANCE_FACTOR
    )]
    Unphysical {
        file: String,
        sheet: &'static str,
        cell: String,
        value: f64,
    },
    #[error(
        "{file}: sheet \"{sheet}\", cell {cell}: wavelength grid {found} is not the MA-T12's \
         400–700 nm at 10 nm (31 columns, 400, 410, …, 700)"
    )]
    WavelengthGrid {
        file: String,
        sheet: &'static str,
        cell: String,
        found: String,
    },
    #[error(
        "{file}: sheet \"{sheet}\", cell {cell}: geometry \"{geometry}\" is already in cell \
         {first} for this Name and Date/Time; an MA-T12 measurement has each geometry once"
    )]
    DuplicateGeometry {
        file: String,
        sheet: &'static str,
        cell: String,
        geometry: &'static str,
        first: String,
    },
    #[error(
        "{file}: sheet \"{sheet}\": measurement \"{measurement}\" ({date}) has no row for \
         geometr{} {}; an MA-T12 measurement has all 12",
        if missing.len() == 1 { "y" } else { "ies" },
        missing.join(", ")
    )]
    MissingGeometry {
        file: String,
        sheet: &'static str,
        measurement: String,
        date: String,
        missing: Vec<String>,
    },
    #[error(
        "{file}: sheet \"Color Data\", cell {cell}: row \"{name}\" {date} {geometry} matches no \
         row of \"Spectral Data\" (by Date/Time and Geometry)"
    )]
    UnmatchedColorRow {
        file: String,
        cell: String,
        name: String,
        date: String,
        geometry: String,
    },
    #[error(
        "measurement \"{measurement}\": illuminant/observer {illuminant}/{observer_deg} cannot \
         be computed by brdfd, which computes D65 with the 2° or the 10° observer"
    )]
    UnsupportedColorimetry {
        measurement: String,
        illuminant: String,
        observer_deg: u32,
    },
}

/// A fixture for tests: the real exports kept under [`REAL_EXPORTS_DIR`], by file name.
pub const REAL_EXPORTS: [&str; 6] = [
    "PAR_EW_RL_NG_3.xlsx",
    "PAR_NB_NP_CC_0.xlsx",
    "PAR_PW_CB_NG_1.xlsx",
    "PAR_PW_GE_MC_1.xlsx",
    "PAR_PW_RO_NG_1.xlsx",
    "PEN_PW_EB_NG_1.xlsx",
];

/// Where [`REAL_EXPORTS`] are, in the source tree (their source in its README).
pub const REAL_EXPORTS_DIR: &str = "tests/data/real-mat12";

/// Reads the file at `path` within `budget` (refused unread when larger than its file size).
pub fn read_file(path: &Path, budget: &Budget) -> Result<XriteExport, XlsxError> {
    let name = path.file_name().map_or_else(
        || path.display().to_string(),
        |n| n.to_string_lossy().into_owned(),
    );
    let bytes = budget.read_file(path, &name).map_err(|e| match e {
        super::budget::ReadError::Io(source) => XlsxError::Read {
            path: path.to_path_buf(),
            source,
        },
        super::budget::ReadError::Over(e) => XlsxError::Budget(e),
    })?;
    read(&bytes, &name, budget)
}

/// Reads an export from its bytes within `budget`; `file_name` names it in errors.
pub fn read(bytes: &[u8], file_name: &str, budget: &Budget) -> Result<XriteExport, XlsxError> {
    let file = file_name.to_string();
    budget.check(
        Limit::FileBytes,
        &file,
        "the whole file",
        bytes.len() as u64,
    )?;
    let mut zip = zip::ZipArchive::new(Cursor::new(bytes)).map_err(|e| XlsxError::NotZip {
        file: file.clone(),
        message: e.to_string(),
    })?;
    for i in 0..zip.len() {
        let entry = zip.by_index_raw(i).map_err(|e| XlsxError::NotZip {
            file: file.clone(),
            message: e.to_string(),
        })?;
        let part = format!(
            "part \"{}\"",
            entry.name().map(|n| n.into_owned()).unwrap_or_default()
        );
        budget.check(Limit::PartBytes, &file, &part, entry.size())?;
    }
    let mut parts = Parts {
        file: &file,
        zip: &mut zip,
        budget,
        images: BTreeMap::new(),
    };
    // What the spreadsheet reader will hold is checked before it reads anything: the shared
    // strings it reads whole, and the bounding box of each sheet it is asked for, which it
    // allocates as a dense grid.
    let workbook = parts.workbook()?;
    parts.check_shared_strings()?;
    for name in [COLOR_SHEET, SPECTRAL_SHEET, TEXTURE_IMAGES_SHEET] {
        if let Some(part) = workbook.sheets.get(name) {
            parts.check_sheet(name, part)?;
        }
    }
    let not_xlsx = |message: String| XlsxError::NotXlsx {
        file: file.clone(),
        message,
    };
    // calamine is the reader of the workbook's cells; a file it cannot handle must come back
    // as a refusal, so a panic inside it (seen: an integer overflow on a corrupted cell
    // reference) is caught and reported as such.
    let calamine_panicked =
        |what: &str| not_xlsx(format!("the spreadsheet reader failed on {what}"));
    let mut book = catch_unwind(AssertUnwindSafe(|| Xlsx::new(Cursor::new(bytes))))
        .map_err(|_| calamine_panicked("the workbook"))?
        .map_err(|e| not_xlsx(e.to_string()))?;
    let names = book.sheet_names();
    let mut sheet = |name: &'static str, required: bool| -> Result<Option<Sheet>, XlsxError> {
        if !names.iter().any(|n| n == name) {
            if !required {
                return Ok(None);
            }
            return Err(XlsxError::MissingSheet {
                file: file.clone(),
                sheet: name,
                found: names
                    .iter()
                    .map(|n| format!("\"{n}\""))
                    .collect::<Vec<_>>()
                    .join(", "),
            });
        }
        let range = catch_unwind(AssertUnwindSafe(|| book.worksheet_range(name)))
            .map_err(|_| calamine_panicked(&format!("sheet \"{name}\"")))?
            .map_err(|e| not_xlsx(format!("sheet \"{name}\": {e}")))?;
        Ok(Some(Sheet {
            file: file.clone(),
            name,
            range,
        }))
    };
    let color = sheet(COLOR_SHEET, true)?.expect("required");
    let spectral = sheet(SPECTRAL_SHEET, true)?.expect("required");
    let images_sheet = sheet(TEXTURE_IMAGES_SHEET, false)?;
    drop(book);

    let s_meta = spectral.metadata()?;
    let c_meta = color.metadata()?;
    let job = s_meta
        .job
        .clone()
        .or_else(|| c_meta.job.clone())
        .ok_or_else(|| spectral.sheet_error("no \"QC JOB:\" row above the header"))?;
    let standard = s_meta
        .standard
        .clone()
        .or_else(|| c_meta.standard.clone())
        .ok_or_else(|| spectral.sheet_error("no \"STANDARD:\" row above the header"))?;
    let serial = s_meta.serial.clone().or_else(|| c_meta.serial.clone());
    let (illuminant, observer_deg) = color.illuminant_observer(&c_meta)?;

    let mut measurements = spectral.spectral_rows(workbook.date1904)?;
    let labs = color.color_rows(
        workbook.date1904,
        &measurements,
        &format!("{illuminant}/{observer_deg}"),
    )?;

    let textures = match &images_sheet {
        Some(s) => parts.textures(s, &workbook)?,
        None => Vec::new(),
    };

    let mut out = Vec::with_capacity(measurements.len());
    for (m, (lab, color_name)) in measurements.iter_mut().zip(labs) {
        out.push(XriteMeasurement {
            name: m.name.clone(),
            color_data_name: color_name.filter(|n| *n != m.name),
            measured_at: m.at,
            measured_at_text: m.at_text.clone(),
            job: job.clone(),
            standard: standard.clone(),
            illuminant: illuminant.clone(),
            observer_deg,
            instrument_serial: serial.clone(),
            spectra: std::mem::replace(&mut m.spectra, [None; MA_T12_COUNT])
                .map(|s| s.expect("every geometry was checked present")),
            lab,
            textures: Vec::new(),
        });
    }
    let mut unassigned = Vec::new();
    for (heading, image) in textures {
        let owner = if out.len() == 1 {
            Some(0)
        } else {
            let hits: Vec<usize> = (0..out.len())
                .filter(|&i| {
                    heading.as_deref().is_some_and(|h| {
                        out[i].name == h || out[i].color_data_name.as_deref() == Some(h)
                    })
                })
                .collect();
            (hits.len() == 1).then(|| hits[0])
        };
        match owner {
            Some(i) => out[i].textures.push(image),
            None => unassigned.push(image),
        }
    }

    Ok(XriteExport {
        file_name: file,
        sha256_hex: hex::encode(Sha256::digest(bytes)),
        measurements: out,
        unassigned_textures: unassigned,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::io::{Read, Write};

    /// The reader with the shipped budget.
    pub(super) fn read(bytes: &[u8], name: &str) -> Result<XriteExport, XlsxError> {
        super::read(bytes, name, &Budget::default())
    }

    pub(super) fn read_file(path: &Path) -> Result<XriteExport, XlsxError> {
        super::read_file(path, &Budget::default())
    }

    pub(super) fn path(name: &str) -> std::path::PathBuf {
        Path::new(env!("CARGO_MANIFEST_DIR"))
            .join(REAL_EXPORTS_DIR)
            .join(name)
    }

    pub(super) fn bytes(name: &str) -> Vec<u8> {
        std::fs::read(path(name)).unwrap()
    }

    /// The archive's parts, in order.
    pub(super) fn unzip(bytes: &[u8]) -> Vec<(String, Vec<u8>)> {
        let mut z = zip::ZipArchive::new(Cursor::new(bytes)).unwrap();
        (0..z.len())
            .map(|i| {
                let mut f = z.by_index(i).unwrap();
                let mut b = Vec::new();
                f.read_to_end(&mut b).unwrap();
                (f.name().unwrap().into_owned(), b)
            })
            .collect()
    }

    /// An archive of `parts` (stored, uncompressed).
    pub(super) fn rezip(parts: &[(String, Vec<u8>)]) -> Vec<u8> {
        let mut w = zip::ZipWriter::new(Cursor::new(Vec::new()));
        let opts = zip::write::SimpleFileOptions::default()
            .compression_method(zip::CompressionMethod::Stored);
        for (name, b) in parts {
            w.start_file(name.as_str(), opts).unwrap();
            w.write_all(b).unwrap();
        }
        w.finish().unwrap().into_inner()
    }

    /// `file` with `edit` applied to the text of `part`.
    pub(super) fn edited(file: &str, part: &str, edit: impl FnOnce(String) -> String) -> Vec<u8> {
        let mut parts = unzip(&bytes(file));
        let p = parts.iter_mut().find(|(n, _)| n == part).unwrap();
        let text = String::from_utf8(std::mem::take(&mut p.1)).unwrap();
        let new = edit(text.clone());
        assert_ne!(new, text, "the edit of {part} changed nothing");
        p.1 = new.into_bytes();
        rezip(&parts)
    }

    /// Replaces the XML of cell `cell` (`<c r="D7" …>…</c>` or `<c r="D7" …/>`) by `with`.
    pub(super) fn set_cell(xml: String, cell: &str, with: &str) -> String {
        let start = xml
            .find(&format!("<c r=\"{cell}\""))
            .unwrap_or_else(|| panic!("no cell {cell}"));
        let open_end = start + xml[start..].find('>').unwrap();
        let end = if xml.as_bytes()[open_end - 1] == b'/' {
            open_end + 1
        } else {
            open_end + xml[open_end..].find("</c>").unwrap() + 4
        };
        format!("{}{with}{}", &xml[..start], &xml[end..])
    }

    pub(super) fn err(bytes: &[u8]) -> String {
        match read(bytes, "PAR_x.xlsx") {
            Ok(_) => panic!("accepted"),
            Err(e) => e.to_string(),
        }
    }

    // Color Data is sheet1, Spectral Data sheet3, Texture Images sheet4 in these files.
    pub(super) const COLOR: &str = "xl/worksheets/sheet1.xml";
    pub(super) const SPECTRAL: &str = "xl/worksheets/sheet3.xml";
    pub(super) const REGULAR: &str = "PAR_EW_RL_NG_3.xlsx";

    #[test]
    fn all_six_files_read_with_12_geometries_and_7_images() {
        for f in REAL_EXPORTS {
            let x = read_file(&path(f)).unwrap_or_else(|e| panic!("{e}"));
            assert_eq!(x.file_name, f);
            assert_eq!(x.sha256_hex.len(), 64);
            assert_eq!(x.measurements.len(), 1, "{f}");
            assert!(x.unassigned_textures.is_empty());
            let m = &x.measurements[0];
            assert_eq!((m.illuminant.as_str(), m.observer_deg), ("D65", 10), "{f}");
            assert!(m.job.starts_with("Job "), "{f}: {}", m.job);
            assert_eq!(m.instrument_serial, None);
            for s in &m.spectra {
                assert!(
                    s.iter().all(|v| v.is_finite() && *v >= 0.0 && *v < 2.0),
                    "{f}"
                );
            }
            let names: Vec<&str> = m.textures.iter().map(|t| t.geometry.as_str()).collect();
            assert_eq!(
                names,
                [
                    "15as-45", "15as-30", "15as-15", "15as15", "15as45", "15as80", "15d"
                ],
                "{f}"
            );
            let anchors: Vec<&str> = m.textures.iter().map(|t| t.anchor.as_str()).collect();
            assert_eq!(anchors, ["B2", "B3", "B4", "B5", "B6", "B7", "B8"], "{f}");
            assert!(m.textures.iter().all(|t| t.png.starts_with(b"\x89PNG")));
        }
    }

    #[test]
    fn a_regular_file_reads_as_the_cells_say() {
        let x = read_file(&path(REGULAR)).unwrap();
        let m = &x.measurements[0];
        assert_eq!(m.name, "PAR_EW_RL_NG_3");
        assert_eq!(m.color_data_name, None);
        assert_eq!(m.standard, "PAR_EW_RL_NG_3");
        assert_eq!(m.job, "Job 29.05.2024");
        // 45441.7965277778 days after 1899-12-30.
        assert_eq!(m.measured_at_text, "45441.7965277778");
        assert_eq!(m.measured_at.to_string(), "2024-05-29T19:07:00");
        // Spectral Data D4 and AH4 (15as-45 at 400 nm, and the Color Data row 5).
        assert_eq!(m.spectra[0][0], 0.036533191204071);
        assert_eq!(
            m.lab[0],
            Lab {
                l: 28.9307988064274,
                a: 37.0121698368685,
                b: 15.4687582967474
            }
        );
        assert_eq!(m.lab[11].l, 31.3605540607635);
        // The SHA-256 is of the file's bytes.
        let want = hex::encode(Sha256::digest(bytes(REGULAR)));
        assert_eq!(x.sha256_hex, want);
        // Texture 15as15 is drawing rId4's image, anchored in row 5 (as the drawing says).
        assert_eq!(m.textures[3].geometry, "15as15");
    }

    #[test]
    fn the_padded_file_with_differing_names_reads() {
        let x = read_file(&path("PAR_NB_NP_CC_0.xlsx")).unwrap();
        let m = &x.measurements[0];
        assert_eq!(m.name, "PAR_CC");
        assert_eq!(m.color_data_name.as_deref(), Some("PAR_NaN_NaN_CC_NaN"));
        assert_eq!(m.standard, "PAR_CC");
        assert_eq!(m.measured_at.to_string(), "2024-08-20T18:21:37");
        assert_eq!(m.lab[0].l, 89.7051201147229);
        assert_eq!(m.spectra[0][0], 0.628225975036621);
        // Its images are anchored in a shuffled relationship order: the anchor row decides.
        assert_eq!(m.textures[6].geometry, "15d");
    }

    #[test]
    fn a_missing_sheet_is_an_error_listing_the_sheets() {
        let b = edited(REGULAR, "xl/workbook.xml", |x| {
            x.replace("name=\"Spectral Data\"", "name=\"Spectra\"")
        });
        let e = err(&b);
        assert!(
            e.starts_with("PAR_x.xlsx: no sheet \"Spectral Data\"") && e.contains("\"Spectra\""),
            "{e}"
        );
        // The texture sheets are optional.
        let b = edited(REGULAR, "xl/workbook.xml", |x| {
            x.replace("name=\"Texture Images\"", "name=\"Other\"")
        });
        let x = read(&b, "x.xlsx").unwrap();
        assert!(x.measurements[0].textures.is_empty());
    }

    #[test]
    fn not_a_zip_not_an_xlsx_and_too_large_are_errors() {
        let e = err(b"Name,Date/Time,Geometry\n");
        assert!(e.starts_with("PAR_x.xlsx: not a zip archive"), "{e}");
        let e = err(&rezip(&[("a.txt".into(), b"hello".to_vec())]));
        assert!(
            e.starts_with("PAR_x.xlsx: a zip archive but not a readable .xlsx"),
            "{e}"
        );
        let dir = tempfile::tempdir().unwrap();
        let big = dir.path().join("big.xlsx");
        std::fs::File::create(&big)
            .unwrap()
            .set_len(200 * 1024 * 1024)
            .unwrap();
        let e = read_file(&big).unwrap_err().to_string();
        assert!(
            e.starts_with("big.xlsx: the whole file: 209715200 bytes is beyond the import limit"),
            "{e}"
        );
        let e = read_file(&dir.path().join("none.xlsx"))
            .unwrap_err()
            .to_string();
        assert!(e.starts_with("cannot read"), "{e}");
    }
}
