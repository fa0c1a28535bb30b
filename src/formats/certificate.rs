//! The reference tile's calibration certificate: its reflectance factor on brdfd's 31-band grid,
//! read from a CGATS.17 or CxF3 file (SCIENCE.md §3, `[reference] reflectance` in `brdfd.toml`).
//!
//! Decisions:
//! - One tile, one spectrum. A CGATS certificate has exactly one data row with the columns
//!   `SPECTRAL_NM400` … `SPECTRAL_NM700` (or the aliases [`super::table`] accepts; bands outside
//!   400–700 nm are ignored); a CxF3 certificate's first `ReflectanceSpectrum` is the tile's
//!   (its `StartWL`, else its `ColorSpecification`'s `WavelengthRange`, at an increment that
//!   divides 10 nm: a 5 nm certificate is read at every second value, never interpolated).
//! - Values are reflectance factors on the 0–1 scale, as brdfd writes them and as CxF3 defines
//!   `ReflectanceSpectrum`. A certificate in percent (values above 1.5, which no grey tile
//!   reaches) is refused with a message saying so rather than guessed at.
//! - Every value must be positive and finite: processing divides by none of them but multiplies
//!   every reading by them, so a zero would silently black out a band.

use std::collections::HashMap;

use super::{FormatError, cgats, parse_number};
use crate::spectral::{BANDS, FIRST_NM, STEP_NM, Spectrum, wavelengths_nm};

/// A reflectance factor above this is taken to be a percentage (a certificate in %).
const PERCENT_SUSPECT: f64 = 1.5;

/// Reads the tile's reflectance factor from a certificate's text; `file` names it in errors.
/// CxF3 when the text is XML (starts with `<` after white space), else CGATS.
pub fn read(file: &str, text: &str) -> Result<Spectrum, FormatError> {
    let spectrum = if text.trim_start().starts_with('<') {
        from_cxf3(file, text)?
    } else {
        from_cgats(file, text)?
    };
    check(file, &spectrum)?;
    Ok(spectrum)
}

/// Checks a calibration spectrum from any source (a file, or values in `brdfd.toml`).
pub fn check(origin: &str, rho: &Spectrum) -> Result<(), FormatError> {
    let nm = wavelengths_nm();
    for (i, &v) in rho.iter().enumerate() {
        if !(v.is_finite() && v > 0.0) {
            return Err(FormatError::Missing {
                file: origin.to_string(),
                message: format!(
                    "reflectance at {} nm is {v}; a tile's reflectance factor is positive (0–1 scale)",
                    nm[i]
                ),
            });
        }
        if v > PERCENT_SUSPECT {
            return Err(FormatError::Missing {
                file: origin.to_string(),
                message: format!(
                    "reflectance at {} nm is {v}; brdfd reads reflectance factors on the 0–1 scale \
                     (a certificate in percent must be divided by 100)",
                    nm[i]
                ),
            });
        }
    }
    Ok(())
}

fn from_cgats(file: &str, text: &str) -> Result<Spectrum, FormatError> {
    let table = cgats::parse(file, text)?;
    let bands = table.bands()?;
    let (line, values) = match table.rows.as_slice() {
        [one] => one,
        [] => {
            return Err(FormatError::Missing {
                file: file.into(),
                message: "no data row; a tile certificate has one row with the tile's spectrum"
                    .into(),
            });
        }
        more => {
            return Err(FormatError::invalid(
                file,
                more[1].0,
                "BEGIN_DATA",
                format!(
                    "{} data rows; a tile certificate has exactly one (the tile's spectrum)",
                    more.len()
                ),
            ));
        }
    };
    let mut out = [0.0; BANDS];
    for (b, (slot, &col)) in out.iter_mut().zip(&bands).enumerate() {
        let text = values.get(col).map(String::as_str).unwrap_or("");
        *slot = parse_number(
            file,
            *line,
            &format!("SPECTRAL_NM{}", wavelengths_nm()[b]),
            text,
        )?;
    }
    Ok(out)
}

fn from_cxf3(file: &str, text: &str) -> Result<Spectrum, FormatError> {
    let doc = roxmltree::Document::parse(text)
        .map_err(|e| FormatError::invalid(file, e.pos().row as usize, "xml", e.to_string()))?;
    let line = |n: &roxmltree::Node| doc.text_pos_at(n.range().start).row as usize;
    let is = |n: &roxmltree::Node, name: &str| n.is_element() && n.tag_name().name() == name;
    // (StartWL, Increment) of each ColorSpecification's WavelengthRange.
    let mut ranges: HashMap<&str, (Option<&str>, Option<&str>)> = HashMap::new();
    for cs in doc.descendants().filter(|n| is(n, "ColorSpecification")) {
        if let (Some(id), Some(r)) = (
            cs.attribute("Id"),
            cs.descendants().find(|n| is(n, "WavelengthRange")),
        ) {
            ranges.insert(id, (r.attribute("StartWL"), r.attribute("Increment")));
        }
    }
    let sp = doc
        .descendants()
        .find(|n| is(n, "ReflectanceSpectrum"))
        .ok_or_else(|| FormatError::Missing {
            file: file.into(),
            message: "no ReflectanceSpectrum element; a CxF3 tile certificate holds the tile's \
                      reflectance as one"
                .into(),
        })?;
    let at = line(&sp);
    let range = sp
        .attribute("ColorSpecification")
        .and_then(|id| ranges.get(id))
        .copied()
        .unwrap_or((None, None));
    let start = match sp.attribute("StartWL").or(range.0) {
        Some(v) => parse_number(file, at, "StartWL", v)?,
        None => f64::from(FIRST_NM),
    };
    let step = match range.1 {
        Some(v) => parse_number(file, at, "WavelengthRange/@Increment", v)?,
        None => f64::from(STEP_NM),
    };
    let every = f64::from(STEP_NM) / step;
    let offset = (f64::from(FIRST_NM) - start) / step;
    if !(step > 0.0 && every.fract() == 0.0 && offset >= 0.0 && offset.fract() == 0.0) {
        return Err(FormatError::invalid(
            file,
            at,
            "ReflectanceSpectrum",
            format!(
                "starts at {start} nm every {step} nm; brdfd needs values at 400, 410, … 700 nm \
                 (a start at or below 400 nm on a 1, 2, 5 or 10 nm grid)"
            ),
        ));
    }
    let list: Vec<&str> = sp.text().unwrap_or("").split_whitespace().collect();
    let (offset, every) = (offset as usize, every as usize);
    let mut out = [0.0; BANDS];
    for (b, slot) in out.iter_mut().enumerate() {
        let i = offset + b * every;
        let nm = wavelengths_nm()[b];
        let Some(v) = list.get(i) else {
            return Err(FormatError::invalid(
                file,
                at,
                "ReflectanceSpectrum",
                format!(
                    "{} values from {start} nm every {step} nm end before {nm} nm; brdfd needs 400–700 nm",
                    list.len()
                ),
            ));
        };
        *slot = parse_number(file, at, &format!("ReflectanceSpectrum at {nm} nm"), v)?;
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cgats_text(rows: &[Vec<f64>]) -> String {
        let mut t = String::from("CGATS.17\nORIGINATOR \"lab\"\nNUMBER_OF_FIELDS 32\n");
        t.push_str("BEGIN_DATA_FORMAT\nSAMPLE_ID");
        for nm in wavelengths_nm() {
            t.push_str(&format!(" SPECTRAL_NM{nm}"));
        }
        t.push_str(&format!(
            "\nEND_DATA_FORMAT\nNUMBER_OF_SETS {}\nBEGIN_DATA\n",
            rows.len()
        ));
        for (i, r) in rows.iter().enumerate() {
            t.push_str(&format!("{}", i + 1));
            for v in r {
                t.push_str(&format!(" {v}"));
            }
            t.push('\n');
        }
        t.push_str("END_DATA\n");
        t
    }

    #[test]
    fn reads_one_cgats_row() {
        let row: Vec<f64> = (0..BANDS).map(|i| 0.7 + 0.002 * i as f64).collect();
        let rho = read("n9.cgats", &cgats_text(&[row.clone()])).unwrap();
        assert_eq!(rho.to_vec(), row);
    }

    #[test]
    fn refuses_two_rows_percent_and_zero() {
        let row = vec![0.77; BANDS];
        let e = read("n9.cgats", &cgats_text(&[row.clone(), row]))
            .unwrap_err()
            .to_string();
        assert!(e.contains("2 data rows"), "{e}");
        let e = read("n9.cgats", &cgats_text(&[vec![77.0; BANDS]]))
            .unwrap_err()
            .to_string();
        assert!(e.contains("divided by 100"), "{e}");
        let mut row = vec![0.77; BANDS];
        row[30] = 0.0;
        let e = read("n9.cgats", &cgats_text(&[row]))
            .unwrap_err()
            .to_string();
        assert!(e.contains("700 nm is 0"), "{e}");
    }

    #[test]
    fn reads_a_cxf3_spectrum_on_a_5_nm_grid_from_380() {
        // 380–730 nm every 5 nm: 71 values, value = wavelength / 1000.
        let values: Vec<String> = (0..71)
            .map(|i| format!("{}", (380 + 5 * i) as f64 / 1000.0))
            .collect();
        let xml = format!(
            r#"<?xml version="1.0"?>
<cc:CxF xmlns:cc="http://colorexchangeformat.com/CxF3-core">
 <cc:Resources>
  <cc:ObjectCollection><cc:Object ObjectType="Standard" Name="N9" Id="o1"><cc:ColorValues>
   <cc:ReflectanceSpectrum ColorSpecification="cs1">{}</cc:ReflectanceSpectrum>
  </cc:ColorValues></cc:Object></cc:ObjectCollection>
  <cc:ColorSpecificationCollection><cc:ColorSpecification Id="cs1"><cc:MeasurementSpec>
   <cc:WavelengthRange StartWL="380" Increment="5"/>
  </cc:MeasurementSpec></cc:ColorSpecification></cc:ColorSpecificationCollection>
 </cc:Resources>
</cc:CxF>"#,
            values.join(" ")
        );
        let rho = read("n9.cxf", &xml).unwrap();
        for (b, nm) in wavelengths_nm().iter().enumerate() {
            assert_eq!(rho[b], f64::from(*nm) / 1000.0);
        }
        let short = xml.replace("StartWL=\"380\"", "StartWL=\"450\"");
        let e = read("n9.cxf", &short).unwrap_err().to_string();
        assert!(e.contains("at or below 400 nm"), "{e}");
    }
}
