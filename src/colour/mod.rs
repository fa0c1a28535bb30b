//! Colour from spectra (SCIENCE.md §7): reflectance factor → CIE XYZ (D65, 1931 2° observer,
//! CIE 15 summation over the 31 bands) → CIELAB → CIEDE2000, and 8-bit sRGB for swatches.
//!
//! - [`cie`]: the embedded CIE tables sampled at the band centres.
//! - [`ciede2000`](mod@ciede2000): ΔE00, proven against Sharma, Wu & Dalal (2005).
//! - [`srgb`]: XYZ → clipped 8-bit sRGB that says when it clipped.
//! - [`e308`]: ASTM E308 / E2022 weighting factors for the 10 nm grid.
//!
//! [`Colorimetry`] is the `[colour]` choice (SCIENCE.md §7.1): observer 2° (CIE 1931) or 10°
//! (CIE 1964), weighting by plain summation at the band centres (CIE 15, the paper's) or by
//! ASTM E308 weights (what instrument software does). The default is the paper's, 2° with
//! summation, and runs exactly the code the free functions below run, so every result made
//! before the option existed is unchanged bit for bit.
//!
//! Units: reflectance factor is 1 for the perfect white diffuser; BRDF is in sr⁻¹ and becomes a
//! reflectance factor as `R = π · f`; XYZ is scaled so the white diffuser has Y = 100.

pub mod cie;
pub mod ciede2000;
pub mod e308;
pub mod srgb;

use std::sync::LazyLock;

use serde::{Deserialize, Serialize};

use crate::spectral::Spectrum;

pub use ciede2000::ciede2000;
pub use srgb::{Srgb8, xyz_to_srgb8};

/// CIE 1931 tristimulus values, D65, scaled so the white diffuser has Y = 100.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Xyz {
    pub x: f64,
    pub y: f64,
    pub z: f64,
}

/// CIE 1976 L*a*b* (CIELAB).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Lab {
    /// Lightness L*, 0 (black) to 100 (white diffuser); a specular reading may exceed 100.
    pub l: f64,
    /// Red–green opponent a*.
    pub a: f64,
    /// Yellow–blue opponent b*.
    pub b: f64,
}

/// `k = 100 / Σ S(λ) ȳ(λ)` and the per-band weights `S(λ)·x̄ȳz̄(λ)`, computed once.
struct Weights {
    k: f64,
    /// `S(λ) x̄(λ)`, `S(λ) ȳ(λ)`, `S(λ) z̄(λ)` per band.
    per_band: [[f64; 3]; crate::spectral::BANDS],
}

impl Weights {
    /// CIE 15 summation at the band centres with the given observer sampled there.
    fn summation(cmf: &[[f64; 3]; crate::spectral::BANDS]) -> Weights {
        let s = cie::d65();
        let per_band = std::array::from_fn(|i| cmf[i].map(|c| s[i] * c));
        let sum_sy: f64 = per_band.iter().map(|w| w[1]).sum();
        Weights {
            k: 100.0 / sum_sy,
            per_band,
        }
    }

    /// ASTM E308 weights (already normalised to Y(white) = 100, so k = 1).
    fn astm_e308(ten_degree: bool) -> Weights {
        let d65 = e308::d65_1nm(&cie::d65_rows());
        Weights {
            k: 1.0,
            per_band: e308::weights(&cie::cmf_1nm(ten_degree), &d65),
        }
    }

    fn xyz(&self, r: &Spectrum) -> Xyz {
        let mut sum = [0.0; 3];
        for (ri, wi) in r.iter().zip(&self.per_band) {
            for c in 0..3 {
                sum[c] += ri * wi[c];
            }
        }
        Xyz {
            x: self.k * sum[0],
            y: self.k * sum[1],
            z: self.k * sum[2],
        }
    }
}

static WEIGHTS: LazyLock<Weights> = LazyLock::new(|| Weights::summation(cie::cmf()));
static WEIGHTS_10_SUM: LazyLock<Weights> = LazyLock::new(|| Weights::summation(cie::cmf10()));
static WEIGHTS_2_E308: LazyLock<Weights> = LazyLock::new(|| Weights::astm_e308(false));
static WEIGHTS_10_E308: LazyLock<Weights> = LazyLock::new(|| Weights::astm_e308(true));

/// Reflectance factor spectrum → XYZ under D65 for the 2° observer, CIE 15:2018 §7 summation at
/// the 31 band centres (10 nm step, no interpolation): `X = k Σ R S x̄`, `k = 100 / Σ S ȳ`.
pub fn reflectance_to_xyz(r: &Spectrum) -> Xyz {
    WEIGHTS.xyz(r)
}

/// The CIE standard observer colour is computed for (`[colour] observer`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default, Serialize, Deserialize)]
pub enum Observer {
    /// CIE 1931 2° (the paper's).
    #[default]
    #[serde(rename = "2")]
    Cie1931TwoDegree,
    /// CIE 1964 10° supplementary observer, common in instrument software for samples larger
    /// than 4° of the visual field.
    #[serde(rename = "10")]
    Cie1964TenDegree,
}

/// How the 31 bands are weighted into XYZ (`[colour] weighting`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default, Serialize, Deserialize)]
pub enum Weighting {
    /// CIE 15 summation of `R·S·x̄` at the band centres (the paper's).
    #[default]
    #[serde(rename = "summation")]
    Summation,
    /// ASTM E308 weighting factors (ASTM E2022, 10 nm, spectrum extended by its end values).
    #[serde(rename = "astm-e308")]
    AstmE308,
}

impl std::fmt::Display for Observer {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Observer::Cie1931TwoDegree => "2",
            Observer::Cie1964TenDegree => "10",
        })
    }
}

impl std::str::FromStr for Observer {
    type Err = ColorimetryError;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s.trim().trim_end_matches('°') {
            "2" => Ok(Observer::Cie1931TwoDegree),
            "10" => Ok(Observer::Cie1964TenDegree),
            _ => Err(ColorimetryError::Observer(s.to_string())),
        }
    }
}

impl std::fmt::Display for Weighting {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Weighting::Summation => "summation",
            Weighting::AstmE308 => "astm-e308",
        })
    }
}

impl std::str::FromStr for Weighting {
    type Err = ColorimetryError;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s.trim() {
            "summation" => Ok(Weighting::Summation),
            "astm-e308" => Ok(Weighting::AstmE308),
            _ => Err(ColorimetryError::Weighting(s.to_string())),
        }
    }
}

/// A colorimetry option that does not exist.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ColorimetryError {
    #[error("observer {0:?} is not known; use \"2\" (CIE 1931, the default) or \"10\" (CIE 1964)")]
    Observer(String),
    #[error("weighting {0:?} is not known; use \"summation\" (the default) or \"astm-e308\"")]
    Weighting(String),
}

/// How spectra become XYZ and L*a*b*: the observer and the weighting, always D65. Recorded with
/// every evaluation; the default is the paper's (2°, summation).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Colorimetry {
    #[serde(default)]
    pub observer: Observer,
    #[serde(default)]
    pub weighting: Weighting,
}

impl std::fmt::Display for Colorimetry {
    /// e.g. `D65/2° summation`, `D65/10° astm-e308`.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "D65/{}° {}", self.observer, self.weighting)
    }
}

impl Colorimetry {
    fn weights(&self) -> &'static Weights {
        match (self.observer, self.weighting) {
            (Observer::Cie1931TwoDegree, Weighting::Summation) => &WEIGHTS,
            (Observer::Cie1964TenDegree, Weighting::Summation) => &WEIGHTS_10_SUM,
            (Observer::Cie1931TwoDegree, Weighting::AstmE308) => &WEIGHTS_2_E308,
            (Observer::Cie1964TenDegree, Weighting::AstmE308) => &WEIGHTS_10_E308,
        }
    }

    /// Reflectance factor → XYZ (Y of the white diffuser = 100).
    pub fn reflectance_to_xyz(&self, r: &Spectrum) -> Xyz {
        self.weights().xyz(r)
    }

    /// XYZ of reflectance 1 in every band: the CIELAB reference white.
    pub fn white_point(&self) -> Xyz {
        self.reflectance_to_xyz(&crate::spectral::flat(1.0))
    }

    /// Reflectance factor → CIELAB relative to [`Colorimetry::white_point`].
    pub fn reflectance_to_lab(&self, r: &Spectrum) -> Lab {
        if *self == Colorimetry::default() {
            return reflectance_to_lab(r);
        }
        xyz_to_lab(self.reflectance_to_xyz(r), self.white_point())
    }
}

/// The white point: XYZ of reflectance 1 in every band. Over 400–700 nm every 10 nm it is
/// (94.9401, 100, 108.7091), not the 1 nm 360–830 nm white (95.047, 100, 108.883).
pub fn white_point() -> Xyz {
    reflectance_to_xyz(&crate::spectral::flat(1.0))
}

/// CIE 15:2018 §8.2.1 `f(t)`: a cube root above (6/29)³, a straight line below.
fn lab_f(t: f64) -> f64 {
    const DELTA: f64 = 6.0 / 29.0;
    if t > DELTA * DELTA * DELTA {
        t.cbrt()
    } else {
        t / (3.0 * DELTA * DELTA) + 4.0 / 29.0
    }
}

/// XYZ → CIELAB relative to `white` (CIE 15:2018 §8.2.1). Values above the white (specular
/// readings) are allowed and give L* > 100.
pub fn xyz_to_lab(xyz: Xyz, white: Xyz) -> Lab {
    let (fx, fy, fz) = (
        lab_f(xyz.x / white.x),
        lab_f(xyz.y / white.y),
        lab_f(xyz.z / white.z),
    );
    Lab {
        l: 116.0 * fy - 16.0,
        a: 500.0 * (fx - fy),
        b: 200.0 * (fy - fz),
    }
}

/// Reflectance factor spectrum → CIELAB, D65 / 2°, relative to [`white_point`].
pub fn reflectance_to_lab(r: &Spectrum) -> Lab {
    // The white point is a fixed function of the tables; compute it once.
    static WHITE: LazyLock<Xyz> = LazyLock::new(white_point);
    xyz_to_lab(reflectance_to_xyz(r), *WHITE)
}

/// BRDF (sr⁻¹) → reflectance factor, `R = π · f`: a Lambertian surface of albedo ρ has
/// f = ρ/π, and the white diffuser (ρ = 1) has R = 1.
pub fn brdf_to_reflectance(f: &Spectrum) -> Spectrum {
    f.map(|v| std::f64::consts::PI * v)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::spectral::{BANDS, flat};

    /// colour-science 0.4.7's XYZ of the 24 ColorChecker spectra, `(patch, observer, e308, sum)`.
    fn colour_science_reference() -> Vec<(String, Observer, [f64; 3], [f64; 3])> {
        const CSV: &str = include_str!("data/colorchecker_xyz_d65_astm_e308_colour_science.csv");
        CSV.lines()
            .filter(|l| !l.starts_with('#') && !l.starts_with("patch"))
            .map(|l| {
                let (name, rest) = l[1..].split_once("\",").unwrap();
                let f: Vec<f64> = rest.split(',').map(|v| v.parse().unwrap()).collect();
                let observer = if f[0] == 2.0 {
                    Observer::Cie1931TwoDegree
                } else {
                    Observer::Cie1964TenDegree
                };
                (
                    name.to_string(),
                    observer,
                    [f[1], f[2], f[3]],
                    [f[4], f[5], f[6]],
                )
            })
            .collect()
    }

    fn check_against_colour_science(weighting: Weighting, tol: f64) {
        let reference = colour_science_reference();
        assert_eq!(reference.len(), 48);
        for (name, observer, e308, sum) in reference {
            let r = crate::synth::colorchecker_patch(&name)
                .unwrap_or_else(|| panic!("no ColorChecker patch {name:?}"));
            let c = Colorimetry {
                observer,
                weighting,
            };
            let xyz = c.reflectance_to_xyz(&r);
            let want = match weighting {
                Weighting::AstmE308 => e308,
                Weighting::Summation => sum,
            };
            for (got, want) in [xyz.x, xyz.y, xyz.z].into_iter().zip(want) {
                assert!(
                    (got - want).abs() < tol,
                    "{name} {c}: {got} vs colour-science {want} ({xyz:?})"
                );
            }
        }
    }

    #[test]
    fn astm_e308_matches_colour_science_for_the_colorchecker_to_1e4() {
        check_against_colour_science(Weighting::AstmE308, 1e-4);
    }

    #[test]
    fn summation_matches_colour_science_for_the_colorchecker_to_1e4() {
        check_against_colour_science(Weighting::Summation, 1e-4);
    }

    #[test]
    fn the_default_colorimetry_is_the_papers_bit_for_bit() {
        let c = Colorimetry::default();
        assert_eq!(c.to_string(), "D65/2° summation");
        for (_, r) in crate::synth::colorchecker() {
            assert_eq!(c.reflectance_to_lab(r), reflectance_to_lab(r));
            assert_eq!(c.reflectance_to_xyz(r), reflectance_to_xyz(r));
        }
    }

    #[test]
    fn every_colorimetry_has_white_at_y_100_and_neutral_grey() {
        for observer in [Observer::Cie1931TwoDegree, Observer::Cie1964TenDegree] {
            for weighting in [Weighting::Summation, Weighting::AstmE308] {
                let c = Colorimetry {
                    observer,
                    weighting,
                };
                assert!((c.white_point().y - 100.0).abs() < 1e-9, "{c}");
                let lab = c.reflectance_to_lab(&flat(0.5));
                assert!((lab.l - 76.0693).abs() < 1e-4, "{c}: {lab:?}");
                assert!(lab.a.abs() < 1e-9 && lab.b.abs() < 1e-9, "{c}: {lab:?}");
            }
        }
    }

    #[test]
    fn colorimetry_parses_and_names_its_options() {
        let c: Colorimetry =
            serde_json::from_str(r#"{"observer":"10","weighting":"astm-e308"}"#).unwrap();
        assert_eq!(c.observer, Observer::Cie1964TenDegree);
        assert_eq!(c.weighting, Weighting::AstmE308);
        assert_eq!(c.to_string(), "D65/10° astm-e308");
        assert_eq!(
            "10".parse::<Observer>().unwrap(),
            Observer::Cie1964TenDegree
        );
        let e = "5".parse::<Observer>().unwrap_err().to_string();
        assert!(e.contains("\"5\"") && e.contains("\"10\""), "{e}");
        let e = "astm".parse::<Weighting>().unwrap_err().to_string();
        assert!(e.contains("astm-e308"), "{e}");
        assert_eq!(
            serde_json::from_str::<Colorimetry>("{}").unwrap(),
            Colorimetry::default()
        );
    }

    #[test]
    fn white_point_matches_science_md() {
        let w = white_point();
        assert!((w.x - 94.9401).abs() < 1e-4, "X = {}", w.x);
        assert!((w.y - 100.0).abs() < 1e-12, "Y = {}", w.y);
        assert!((w.z - 108.7091).abs() < 1e-4, "Z = {}", w.z);
    }

    #[test]
    fn flat_half_reflectance_is_neutral_l_76_0693() {
        let lab = reflectance_to_lab(&flat(0.5));
        assert!((lab.l - 76.0693).abs() < 1e-4, "L* = {}", lab.l);
        assert!(lab.a.abs() < 1e-4, "a* = {}", lab.a);
        assert!(lab.b.abs() < 1e-4, "b* = {}", lab.b);
    }

    #[test]
    fn white_is_l100_and_black_is_l0() {
        let white = reflectance_to_lab(&flat(1.0));
        assert!((white.l - 100.0).abs() < 1e-12);
        let black = reflectance_to_lab(&flat(0.0));
        assert_eq!(
            black,
            Lab {
                l: 0.0,
                a: 0.0,
                b: 0.0
            }
        );
    }

    #[test]
    fn dark_colours_use_the_linear_segment() {
        // Y/Yn = 0.001 < (6/29)³ ≈ 0.008856: L* = 116·(0.001·841/108 + 4/29) − 16 = 903.296·0.001.
        let lab = reflectance_to_lab(&flat(0.001));
        assert!((lab.l - 0.903_296).abs() < 1e-6, "L* = {}", lab.l);
        // The two segments meet at (6/29)³, where L* = 8.
        let t = (6.0f64 / 29.0).powi(3);
        let below = xyz_to_lab(
            Xyz { x: t, y: t, z: t },
            Xyz {
                x: 1.0,
                y: 1.0,
                z: 1.0,
            },
        );
        assert!((below.l - 8.0).abs() < 1e-12);
        let above = xyz_to_lab(
            Xyz {
                x: t * 1.000_001,
                y: t * 1.000_001,
                z: t * 1.000_001,
            },
            Xyz {
                x: 1.0,
                y: 1.0,
                z: 1.0,
            },
        );
        assert!((above.l - 8.0).abs() < 1e-4);
    }

    #[test]
    fn a_single_band_reflector_is_weighted_by_d65_times_the_cmf() {
        // Reflectance 1 only at 560 nm: X : Y : Z = x̄ : ȳ : z̄ there (0.5945 : 0.995 : 0.0039).
        let mut r = [0.0; BANDS];
        r[16] = 1.0;
        let xyz = reflectance_to_xyz(&r);
        assert!((xyz.x / xyz.y - 0.5945 / 0.995).abs() < 1e-12);
        assert!((xyz.z / xyz.y - 0.0039 / 0.995).abs() < 1e-12);
        // The summation is linear: the 31 single-band reflectors add up to the white.
        let mut total = [0.0; 3];
        for band in 0..BANDS {
            let mut r = [0.0; BANDS];
            r[band] = 1.0;
            let xyz = reflectance_to_xyz(&r);
            total[0] += xyz.x;
            total[1] += xyz.y;
            total[2] += xyz.z;
        }
        let w = white_point();
        assert!((total[0] - w.x).abs() < 1e-9 && (total[1] - w.y).abs() < 1e-9);
        assert!((total[2] - w.z).abs() < 1e-9);
    }

    #[test]
    fn brdf_of_the_white_diffuser_is_reflectance_one() {
        let r = brdf_to_reflectance(&flat(1.0 / std::f64::consts::PI));
        assert!(r.iter().all(|v| (v - 1.0).abs() < 1e-15));
    }

    #[test]
    fn lab_serialises_with_short_field_names() {
        let json = serde_json::to_string(&Lab {
            l: 50.0,
            a: 1.0,
            b: -2.0,
        })
        .unwrap();
        assert_eq!(json, r#"{"l":50.0,"a":1.0,"b":-2.0}"#);
    }
}
