//! The export's rows as comma-separated values (RFC 4180, via the `csv` crate): the same rows
//! and columns as the CGATS export, with short lower-case column names, for spreadsheets and
//! data-frame tools.
//!
//! Columns: `sample,data_kind,reference,cost_function,method,device,geometry,theta_i_deg,
//! theta_r_deg,phi_r_deg`, the sample's provenance ([`super::PROVENANCE_FIELDS`]: `scan_id,
//! station,measured_at,source,ma_t12_model,…,sra_origin`), then `nm400,…,nm700`. The angle
//! columns are for the reader's convenience; on import the geometry is taken from its name
//! (SCIENCE.md §2), never from the angles, and the provenance columns are not read (an imported
//! scan's provenance is the import).

use super::table::Table;
use super::{FormatError, PROVENANCE_FIELDS, rows};
use crate::spectral::wavelengths_nm;
use crate::study::Study;

/// The column names, in order.
pub fn header() -> Vec<String> {
    let mut h: Vec<String> = [
        "sample",
        "data_kind",
        "reference",
        "cost_function",
        "method",
        "device",
        "geometry",
        "theta_i_deg",
        "theta_r_deg",
        "phi_r_deg",
    ]
    .map(String::from)
    .to_vec();
    h.extend(PROVENANCE_FIELDS.map(String::from));
    h.extend(wavelengths_nm().iter().map(|nm| format!("nm{nm}")));
    h
}

fn csv_error(e: ::csv::Error) -> FormatError {
    FormatError::Unwritable {
        format: "csv",
        message: e.to_string(),
    }
}

/// The study as CSV text.
pub fn write(study: &Study) -> Result<String, FormatError> {
    let mut w = ::csv::Writer::from_writer(Vec::new());
    w.write_record(header()).map_err(csv_error)?;
    for r in rows(study) {
        let g = r.geometry;
        let mut rec: Vec<String> = vec![
            r.sample,
            r.kind.name().into(),
            r.reference,
            r.cost_function.map_or(String::new(), |c| c.name().into()),
            r.method.unwrap_or_default(),
            g.device.key().into(),
            g.name.into(),
            g.theta_i_deg.to_string(),
            g.theta_r_deg.to_string(),
            g.phi_r_deg.to_string(),
        ];
        rec.extend(r.origin);
        rec.extend(r.values.iter().map(|v| v.to_string()));
        w.write_record(&rec).map_err(csv_error)?;
    }
    let bytes = w.into_inner().map_err(|e| FormatError::Unwritable {
        format: "csv",
        message: e.to_string(),
    })?;
    Ok(String::from_utf8(bytes).expect("csv writes the UTF-8 it is given"))
}

/// Parses CSV with a header row into a table.
pub(crate) fn parse(file: &str, text: &str) -> Result<Table, FormatError> {
    let mut r = ::csv::ReaderBuilder::new()
        .has_headers(true)
        .flexible(false)
        .trim(::csv::Trim::All)
        .from_reader(text.as_bytes());
    let at = |e: &::csv::Error| e.position().map_or(1, |p| p.line() as usize);
    let fields: Vec<String> = r
        .headers()
        .map_err(|e| FormatError::invalid(file, at(&e), "header", e.to_string()))?
        .iter()
        .map(str::to_string)
        .collect();
    if fields.iter().all(String::is_empty) {
        return Err(FormatError::invalid(
            file,
            1,
            "header",
            "empty; the first line must name the columns",
        ));
    }
    let mut rows = Vec::new();
    for rec in r.records() {
        let rec = rec.map_err(|e| {
            let message = match e.kind() {
                ::csv::ErrorKind::UnequalLengths {
                    expected_len, len, ..
                } => {
                    format!("{len} values, expected {expected_len} (one per column of the header)")
                }
                _ => e.to_string(),
            };
            FormatError::invalid(file, at(&e), "record", message)
        })?;
        let line = rec.position().map_or(0, |p| p.line() as usize);
        rows.push((line, rec.iter().map(str::to_string).collect()));
    }
    Ok(Table {
        file: file.to_string(),
        header_line: 1,
        fields,
        rows,
        keywords: Vec::new(),
    })
}

#[cfg(test)]
mod tests {
    use super::super::tests::study;
    use super::super::{Format, ImportOptions, import};
    use super::*;

    fn err(text: &str) -> String {
        import(Format::Csv, "x.csv", text, None, &ImportOptions::default())
            .unwrap_err()
            .to_string()
    }

    #[test]
    fn one_row_per_sample_kind_and_geometry_with_a_header() {
        let text = write(&study()).unwrap();
        let lines: Vec<&str> = text.lines().collect();
        assert_eq!(lines.len(), 1 + (3 * 3 + 8) * 14);
        assert!(lines[0].starts_with(
            "sample,data_kind,reference,cost_function,method,device,geometry,theta_i_deg"
        ));
        assert!(lines[0].ends_with(",nm690,nm700"));
        assert!(
            lines[1].starts_with("T.Freesia pink,reading,Munsell N9,,,ma_t12,15as-45,60,15,180,"),
            "{}",
            lines[1]
        );
    }

    #[test]
    fn bad_files_are_rejected_naming_file_line_and_field() {
        let good = write(&study()).unwrap();
        let mut lines: Vec<String> = good.lines().map(str::to_string).collect();
        lines[5] = lines[5].rsplit_once(',').unwrap().0.into();
        let e = err(&lines.join("\n"));
        assert_eq!(
            e,
            "x.csv:6: record: 54 values, expected 55 (one per column of the header)"
        );
        let mut lines: Vec<String> = good.lines().map(str::to_string).collect();
        let mut cells: Vec<String> = lines[3].split(',').map(str::to_string).collect();
        cells[26] = "NaN".into(); // nm420, after 10 geometry and 14 provenance columns
        lines[3] = cells.join(",");
        let e = err(&lines.join("\n"));
        assert_eq!(e, "x.csv:4: nm420: NaN is not a finite number");
        let e = err(&good.replacen(",reading,", ",raw,", 1));
        assert!(
            e.starts_with("x.csv:2: data_kind: unknown data kind \"raw\""),
            "{e}"
        );
        let e = err(&good.replacen("sample,", "name,", 1));
        assert!(
            e.starts_with("x.csv:1: fields: no sample name column"),
            "{e}"
        );
        let mut lines: Vec<String> = good.lines().map(str::to_string).collect();
        let mut cells: Vec<String> = lines[2].split(',').map(str::to_string).collect();
        cells[34] = "-0.5".into();
        lines[2] = cells.join(",");
        let e = err(&lines.join("\n"));
        assert_eq!(
            e,
            "x.csv:3: nm500: sample \"T.Freesia pink\" at 15as-30 at 500 nm: -0.5: a device reading cannot be negative"
        );
    }
}

/// Property tests: whatever text arrives as CSV, the import returns (never panics), an error
/// names a problem, and the scans of an accepted file validate.
#[cfg(test)]
mod proptests {
    use super::super::Format;
    use super::super::proptests::import_properties;

    const PIECES: [&str; 26] = [
        "sample",
        "data_kind",
        "reference",
        "geometry",
        "nm400",
        "nm700",
        "reading",
        "measured",
        "Munsell N9",
        "A",
        "45as45",
        "sra-60",
        ",",
        ",",
        "\"",
        "\"\"",
        "\n",
        "\n",
        "\r\n",
        " ",
        "1",
        "0",
        "-1",
        "1e999",
        "NaN",
        "é",
    ];

    import_properties!(Format::Csv, csv_pieces_are_rejected_or_valid, &PIECES);
}
