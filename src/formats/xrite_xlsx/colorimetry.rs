//! The check of an export's own L*a*b* against brdfd's colorimetry: [`check_colorimetry`]
//! recomputes each geometry's colour from the spectra the reader kept and flags the ones that
//! differ from the file's.

use super::{XlsxError, XriteMeasurement};
use crate::colour::{Colorimetry, Lab, Observer, Weighting, ciede2000};
use crate::geometry::{MA_T12_COUNT, ma_t12};

/// ΔE00 between X-Rite's L*a*b* and brdfd's above which a geometry is flagged by
/// [`check_colorimetry`]: the two agree to about 1e-5 on real files (ASTM E308 weighting), so a
/// larger difference means a wrong column or an edited file.
pub const COLORIMETRY_THRESHOLD: f64 = 0.01;

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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::formats::xrite_xlsx::tests::{
        COLOR, REGULAR, edited, path, read, read_file, set_cell,
    };

    use crate::formats::xrite_xlsx::REAL_EXPORTS;

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
}
