//! The row table CGATS and CSV files share once parsed: field names, and per data row its
//! line number and text values. One interpretation turns either into [`Observation`]s, so the
//! two formats accept the same columns and report errors the same way.
//!
//! Columns are found by name, case-insensitively, under the CGATS name or a short alias:
//! `SAMPLE_NAME` (`sample`), `DATA_KIND`, `REFERENCE_NAME` (`reference`), `GEOMETRY`, and a
//! band at λ nm as `SPECTRAL_NM<λ>`, `SPECTRAL_<λ>` or `NM<λ>`. Other columns (`SAMPLE_ID`,
//! `COST_FUNCTION`, bands outside 400–700 nm, …) are ignored on import.

use super::{
    DataKind, FormatError, ImportOptions, Location, Observation, Owner, Value, geometry_named,
    parse_number, sample_name,
};
use crate::spectral::{BANDS, wavelengths_nm};

/// A parsed table.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Table {
    /// The file's name, for errors.
    pub file: String,
    /// Line of the field names (CGATS: `BEGIN_DATA_FORMAT`'s content; CSV: the header).
    pub header_line: usize,
    pub fields: Vec<String>,
    /// (line, one value per field).
    pub rows: Vec<(usize, Vec<String>)>,
    /// The file's header keywords and their values, in file order (CGATS: `CREATED`,
    /// `INSTRUMENTATION`, `ORIGINATOR`, …; CSV has none).
    pub keywords: Vec<(String, String)>,
}

impl Table {
    /// The value of header keyword `name` (case-insensitive), if the file has it.
    pub(crate) fn keyword(&self, name: &str) -> Option<&str> {
        self.keywords
            .iter()
            .find(|(k, _)| k.eq_ignore_ascii_case(name))
            .map(|(_, v)| v.as_str())
    }

    /// Whether the table is brdfd's own export (it has a `DATA_KIND` column), not an
    /// instrument's.
    pub(crate) fn is_brdfd_export(&self) -> bool {
        self.column(&["DATA_KIND"]).is_some()
    }
}

impl Table {
    fn column(&self, names: &[&str]) -> Option<usize> {
        self.fields
            .iter()
            .position(|f| names.iter().any(|n| f.eq_ignore_ascii_case(n)))
    }

    fn require(&self, names: &[&str], what: &str) -> Result<usize, FormatError> {
        self.column(names).ok_or_else(|| {
            FormatError::invalid(
                &self.file,
                self.header_line,
                "fields",
                format!(
                    "no {what} column (expected one named {})",
                    names.join(" or ")
                ),
            )
        })
    }

    /// The column of each band, 400–700 nm.
    pub(crate) fn bands(&self) -> Result<[usize; BANDS], FormatError> {
        let mut out = [0; BANDS];
        for (slot, nm) in out.iter_mut().zip(wavelengths_nm()) {
            *slot = self.require(
                &[
                    &format!("SPECTRAL_NM{nm}"),
                    &format!("SPECTRAL_{nm}"),
                    &format!("NM{nm}"),
                ],
                &format!("{nm} nm"),
            )?;
        }
        Ok(out)
    }
}

/// The readings a table holds (rows of kind `measured` and `estimated` are skipped).
pub(crate) fn observations(
    table: &Table,
    opts: &ImportOptions,
) -> Result<Vec<Observation>, FormatError> {
    let sample = table.require(&["SAMPLE_NAME", "sample"], "sample name")?;
    let geometry = table.require(&["GEOMETRY"], "geometry")?;
    let kind = table.column(&["DATA_KIND"]);
    let reference = table.column(&["REFERENCE_NAME", "reference"]);
    let bands = table.bands()?;
    let file = table.file.as_str();

    let mut out = Vec::new();
    for (line, values) in &table.rows {
        let line = *line;
        let name = sample_name(file, line, &table.fields[sample], &values[sample])?;
        let owner = match kind {
            Some(k) => {
                let data_kind: DataKind = values[k]
                    .trim()
                    .parse()
                    .map_err(|e: String| FormatError::invalid(file, line, &table.fields[k], e))?;
                match data_kind {
                    DataKind::Measured
                    | DataKind::Estimated
                    | DataKind::EstimatedLow
                    | DataKind::EstimatedHigh => continue,
                    DataKind::Reading => Owner::Sample(name.to_string()),
                    DataKind::Reference => {
                        let tile = reference
                            .map(|r| values[r].trim().to_string())
                            .filter(|t| !t.is_empty())
                            .unwrap_or_else(|| opts.reference.clone());
                        Owner::ReferenceOf {
                            sample: name.to_string(),
                            tile,
                        }
                    }
                }
            }
            None if name == opts.reference => Owner::SharedReference,
            None => Owner::Sample(name.to_string()),
        };
        let g = geometry_named(file, line, &table.fields[geometry], &values[geometry])?;
        let mut spectrum = [0.0; BANDS];
        for (v, &col) in spectrum.iter_mut().zip(&bands) {
            *v = parse_number(file, line, &table.fields[col], &values[col])?;
        }
        out.push(Observation {
            owner,
            geometry: g,
            value: Value::Spectrum(spectrum),
            at: Location {
                file: file.to_string(),
                line,
            },
            fields: bands.iter().map(|&c| table.fields[c].clone()).collect(),
        });
    }
    Ok(out)
}
