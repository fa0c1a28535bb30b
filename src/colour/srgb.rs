//! 8-bit sRGB for swatches in reports (SCIENCE.md §7), per IEC 61966-2-1:1999:
//! XYZ/100 → linear sRGB by the standard's matrix → the sRGB transfer curve → 8 bits, clipped.
//!
//! Specular readings are often brighter than a perfect white diffuser, so clipping is expected;
//! [`Srgb8::clipped`] says when it changed the picture so a report can mark the swatch.

use serde::{Deserialize, Serialize};

use super::Xyz;

/// XYZ (Y = 1 for white) → linear sRGB, IEC 61966-2-1:1999 §5.2, the standard's 4-decimal matrix.
const XYZ_TO_LINEAR_SRGB: [[f64; 3]; 3] = [
    [3.2406, -1.5372, -0.4986],
    [-0.9689, 1.8758, 0.0415],
    [0.0557, -0.2040, 1.0570],
];

/// An 8-bit sRGB swatch colour.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct Srgb8 {
    /// R, G, B code values, 0–255.
    pub rgb: [u8; 3],
    /// True when some channel lay outside the sRGB gamut before clipping: above white (a
    /// reading brighter than the white diffuser, typical at specular geometries) or below zero
    /// (a colour more saturated than the sRGB primaries). The swatch then shows the nearest
    /// displayable colour, not the measured one.
    pub clipped: bool,
}

impl Srgb8 {
    /// `#rrggbb`, for SVG and HTML reports.
    pub fn hex(&self) -> String {
        let [r, g, b] = self.rgb;
        format!("#{r:02x}{g:02x}{b:02x}")
    }
}

/// The sRGB transfer curve (IEC 61966-2-1 §5.2), linear → non-linear, for `c` in [0, 1].
fn encode(c: f64) -> f64 {
    if c <= 0.003_130_8 {
        12.92 * c
    } else {
        1.055 * c.powf(1.0 / 2.4) - 0.055
    }
}

/// Linear value → 8-bit code before clamping (may be outside 0..=255).
fn code_unclamped(linear: f64) -> f64 {
    // Extend the curve past [0, 1] symmetrically so an out-of-gamut value maps to a code
    // outside 0..=255 rather than to NaN (powf of a negative number).
    let encoded = encode(linear.abs()).copysign(linear);
    (encoded * 255.0).round()
}

/// CIE XYZ (Y = 100 for the white diffuser) → sRGB values before clipping and quantisation
/// (the transfer curve extended past [0, 1] as in [`xyz_to_srgb8`]; 1 is code 255). The
/// sphere previews use it so that their pixels follow the swatches' colour path exactly.
pub fn xyz_to_srgb_unclipped(xyz: Xyz) -> [f64; 3] {
    let v = [xyz.x / 100.0, xyz.y / 100.0, xyz.z / 100.0];
    XYZ_TO_LINEAR_SRGB.map(|row| {
        let linear = row[0] * v[0] + row[1] * v[1] + row[2] * v[2];
        encode(linear.abs()).copysign(linear)
    })
}

/// CIE XYZ (Y = 100 for the white diffuser) → clipped 8-bit sRGB.
///
/// `clipped` is set when clipping changes an 8-bit code, i.e. a channel rounds to a code outside
/// 0..=255. Judging at the 8-bit code rather than at exactly [0, 1] is deliberate: brdfd's white
/// (D65 summed over 31 bands, SCIENCE.md §7) is not bit-for-bit sRGB's D65, and maps to a
/// linear green of 1.001, which is white on any display and must not be flagged "above white".
pub fn xyz_to_srgb8(xyz: Xyz) -> Srgb8 {
    let v = [xyz.x / 100.0, xyz.y / 100.0, xyz.z / 100.0];
    let mut rgb = [0u8; 3];
    let mut clipped = false;
    for (out, row) in rgb.iter_mut().zip(XYZ_TO_LINEAR_SRGB) {
        let linear = row[0] * v[0] + row[1] * v[1] + row[2] * v[2];
        let code = code_unclamped(linear);
        // NaN (from a NaN input) is not in range either: show black and flag it.
        clipped |= !(0.0..=255.0).contains(&code);
        *out = if code.is_nan() {
            0
        } else {
            code.clamp(0.0, 255.0) as u8
        };
    }
    Srgb8 { rgb, clipped }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::colour::{reflectance_to_xyz, white_point};
    use crate::spectral::flat;

    #[test]
    fn white_is_255_and_not_clipped() {
        let s = xyz_to_srgb8(white_point());
        assert_eq!(s.rgb, [255, 255, 255]);
        assert!(!s.clipped);
        assert_eq!(s.hex(), "#ffffff");
    }

    #[test]
    fn black_is_0() {
        let s = xyz_to_srgb8(reflectance_to_xyz(&flat(0.0)));
        assert_eq!(
            s,
            Srgb8 {
                rgb: [0, 0, 0],
                clipped: false
            }
        );
    }

    #[test]
    fn above_white_clips_and_says_so() {
        let s = xyz_to_srgb8(reflectance_to_xyz(&flat(1.5)));
        assert_eq!(s.rgb, [255, 255, 255]);
        assert!(s.clipped);
    }

    #[test]
    fn srgb_primaries_round_trip() {
        // The XYZ of the sRGB primaries at full intensity (IEC 61966-2-1 inverse matrix columns),
        // red, green, blue.
        for ([x, y, z], rgb) in [
            ([41.24, 21.26, 1.93], [255, 0, 0]),
            ([35.76, 71.52, 11.92], [0, 255, 0]),
            ([18.05, 7.22, 95.05], [0, 0, 255]),
        ] {
            assert_eq!(
                xyz_to_srgb8(Xyz { x, y, z }),
                Srgb8 {
                    rgb,
                    clipped: false
                }
            );
        }
    }

    #[test]
    fn mid_grey_follows_the_transfer_curve() {
        // Y = 20 (linear 0.2) → 1.055·0.2^(1/2.4) − 0.055 = 0.48453 → code 124 on every channel,
        // using sRGB's own D65 chromaticity so the three channels are equal.
        let s = xyz_to_srgb8(Xyz {
            x: 0.2 * 95.05,
            y: 20.0,
            z: 0.2 * 108.90,
        });
        assert_eq!(s.rgb, [124, 124, 124]);
        assert!(!s.clipped);
        // The linear segment: linear 0.002 → 12.92·0.002·255 = 6.59 → 7.
        let s = xyz_to_srgb8(Xyz {
            x: 0.002 * 95.05,
            y: 0.2,
            z: 0.002 * 108.90,
        });
        assert_eq!(s.rgb, [7, 7, 7]);
    }

    #[test]
    fn out_of_gamut_saturation_clips() {
        // Spectral-locus green near 520 nm lies outside the sRGB triangle: red goes negative.
        let s = xyz_to_srgb8(Xyz {
            x: 7.4,
            y: 83.4,
            z: 7.8,
        });
        assert_eq!(s.rgb[0], 0);
        assert!(s.clipped);
    }
}
