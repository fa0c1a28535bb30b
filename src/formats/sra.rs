//! The Canon RA-532H (SRA) values as CSV, as its software exports them for a session: a header
//! `sample,geometry,intensity`, then one row per measured object and geometry (`sra-20`,
//! `sra-60`, SCIENCE.md §2), the intensity in the device's own unit. The row named like the
//! reference tile (`--reference`, default "Munsell N9") is the reference of every sample in the
//! file. Columns are found by name, case-insensitively; others are ignored.

use std::fmt::Write as _;

use super::{
    FormatError, ImportOptions, Location, Observation, Owner, Value, geometry_named, parse_number,
    sample_name,
};
use crate::geometry::{Device, sra};
use crate::scan::Scan;

/// The SRA values of `scans` as the SRA's software would export them: each sample's two rows,
/// then the reference tile's (from the first scan: a session has one tile reading).
pub fn write_scans(scans: &[Scan]) -> String {
    let mut t = String::from("sample,geometry,intensity\n");
    let q = |s: &str| {
        if s.contains([',', '"', '\n']) {
            format!("\"{}\"", s.replace('"', "\"\""))
        } else {
            s.to_string()
        }
    };
    // A scan without SRA readings has no rows here.
    for s in scans {
        for (g, v) in sra().iter().zip(s.readings.sra.into_iter().flatten()) {
            let _ = writeln!(t, "{},{},{v}", q(&s.sample), g.name);
        }
    }
    let tile = scans
        .iter()
        .find_map(|s| s.reference.as_ref().filter(|r| r.readings.sra.is_some()));
    if let Some(reference) = tile {
        for (g, v) in sra()
            .iter()
            .zip(reference.readings.sra.into_iter().flatten())
        {
            let _ = writeln!(t, "{},{},{v}", q(&reference.name), g.name);
        }
    }
    t
}

/// The readings an SRA CSV holds.
pub(crate) fn observations(
    file: &str,
    text: &str,
    opts: &ImportOptions,
) -> Result<Vec<Observation>, FormatError> {
    let table = super::csv::parse(file, text)?;
    let col = |name: &str| -> Result<usize, FormatError> {
        table
            .fields
            .iter()
            .position(|f| f.eq_ignore_ascii_case(name))
            .ok_or_else(|| {
                FormatError::invalid(
                    file,
                    1,
                    "header",
                    format!(
                        "no \"{name}\" column; an SRA CSV has the columns sample,geometry,intensity"
                    ),
                )
            })
    };
    let (sample, geometry, intensity) = (col("sample")?, col("geometry")?, col("intensity")?);
    let mut out = Vec::new();
    for (line, values) in &table.rows {
        let line = *line;
        let name = sample_name(file, line, "sample", &values[sample])?;
        let g = geometry_named(file, line, "geometry", &values[geometry])?;
        if g.device != Device::Sra {
            return Err(FormatError::invalid(
                file,
                line,
                "geometry",
                format!(
                    "{} is an MA-T12 geometry; an SRA CSV holds sra-20 and sra-60 only",
                    g.name
                ),
            ));
        }
        let v = parse_number(file, line, "intensity", &values[intensity])?;
        let owner = if name == opts.reference {
            Owner::SharedReference
        } else {
            Owner::Sample(name.to_string())
        };
        out.push(Observation {
            owner,
            geometry: g,
            value: Value::Intensity(v),
            at: Location {
                file: file.to_string(),
                line,
            },
            fields: vec!["intensity".into()],
        });
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn err(text: &str) -> String {
        observations("s.csv", text, &ImportOptions::default())
            .unwrap_err()
            .to_string()
    }

    #[test]
    fn rows_are_read_with_their_owner() {
        let obs = observations(
            "s.csv",
            "Sample,Geometry,Intensity\n\"Red, glossy\",sra-60,7.25\nMunsell N9,sra-20,0.245\n",
            &ImportOptions::default(),
        )
        .unwrap();
        assert_eq!(obs.len(), 2);
        assert_eq!(obs[0].owner, Owner::Sample("Red, glossy".into()));
        assert_eq!(obs[0].value, Value::Intensity(7.25));
        assert_eq!(obs[0].at.line, 2);
        assert_eq!(obs[1].owner, Owner::SharedReference);
    }

    #[test]
    fn bad_files_name_file_line_and_field() {
        assert_eq!(
            err("sample,geometry,value\n"),
            "s.csv:1: header: no \"intensity\" column; an SRA CSV has the columns sample,geometry,intensity"
        );
        assert_eq!(
            err("sample,geometry,intensity\nA,sra-20,1\nA,45as45,2\n"),
            "s.csv:3: geometry: 45as45 is an MA-T12 geometry; an SRA CSV holds sra-20 and sra-60 only"
        );
        assert_eq!(
            err("sample,geometry,intensity\nA,sra-20,high\n"),
            "s.csv:2: intensity: \"high\" is not a number"
        );
        assert!(
            err("sample,geometry,intensity\nA,sra-30,1\n")
                .starts_with("s.csv:2: geometry: unknown geometry \"sra-30\"")
        );
    }
}

/// Property tests: whatever text arrives as the SRA CSV, the import returns (never panics), an
/// error names a problem, and the scans of an accepted pair of files validate.
#[cfg(test)]
mod proptests {
    use super::super::proptests::{SCANS, check_import, soup};
    use super::super::{Format, ImportOptions, import};
    use super::*;
    use crate::scan::proptests::{apply, assert_names_a_problem, mutations};
    use crate::spectral::wavelengths_nm;
    use proptest::prelude::*;
    use std::sync::LazyLock;

    /// The MA-T12 half of an instrument export of [`SCANS`] as CSV (the reference tile once,
    /// by name, then each sample), which the SRA CSV completes.
    static MA_T12_CSV: LazyLock<String> = LazyLock::new(|| {
        let mut t = String::from("sample,geometry");
        for nm in wavelengths_nm() {
            let _ = write!(t, ",nm{nm}");
        }
        t.push('\n');
        let tile = SCANS[0].reference.as_ref().unwrap();
        let objects = std::iter::once((&tile.name, &tile.readings))
            .chain(SCANS.iter().map(|s| (&s.sample, &s.readings)));
        for (name, readings) in objects {
            for g in crate::geometry::ma_t12() {
                let _ = write!(t, "{name},{}", g.name);
                for v in readings.ma_t12[g.index] {
                    let _ = write!(t, ",{v}");
                }
                t.push('\n');
            }
        }
        t
    });

    static VALID: LazyLock<String> = LazyLock::new(|| write_scans(&SCANS));

    const PIECES: [&str; 18] = [
        "sample",
        "geometry",
        "intensity",
        "Munsell N9",
        "T.Freesia pink",
        "sra-20",
        "sra-60",
        "45as45",
        ",",
        ",",
        "\"",
        "\n",
        "\n",
        "1",
        "0",
        "-1",
        "1e999",
        "NaN",
    ];

    /// Reads `text` alone, then as the SRA half of the instrument export.
    fn check(text: &str) -> Result<(), TestCaseError> {
        if let Err(e) = observations("s.csv", text, &ImportOptions::default()) {
            assert_names_a_problem(&e)?;
        }
        check_import(Format::Csv, &MA_T12_CSV, Some(text))
    }

    #[test]
    fn the_two_halves_import_to_the_scans() {
        let got = import(
            Format::Csv,
            "m.csv",
            &MA_T12_CSV,
            Some(("s.csv", &VALID)),
            &ImportOptions::default(),
        )
        .unwrap();
        let want: Vec<Scan> = SCANS
            .iter()
            .map(|s| Scan {
                reference: SCANS[0].reference.clone(),
                ..s.clone()
            })
            .collect();
        assert_eq!(got, want);
    }

    proptest! {
        #![proptest_config(crate::test_support::proptest_config())]

        #[test]
        fn arbitrary_text_is_rejected_or_valid(text in any::<String>()) {
            check(&text)?;
        }

        #[test]
        fn sra_csv_pieces_are_rejected_or_valid(text in soup(&PIECES)) {
            check(&text)?;
        }

        #[test]
        fn a_mutated_sra_csv_is_rejected_or_valid(ms in mutations()) {
            check(&apply(&VALID, &ms))?;
        }
    }
}
