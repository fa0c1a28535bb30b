//! The workbook's cells: each sheet's bounding box and the shared strings checked within the
//! import budget (limits "sheet cells", "shared strings", "text size") before the spreadsheet
//! reader builds its dense grid, then [`Sheet`], a sheet as calamine gives it, and the reading
//! of its cells into measurements: the metadata rows, the header's columns, the `Spectral Data`
//! measurements and the `Color Data` L*a*b* rows, each error naming its cell.

use calamine::{Data, Range};

use super::XlsxError;
use super::archive::Parts;
use super::markup::{parse_reference, parse_u64, tags};
use crate::colour::Lab;
use crate::formats::budget::Limit;
use crate::geometry::{Device, MA_T12_COUNT, by_name, ma_t12};
use crate::spectral::{BANDS, FIRST_NM, STEP_NM, Spectrum};

/// `A1`-style name of a 0-based cell position.
pub(super) fn cell_name(row: u32, col: u32) -> String {
    cell_name_u64(u64::from(row) + 1, u64::from(col) + 1)
}

/// `A1`-style name of a 1-based cell position.
pub(super) fn cell_name_u64(row: u64, col: u64) -> String {
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
pub(super) struct Metadata {
    pub(super) job: Option<String>,
    pub(super) standard: Option<String>,
    pub(super) serial: Option<String>,
    /// The `ILLUMINANT/OBSERVER:` value and its cell.
    pub(super) illuminant_observer: Option<(String, (u32, u32))>,
    /// The header row.
    pub(super) header: u32,
}

/// One `Spectral Data` measurement while it is being read.
pub(super) struct SpectralMeasurement {
    pub(super) name: String,
    pub(super) at: jiff::civil::DateTime,
    pub(super) at_text: String,
    pub(super) spectra: [Option<Spectrum>; MA_T12_COUNT],
    /// The cell of each geometry's `Geometry`, for duplicate errors.
    pub(super) cells: [Option<String>; MA_T12_COUNT],
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

pub(super) struct Sheet {
    pub(super) file: String,
    pub(super) name: &'static str,
    pub(super) range: Range<Data>,
}

impl Sheet {
    pub(super) fn get(&self, row: u32, col: u32) -> &Data {
        self.range.get_value((row, col)).unwrap_or(&Data::Empty)
    }

    /// The cell's text (numbers in their shortest decimal), trimmed; `None` when empty.
    pub(super) fn text(&self, row: u32, col: u32) -> Option<String> {
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

    pub(super) fn rows(&self) -> std::ops::RangeInclusive<u32> {
        match (self.range.start(), self.range.end()) {
            (Some(s), Some(e)) => s.0..=e.0,
            #[allow(clippy::reversed_empty_ranges)]
            _ => 1..=0,
        }
    }

    pub(super) fn cols(&self) -> std::ops::RangeInclusive<u32> {
        match (self.range.start(), self.range.end()) {
            (Some(s), Some(e)) => s.1..=e.1,
            #[allow(clippy::reversed_empty_ranges)]
            _ => 1..=0,
        }
    }

    pub(super) fn row_is_empty(&self, row: u32) -> bool {
        self.cols().all(|c| self.text(row, c).is_none())
    }

    /// The rows below `header` that hold anything.
    pub(super) fn data_rows(&self, header: u32) -> impl Iterator<Item = u32> + '_ {
        self.rows()
            .filter(move |&r| r > header && !self.row_is_empty(r))
    }

    pub(super) fn sheet_error(&self, message: impl Into<String>) -> XlsxError {
        XlsxError::Sheet {
            file: self.file.clone(),
            sheet: self.name,
            message: message.into(),
        }
    }

    pub(super) fn cell_error(&self, row: u32, col: u32, message: impl Into<String>) -> XlsxError {
        XlsxError::Cell {
            file: self.file.clone(),
            sheet: self.name,
            cell: cell_name(row, col),
            message: message.into(),
        }
    }

    pub(super) fn empty(&self, row: u32, col: u32, what: &str) -> XlsxError {
        XlsxError::EmptyCell {
            file: self.file.clone(),
            sheet: self.name,
            cell: cell_name(row, col),
            what: what.to_string(),
        }
    }

    /// The header row (first cell `Name`) and the labelled rows above it.
    pub(super) fn metadata(&self) -> Result<Metadata, XlsxError> {
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
    pub(super) fn column(&self, header: u32, title: &str) -> Result<u32, XlsxError> {
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
    pub(super) fn illuminant_observer(&self, meta: &Metadata) -> Result<(String, u32), XlsxError> {
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
    pub(super) fn number(&self, row: u32, col: u32, what: &str) -> Result<f64, XlsxError> {
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
    pub(super) fn geometry(&self, row: u32, col: u32) -> Result<usize, XlsxError> {
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
    pub(super) fn claim_geometry(
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
    pub(super) fn every_geometry(
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
    pub(super) fn spectral_rows(
        &self,
        date1904: bool,
    ) -> Result<Vec<SpectralMeasurement>, XlsxError> {
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
    pub(super) fn wavelength_columns(
        &self,
        header: u32,
        geo_col: u32,
    ) -> Result<Vec<u32>, XlsxError> {
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
    pub(super) fn color_rows(
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
pub(super) fn excel_serial_to_datetime(
    serial: f64,
    date1904: bool,
) -> Option<jiff::civil::DateTime> {
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

impl Parts<'_, '_> {
    /// The shared strings (every part of the archive named so, whichever the workbook
    /// points at): at most the markup allowance in all, a declared and a held count within
    /// the budget, and no string longer than the text allowance.
    pub(super) fn check_shared_strings(&mut self) -> Result<(), XlsxError> {
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
    pub(super) fn check_sheet(&mut self, name: &str, part: &str) -> Result<(), XlsxError> {
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
    pub(super) fn of(xml: &[u8]) -> Extent {
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
    pub(super) fn bounding_box(&self) -> Option<(u64, u64)> {
        (self.cells > 0).then(|| {
            (
                self.rows.1 - self.rows.0 + 1,
                self.cols.1.saturating_sub(self.cols.0).saturating_add(1),
            )
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::formats::xrite_xlsx::tests::{
        COLOR, REGULAR, SPECTRAL, bytes, edited, err, read, rezip, set_cell, unzip,
    };

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
