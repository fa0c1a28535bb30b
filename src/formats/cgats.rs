//! CGATS.17 (ANSI CGATS.17-2005, the text format of IT8 charts and of most colour
//! instruments' software): written one row per sample, data kind and geometry, read from
//! brdfd's own files and from an MA-T12's software export.
//!
//! Written layout: the header names the originator and time, explains the data kinds and
//! units in `#` comments, and declares every field that is not a CGATS standard one with
//! `KEYWORD` (`DATA_KIND`, `REFERENCE_NAME`, `COST_FUNCTION`, `METHOD`, `GEOMETRY`), as the
//! standard asks, so strict readers (LittleCMS built with `CMS_STRICT_CGATS`) accept the file.
//! Data fields: `SAMPLE_ID SAMPLE_NAME DATA_KIND REFERENCE_NAME COST_FUNCTION METHOD GEOMETRY`,
//! the sample's provenance (`SCAN_ID STATION MEASURED_AT SOURCE MA_T12_MODEL … SRA_ORIGIN`,
//! all quoted), `SPECTRAL_NM400 … SPECTRAL_NM700`; text values are quoted, numbers use Rust's shortest
//! round-trip form. `COST_FUNCTION` and `METHOD` are `""` except on `estimated` rows.
//!
//! Read: the first data table; one data set per line (what every writer does); quoted strings,
//! `#` comments. Columns are found by name ([`super::table`]).

use std::fmt::Write as _;

use super::table::Table;
use super::{ExportOptions, FormatError, rows};
use crate::scan::DeviceReadings;
use crate::spectral::wavelengths_nm;
use crate::study::Study;

/// Fields that are not CGATS.17 standard ones and so are declared with `KEYWORD`: the row's
/// kind, reference, fit and geometry, then the sample's provenance
/// ([`super::PROVENANCE_FIELDS`], upper-cased).
pub const DECLARED: [&str; 19] = [
    "DATA_KIND",
    "REFERENCE_NAME",
    "COST_FUNCTION",
    "METHOD",
    "GEOMETRY",
    "SCAN_ID",
    "STATION",
    "MEASURED_AT",
    "SOURCE",
    "MA_T12_MODEL",
    "MA_T12_SERIAL",
    "MA_T12_FIRMWARE",
    "MA_T12_SIMULATED",
    "SRA_MODEL",
    "SRA_SERIAL",
    "SRA_FIRMWARE",
    "SRA_SIMULATED",
    "MA_T12_ORIGIN",
    "SRA_ORIGIN",
];

/// A CGATS quoted string; CGATS has no escape for `"` or a line break, so those are refused.
fn quoted(s: &str) -> Result<String, FormatError> {
    if s.contains('"') || s.contains('\n') || s.contains('\r') {
        return Err(FormatError::Unwritable {
            format: "cgats",
            message: format!(
                "\"{}\" contains a double quote or a line break, which CGATS strings cannot hold; rename it",
                s.escape_debug()
            ),
        });
    }
    Ok(format!("\"{s}\""))
}

/// The study as CGATS.17 text.
pub fn write(study: &Study, opts: &ExportOptions) -> Result<String, FormatError> {
    let rows = rows(study);
    let mut t = String::new();
    let _ = writeln!(t, "CGATS.17");
    let _ = writeln!(t, "ORIGINATOR {}", quoted(&opts.originator)?);
    let _ = writeln!(
        t,
        "FILE_DESCRIPTOR \"Spectral BRDF study: device readings, measured and estimated reflectance factor per geometry\""
    );
    let _ = writeln!(t, "CREATED {}", quoted(&opts.created)?);
    for line in [
        "DATA_KIND: reading = the sample's device reading, reference = the reference tile's",
        "  reading for that scan, measured = reflectance factor pi*M relative to the tile,",
        "  estimated = the fitted model's reflectance factor pi*f (COST_FUNCTION, METHOD set).",
        "MA-T12 readings: reflectance factor as the device reports it (0-1 scale).",
        "SRA readings (GEOMETRY sra-20, sra-60): the device's single achromatic intensity,",
        "  in its own unit, repeated in every band.",
        "GEOMETRY: the device's geometry name; angles in degrees:",
    ] {
        let _ = writeln!(t, "# {line}");
    }
    for g in &crate::geometry::GEOMETRIES {
        let _ = writeln!(
            t,
            "#   {:<8} {}: theta_i {}, theta_r {}, phi_r {}, aspecular {}",
            g.name, g.device, g.theta_i_deg, g.theta_r_deg, g.phi_r_deg, g.aspecular_deg
        );
    }
    for k in DECLARED {
        let _ = writeln!(t, "KEYWORD \"{k}\"");
    }
    let bands: Vec<String> = wavelengths_nm()
        .iter()
        .map(|nm| format!("SPECTRAL_NM{nm}"))
        .collect();
    let _ = writeln!(t, "NUMBER_OF_FIELDS {}", 2 + DECLARED.len() + bands.len());
    let _ = writeln!(t, "BEGIN_DATA_FORMAT");
    let _ = writeln!(
        t,
        "SAMPLE_ID\tSAMPLE_NAME\t{}\t{}",
        DECLARED.join("\t"),
        bands.join("\t")
    );
    let _ = writeln!(t, "END_DATA_FORMAT");
    let _ = writeln!(t, "NUMBER_OF_SETS {}", rows.len());
    let _ = writeln!(t, "BEGIN_DATA");
    for (i, r) in rows.iter().enumerate() {
        let _ = write!(
            t,
            "{}\t{}\t{}\t{}\t{}\t{}\t{}",
            i + 1,
            quoted(&r.sample)?,
            quoted(r.kind.name())?,
            quoted(&r.reference)?,
            quoted(r.cost_function.map_or("", |c| c.name()))?,
            quoted(r.method.as_deref().unwrap_or(""))?,
            quoted(r.geometry.name)?,
        );
        for v in &r.origin {
            let _ = write!(t, "\t{}", quoted(v)?);
        }
        for v in r.values {
            let _ = write!(t, "\t{v}");
        }
        t.push('\n');
    }
    let _ = writeln!(t, "END_DATA");
    Ok(t)
}

/// Splits one line into tokens: quoted strings (quotes removed) and bare words; a `#`
/// outside quotes starts a comment.
fn tokens(file: &str, line_no: usize, line: &str) -> Result<Vec<String>, FormatError> {
    let mut out = Vec::new();
    let mut chars = line.chars().peekable();
    while let Some(&c) = chars.peek() {
        if c.is_whitespace() {
            chars.next();
        } else if c == '#' {
            break;
        } else if c == '"' {
            chars.next();
            let mut s = String::new();
            loop {
                match chars.next() {
                    Some('"') => break,
                    Some(c) => s.push(c),
                    None => {
                        return Err(FormatError::invalid(
                            file,
                            line_no,
                            "string",
                            "a quoted string is not closed on its line",
                        ));
                    }
                }
            }
            out.push(s);
        } else {
            let mut s = String::new();
            while let Some(&c) = chars.peek() {
                if c.is_whitespace() {
                    break;
                }
                s.push(c);
                chars.next();
            }
            out.push(s);
        }
    }
    Ok(out)
}

/// Parses the first data table of a CGATS file.
pub(crate) fn parse(file: &str, text: &str) -> Result<Table, FormatError> {
    #[derive(PartialEq)]
    enum State {
        Identifier,
        Header,
        Format,
        BetweenFormatAndData,
        Data,
    }
    let mut state = State::Identifier;
    let mut fields: Vec<String> = Vec::new();
    let mut header_line = 0;
    let mut rows = Vec::new();
    let mut keywords = Vec::new();
    let mut last = 0;
    for (i, line) in text.lines().enumerate() {
        let n = i + 1;
        last = n;
        let toks = tokens(file, n, line)?;
        let Some(first) = toks.first() else { continue };
        match state {
            State::Identifier => state = State::Header,
            State::Header | State::BetweenFormatAndData => {
                if first == "BEGIN_DATA_FORMAT" {
                    if state == State::BetweenFormatAndData {
                        return Err(FormatError::invalid(
                            file,
                            n,
                            "BEGIN_DATA_FORMAT",
                            "a second data format before BEGIN_DATA",
                        ));
                    }
                    state = State::Format;
                    fields.extend(toks.into_iter().skip(1));
                    header_line = n;
                } else if first == "BEGIN_DATA" {
                    if state == State::Header {
                        return Err(FormatError::invalid(
                            file,
                            n,
                            "BEGIN_DATA",
                            "data before any BEGIN_DATA_FORMAT … END_DATA_FORMAT block naming the fields",
                        ));
                    }
                    state = State::Data;
                } else if state == State::Header {
                    // A header keyword and its value (`CREATED "2024-05-29T16:37:15"`).
                    let value = toks[1..].join(" ");
                    keywords.push((first.clone(), value));
                }
            }
            State::Format => {
                for t in toks {
                    if t == "END_DATA_FORMAT" {
                        state = State::BetweenFormatAndData;
                        break;
                    }
                    if header_line == 0 || fields.is_empty() {
                        header_line = n;
                    }
                    fields.push(t);
                }
            }
            State::Data => {
                if first == "END_DATA" {
                    if fields.is_empty() {
                        return Err(FormatError::invalid(
                            file,
                            header_line,
                            "BEGIN_DATA_FORMAT",
                            "no fields named",
                        ));
                    }
                    return Ok(Table {
                        file: file.to_string(),
                        header_line,
                        fields,
                        rows,
                        keywords,
                    });
                }
                if toks.len() != fields.len() {
                    return Err(FormatError::invalid(
                        file,
                        n,
                        "data set",
                        format!(
                            "{} values, expected {} (one per field of BEGIN_DATA_FORMAT, one data set per line)",
                            toks.len(),
                            fields.len()
                        ),
                    ));
                }
                rows.push((n, toks));
            }
        }
    }
    let (field, message) = match state {
        State::Identifier => (
            "file",
            "empty; a CGATS file starts with its identifier, e.g. CGATS.17",
        ),
        State::Header => (
            "BEGIN_DATA_FORMAT",
            "no BEGIN_DATA_FORMAT block naming the fields",
        ),
        State::Format => (
            "END_DATA_FORMAT",
            "BEGIN_DATA_FORMAT is never closed by END_DATA_FORMAT",
        ),
        State::BetweenFormatAndData => ("BEGIN_DATA", "no BEGIN_DATA block"),
        State::Data => ("END_DATA", "BEGIN_DATA is never closed by END_DATA"),
    };
    Err(FormatError::invalid(file, last.max(1), field, message))
}

/// A fixture for tests of the import by object name: what an MA-T12's software writes for one
/// session, each of `objects` (name, device readings) as 12 rows of MA-T12 spectra, with
/// neither data kinds nor SRA values.
pub fn instrument_export(objects: &[(&str, &DeviceReadings)]) -> String {
    let mut t = String::from(
        "CGATS.17\nORIGINATOR \"MA-T12 software\"\nKEYWORD \"GEOMETRY\"\nBEGIN_DATA_FORMAT\nSAMPLE_ID SAMPLE_NAME GEOMETRY",
    );
    for nm in wavelengths_nm() {
        let _ = write!(t, " SPECTRAL_NM{nm}");
    }
    t += "\nEND_DATA_FORMAT\nBEGIN_DATA\n";
    let mut id = 0;
    for (name, readings) in objects {
        for g in crate::geometry::ma_t12() {
            id += 1;
            let _ = write!(t, "{id} \"{name}\" {}", g.name);
            for v in readings.ma_t12[g.index] {
                let _ = write!(t, " {v}");
            }
            t.push('\n');
        }
    }
    t += "END_DATA\n";
    t
}

#[cfg(test)]
mod tests {
    use super::super::tests::{fixed, study};
    use super::super::{Format, ImportOptions, import};
    use super::*;

    fn err(text: &str) -> String {
        import(
            Format::Cgats,
            "m.txt",
            text,
            None,
            &ImportOptions::default(),
        )
        .unwrap_err()
        .to_string()
    }

    #[test]
    fn the_provenance_fields_are_declared_and_written_per_row() {
        assert_eq!(
            DECLARED[5..].to_vec(),
            super::super::PROVENANCE_FIELDS
                .map(|f| f.to_uppercase())
                .to_vec()
        );
        let text = write(&super::super::tests::stored_study(), &fixed()).unwrap();
        assert!(text.contains("KEYWORD \"MA_T12_SERIAL\""));
        let row = text
            .lines()
            .skip_while(|l| *l != "BEGIN_DATA")
            .nth(1)
            .unwrap();
        assert!(
            row.contains("\"11\"\t\"bench-2\"\t\"2024-05-01T12:00:00Z\"\t\"measured\"\t\"MA-T12\"\t\"MT-7\"\t\"2.1.0\"\t\"no\""),
            "{row}"
        );
        assert!(
            row.contains("\"sim\"\t\"yes\"\t\"measured\"\t\"simulated\""),
            "{row}"
        );
    }

    #[test]
    fn the_header_declares_every_custom_field_before_the_data_format() {
        let text = write(&study(), &fixed()).unwrap();
        let format_at = text.find("BEGIN_DATA_FORMAT").unwrap();
        for k in DECLARED {
            let at = text.find(&format!("KEYWORD \"{k}\"")).unwrap();
            assert!(at < format_at, "{k}");
        }
        assert!(text.starts_with("CGATS.17\n"));
        let table = parse("x", &text).unwrap();
        assert_eq!(table.fields.len(), 52);
        assert_eq!(table.fields[6], "GEOMETRY");
        assert_eq!(table.fields[7], "SCAN_ID");
        assert_eq!(table.fields[18], "SRA_SIMULATED");
        assert_eq!(table.fields[20], "SRA_ORIGIN");
        assert_eq!(table.fields[21], "SPECTRAL_NM400");
        assert_eq!(table.fields[51], "SPECTRAL_NM700");
        assert_eq!(table.rows.len(), (3 * 3 + 8) * 14);
        assert_eq!(table.rows[0].1[1], "T.Freesia pink");
        let est = table.rows.iter().find(|r| r.1[2] == "estimated").unwrap();
        assert_eq!(est.1[4], "cf1");
        assert_eq!(est.1[5], "separable");
    }

    #[test]
    fn an_instrument_export_without_data_kinds_reads_by_name() {
        let study = study();
        let s = &study.samples[1];
        // What the MA-T12's software would write: the tile and the sample by name, 12 rows each.
        let t = instrument_export(&[
            ("Munsell N9", &s.scan.reference.as_ref().unwrap().readings),
            (s.name.as_str(), &s.scan.readings),
        ]);
        // Without the SRA values the scan is incomplete, and the message says where they go.
        let e = err(&t);
        assert!(
            e.contains("m.txt: sample \"T.Prairie green\": no reading at geometry sra-20"),
            "{e}"
        );
        assert!(e.contains("SRA CSV (--sra)"), "{e}");
        let sra = super::super::sra::write_scans(std::slice::from_ref(&s.scan));
        let got = import(
            Format::Cgats,
            "m.txt",
            &t,
            Some(("s.csv", &sra)),
            &ImportOptions::default(),
        )
        .unwrap();
        // The readings as written, and what the header says of them (no CREATED or
        // INSTRUMENTATION here: the originator only).
        let mut got = got;
        let origin = got[0].origin.take().expect("an instrument export's origin");
        assert_eq!(got, vec![s.scan.clone()]);
        assert_eq!(origin.measured_at, None);
        assert_eq!(origin.ma_t12, None);
        assert_eq!(
            origin.notes.get("originator").map(String::as_str),
            Some("MA-T12 software")
        );
    }

    #[test]
    fn bad_files_are_rejected_naming_file_line_and_field() {
        let good = write(&study(), &fixed()).unwrap();
        // A number that is not one.
        let bad = good.replacen("\t0.", "\tzero.", 1);
        let line = bad.lines().position(|l| l.contains("\tzero.")).unwrap() + 1;
        let e = err(&bad);
        assert!(e.starts_with(&format!("m.txt:{line}: SPECTRAL_NM")), "{e}");
        assert!(e.contains("is not a number"), "{e}");
        // A short row.
        let mut lines: Vec<String> = good.lines().map(str::to_string).collect();
        let data = lines.iter().position(|l| l == "BEGIN_DATA").unwrap() + 3;
        lines[data] = lines[data].rsplit_once('\t').unwrap().0.to_string();
        let e = err(&lines.join("\n"));
        assert_eq!(
            e,
            format!(
                "m.txt:{}: data set: 51 values, expected 52 (one per field of BEGIN_DATA_FORMAT, one data set per line)",
                data + 1
            )
        );
        // An unknown geometry.
        let e = err(&good.replacen("\"45as25\"", "\"45as26\"", 1));
        assert!(e.contains(": GEOMETRY: unknown geometry \"45as26\""), "{e}");
        // A missing geometry.
        let cut: Vec<&str> = good
            .lines()
            .filter(|l| !(l.contains("\"reading\"") && l.contains("\"15as80\"")))
            .collect();
        let e = err(&cut.join("\n"));
        assert!(
            e.starts_with("m.txt: sample \"T.Freesia pink\": no reading at geometry 15as80"),
            "{e}"
        );
        // A reference reading of zero.
        let mut lines: Vec<String> = good.lines().map(str::to_string).collect();
        let r = lines
            .iter()
            .position(|l| l.contains("\"reference\"") && l.contains("\"45as45\""))
            .unwrap();
        let mut cells: Vec<String> = lines[r].split('\t').map(str::to_string).collect();
        cells[24] = "0".into(); // SPECTRAL_NM430, after 7 + 14 text fields
        lines[r] = cells.join("\t");
        let e = err(&lines.join("\n"));
        assert!(
            e.starts_with(&format!("m.txt:{}: SPECTRAL_NM430: reference", r + 1)),
            "{e}"
        );
        assert!(
            e.contains("at 45as45 at 430 nm: 0: a reference reading must be positive"),
            "{e}"
        );
        // A reference reading so small that the sample's is beyond any reflectance factor
        // against it: refused at the sample's line.
        cells[24] = "1e-300".into();
        lines[r] = cells.join("\t");
        let s = lines
            .iter()
            .position(|l| l.contains("\"reading\"") && l.contains("\"45as45\""))
            .unwrap();
        let e = err(&lines.join("\n"));
        assert!(
            e.starts_with(&format!(
                "m.txt:{}: SPECTRAL_NM430: sample \"T.Freesia pink\" at 45as45 at 430 nm: ",
                s + 1
            )) && e.contains("times the reference tile \"Munsell N9\"'s 1e-300"),
            "{e}"
        );
        // Structure.
        assert!(err("").contains("m.txt:1: file: empty"));
        let e = err(&good.replace("END_DATA\n", ""));
        assert!(e.contains("END_DATA: BEGIN_DATA is never closed"), "{e}");
        let e = err(&good.replace("GEOMETRY\tSCAN_ID", "GEO\tSCAN_ID"));
        assert!(e.contains(": fields: no geometry column"), "{e}");
    }

    #[test]
    fn names_cgats_cannot_hold_are_refused() {
        let mut s = study();
        s.samples[0].name = "6\" tile".into();
        let e = write(&s, &fixed()).unwrap_err().to_string();
        assert!(
            e.starts_with("cgats: \"6\\\" tile\" contains a double quote"),
            "{e}"
        );
    }
}

/// Property tests: whatever text arrives as CGATS, the import returns (never panics), an error
/// names a problem, and the scans of an accepted file validate.
#[cfg(test)]
mod proptests {
    use super::super::Format;
    use super::super::proptests::import_properties;

    const PIECES: [&str; 34] = [
        "CGATS.17\n",
        "BEGIN_DATA_FORMAT",
        "END_DATA_FORMAT",
        "BEGIN_DATA",
        "END_DATA",
        "NUMBER_OF_FIELDS 3",
        "KEYWORD \"GEOMETRY\"",
        "SAMPLE_ID",
        "SAMPLE_NAME",
        "DATA_KIND",
        "REFERENCE_NAME",
        "GEOMETRY",
        "SPECTRAL_NM400",
        "SPECTRAL_NM700",
        "\"reading\"",
        "\"reference\"",
        "\"measured\"",
        "\"Munsell N9\"",
        "\"A\"",
        "45as45",
        "sra-20",
        "\"",
        "#",
        "\n",
        "\n",
        "\t",
        " ",
        "1",
        "0",
        "-1",
        "0.5",
        "1e999",
        "NaN",
        "é",
    ];

    import_properties!(Format::Cgats, cgats_pieces_are_rejected_or_valid, &PIECES);
}
