//! Colour from spectra (SCIENCE.md §7): reflectance factor → CIE XYZ (D65, 1931 2° observer,
//! CIE 15 summation over the 31 bands) → CIELAB → CIEDE2000, and 8-bit sRGB for swatches.
//!
//! - [`cie`]: the embedded CIE tables sampled at the band centres.
//! - [`ciede2000`](mod@ciede2000): ΔE00, proven against Sharma, Wu & Dalal (2005).
//! - [`srgb`]: XYZ → clipped 8-bit sRGB that says when it clipped.
//!
//! Units: reflectance factor is 1 for the perfect white diffuser; BRDF is in sr⁻¹ and becomes a
//! reflectance factor as `R = π · f`; XYZ is scaled so the white diffuser has Y = 100.

pub mod cie;
pub mod ciede2000;
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

static WEIGHTS: LazyLock<Weights> = LazyLock::new(|| {
    let cmf = cie::cmf();
    let s = cie::d65();
    let per_band = std::array::from_fn(|i| cmf[i].map(|c| s[i] * c));
    let sum_sy: f64 = per_band.iter().map(|w| w[1]).sum();
    Weights {
        k: 100.0 / sum_sy,
        per_band,
    }
});

/// Reflectance factor spectrum → XYZ under D65 for the 2° observer, CIE 15:2018 §7 summation at
/// the 31 band centres (10 nm step, no interpolation): `X = k Σ R S x̄`, `k = 100 / Σ S ȳ`.
pub fn reflectance_to_xyz(r: &Spectrum) -> Xyz {
    let w = &*WEIGHTS;
    let mut sum = [0.0; 3];
    for (ri, wi) in r.iter().zip(&w.per_band) {
        for c in 0..3 {
            sum[c] += ri * wi[c];
        }
    }
    Xyz {
        x: w.k * sum[0],
        y: w.k * sum[1],
        z: w.k * sum[2],
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
