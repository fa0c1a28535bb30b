//! The CIE tables colour is computed with (SCIENCE.md §7), embedded from `src/colour/data/`
//! and sampled once at the 31 band centres of [`crate::spectral`]:
//! the CIE 1931 2° observer x̄ȳz̄ (CIE 018:2019 / CIE 15:2018) and illuminant D65
//! (CIE S 014-2 / ISO 11664-2). Sources are cited in `src/colour/data/README.md`.
//!
//! Both tables list every band centre (400, 410, …, 700 nm) exactly, so sampling is a lookup,
//! never an interpolation; a table without one of those rows is rejected.

use std::sync::LazyLock;

use crate::spectral::{BANDS, Spectrum, wavelengths_nm};

/// CIE 1931 2° colour-matching functions, 360–830 nm every 1 nm: `nm,xbar,ybar,zbar`.
const CMF_CSV: &str = include_str!("data/cie1931_2deg_cmf_1nm.csv");
/// CIE D65 relative SPD, 300–780 nm every 5 nm: `nm,d65`.
const D65_CSV: &str = include_str!("data/cie_d65_spd_5nm.csv");

/// A CIE table that cannot be used. The embedded copies are checked by the tests, so these
/// only appear if a table file under `src/colour/data/` has been edited or replaced.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum CieTableError {
    #[error(
        "CIE table {table}, line {line}: {text:?} is not {expected} comma-separated numbers; \
         restore the file from the source cited in src/colour/data/README.md"
    )]
    BadRow {
        table: &'static str,
        line: usize,
        text: String,
        expected: usize,
    },
    #[error(
        "CIE table {table} has no row at {nm} nm, which the 31-band grid needs; \
         use a table that lists every 10 nm from 400 to 700 nm"
    )]
    MissingWavelength { table: &'static str, nm: u32 },
}

/// Parses a CIE CSV (`#` comment lines, one header line starting with `nm`, then rows of
/// `columns` numbers with the wavelength in nm first) and keeps the rows at the band centres.
pub fn sample_table<const N: usize>(
    table: &'static str,
    csv: &str,
) -> Result<[[f64; N]; BANDS], CieTableError> {
    let mut out = [[f64::NAN; N]; BANDS];
    let mut found = [false; BANDS];
    for (i, raw) in csv.lines().enumerate() {
        let text = raw.trim();
        if text.is_empty() || text.starts_with('#') || text.starts_with("nm") {
            continue;
        }
        let bad = || CieTableError::BadRow {
            table,
            line: i + 1,
            text: text.to_string(),
            expected: N + 1,
        };
        let fields: Vec<f64> = text
            .split(',')
            .map(|f| f.trim().parse::<f64>())
            .collect::<Result<_, _>>()
            .map_err(|_| bad())?;
        if fields.len() != N + 1 || fields.iter().any(|v| !v.is_finite()) {
            return Err(bad());
        }
        // Wavelengths in these tables are whole nanometres; anything else is not a band centre.
        let nm = fields[0];
        for (band, &centre) in wavelengths_nm().iter().enumerate() {
            if nm == f64::from(centre) {
                out[band].copy_from_slice(&fields[1..]);
                found[band] = true;
            }
        }
    }
    match found.iter().position(|f| !f) {
        Some(band) => Err(CieTableError::MissingWavelength {
            table,
            nm: wavelengths_nm()[band],
        }),
        None => Ok(out),
    }
}

static CMF: LazyLock<[[f64; 3]; BANDS]> = LazyLock::new(|| {
    sample_table::<3>("cie1931_2deg_cmf_1nm.csv", CMF_CSV)
        .unwrap_or_else(|e| panic!("embedded table is damaged: {e}"))
});

static D65: LazyLock<Spectrum> = LazyLock::new(|| {
    let rows = sample_table::<1>("cie_d65_spd_5nm.csv", D65_CSV)
        .unwrap_or_else(|e| panic!("embedded table is damaged: {e}"));
    rows.map(|[s]| s)
});

/// CIE 1931 2° x̄, ȳ, z̄ at each band centre (dimensionless).
pub fn cmf() -> &'static [[f64; 3]; BANDS] {
    &CMF
}

/// CIE D65 relative spectral power at each band centre (normalised to 100 at 560 nm by the CIE).
pub fn d65() -> &'static Spectrum {
    &D65
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn embedded_tables_sample_to_the_cie_values_at_the_ends_and_the_middle() {
        // Values read off the CIE tables themselves (CIE 018:2019, CIE S 014-2).
        assert_eq!(cmf()[0], [0.01431, 0.000396, 0.06785001]); // 400 nm
        assert_eq!(cmf()[16], [0.5945, 0.995, 0.0039]); // 560 nm
        assert_eq!(cmf()[BANDS - 1], [0.01135916, 0.004102, 0.0]); // 700 nm
        assert_eq!(d65()[0], 82.7549); // 400 nm
        assert_eq!(d65()[16], 100.0); // 560 nm, the normalisation point
        assert_eq!(d65()[BANDS - 1], 71.6091); // 700 nm
    }

    #[test]
    fn parser_takes_comments_header_and_rows() {
        let mut csv = String::from("# a comment\nnm,v\n");
        for nm in (390..=710).step_by(5) {
            csv.push_str(&format!("{nm},{}\n", nm as f64 / 10.0));
        }
        let rows = sample_table::<1>("t", &csv).unwrap();
        assert_eq!(rows[0], [40.0]);
        assert_eq!(rows[BANDS - 1], [70.0]);
    }

    #[test]
    fn parser_names_the_missing_band_centre() {
        let mut csv = String::from("nm,v\n");
        for nm in (400..=700).step_by(10).filter(|&nm| nm != 550) {
            csv.push_str(&format!("{nm},1\n"));
        }
        assert_eq!(
            sample_table::<1>("t", &csv),
            Err(CieTableError::MissingWavelength {
                table: "t",
                nm: 550
            })
        );
    }

    #[test]
    fn parser_names_the_bad_line() {
        let err = sample_table::<3>("t", "nm,x,y,z\n400,1,2\n").unwrap_err();
        assert_eq!(
            err,
            CieTableError::BadRow {
                table: "t",
                line: 2,
                text: "400,1,2".into(),
                expected: 4
            }
        );
        let err = sample_table::<1>("t", "400,abc\n").unwrap_err();
        assert!(err.to_string().contains("line 1"), "{err}");
    }
}
