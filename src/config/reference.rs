//! `[reference]`: the reference tile's calibrated reflectance: one value, 31 values or its
//! certificate file.

use std::path::Path;

use serde::Deserialize;

use super::check::{Checker, ConfigError, S};

/// `[reference]`
#[derive(Debug, Clone, PartialEq, Default)]
pub struct ReferenceConfig {
    /// The reference tile's calibrated reflectance factor (SCIENCE.md §3), recorded with every
    /// reference set measured while it is configured; `None`: ρ_ref = 1, results relative to the
    /// tile (the paper's choice).
    pub reflectance: Option<crate::spectral::Spectrum>,
    /// Where it came from, for logs: "one value", "31 values" or the certificate's path.
    pub source: Option<String>,
}

/// `[reference] reflectance`: one value for a flat tile, 31 values (400–700 nm every 10 nm), or
/// a certificate file (CGATS or CxF3, [`crate::formats::certificate`]) whose relative path is
/// relative to the configuration file's directory. Returns the spectrum and where it came from.
fn reference_reflectance(
    v: &toml::Value,
    origin: &str,
    base: Option<&Path>,
) -> Result<(crate::spectral::Spectrum, String), String> {
    use crate::spectral::BANDS;
    let number = |v: &toml::Value| match v {
        toml::Value::Float(f) => Some(*f),
        toml::Value::Integer(i) => Some(*i as f64),
        _ => None,
    };
    let (rho, source) = match v {
        toml::Value::String(path) if path.trim().is_empty() => {
            return Err("must not be empty; leave the key out for ρ_ref = 1".into());
        }
        toml::Value::String(path) => {
            let dir = base.unwrap_or(Path::new(origin).parent().unwrap_or(Path::new("")));
            let full = dir.join(path);
            let text = crate::formats::read_text(&full).map_err(|e| e.to_string())?;
            let rho = crate::formats::certificate::read(&full.display().to_string(), &text)
                .map_err(|e| format!("the tile certificate: {e}"))?;
            (rho, full.display().to_string())
        }
        toml::Value::Array(items) => {
            if items.len() != BANDS {
                return Err(format!(
                    "{} values; give one value or 31 (400, 410, … 700 nm)",
                    items.len()
                ));
            }
            let mut rho = [0.0; BANDS];
            for (i, (slot, item)) in rho.iter_mut().zip(items).enumerate() {
                *slot = number(item).ok_or_else(|| {
                    format!("value {} ({} nm) is not a number", i + 1, 400 + 10 * i)
                })?;
            }
            (rho, "31 values".into())
        }
        other => match number(other) {
            Some(x) => ([x; BANDS], "one value".into()),
            None => {
                return Err(
                    "must be a number (a flat tile), an array of 31 numbers (400–700 nm every \
                     10 nm) or the path of the tile's certificate (CGATS or CxF3)"
                        .into(),
                );
            }
        },
    };
    crate::formats::certificate::check("the calibration", &rho).map_err(|e| e.to_string())?;
    Ok((rho, source))
}

// ---- Stage 1: the section's shape ----------------------------------------------------------

#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawReference {
    /// A number, an array of 31 numbers, or a certificate file's path.
    reflectance: S<toml::Value>,
}

// ---- Stage 2: its checks ------------------------------------------------------------------

impl Checker<'_> {
    /// `[reference]`
    pub(super) fn reference(&self, raw: &RawReference) -> Result<ReferenceConfig, ConfigError> {
        Ok(match &raw.reflectance {
            None => ReferenceConfig::default(),
            Some(v) => {
                let (rho, source) = reference_reflectance(v.get_ref(), self.origin, self.base)
                    .map_err(|m| self.invalid("reference.reflectance", v, m))?;
                ReferenceConfig {
                    reflectance: Some(rho),
                    source: Some(source),
                }
            }
        })
    }
}

#[cfg(test)]
mod tests {
    use crate::config::tests::parse;
    use crate::config::*;

    #[test]
    fn reference_reflectance_is_one_value_31_values_or_a_certificate() {
        assert_eq!(Config::default().reference.reflectance, None);
        let c = parse("[reference]\nreflectance = 0.77\n").unwrap();
        assert_eq!(c.reference.reflectance, Some([0.77; 31]));
        let values: Vec<String> = (0..31).map(|i| format!("0.{}", 40 + i)).collect();
        let c = parse(&format!(
            "[reference]\nreflectance = [{}]\n",
            values.join(", ")
        ))
        .unwrap();
        assert_eq!(c.reference.reflectance.unwrap()[30], 0.7);
        let e = parse("[reference]\nreflectance = [0.7, 0.8]\n")
            .unwrap_err()
            .to_string();
        assert_eq!(
            e,
            "test.toml:2: reference.reflectance: 2 values; give one value or 31 (400, 410, … 700 nm)"
        );
        let e = parse("[reference]\nreflectance = 77\n")
            .unwrap_err()
            .to_string();
        assert!(e.contains("divided by 100"), "{e}");
        let e = parse("[reference]\nreflectance = 0\n")
            .unwrap_err()
            .to_string();
        assert!(e.contains("400 nm is 0"), "{e}");

        // A certificate next to the configuration file.
        let dir = tempfile::tempdir().unwrap();
        let mut cert = String::from("CGATS.17\nBEGIN_DATA_FORMAT\nSAMPLE_ID");
        for nm in crate::spectral::wavelengths_nm() {
            cert.push_str(&format!(" SPECTRAL_NM{nm}"));
        }
        cert.push_str("\nEND_DATA_FORMAT\nBEGIN_DATA\n1");
        for _ in 0..31 {
            cert.push_str(" 0.765");
        }
        cert.push_str("\nEND_DATA\n");
        std::fs::write(dir.path().join("n9.cgats"), cert).unwrap();
        let toml_path = dir.path().join("brdfd.toml");
        std::fs::write(
            &toml_path,
            "[reference]\nreflectance = \"n9.cgats\"\n[devices.ma_t12]\ntransport = \"usb\"\n\
             [devices.sra]\ntransport = \"serial\"\n",
        )
        .unwrap();
        let c = Config::load(&toml_path).unwrap();
        assert_eq!(c.reference.reflectance, Some([0.765; 31]));
        let e = parse("[reference]\nreflectance = \"missing.cgats\"\n")
            .unwrap_err()
            .to_string();
        assert!(
            e.starts_with("test.toml:2: reference.reflectance: cannot read missing.cgats"),
            "{e}"
        );
    }
}
