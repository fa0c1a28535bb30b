//! The CIE tables colour is computed with (SCIENCE.md §7), embedded from `src/colour/data/`
//! and sampled once at the 31 band centres of [`crate::spectral`]:
//! the CIE 1931 2° observer x̄ȳz̄ (CIE 018:2019 / CIE 15:2018) and illuminant D65
//! (CIE S 014-2 / ISO 11664-2), and the CIE 1964 10° observer (CIE 15:2018) for the `[colour]
//! observer = "10"` option, and CIE illuminant C (CIE 15:2004) for the SRA's luminance reading.
//! Sources are cited in `src/colour/data/README.md`.
//! The whole 1 nm tables are also available, for the ASTM E308 weights of [`super::e308`].
//!
//! Both tables list every band centre (400, 410, …, 700 nm) exactly, so sampling is a lookup,
//! never an interpolation; a table without one of those rows is rejected.

use std::sync::LazyLock;

use crate::spectral::{BANDS, Spectrum, wavelengths_nm};

/// CIE 1931 2° colour-matching functions, 360–830 nm every 1 nm: `nm,xbar,ybar,zbar`.
const CMF_CSV: &str = include_str!("data/cie1931_2deg_cmf_1nm.csv");
/// CIE 1964 10° colour-matching functions, 360–830 nm every 1 nm: `nm,x_bar_10,y_bar_10,z_bar_10`.
const CMF10_CSV: &str = include_str!("data/cie1964_10deg_cmf_1nm.csv");
/// CIE D65 relative SPD, 300–780 nm every 5 nm: `nm,d65`.
const D65_CSV: &str = include_str!("data/cie_d65_spd_5nm.csv");
/// CIE illuminant C relative SPD, 300–780 nm every 5 nm: `nm,c` (ISO 2813's gloss illuminant,
/// for the SRA's luminance reading, [`crate::sra_reading`]).
const ILLUMINANT_C_CSV: &str = include_str!("data/cie_illuminant_c_spd_5nm.csv");

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
    for (nm, values) in all_rows::<N>(table, csv)? {
        // Wavelengths in these tables are whole nanometres; anything else is not a band centre.
        for (band, &centre) in wavelengths_nm().iter().enumerate() {
            if nm == f64::from(centre) {
                out[band] = values;
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

static ILLUMINANT_C: LazyLock<Spectrum> = LazyLock::new(|| {
    let rows = sample_table::<1>("cie_illuminant_c_spd_5nm.csv", ILLUMINANT_C_CSV)
        .unwrap_or_else(|e| panic!("embedded table is damaged: {e}"));
    rows.map(|[s]| s)
});

static CMF10: LazyLock<[[f64; 3]; BANDS]> = LazyLock::new(|| {
    sample_table::<3>("cie1964_10deg_cmf_1nm.csv", CMF10_CSV)
        .unwrap_or_else(|e| panic!("embedded table is damaged: {e}"))
});

/// Every row of a CIE CSV as `(nm, values)`, in file order (same format as [`sample_table`]).
pub fn all_rows<const N: usize>(
    table: &'static str,
    csv: &str,
) -> Result<Vec<(f64, [f64; N])>, CieTableError> {
    let mut out = Vec::new();
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
        out.push((fields[0], std::array::from_fn(|k| fields[k + 1])));
    }
    Ok(out)
}

/// The whole 1 nm table (360–830 nm) of the 2° (`ten_degree = false`) or 10° observer.
pub fn cmf_1nm(ten_degree: bool) -> Vec<[f64; 3]> {
    let (name, csv) = if ten_degree {
        ("cie1964_10deg_cmf_1nm.csv", CMF10_CSV)
    } else {
        ("cie1931_2deg_cmf_1nm.csv", CMF_CSV)
    };
    let rows =
        all_rows::<3>(name, csv).unwrap_or_else(|e| panic!("embedded table is damaged: {e}"));
    // Whole nanometres in order, 360 to 830: checked, since the E308 weights index by nm.
    for (j, (nm, _)) in rows.iter().enumerate() {
        assert_eq!(
            *nm,
            (360 + j) as f64,
            "{name}: rows must be every nm from 360"
        );
    }
    assert_eq!(rows.len(), 471, "{name}: rows must end at 830 nm");
    rows.into_iter().map(|(_, v)| v).collect()
}

/// The D65 table's rows, `(nm, relative power)`, 300–780 nm every 5 nm.
pub fn d65_rows() -> Vec<(f64, f64)> {
    all_rows::<1>("cie_d65_spd_5nm.csv", D65_CSV)
        .unwrap_or_else(|e| panic!("embedded table is damaged: {e}"))
        .into_iter()
        .map(|(nm, [v])| (nm, v))
        .collect()
}

/// CIE illuminant C relative spectral power at each band centre (CIE 15, 105.30 at 560 nm).
pub fn illuminant_c() -> &'static Spectrum {
    &ILLUMINANT_C
}

/// CIE 1964 10° x̄₁₀, ȳ₁₀, z̄₁₀ at each band centre (dimensionless).
pub fn cmf10() -> &'static [[f64; 3]; BANDS] {
    &CMF10
}

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
    fn ten_degree_table_samples_to_the_cie_values() {
        // CIE 15:2018, 1964 10° observer at 400, 560 and 700 nm.
        assert_eq!(cmf10()[0], [0.0191097, 0.0020044, 0.0860109]);
        assert_eq!(cmf10()[16], [0.705224, 0.99734, 0.0]);
        assert_eq!(cmf10()[BANDS - 1], [0.00957688, 0.00371774, 0.0]);
        assert_eq!(cmf_1nm(true).len(), 471);
        assert_eq!(cmf_1nm(false)[200], cmf()[16]);
        assert_eq!(d65_rows().len(), 97);
    }

    #[test]
    fn illuminant_c_samples_to_the_cie_values() {
        // CIE 15:2004 Table T.1, illuminant C at 400, 560 and 700 nm.
        assert_eq!(illuminant_c()[0], 63.30);
        assert_eq!(illuminant_c()[16], 105.30);
        assert_eq!(illuminant_c()[BANDS - 1], 76.30);
        // Its chromaticity with the 2° observer over the whole 5 nm table, 380–780 nm, is the
        // CIE's (x, y) = (0.31006, 0.31616) of illuminant C.
        let rows = all_rows::<1>("c", ILLUMINANT_C_CSV).unwrap();
        let cmf = cmf_1nm(false);
        let mut xyz = [0.0; 3];
        for (nm, [s]) in rows.into_iter().filter(|(nm, _)| *nm >= 360.0) {
            let c = cmf[(nm - 360.0) as usize];
            for (acc, ck) in xyz.iter_mut().zip(c) {
                *acc += s * ck;
            }
        }
        let sum: f64 = xyz.iter().sum();
        assert!((xyz[0] / sum - 0.31006).abs() < 5e-5, "{}", xyz[0] / sum);
        assert!((xyz[1] / sum - 0.31616).abs() < 5e-5, "{}", xyz[1] / sum);
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
