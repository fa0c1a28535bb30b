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

use std::collections::BTreeMap;
use std::io::{Cursor, Read};
use std::panic::{AssertUnwindSafe, catch_unwind};
use std::path::Path;

use calamine::{Data, Range, Reader, Xlsx};
use sha2::{Digest, Sha256};

use super::budget::{Budget, Limit, OverBudget};
use crate::colour::{Colorimetry, Lab, Observer, Weighting, ciede2000};
use crate::geometry::{Device, MA_T12_COUNT, by_name, ma_t12};
use crate::spectral::{BANDS, FIRST_NM, STEP_NM, Spectrum};

/// ΔE00 between X-Rite's L*a*b* and brdfd's above which a geometry is flagged by
/// [`check_colorimetry`]: the two agree to about 1e-5 on real files (ASTM E308 weighting), so a
/// larger difference means a wrong column or an edited file.
pub const COLORIMETRY_THRESHOLD: f64 = 0.01;

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

/// brdfd's L*a*b* against the file's, per geometry.
#[derive(Debug, Clone, PartialEq)]
pub struct ColorimetryCheck {
    /// The colorimetry used: the file's observer, D65, ASTM E308 weighting.
    pub colorimetry: Colorimetry,
    /// brdfd's L*a*b* from the spectra, in [`crate::geometry::GEOMETRIES`] order.
    pub recomputed: [Lab; MA_T12_COUNT],
    /// ΔE00 between the file's and brdfd's L*a*b*, same order.
    pub delta_e00: [f64; MA_T12_COUNT],
    /// The largest of [`ColorimetryCheck::delta_e00`].
    pub largest: f64,
    /// The geometry of the largest.
    pub largest_at: &'static str,
    /// The geometries more than [`COLORIMETRY_THRESHOLD`] apart, in table order.
    pub flagged: Vec<&'static str>,
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

/// Recomputes the L*a*b* of every geometry from the spectra with brdfd's colorimetry (D65, the
/// file's observer, ASTM E308 weighting, as X-Rite's software computes it) and compares them
/// with the file's by ΔE00.
pub fn check_colorimetry(m: &XriteMeasurement) -> Result<ColorimetryCheck, XlsxError> {
    let observer = match (
        m.illuminant.trim().to_ascii_uppercase().as_str(),
        m.observer_deg,
    ) {
        ("D65", 2) => Observer::Cie1931TwoDegree,
        ("D65", 10) => Observer::Cie1964TenDegree,
        _ => {
            return Err(XlsxError::UnsupportedColorimetry {
                measurement: m.name.clone(),
                illuminant: m.illuminant.clone(),
                observer_deg: m.observer_deg,
            });
        }
    };
    let colorimetry = Colorimetry {
        observer,
        weighting: Weighting::AstmE308,
    };
    let recomputed = m.spectra.map(|s| colorimetry.reflectance_to_lab(&s));
    let delta_e00: [f64; MA_T12_COUNT] =
        std::array::from_fn(|i| ciede2000(m.lab[i], recomputed[i]));
    let geometries = ma_t12();
    let (at, largest) = delta_e00
        .iter()
        .copied()
        .enumerate()
        // NaN (a spectrum brdfd cannot turn into a colour) counts as the largest.
        .max_by(|a, b| a.1.total_cmp(&b.1))
        .expect("12 geometries");
    let flagged = geometries
        .iter()
        .zip(&delta_e00)
        .filter(|(_, d)| d.is_nan() || **d > COLORIMETRY_THRESHOLD)
        .map(|(g, _)| g.name)
        .collect();
    Ok(ColorimetryCheck {
        colorimetry,
        recomputed,
        delta_e00,
        largest,
        largest_at: geometries[at].name,
        flagged,
    })
}

/// `A1`-style name of a 0-based cell position.
fn cell_name(row: u32, col: u32) -> String {
    cell_name_u64(u64::from(row) + 1, u64::from(col) + 1)
}

/// `A1`-style name of a 1-based cell position.
fn cell_name_u64(row: u64, col: u64) -> String {
    let mut letters = Vec::new();
    let mut c = col;
    while c > 0 {
        let r = ((c - 1) % 26) as u8;
        letters.push(b'A' + r);
        c = (c - 1) / 26;
    }
    letters.reverse();
    format!("{}{row}", String::from_utf8(letters).expect("ASCII"))
}

/// The labelled rows above a sheet's header.
#[derive(Debug, Default)]
struct Metadata {
    job: Option<String>,
    standard: Option<String>,
    serial: Option<String>,
    /// The `ILLUMINANT/OBSERVER:` value and its cell.
    illuminant_observer: Option<(String, (u32, u32))>,
    /// The header row.
    header: u32,
}

/// One `Spectral Data` measurement while it is being read.
struct SpectralMeasurement {
    name: String,
    at: jiff::civil::DateTime,
    at_text: String,
    spectra: [Option<Spectrum>; MA_T12_COUNT],
    /// The cell of each geometry's `Geometry`, for duplicate errors.
    cells: [Option<String>; MA_T12_COUNT],
}

/// A parsed `Date/Time` cell.
struct When {
    at: jiff::civil::DateTime,
    text: String,
}

/// The header row and the columns that say which measurement and geometry a data row is of.
struct KeyColumns {
    header: u32,
    name: u32,
    date: u32,
    geometry: u32,
}

struct Sheet {
    file: String,
    name: &'static str,
    range: Range<Data>,
}

impl Sheet {
    fn get(&self, row: u32, col: u32) -> &Data {
        self.range.get_value((row, col)).unwrap_or(&Data::Empty)
    }

    /// The cell's text (numbers in their shortest decimal), trimmed; `None` when empty.
    fn text(&self, row: u32, col: u32) -> Option<String> {
        let t = match self.get(row, col) {
            Data::Empty => return None,
            Data::String(s) | Data::DateTimeIso(s) | Data::DurationIso(s) => s.trim().to_string(),
            Data::Float(f) => f.to_string(),
            Data::Int(i) => i.to_string(),
            Data::Bool(b) => b.to_string(),
            Data::DateTime(d) => d.as_f64().to_string(),
            Data::Error(e) => format!("#{e:?}"),
        };
        (!t.is_empty()).then_some(t)
    }

    fn rows(&self) -> std::ops::RangeInclusive<u32> {
        match (self.range.start(), self.range.end()) {
            (Some(s), Some(e)) => s.0..=e.0,
            #[allow(clippy::reversed_empty_ranges)]
            _ => 1..=0,
        }
    }

    fn cols(&self) -> std::ops::RangeInclusive<u32> {
        match (self.range.start(), self.range.end()) {
            (Some(s), Some(e)) => s.1..=e.1,
            #[allow(clippy::reversed_empty_ranges)]
            _ => 1..=0,
        }
    }

    fn row_is_empty(&self, row: u32) -> bool {
        self.cols().all(|c| self.text(row, c).is_none())
    }

    /// The rows below `header` that hold anything.
    fn data_rows(&self, header: u32) -> impl Iterator<Item = u32> + '_ {
        self.rows()
            .filter(move |&r| r > header && !self.row_is_empty(r))
    }

    fn sheet_error(&self, message: impl Into<String>) -> XlsxError {
        XlsxError::Sheet {
            file: self.file.clone(),
            sheet: self.name,
            message: message.into(),
        }
    }

    fn cell_error(&self, row: u32, col: u32, message: impl Into<String>) -> XlsxError {
        XlsxError::Cell {
            file: self.file.clone(),
            sheet: self.name,
            cell: cell_name(row, col),
            message: message.into(),
        }
    }

    fn empty(&self, row: u32, col: u32, what: &str) -> XlsxError {
        XlsxError::EmptyCell {
            file: self.file.clone(),
            sheet: self.name,
            cell: cell_name(row, col),
            what: what.to_string(),
        }
    }

    /// The header row (first cell `Name`) and the labelled rows above it.
    fn metadata(&self) -> Result<Metadata, XlsxError> {
        let mut m = Metadata::default();
        let first_col = self.range.start().map_or(0, |s| s.1);
        for row in self.rows() {
            let Some(label) = self.text(row, first_col) else {
                continue;
            };
            let value = || self.text(row, first_col + 1);
            let upper = label.to_ascii_uppercase();
            if upper == "NAME" {
                m.header = row;
                return Ok(m);
            } else if upper.starts_with("QC JOB") {
                m.job = value();
            } else if upper.starts_with("STANDARD") {
                m.standard = value();
            } else if upper.starts_with("ILLUMINANT") {
                m.illuminant_observer = value().map(|v| (v, (row, first_col + 1)));
            } else if upper.contains("SERIAL") {
                m.serial = value();
            }
        }
        Err(self.sheet_error(
            "no header row (a row starting with \"Name\", then \"Date/Time\" and \"Geometry\")",
        ))
    }

    /// The column whose header is `title` (case-insensitive).
    fn column(&self, header: u32, title: &str) -> Result<u32, XlsxError> {
        self.cols()
            .find(|&c| {
                self.text(header, c)
                    .is_some_and(|t| t.eq_ignore_ascii_case(title))
            })
            .ok_or_else(|| {
                self.sheet_error(format!(
                    "the header in row {} has no \"{title}\" column",
                    header + 1
                ))
            })
    }

    /// `ILLUMINANT/OBSERVER:` as (illuminant, observer in degrees).
    fn illuminant_observer(&self, meta: &Metadata) -> Result<(String, u32), XlsxError> {
        let Some((text, (row, col))) = &meta.illuminant_observer else {
            return Err(self.sheet_error(
                "no \"ILLUMINANT/OBSERVER:\" row (e.g. \"D65/10\") above the header",
            ));
        };
        let bad = || {
            self.cell_error(
                *row,
                *col,
                format!("illuminant/observer {text:?} is not of the form \"D65/10\""),
            )
        };
        let (ill, obs) = text.split_once('/').ok_or_else(bad)?;
        let observer: u32 = obs
            .trim()
            .trim_end_matches('°')
            .parse()
            .map_err(|_| bad())?;
        let ill = ill.trim();
        if ill.is_empty() {
            return Err(bad());
        }
        Ok((ill.to_string(), observer))
    }

    /// A number cell (numeric text accepted), finite.
    fn number(&self, row: u32, col: u32, what: &str) -> Result<f64, XlsxError> {
        let v = match self.get(row, col) {
            Data::Float(f) => *f,
            Data::Int(i) => *i as f64,
            Data::Empty => return Err(self.empty(row, col, what)),
            Data::String(s) if s.trim().is_empty() => return Err(self.empty(row, col, what)),
            Data::String(s) => s.trim().parse::<f64>().map_err(|_| XlsxError::NotANumber {
                file: self.file.clone(),
                sheet: self.name,
                cell: cell_name(row, col),
                text: s.clone(),
            })?,
            _ => {
                return Err(XlsxError::NotANumber {
                    file: self.file.clone(),
                    sheet: self.name,
                    cell: cell_name(row, col),
                    text: self.text(row, col).unwrap_or_default(),
                });
            }
        };
        if !v.is_finite() {
            return Err(XlsxError::NotANumber {
                file: self.file.clone(),
                sheet: self.name,
                cell: cell_name(row, col),
                text: v.to_string(),
            });
        }
        Ok(v)
    }

    /// A `Date/Time` cell: an Excel serial day number or ISO 8601 text.
    fn when(&self, row: u32, col: u32, date1904: bool) -> Result<When, XlsxError> {
        let serial = match self.get(row, col) {
            Data::Empty => return Err(self.empty(row, col, "the measurement's date and time")),
            Data::DateTime(d) => d.as_f64(),
            Data::Float(f) => *f,
            Data::Int(i) => *i as f64,
            Data::String(s) | Data::DateTimeIso(s) => {
                let t = s.trim();
                if t.is_empty() {
                    return Err(self.empty(row, col, "the measurement's date and time"));
                }
                return match t.parse::<jiff::civil::DateTime>() {
                    Ok(at) => Ok(When {
                        at,
                        text: t.to_string(),
                    }),
                    Err(_) => Err(self.cell_error(
                        row,
                        col,
                        format!(
                            "{t:?} is not a date and time (an Excel date or ISO 8601 text, \
                             e.g. 2024-08-20T18:21:37)"
                        ),
                    )),
                };
            }
            _ => {
                return Err(self.cell_error(
                    row,
                    col,
                    format!(
                        "{:?} is not a date and time",
                        self.text(row, col).unwrap_or_default()
                    ),
                ));
            }
        };
        let at = excel_serial_to_datetime(serial, date1904).ok_or_else(|| {
            self.cell_error(
                row,
                col,
                format!("{serial} is not an Excel date between 1900-03-01 and 9999-12-31"),
            )
        })?;
        Ok(When {
            at,
            text: serial.to_string(),
        })
    }

    /// A `Geometry` cell: one of the 12 MA-T12 geometries, by its index in table order.
    fn geometry(&self, row: u32, col: u32) -> Result<usize, XlsxError> {
        let Some(t) = self.text(row, col) else {
            return Err(self.empty(row, col, "an MA-T12 geometry (15as-45 … 45as110)"));
        };
        match by_name(&t) {
            Some(g) if g.device == Device::MaT12 => Ok(g.index),
            _ => Err(self.cell_error(
                row,
                col,
                format!(
                    "geometry {t:?} is not one of the MA-T12's: {}",
                    ma_t12()
                        .iter()
                        .map(|g| g.name)
                        .collect::<Vec<_>>()
                        .join(", ")
                ),
            )),
        }
    }

    /// The header row and its `Name`, `Date/Time` and `Geometry` columns.
    fn key_columns(&self) -> Result<KeyColumns, XlsxError> {
        let header = self.metadata()?.header;
        Ok(KeyColumns {
            header,
            name: self.column(header, "Name")?,
            date: self.column(header, "Date/Time")?,
            geometry: self.column(header, "Geometry")?,
        })
    }

    /// The measurement name, time and geometry (index) data row `row` is of.
    fn row_key(
        &self,
        key: &KeyColumns,
        row: u32,
        date1904: bool,
    ) -> Result<(String, When, usize), XlsxError> {
        let name = self
            .text(row, key.name)
            .ok_or_else(|| self.empty(row, key.name, "the measurement's name"))?;
        let when = self.when(row, key.date, date1904)?;
        let g = self.geometry(row, key.geometry)?;
        Ok((name, when, g))
    }

    /// Records in `cells` that `row` gives a measurement's geometry `g`; a second row for it is
    /// an error naming both cells.
    fn claim_geometry(
        &self,
        cells: &mut [Option<String>; MA_T12_COUNT],
        row: u32,
        geo_col: u32,
        g: usize,
    ) -> Result<(), XlsxError> {
        if let Some(first) = &cells[g] {
            return Err(XlsxError::DuplicateGeometry {
                file: self.file.clone(),
                sheet: self.name,
                cell: cell_name(row, geo_col),
                geometry: ma_t12()[g].name,
                first: first.clone(),
            });
        }
        cells[g] = Some(cell_name(row, geo_col));
        Ok(())
    }

    /// An error naming the geometries measurement `m` has no row at (`has(g)` false), if any.
    fn every_geometry(
        &self,
        m: &SpectralMeasurement,
        has: impl Fn(usize) -> bool,
    ) -> Result<(), XlsxError> {
        let missing: Vec<String> = ma_t12()
            .iter()
            .filter(|g| !has(g.index))
            .map(|g| g.name.to_string())
            .collect();
        if missing.is_empty() {
            return Ok(());
        }
        Err(XlsxError::MissingGeometry {
            file: self.file.clone(),
            sheet: self.name,
            measurement: m.name.clone(),
            date: m.at.to_string(),
            missing,
        })
    }

    /// The measurements of `Spectral Data`, each with all 12 geometries.
    fn spectral_rows(&self, date1904: bool) -> Result<Vec<SpectralMeasurement>, XlsxError> {
        let key = self.key_columns()?;
        let band_cols = self.wavelength_columns(key.header, key.geometry)?;

        let mut out: Vec<SpectralMeasurement> = Vec::new();
        for row in self.data_rows(key.header) {
            let (name, when, g) = self.row_key(&key, row, date1904)?;
            let mut spectrum = [0.0; BANDS];
            for (b, &col) in band_cols.iter().enumerate() {
                let v = self.number(row, col, "a reflectance factor")?;
                if v < 0.0 {
                    return Err(XlsxError::Negative {
                        file: self.file.clone(),
                        sheet: self.name,
                        cell: cell_name(row, col),
                        value: v,
                    });
                }
                if !crate::scan::physical_reflectance_factor(v) {
                    return Err(XlsxError::Unphysical {
                        file: self.file.clone(),
                        sheet: self.name,
                        cell: cell_name(row, col),
                        value: v,
                    });
                }
                spectrum[b] = v;
            }
            let i = match out.iter().position(|m| m.at == when.at && m.name == name) {
                Some(i) => i,
                None => {
                    out.push(SpectralMeasurement {
                        name,
                        at: when.at,
                        at_text: when.text,
                        spectra: [None; MA_T12_COUNT],
                        cells: Default::default(),
                    });
                    out.len() - 1
                }
            };
            let m = &mut out[i];
            self.claim_geometry(&mut m.cells, row, key.geometry, g)?;
            m.spectra[g] = Some(spectrum);
        }
        if out.is_empty() {
            return Err(self.sheet_error(format!(
                "no measurement rows below the header in row {}",
                key.header + 1
            )));
        }
        for m in &out {
            self.every_geometry(m, |g| m.spectra[g].is_some())?;
        }
        Ok(out)
    }

    /// The columns of the 31 bands, 400–700 nm at 10 nm, right of `Geometry`.
    fn wavelength_columns(&self, header: u32, geo_col: u32) -> Result<Vec<u32>, XlsxError> {
        let cols: Vec<u32> = self
            .cols()
            .filter(|&c| c > geo_col && self.text(header, c).is_some())
            .collect();
        let mut nm = Vec::with_capacity(cols.len());
        for &c in &cols {
            let t = self.text(header, c).expect("filtered");
            let v = t
                .trim_end_matches("nm")
                .trim()
                .parse::<f64>()
                .map_err(|_| XlsxError::WavelengthGrid {
                    file: self.file.clone(),
                    sheet: self.name,
                    cell: cell_name(header, c),
                    found: format!("heading {t:?}"),
                })?;
            nm.push(v);
        }
        let want: Vec<f64> = (0..BANDS as u32)
            .map(|i| f64::from(FIRST_NM + i * STEP_NM))
            .collect();
        // The first column that differs from the grid, or the first missing/extra one.
        let bad = (0..nm.len().max(want.len())).find(|&i| nm.get(i) != want.get(i));
        if let Some(i) = bad {
            let found = match (nm.first(), nm.last()) {
                (Some(a), Some(b)) => format!("{a}–{b} nm in {} columns", nm.len()),
                _ => "with no wavelength columns".to_string(),
            };
            let col = cols
                .get(i)
                .copied()
                .unwrap_or_else(|| cols.last().map_or(geo_col + 1, |c| c + 1));
            return Err(XlsxError::WavelengthGrid {
                file: self.file.clone(),
                sheet: self.name,
                cell: cell_name(header, col),
                found,
            });
        }
        Ok(cols)
    }

    /// X-Rite's L*a*b* of each measurement (by `Date/Time` + `Geometry`), and the `Name` its
    /// `Color Data` rows give it.
    #[allow(clippy::type_complexity)]
    fn color_rows(
        &self,
        date1904: bool,
        measurements: &[SpectralMeasurement],
        stated: &str,
    ) -> Result<Vec<([Lab; MA_T12_COUNT], Option<String>)>, XlsxError> {
        let key = self.key_columns()?;
        let header = key.header;
        let mut lab_cols = [0u32; 3];
        for (k, prefix) in ["L*", "a*", "b*"].into_iter().enumerate() {
            let col = self
                .cols()
                .find(|&c| self.text(header, c).is_some_and(|t| t.starts_with(prefix)))
                .ok_or_else(|| {
                    self.sheet_error(format!(
                        "the header in row {} has no \"{prefix}\" column",
                        header + 1
                    ))
                })?;
            // "L* (D65/10)": the column must be under the stated illuminant/observer.
            let t = self.text(header, col).expect("found");
            let rest = t[prefix.len()..].trim();
            if let Some(inner) = rest.strip_prefix('(').and_then(|r| r.strip_suffix(')'))
                && inner.trim() != stated
            {
                return Err(self.cell_error(
                    header,
                    col,
                    format!("column {t:?} is not under the sheet's ILLUMINANT/OBSERVER {stated:?}"),
                ));
            }
            lab_cols[k] = col;
        }

        let mut labs: Vec<[Option<Lab>; MA_T12_COUNT]> =
            vec![[None; MA_T12_COUNT]; measurements.len()];
        let mut cells: Vec<[Option<String>; MA_T12_COUNT]> =
            vec![Default::default(); measurements.len()];
        let mut names: Vec<Option<(String, String)>> = vec![None; measurements.len()];
        for row in self.data_rows(header) {
            let (name, when, g) = self.row_key(&key, row, date1904)?;
            let same_time: Vec<usize> = (0..measurements.len())
                .filter(|&i| measurements[i].at == when.at)
                .collect();
            let i = match same_time.as_slice() {
                [i] => *i,
                [] => {
                    return Err(XlsxError::UnmatchedColorRow {
                        file: self.file.clone(),
                        cell: cell_name(row, key.date),
                        name,
                        date: when.at.to_string(),
                        geometry: ma_t12()[g].name.to_string(),
                    });
                }
                several => match several.iter().find(|&&i| measurements[i].name == name) {
                    Some(i) => *i,
                    None => {
                        return Err(self.cell_error(
                            row,
                            key.name,
                            format!(
                                "\"{name}\" at {} could be any of the {} Spectral Data \
                                 measurements of that time, and names none of them",
                                when.at,
                                several.len()
                            ),
                        ));
                    }
                },
            };
            let m = &measurements[i];
            self.claim_geometry(&mut cells[i], row, key.geometry, g)?;
            match &names[i] {
                Some((n, first)) if *n != name => {
                    return Err(self.cell_error(
                        row,
                        key.name,
                        format!(
                            "\"{name}\" names measurement \"{}\" ({}) differently from cell \
                             {first} (\"{n}\")",
                            m.name, m.at
                        ),
                    ));
                }
                Some(_) => {}
                None => names[i] = Some((name, cell_name(row, key.name))),
            }
            let l = self.number(row, lab_cols[0], "L*")?;
            let a = self.number(row, lab_cols[1], "a*")?;
            let b = self.number(row, lab_cols[2], "b*")?;
            labs[i][g] = Some(Lab { l, a, b });
        }
        let mut out = Vec::with_capacity(measurements.len());
        for ((m, lab), name) in measurements.iter().zip(labs).zip(names) {
            self.every_geometry(m, |g| lab[g].is_some())?;
            out.push((lab.map(|l| l.expect("checked")), name.map(|n| n.0)));
        }
        Ok(out)
    }
}

/// An Excel serial day number (days since 1899-12-30, or since 1904-01-01 in a 1904 workbook,
/// the fraction being the time of day) as a civil date and time, to the millisecond. Serial
/// numbers before 1900-03-01 (where Excel's 1900 leap-year bug makes them ambiguous) and after
/// 9999 are refused.
fn excel_serial_to_datetime(serial: f64, date1904: bool) -> Option<jiff::civil::DateTime> {
    if !serial.is_finite() || serial < if date1904 { 0.0 } else { 61.0 } || serial >= 2_958_466.0 {
        return None;
    }
    let epoch = if date1904 {
        jiff::civil::date(1904, 1, 1)
    } else {
        jiff::civil::date(1899, 12, 30)
    };
    let ms = (serial * 86_400_000.0).round() as i64;
    epoch
        .at(0, 0, 0, 0)
        .checked_add(jiff::SignedDuration::from_millis(ms))
        .ok()
}

/// What the workbook part says that calamine does not give.
struct Workbook {
    date1904: bool,
    /// Sheet name → its part's path in the archive.
    sheets: BTreeMap<String, String>,
}

/// The archive, for the parts calamine does not read.
struct Parts<'a, 'b> {
    file: &'a str,
    zip: &'a mut zip::ZipArchive<Cursor<&'b [u8]>>,
    budget: &'a Budget,
    /// Each image part as read, once however many anchors point at it.
    images: BTreeMap<String, std::rc::Rc<Vec<u8>>>,
}

const REL_NS: &str = "http://schemas.openxmlformats.org/officeDocument/2006/relationships";

impl Parts<'_, '_> {
    fn not_xlsx(&self, message: String) -> XlsxError {
        XlsxError::NotXlsx {
            file: self.file.to_string(),
            message,
        }
    }

    /// The part's bytes, read up to `limit`'s allowance (a part that unpacks to more is
    /// refused, whatever size the archive declares); `None` when the archive has no such part.
    fn bytes(&mut self, part: &str, limit: Limit) -> Result<Option<Vec<u8>>, XlsxError> {
        let file = self.file;
        let not_xlsx = |e: &dyn std::fmt::Display| XlsxError::NotXlsx {
            file: file.to_string(),
            message: format!("part \"{part}\": {e}"),
        };
        let allowed = self.budget.allowed(limit);
        let mut f = match self.zip.by_name(part) {
            Ok(f) => f,
            Err(zip::result::ZipError::FileNotFound) => return Ok(None),
            Err(e) => return Err(not_xlsx(&e)),
        };
        self.budget
            .check(limit, file, &format!("part \"{part}\""), f.size())?;
        let mut out = Vec::with_capacity(f.size() as usize);
        if let Err(e) = (&mut f).take(allowed + 1).read_to_end(&mut out) {
            return Err(not_xlsx(&e));
        }
        drop(f);
        self.budget
            .check(limit, file, &format!("part \"{part}\""), out.len() as u64)?;
        Ok(Some(out))
    }

    fn text(&mut self, part: &str) -> Result<Option<String>, XlsxError> {
        match self.bytes(part, Limit::MarkupBytes)? {
            None => Ok(None),
            Some(b) => String::from_utf8(b)
                .map(Some)
                .map_err(|_| self.not_xlsx(format!("part \"{part}\" is not UTF-8 XML"))),
        }
    }

    /// The shared strings (every part of the archive named so, whichever the workbook
    /// points at): at most the markup allowance in all, a declared and a held count within
    /// the budget, and no string longer than the text allowance.
    fn check_shared_strings(&mut self) -> Result<(), XlsxError> {
        let names: Vec<String> = self
            .zip
            .file_names()
            .filter_map(|n| n.ok())
            .filter(|n| n.to_ascii_lowercase().ends_with("sharedstrings.xml"))
            .map(|n| n.into_owned())
            .collect();
        for part in names {
            let Some(xml) = self.bytes(&part, Limit::MarkupBytes)? else {
                continue;
            };
            let what = format!("part \"{part}\"");
            let mut held = 0u64;
            let mut open = None;
            for tag in tags(&xml) {
                match (tag.local, tag.closing) {
                    (b"sst", false) => {
                        for key in [&b"uniqueCount"[..], b"count"] {
                            if let Some(n) = tag.attribute(key) {
                                let n = parse_u64(n).unwrap_or(u64::MAX);
                                self.budget
                                    .check(Limit::SharedStrings, self.file, &what, n)?;
                            }
                        }
                    }
                    (b"si", false) => {
                        held += 1;
                        self.budget
                            .check(Limit::SharedStrings, self.file, &what, held)?;
                        open = Some(tag.end);
                    }
                    (b"si", true) => {
                        if let Some(start) = open.take() {
                            self.budget.check(
                                Limit::TextBytes,
                                self.file,
                                &format!("{what}, shared string {}", held - 1),
                                tag.start.saturating_sub(start) as u64,
                            )?;
                        }
                    }
                    _ => {}
                }
            }
            if let Some(start) = open {
                self.budget.check(
                    Limit::TextBytes,
                    self.file,
                    &format!("{what}, shared string {}", held - 1),
                    (xml.len() - start) as u64,
                )?;
            }
        }
        Ok(())
    }

    /// Sheet `name` (part `part`): its declared dimension, and the bounding box and count of
    /// the cells it holds, within the sheet-cells allowance.
    fn check_sheet(&mut self, name: &str, part: &str) -> Result<(), XlsxError> {
        let Some(xml) = self.bytes(part, Limit::PartBytes)? else {
            return Ok(());
        };
        let e = Extent::of(&xml);
        let what = |detail: &str| format!("sheet \"{name}\" ({detail})");
        if let Some((rows, cols)) = e.declared {
            self.budget.check(
                Limit::SheetCells,
                self.file,
                &what(&format!(
                    "declared dimension of {rows} rows × {cols} columns"
                )),
                rows.saturating_mul(cols),
            )?;
        }
        self.budget
            .check(Limit::SheetCells, self.file, &what("cells held"), e.cells)?;
        if let Some((rows, cols)) = e.bounding_box() {
            let last = cell_name_u64(e.rows.1, e.cols.1);
            self.budget.check(
                Limit::SheetCells,
                self.file,
                &what(&format!(
                    "{} cells spread over {rows} rows × {cols} columns, to cell {last}",
                    e.cells
                )),
                rows.saturating_mul(cols),
            )?;
        }
        Ok(())
    }

    fn with_xml<T>(
        &mut self,
        part: &str,
        f: impl FnOnce(&roxmltree::Document) -> T,
    ) -> Result<Option<T>, XlsxError> {
        let Some(text) = self.text(part)? else {
            return Ok(None);
        };
        let doc = roxmltree::Document::parse(&text)
            .map_err(|e| self.not_xlsx(format!("part \"{part}\": {e}")))?;
        Ok(Some(f(&doc)))
    }

    /// The relationships of `part`: id → (type, target part path).
    fn relationships(
        &mut self,
        part: &str,
    ) -> Result<BTreeMap<String, (String, String)>, XlsxError> {
        let (dir, file) = part.rsplit_once('/').unwrap_or(("", part));
        let rels = if dir.is_empty() {
            format!("_rels/{file}.rels")
        } else {
            format!("{dir}/_rels/{file}.rels")
        };
        let dir = dir.to_string();
        Ok(self
            .with_xml(&rels, |doc| {
                doc.descendants()
                    .filter(|n| n.has_tag_name("Relationship"))
                    .filter_map(|n| {
                        let id = n.attribute("Id")?;
                        let target = n.attribute("Target")?;
                        let typ = n.attribute("Type").unwrap_or_default();
                        Some((
                            id.to_string(),
                            (typ.to_string(), resolve_part(&dir, target)),
                        ))
                    })
                    .collect()
            })?
            .unwrap_or_default())
    }

    fn workbook(&mut self) -> Result<Workbook, XlsxError> {
        let part = "xl/workbook.xml";
        let rels = self.relationships(part)?;
        let parsed = self
            .with_xml(part, |doc| {
                let date1904 = doc
                    .descendants()
                    .find(|n| n.has_tag_name("workbookPr"))
                    .and_then(|n| n.attribute("date1904"))
                    .is_some_and(|v| v == "1" || v.eq_ignore_ascii_case("true"));
                let sheets: Vec<(String, String)> = doc
                    .descendants()
                    .filter(|n| n.has_tag_name("sheet"))
                    .filter_map(|n| {
                        Some((
                            n.attribute("name")?.to_string(),
                            n.attribute((REL_NS, "id"))?.to_string(),
                        ))
                    })
                    .collect();
                (date1904, sheets)
            })?
            .ok_or_else(|| self.not_xlsx(format!("no part \"{part}\"")))?;
        let sheets = parsed
            .1
            .into_iter()
            .filter_map(|(name, id)| rels.get(&id).map(|(_, target)| (name, target.clone())))
            .collect();
        Ok(Workbook {
            date1904: parsed.0,
            sheets,
        })
    }

    /// The `Texture Images` sheet's images with the heading above each (see the module docs).
    fn textures(
        &mut self,
        sheet: &Sheet,
        workbook: &Workbook,
    ) -> Result<Vec<(Option<String>, TextureImage)>, XlsxError> {
        let me = self;
        let Some(sheet_part) = workbook.sheets.get(sheet.name) else {
            return Err(me.not_xlsx(format!("sheet \"{}\" has no part", sheet.name)));
        };
        let drawing = me
            .relationships(sheet_part)?
            .into_values()
            .find(|(typ, _)| typ.ends_with("/drawing"));
        let Some((_, drawing)) = drawing else {
            return Ok(Vec::new());
        };
        let rels = me.relationships(&drawing)?;
        // (row, col, relationship id) of each picture, in document order.
        let anchors: Vec<(u32, u32, Option<String>)> = me
            .with_xml(&drawing, |doc| {
                doc.descendants()
                    .filter(|n| n.has_tag_name("oneCellAnchor") || n.has_tag_name("twoCellAnchor"))
                    .filter_map(|a| {
                        let pic = a.children().find(|c| c.has_tag_name("pic"))?;
                        let from = a.children().find(|c| c.has_tag_name("from"))?;
                        let num = |tag: &str| -> Option<u32> {
                            from.children()
                                .find(|c| c.has_tag_name(tag))?
                                .text()?
                                .trim()
                                .parse()
                                .ok()
                        };
                        let embed = pic
                            .descendants()
                            .find(|c| c.has_tag_name("blip"))
                            .and_then(|b| b.attribute((REL_NS, "embed")))
                            .map(str::to_string);
                        Some((num("row")?, num("col")?, embed))
                    })
                    .collect()
            })?
            .ok_or_else(|| me.not_xlsx(format!("no part \"{drawing}\"")))?;

        let images = anchors.len() as u64;
        let what = format!("sheet \"{}\" ({images} image anchors)", sheet.name);
        me.budget.check(Limit::Images, me.file, &what, images)?;

        // Headings: rows with column A empty and text in column B, found in one pass over the
        // sheet (whose rows the budget bounds); an anchor's is the last one above it.
        let label_col = 0;
        let headings: Vec<(u32, String)> = sheet
            .rows()
            .filter(|&r| sheet.text(r, label_col).is_none())
            .filter_map(|r| sheet.text(r, label_col + 1).map(|h| (r, h)))
            .collect();
        let mut out = Vec::with_capacity(anchors.len());
        let mut total = 0u64;
        for (row, col, embed) in anchors {
            let anchor = cell_name(row, col);
            let geometry = sheet.text(row, label_col).ok_or_else(|| {
                sheet.cell_error(
                    row,
                    label_col,
                    format!(
                        "empty, but an image is anchored in {anchor}; a geometry name expected"
                    ),
                )
            })?;
            let above = headings.partition_point(|(r, _)| *r < row);
            let heading = above.checked_sub(1).map(|i| headings[i].1.clone());
            let image = embed
                .as_ref()
                .and_then(|id| rels.get(id))
                .map(|(_, target)| target.clone())
                .ok_or_else(|| {
                    sheet.cell_error(row, col, "the image anchored here has no image part")
                })?;
            let png = me.image(&image)?.ok_or_else(|| {
                sheet.cell_error(row, col, format!("the image part \"{image}\" is missing"))
            })?;
            total += png.len() as u64;
            me.budget.check(
                Limit::ImagesBytes,
                me.file,
                &format!(
                    "sheet \"{}\", the images up to the one anchored in {anchor}",
                    sheet.name
                ),
                total,
            )?;
            let Some((width, height)) = png_size(&png) else {
                return Err(sheet.cell_error(
                    row,
                    col,
                    format!("the image anchored here (\"{image}\") is not a PNG"),
                ));
            };
            me.budget.check(
                Limit::ImagePixels,
                me.file,
                &format!("image \"{image}\" of {width} × {height} pixels, anchored in {anchor}"),
                u64::from(width) * u64::from(height),
            )?;
            out.push((
                heading,
                TextureImage {
                    geometry,
                    anchor,
                    png: png.as_ref().clone(),
                },
            ));
        }
        Ok(out)
    }

    /// An image part, read once (within the image-size allowance) however many anchors point
    /// at it; `None` when the archive has no such part.
    fn image(&mut self, part: &str) -> Result<Option<std::rc::Rc<Vec<u8>>>, XlsxError> {
        if let Some(png) = self.images.get(part) {
            return Ok(Some(png.clone()));
        }
        let Some(png) = self.bytes(part, Limit::ImageBytes)? else {
            return Ok(None);
        };
        let png = std::rc::Rc::new(png);
        self.images.insert(part.to_string(), png.clone());
        Ok(Some(png))
    }
}

/// A PNG's width and height as its IHDR chunk declares them; `None` when `png` is no PNG.
fn png_size(png: &[u8]) -> Option<(u32, u32)> {
    if !png.starts_with(b"\x89PNG\r\n\x1a\n") || png.get(12..16)? != b"IHDR" {
        return None;
    }
    let be = |at: usize| -> Option<u32> {
        Some(u32::from_be_bytes(png.get(at..at + 4)?.try_into().ok()?))
    };
    Some((be(16)?, be(20)?))
}

/// One tag of an XML part, as the budget checks scan it (without building a document):
/// its local name, whether it closes an element, its attributes' text and its byte span.
struct Tag<'a> {
    local: &'a [u8],
    closing: bool,
    attrs: &'a [u8],
    start: usize,
    end: usize,
}

impl<'a> Tag<'a> {
    /// The value of the attribute named `key` (without a prefix), if the tag has it.
    fn attribute(&self, key: &[u8]) -> Option<&'a [u8]> {
        let a = self.attrs;
        let mut i = 0;
        while i < a.len() {
            while i < a.len() && (a[i].is_ascii_whitespace() || a[i] == b'/') {
                i += 1;
            }
            let name_start = i;
            while i < a.len() && a[i] != b'=' && !a[i].is_ascii_whitespace() {
                i += 1;
            }
            let name = &a[name_start..i];
            while i < a.len() && (a[i].is_ascii_whitespace() || a[i] == b'=') {
                i += 1;
            }
            let quote = *a.get(i)?;
            if quote != b'"' && quote != b'\'' {
                return None;
            }
            let value_start = i + 1;
            let len = a[value_start..].iter().position(|&b| b == quote)?;
            i = value_start + len + 1;
            if name == key {
                return Some(&a[value_start..value_start + len]);
            }
        }
        None
    }
}

/// The tags of `xml` in document order (comments, CDATA, declarations and processing
/// instructions skipped).
fn tags(xml: &[u8]) -> impl Iterator<Item = Tag<'_>> {
    let mut at = 0;
    std::iter::from_fn(move || {
        loop {
            let lt = at + xml.get(at..)?.iter().position(|&b| b == b'<')?;
            let rest = &xml[lt + 1..];
            if rest.starts_with(b"![CDATA[") || rest.starts_with(b"!--") {
                let close: &[u8] = if rest[1] == b'[' { b"]]>" } else { b"-->" };
                at = find(&xml[lt..], close).map_or(xml.len(), |i| lt + i + close.len());
                continue;
            }
            let gt = lt + xml[lt..].iter().position(|&b| b == b'>')?;
            at = gt + 1;
            let inner = &xml[lt + 1..gt];
            if matches!(inner.first(), Some(b'?' | b'!')) {
                continue;
            }
            let closing = inner.first() == Some(&b'/');
            let body = if closing { &inner[1..] } else { inner };
            let name_end = body
                .iter()
                .position(|b| b.is_ascii_whitespace() || *b == b'/')
                .unwrap_or(body.len());
            let name = &body[..name_end];
            let local = name.rsplit(|&b| b == b':').next().unwrap_or(name);
            return Some(Tag {
                local,
                closing,
                attrs: &body[name_end..],
                start: lt,
                end: gt + 1,
            });
        }
    })
}

fn find(hay: &[u8], needle: &[u8]) -> Option<usize> {
    hay.windows(needle.len()).position(|w| w == needle)
}

/// A decimal number; `None` when it is not one (an overflow saturates).
fn parse_u64(text: &[u8]) -> Option<u64> {
    let t = text.trim_ascii();
    if t.is_empty() || !t.iter().all(u8::is_ascii_digit) {
        return None;
    }
    Some(t.iter().fold(0u64, |n, d| {
        n.saturating_mul(10).saturating_add(u64::from(d - b'0'))
    }))
}

/// An `A1`-style reference as 1-based (row, column): `None` for the row when it has no
/// digits; `None` when it is no reference.
fn parse_reference(text: &[u8]) -> Option<(Option<u64>, u64)> {
    let t = text.trim_ascii();
    let t = t.strip_prefix(b"$").unwrap_or(t);
    let letters = t.iter().take_while(|b| b.is_ascii_alphabetic()).count();
    if letters == 0 {
        return None;
    }
    let col = t[..letters].iter().fold(0u64, |n, b| {
        n.saturating_mul(26)
            .saturating_add(u64::from(b.to_ascii_uppercase() - b'A' + 1))
    });
    let digits = &t[letters..];
    let digits = digits.strip_prefix(b"$").unwrap_or(digits);
    let row = if digits.is_empty() {
        None
    } else {
        Some(parse_u64(digits)?)
    };
    Some((row, col))
}

/// What a sheet part declares and holds, as the spreadsheet reader will place it.
#[derive(Debug, Default, PartialEq)]
struct Extent {
    /// The `<dimension ref>`: rows × columns.
    declared: Option<(u64, u64)>,
    /// The `<c>` elements.
    cells: u64,
    /// First and last row (1-based) of a cell.
    rows: (u64, u64),
    /// First and last column (1-based) of a cell.
    cols: (u64, u64),
}

impl Extent {
    fn of(xml: &[u8]) -> Extent {
        let mut e = Extent {
            rows: (u64::MAX, 0),
            cols: (u64::MAX, 0),
            ..Extent::default()
        };
        let (mut row, mut col) = (0u64, 0u64);
        for tag in tags(xml) {
            if tag.closing {
                continue;
            }
            match tag.local {
                b"dimension" => {
                    let Some(r) = tag.attribute(b"ref") else {
                        continue;
                    };
                    let mut ends = r.split(|&b| b == b':').filter_map(parse_reference);
                    if let Some((r1, c1)) = ends.next() {
                        let (r2, c2) = ends.next().unwrap_or((r1, c1));
                        let (r1, r2) = (r1.unwrap_or(1), r2.unwrap_or(1));
                        e.declared = Some((
                            r1.abs_diff(r2).saturating_add(1),
                            c1.abs_diff(c2).saturating_add(1),
                        ));
                    }
                }
                b"row" => {
                    row = match tag.attribute(b"r") {
                        Some(r) => parse_u64(r).unwrap_or(u64::MAX),
                        None => row.saturating_add(1),
                    };
                    col = 0;
                }
                b"c" => {
                    match tag.attribute(b"r").and_then(parse_reference) {
                        Some((r, c)) => {
                            if let Some(r) = r {
                                row = r;
                            }
                            col = c;
                        }
                        None => col = col.saturating_add(1),
                    }
                    let r = row.max(1);
                    e.cells += 1;
                    e.rows = (e.rows.0.min(r), e.rows.1.max(r));
                    e.cols = (e.cols.0.min(col), e.cols.1.max(col));
                }
                _ => {}
            }
        }
        e
    }

    /// Rows × columns of the cells' bounding box; `None` without cells.
    fn bounding_box(&self) -> Option<(u64, u64)> {
        (self.cells > 0).then(|| {
            (
                self.rows.1 - self.rows.0 + 1,
                self.cols.1.saturating_sub(self.cols.0).saturating_add(1),
            )
        })
    }
}

/// The part a relationship target names, from the directory of the part it belongs to.
fn resolve_part(dir: &str, target: &str) -> String {
    let mut parts: Vec<&str> = if let Some(abs) = target.strip_prefix('/') {
        return normalise(abs.split('/'));
    } else {
        dir.split('/').filter(|p| !p.is_empty()).collect()
    };
    parts.extend(target.split('/'));
    normalise(parts.into_iter())
}

fn normalise<'a>(parts: impl Iterator<Item = &'a str>) -> String {
    let mut out: Vec<&str> = Vec::new();
    for p in parts {
        match p {
            "" | "." => {}
            ".." => {
                out.pop();
            }
            p => out.push(p),
        }
    }
    out.join("/")
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::io::Write;

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
    fn edited(file: &str, part: &str, edit: impl FnOnce(String) -> String) -> Vec<u8> {
        let mut parts = unzip(&bytes(file));
        let p = parts.iter_mut().find(|(n, _)| n == part).unwrap();
        let text = String::from_utf8(std::mem::take(&mut p.1)).unwrap();
        let new = edit(text.clone());
        assert_ne!(new, text, "the edit of {part} changed nothing");
        p.1 = new.into_bytes();
        rezip(&parts)
    }

    /// Replaces the XML of cell `cell` (`<c r="D7" …>…</c>` or `<c r="D7" …/>`) by `with`.
    fn set_cell(xml: String, cell: &str, with: &str) -> String {
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

    fn err(bytes: &[u8]) -> String {
        match read(bytes, "PAR_x.xlsx") {
            Ok(_) => panic!("accepted"),
            Err(e) => e.to_string(),
        }
    }

    // Color Data is sheet1, Spectral Data sheet3, Texture Images sheet4 in these files.
    const COLOR: &str = "xl/worksheets/sheet1.xml";
    const SPECTRAL: &str = "xl/worksheets/sheet3.xml";
    const REGULAR: &str = "PAR_EW_RL_NG_3.xlsx";

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
    fn each_image_is_the_one_anchored_beside_its_geometry() {
        // In the padded file the drawing's relationships are shuffled: the anchor in row 2
        // (15as-45) embeds rId1, which is image3.png, and row 8 (15d) image7.png.
        let f = "PAR_NB_NP_CC_0.xlsx";
        let parts = unzip(&bytes(f));
        let media = |n: &str| &parts.iter().find(|(p, _)| p == n).unwrap().1;
        let m = &read_file(&path(f)).unwrap().measurements[0];
        assert_eq!(m.textures[0].geometry, "15as-45");
        assert_eq!(&m.textures[0].png, media("xl/media/image3.png"));
        assert_eq!(&m.textures[3].png, media("xl/media/image2.png"));
        assert_eq!(&m.textures[6].png, media("xl/media/image7.png"));
    }

    /// Copies rows `from..=to` of a sheet's XML below the last, `shift` rows down, with the
    /// Date/Time serial `old` written as `new` and shared string `name` (the Name) as `new_name`.
    fn append_rows(
        xml: String,
        from: u32,
        to: u32,
        shift: u32,
        (old, new): (&str, &str),
        name: Option<(&str, &str)>,
    ) -> String {
        let mut extra = String::new();
        for r in from..=to {
            let start = xml.find(&format!("<row r=\"{r}\"")).unwrap();
            let end = start + xml[start..].find("</row>").unwrap() + 6;
            let mut row =
                xml[start..end].replace(&format!("r=\"{r}\""), &format!("r=\"{}\"", r + shift));
            for col in ["A", "B", "C", "D", "E", "F"] {
                row = row.replace(
                    &format!("r=\"{col}{r}\""),
                    &format!("r=\"{col}{}\"", r + shift),
                );
            }
            let mut row = row.replace(&format!("<v>{old}</v>"), &format!("<v>{new}</v>"));
            if let Some((from_name, to_name)) = name {
                row = row.replacen(from_name, to_name, 1);
            }
            // Columns G… of Spectral Data.
            let cols: Vec<String> = (6..34)
                .map(|c| cell_name(0, c).trim_end_matches('1').to_string())
                .collect();
            for col in cols {
                row = row.replace(
                    &format!("r=\"{col}{r}\""),
                    &format!("r=\"{col}{}\"", r + shift),
                );
            }
            extra.push_str(&row);
        }
        let at = xml.find("</sheetData>").unwrap();
        let out = format!("{}{extra}{}", &xml[..at], &xml[at..]);
        // The used range grows: drop its declaration (the padded real file has none).
        let d = out.find("<dimension ").unwrap();
        let e = d + out[d..].find("/>").unwrap() + 2;
        format!("{}{}", &out[..d], &out[e..])
    }

    #[test]
    fn a_file_with_two_measurements_reads_both_and_matches_color_rows_by_time() {
        let t = ("45441.7965277778", "45441.8");
        let mut parts = unzip(&bytes(REGULAR));
        for (part, from, to, name) in [
            (SPECTRAL, 4, 15, None),
            // The second measurement's Color Data rows name it otherwise (inline string).
            (
                COLOR,
                5,
                16,
                Some((
                    r#"t="s"><v>3</v>"#,
                    r#"t="inlineStr"><is><t>other</t></is>"#,
                )),
            ),
        ] {
            let p = parts.iter_mut().find(|(n, _)| n == part).unwrap();
            let x = String::from_utf8(std::mem::take(&mut p.1)).unwrap();
            p.1 = append_rows(x, from, to, 12, t, name).into_bytes();
        }
        let x = read(&rezip(&parts), "two.xlsx").unwrap();
        assert_eq!(x.measurements.len(), 2);
        let (a, b) = (&x.measurements[0], &x.measurements[1]);
        assert_eq!(
            (a.name.as_str(), b.name.as_str()),
            ("PAR_EW_RL_NG_3", "PAR_EW_RL_NG_3")
        );
        assert_eq!(a.measured_at.to_string(), "2024-05-29T19:07:00");
        assert_eq!(b.measured_at.to_string(), "2024-05-29T19:12:00");
        assert_eq!(a.color_data_name, None);
        assert_eq!(b.color_data_name.as_deref(), Some("other"));
        assert_eq!((a.spectra, a.lab), (b.spectra, b.lab));
        // The images' heading names both: they belong to neither.
        assert!(a.textures.is_empty() && b.textures.is_empty());
        assert_eq!(x.unassigned_textures.len(), 7);
    }

    #[test]
    fn brdfd_reproduces_xrites_lab_in_every_file_to_1e3() {
        let mut report = Vec::new();
        for f in REAL_EXPORTS {
            let x = read_file(&path(f)).unwrap();
            for m in &x.measurements {
                let c = check_colorimetry(m).unwrap();
                assert_eq!(c.colorimetry.to_string(), "D65/10° astm-e308");
                assert!(c.flagged.is_empty(), "{f}: {:?}", c.flagged);
                for (g, d) in ma_t12().iter().zip(c.delta_e00) {
                    assert!(d <= 1e-3, "{f} {}: ΔE00 {d}", g.name);
                }
                report.push(format!(
                    "{f}: largest ΔE00 {:.2e} at {}",
                    c.largest, c.largest_at
                ));
            }
        }
        println!("{}", report.join("\n"));
    }

    #[test]
    fn an_edited_color_data_cell_is_flagged_at_its_geometry() {
        // Row 14 of Color Data is 45as45; D14 is its L*.
        let b = edited(REGULAR, COLOR, |x| {
            set_cell(x, "D14", r#"<c r="D14" s="2"><v>29.5155937402652</v></c>"#)
        });
        let x = read(&b, REGULAR).unwrap();
        let c = check_colorimetry(&x.measurements[0]).unwrap();
        assert_eq!(c.flagged, ["45as45"]);
        assert_eq!(c.largest_at, "45as45");
        assert!(c.largest > 0.3, "{}", c.largest);
    }

    #[test]
    fn an_illuminant_brdfd_cannot_compute_is_an_error_naming_it() {
        let mut m = read_file(&path(REGULAR)).unwrap().measurements.remove(0);
        m.illuminant = "D50".into();
        let e = check_colorimetry(&m).unwrap_err().to_string();
        assert!(e.contains("D50/10") && e.contains("PAR_EW_RL_NG_3"), "{e}");
        m.illuminant = "D65".into();
        m.observer_deg = 2;
        assert!(check_colorimetry(&m).is_ok());
        m.observer_deg = 5;
        let e = check_colorimetry(&m).unwrap_err().to_string();
        assert!(e.contains("D65/5"), "{e}");
    }

    #[test]
    fn bad_cells_are_errors_naming_file_sheet_and_cell() {
        let spectral = |cell: &str, with: &str| {
            let (cell, with) = (cell.to_string(), with.to_string());
            err(&edited(REGULAR, SPECTRAL, move |x| {
                set_cell(x, &cell, &with)
            }))
        };
        let prefix = "PAR_x.xlsx: sheet \"Spectral Data\", cell D7: ";
        let e = spectral("D7", r#"<c r="D7" t="inlineStr"><is><t>abc</t></is></c>"#);
        assert_eq!(e, format!("{prefix}\"abc\" is not a number"));
        let e = spectral("D7", "");
        assert!(e.starts_with(prefix) && e.contains("empty"), "{e}");
        let e = spectral("D7", r#"<c r="D7" s="3"><v>-0.01</v></c>"#);
        assert!(
            e.starts_with(prefix) && e.contains("-0.01 is negative"),
            "{e}"
        );
        // Wavelength grid: 700 nm written as 710, or missing.
        let e = spectral("AH3", r#"<c r="AH3" t="inlineStr"><is><t>710</t></is></c>"#);
        assert!(
            e.contains("cell AH3") && e.contains("400–700 nm at 10 nm"),
            "{e}"
        );
        let e = spectral("AH3", "");
        assert!(
            e.contains("cell AH3") && e.contains("400–690 nm in 30 columns"),
            "{e}"
        );
        let e = spectral("D3", r#"<c r="D3" t="inlineStr"><is><t>nm</t></is></c>"#);
        assert!(
            e.contains("cell D3") && e.contains("wavelength grid"),
            "{e}"
        );
        // Geometry: a duplicate (row 5 says 15as-45 like row 4), an unknown one.
        let e = spectral("C5", r#"<c r="C5" t="s"><v>12</v></c>"#);
        assert!(
            e.contains("cell C5") && e.contains("\"15as-45\"") && e.contains("already in cell C4"),
            "{e}"
        );
        let e = spectral(
            "C5",
            r#"<c r="C5" t="inlineStr"><is><t>15as16</t></is></c>"#,
        );
        assert!(
            e.contains("cell C5") && e.contains("\"15as16\" is not one of"),
            "{e}"
        );
        let e = spectral(
            "B6",
            r#"<c r="B6" t="inlineStr"><is><t>yesterday</t></is></c>"#,
        );
        assert!(e.contains("cell B6") && e.contains("not a date"), "{e}");
    }

    #[test]
    fn a_missing_geometry_is_an_error_naming_it() {
        // Spectral Data row 13 is 45as45.
        let b = edited(REGULAR, SPECTRAL, |x| {
            let start = x.find("<row r=\"13\"").unwrap();
            let end = start + x[start..].find("</row>").unwrap() + 6;
            format!("{}{}", &x[..start], &x[end..])
        });
        let e = err(&b);
        assert_eq!(
            e,
            "PAR_x.xlsx: sheet \"Spectral Data\": measurement \"PAR_EW_RL_NG_3\" \
             (2024-05-29T19:07:00) has no row for geometry 45as45; an MA-T12 measurement has all 12"
        );
        // In Color Data, an emptied row (padding) leaves its geometry missing there.
        let b = edited(REGULAR, COLOR, |x| {
            let start = x.find("<row r=\"14\"").unwrap();
            let end = start + x[start..].find("</row>").unwrap() + 6;
            format!("{}<row r=\"14\"></row>{}", &x[..start], &x[end..])
        });
        let e = err(&b);
        assert!(
            e.contains("\"Color Data\"") && e.contains("geometry 45as45"),
            "{e}"
        );
    }

    #[test]
    fn a_color_data_row_of_another_time_matches_nothing() {
        let b = edited(REGULAR, COLOR, |x| {
            set_cell(x, "B10", r#"<c r="B10" s="1"><v>45441.8</v></c>"#)
        });
        let e = err(&b);
        assert!(
            e.starts_with("PAR_x.xlsx: sheet \"Color Data\", cell B10: ")
                && e.contains("15as80")
                && e.contains("matches no row of \"Spectral Data\""),
            "{e}"
        );
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

    #[test]
    fn a_cell_far_out_is_refused_before_the_grid_is_built() {
        // One cell in the last row and column of a sheet: calamine would allocate 1,048,576 ×
        // 16,384 cells for it.
        for (cell, part) in [("XFD1048576", SPECTRAL), ("Z1000000", COLOR)] {
            let b = edited(REGULAR, part, |x| {
                x.replace(
                    "</sheetData>",
                    &format!(
                        r#"<row r="{0}"><c r="{1}{0}"><v>1</v></c></row></sheetData>"#,
                        cell.trim_start_matches(char::is_alphabetic),
                        cell.trim_end_matches(|c: char| c.is_ascii_digit())
                    ),
                )
            });
            let e = err(&b);
            assert!(
                e.starts_with("PAR_x.xlsx: sheet \"")
                    && e.contains(&format!("to cell {cell})"))
                    && e.contains("the import limit \"sheet cells\" of 250000 cells")
                    && e.contains("ingest.max_sheet_cells"),
                "{e}"
            );
        }
        // A declared dimension of the whole sheet, and cells without references that run on.
        let b = edited(REGULAR, SPECTRAL, |x| {
            let d = x.find("<dimension ").unwrap();
            let e = d + x[d..].find("/>").unwrap() + 2;
            format!("{}<dimension ref=\"A1:XFD1048576\"/>{}", &x[..d], &x[e..])
        });
        let e = err(&b);
        assert!(
            e.contains("declared dimension of 1048576 rows × 16384 columns"),
            "{e}"
        );
        let b = edited(REGULAR, SPECTRAL, |x| {
            x.replace(
                "</sheetData>",
                &format!("<row>{}</row></sheetData>", "<c/>".repeat(300_000)),
            )
        });
        assert!(err(&b).contains("(cells held): 30"), "{}", err(&b));
        // The padded real file (1,000 rows) is well inside.
        let x = unzip(&bytes("PAR_NB_NP_CC_0.xlsx"));
        let sheet = &x.iter().find(|(n, _)| n == SPECTRAL).unwrap().1;
        let e = Extent::of(sheet);
        let (rows, cols) = e.bounding_box().unwrap();
        assert!(rows <= 1_000 && cols < 40, "{e:?}");
    }

    #[test]
    fn extents_follow_the_references_as_the_reader_places_cells() {
        let e = Extent::of(
            br#"<x:worksheet><x:dimension ref="B2:C3"/><x:sheetData><x:row r="2"><x:c r="B2"/><x:c/></x:row><row><c r='$d$4'><v>1</v></c></row><!-- <c r="Z99"/> --></x:sheetData></x:worksheet>"#,
        );
        assert_eq!(e.declared, Some((2, 2)));
        assert_eq!((e.cells, e.rows, e.cols), (3, (2, 4), (2, 4)));
        assert_eq!(e.bounding_box(), Some((3, 3)));
        assert_eq!(
            parse_reference(b"XFD1048576"),
            Some((Some(1_048_576), 16_384))
        );
        assert_eq!(cell_name_u64(1_048_576, 16_384), "XFD1048576");
    }

    #[test]
    fn shared_strings_and_values_beyond_the_budget_are_refused_naming_them() {
        let sst = "xl/sharedStrings.xml";
        let long = "x".repeat(5_000);
        let b = edited(REGULAR, sst, |x| {
            x.replacen("<t>", &format!("<t>{long}"), 1)
        });
        let e = err(&b);
        assert!(
            e.contains("part \"xl/sharedStrings.xml\", shared string 0: 50")
                && e.contains("\"text size\" of 4096 bytes"),
            "{e}"
        );
        let b = edited(REGULAR, sst, |x| {
            let at = x.find("uniqueCount=\"").unwrap() + 13;
            let end = at + x[at..].find('"').unwrap();
            format!("{}4000000000{}", &x[..at], &x[end..])
        });
        assert!(
            err(&b).contains("4000000000 strings is beyond"),
            "{}",
            err(&b)
        );
        let b = edited(REGULAR, SPECTRAL, |x| {
            set_cell(x, "D7", r#"<c r="D7" s="3"><v>1e308</v></c>"#)
        });
        let e = err(&b);
        assert!(
            e.starts_with(
                "PAR_x.xlsx: sheet \"Spectral Data\", cell D7: 1e308 is beyond any reflectance"
            ),
            "{e}"
        );
        // In the hundreds (a glossy sample near specular) is a reading.
        let b = edited(REGULAR, SPECTRAL, |x| {
            set_cell(x, "D7", r#"<c r="D7" s="3"><v>350.5</v></c>"#)
        });
        assert_eq!(
            read(&b, "x.xlsx").unwrap().measurements[0].spectra[3][0],
            350.5
        );
    }

    #[test]
    fn images_are_read_once_and_bounded_in_number_size_and_pixels() {
        const DRAWING: &str = "xl/drawings/drawing1.xml";
        // Every anchor points at the first anchor's image: read once, seven copies kept.
        let first_embed = |x: &str| {
            let at = x.find("r:embed=\"").unwrap() + 9;
            x[at..at + x[at..].find('"').unwrap()].to_string()
        };
        let b = edited(REGULAR, DRAWING, |x| {
            let id = first_embed(&x);
            let mut out = x.clone();
            for i in 1..=7 {
                out = out.replace(&format!("r:embed=\"rId{i}\""), &format!("r:embed=\"{id}\""));
            }
            out
        });
        let x = read(&b, "x.xlsx").unwrap();
        let t = &x.measurements[0].textures;
        assert!(t.len() == 7 && t.iter().all(|i| i.png == t[0].png));
        // 65 anchors.
        let b = edited(REGULAR, DRAWING, |x| {
            let s = x
                .find("<xdr:twoCellAnchor")
                .or_else(|| x.find("<xdr:oneCellAnchor"))
                .unwrap();
            let close = if x[s..].starts_with("<xdr:two") {
                "</xdr:twoCellAnchor>"
            } else {
                "</xdr:oneCellAnchor>"
            };
            let e = s + x[s..].find(close).unwrap() + close.len();
            format!("{}{}{}", &x[..e], x[s..e].repeat(58), &x[e..])
        });
        let e = err(&b);
        assert!(
            e.contains("(65 image anchors): 65 images is beyond")
                && e.contains("ingest.max_images"),
            "{e}"
        );
        // A PNG that declares 100,000 × 100,000 pixels.
        let mut parts = unzip(&bytes(REGULAR));
        let png = &mut parts
            .iter_mut()
            .find(|(n, _)| n == "xl/media/image1.png")
            .unwrap()
            .1;
        png[16..24].copy_from_slice(&[0, 1, 0x86, 0xa0, 0, 1, 0x86, 0xa0]);
        let e = err(&rezip(&parts));
        assert!(
            e.contains("of 100000 × 100000 pixels") && e.contains("ingest.max_image_megapixels"),
            "{e}"
        );
        // The images' bytes together, and each part's.
        let small = Budget {
            max_images_bytes: 1 << 20,
            ..Budget::default()
        };
        let e = super::read(&bytes(REGULAR), "x.xlsx", &small)
            .unwrap_err()
            .to_string();
        assert!(e.contains("\"images size per file\""), "{e}");
        let small = Budget {
            max_image_bytes: 100_000,
            ..Budget::default()
        };
        let e = super::read(&bytes(REGULAR), "x.xlsx", &small)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("\"image size\" of 100000 bytes") && e.contains("xl/media/"),
            "{e}"
        );
    }

    #[test]
    fn serial_dates_convert_like_excel() {
        let d = |s| excel_serial_to_datetime(s, false).map(|d| d.to_string());
        assert_eq!(d(61.0).as_deref(), Some("1900-03-01T00:00:00"));
        assert_eq!(d(45524.7650115741).as_deref(), Some("2024-08-20T18:21:37"));
        assert_eq!(d(60.0), None);
        assert_eq!(d(f64::NAN), None);
        assert_eq!(
            excel_serial_to_datetime(0.5, true)
                .map(|d| d.to_string())
                .as_deref(),
            Some("1904-01-01T12:00:00")
        );
        assert_eq!(cell_name(0, 0), "A1");
        assert_eq!(cell_name(2, 33), "AH3");
        assert_eq!(cell_name(9, 26 * 27), "AAA10");
    }
}

/// Property tests: mutated copies of a real export are read or refused, never a panic.
#[cfg(test)]
mod proptests {
    use std::sync::LazyLock;

    use super::tests::{bytes, read, rezip, unzip};
    use super::*;
    use proptest::prelude::*;

    /// `PAR_PW_CB_NG_1.xlsx` with each image cut to a 64-byte PNG head, so that an edit often
    /// lands in the sheets, and a case is fast.
    static BASE: LazyLock<Vec<(String, Vec<u8>)>> = LazyLock::new(|| {
        unzip(&bytes("PAR_PW_CB_NG_1.xlsx"))
            .into_iter()
            .map(|(n, b)| {
                let b = if n.starts_with("xl/media/") {
                    b[..64].to_vec()
                } else {
                    b
                };
                (n, b)
            })
            .collect()
    });

    const PARTS: [&str; 6] = [
        "xl/worksheets/sheet1.xml",
        "xl/worksheets/sheet3.xml",
        "xl/worksheets/sheet4.xml",
        "xl/sharedStrings.xml",
        "xl/workbook.xml",
        "xl/drawings/drawing1.xml",
    ];

    /// What goes into an edited value.
    const PIECES: [&str; 16] = [
        "",
        "0",
        "-0.01",
        "0.5",
        "1e999",
        "NaN",
        "abc",
        "45as45",
        "15as-45",
        "400",
        "705",
        "D50/10",
        "D65/2",
        "45441.7965277778",
        "Name",
        "<",
    ];

    #[derive(Debug, Clone)]
    enum Edit {
        /// Replace the text of the k-th `<v>` or `<t>` element of a part.
        Value(usize, usize, String),
        /// Delete the k-th `<c …>` cell, or `<row …>` row, of a part.
        Delete(usize, usize, bool),
        /// Duplicate the k-th row of a part (same row number).
        DuplicateRow(usize, usize),
        /// Flip a byte of a part.
        Flip(usize, usize, u8),
        /// Cut the archive at a fraction (per mille) of its length.
        Truncate(u16),
        /// Flip a byte of the archive.
        FlipArchive(usize, u8),
    }

    fn edit() -> impl Strategy<Value = Edit> {
        let part = 0..PARTS.len();
        prop_oneof![
            4 => (part.clone(), any::<usize>(), proptest::sample::select(&PIECES[..]))
                .prop_map(|(p, k, t)| Edit::Value(p, k, t.to_string())),
            2 => (part.clone(), any::<usize>(), any::<bool>())
                .prop_map(|(p, k, row)| Edit::Delete(p, k, row)),
            1 => (part.clone(), any::<usize>()).prop_map(|(p, k)| Edit::DuplicateRow(p, k)),
            1 => (part, any::<usize>(), 1..=255u8).prop_map(|(p, i, x)| Edit::Flip(p, i, x)),
            1 => (0..1000u16).prop_map(Edit::Truncate),
            1 => (any::<usize>(), 1..=255u8).prop_map(|(i, x)| Edit::FlipArchive(i, x)),
        ]
    }

    /// The byte ranges of the elements of `xml` opened by `open` and closed by `close`.
    fn elements(xml: &[u8], open: &[u8], close: &[u8]) -> Vec<(usize, usize)> {
        let mut out = Vec::new();
        let mut at = 0;
        while let Some(s) = find(&xml[at..], open).map(|i| i + at) {
            let Some(gt) = find(&xml[s..], b">").map(|i| i + s) else {
                break;
            };
            let end = if xml[gt - 1] == b'/' {
                gt + 1
            } else {
                match find(&xml[gt..], close) {
                    Some(i) => gt + i + close.len(),
                    None => break,
                }
            };
            out.push((s, end));
            at = end;
        }
        out
    }

    fn find(hay: &[u8], needle: &[u8]) -> Option<usize> {
        hay.windows(needle.len()).position(|w| w == needle)
    }

    fn apply(edits: &[Edit]) -> Vec<u8> {
        let mut parts = BASE.clone();
        let mut archive_edits = Vec::new();
        for e in edits {
            let part = |p: usize| PARTS[p];
            let get = |parts: &mut Vec<(String, Vec<u8>)>, p: usize| -> usize {
                parts.iter().position(|(n, _)| n == part(p)).expect("part")
            };
            match e {
                Edit::Value(p, k, text) => {
                    let i = get(&mut parts, *p);
                    let x = &parts[i].1;
                    let mut spots = elements(x, b"<v>", b"</v>");
                    spots.extend(elements(x, b"<t>", b"</t>"));
                    if spots.is_empty() {
                        continue;
                    }
                    let (s, end) = spots[k % spots.len()];
                    let new = [&x[..s + 3], text.as_bytes(), &x[end - 4..]].concat();
                    parts[i].1 = new;
                }
                Edit::Delete(p, k, row) => {
                    let i = get(&mut parts, *p);
                    let x = &parts[i].1;
                    let spots = if *row {
                        elements(x, b"<row ", b"</row>")
                    } else {
                        elements(x, b"<c ", b"</c>")
                    };
                    if spots.is_empty() {
                        continue;
                    }
                    let (s, end) = spots[k % spots.len()];
                    parts[i].1 = [&x[..s], &x[end..]].concat();
                }
                Edit::DuplicateRow(p, k) => {
                    let i = get(&mut parts, *p);
                    let x = &parts[i].1;
                    let spots = elements(x, b"<row ", b"</row>");
                    if spots.is_empty() {
                        continue;
                    }
                    let (s, end) = spots[k % spots.len()];
                    parts[i].1 = [&x[..end], &x[s..end], &x[end..]].concat();
                }
                Edit::Flip(p, at, x) => {
                    let i = get(&mut parts, *p);
                    let n = parts[i].1.len();
                    parts[i].1[at % n] ^= x;
                }
                e => archive_edits.push(e.clone()),
            }
        }
        let mut z = rezip(&parts);
        for e in archive_edits {
            match e {
                Edit::Truncate(f) => z.truncate(z.len() * f as usize / 1000),
                Edit::FlipArchive(at, x) => {
                    let n = z.len();
                    if n > 0 {
                        z[at % n] ^= x;
                    }
                }
                _ => unreachable!(),
            }
        }
        z
    }

    /// Either an error that names the file, or measurements that hold what the docs promise.
    fn check(bytes: &[u8]) -> Result<(), TestCaseError> {
        match read(bytes, "m.xlsx") {
            Err(e) => {
                let s = e.to_string();
                prop_assert!(s.starts_with("m.xlsx: "), "error names no file: {s}");
            }
            Ok(x) => {
                prop_assert!(!x.measurements.is_empty());
                for m in &x.measurements {
                    for s in &m.spectra {
                        prop_assert!(s.iter().all(|v| v.is_finite() && *v >= 0.0), "{s:?}");
                    }
                    for l in &m.lab {
                        prop_assert!(l.l.is_finite() && l.a.is_finite() && l.b.is_finite());
                    }
                    prop_assert!(!m.name.is_empty());
                    match check_colorimetry(m) {
                        Ok(c) => prop_assert_eq!(c.delta_e00.len(), MA_T12_COUNT),
                        Err(e) => prop_assert!(
                            matches!(e, XlsxError::UnsupportedColorimetry { .. }),
                            "{e}"
                        ),
                    }
                }
            }
        }
        Ok(())
    }

    #[test]
    fn the_base_reads() {
        let x = read(&apply(&[]), "m.xlsx").unwrap();
        assert_eq!(x.measurements[0].textures.len(), 7);
        assert!(
            check_colorimetry(&x.measurements[0])
                .unwrap()
                .flagged
                .is_empty()
        );
    }

    proptest! {
        #![proptest_config(crate::test_support::proptest_config())]

        #[test]
        fn a_mutated_export_is_read_or_refused(edits in proptest::collection::vec(edit(), 1..4)) {
            check(&apply(&edits))?;
        }
    }
}
