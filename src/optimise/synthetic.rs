//! Synthetic measured BRDFs with known parameters, for the optimiser's tests, its benchmark and
//! its reliability harness (`examples/reliability.rs`).
//!
//! A case is a diffuse spectrum from a real ColorChecker patch (kd = reflectance factor / π,
//! sr⁻¹) plus matt specular parameters of the kind the paper's samples have. The measured BRDF
//! is the model evaluated at the 14 geometries, except that the two SRA geometries are made
//! flat — the mean over bands of the model value — because the real SRA reports one achromatic
//! value per geometry (SCIENCE.md §3). So even a noise-free case is not exactly reachable by the
//! model: its best cost is above zero and its best parameters sit near, not on, the truth.
//! [`consistent`] gives the exactly reachable variant.
//!
//! These are measured BRDFs, not device scans; the scan simulator builds device-level scans.

// Numeric loops index parallel per-geometry and per-band arrays; `for g in 0..G` reads
// closest to the equations.
#![allow(clippy::needless_range_loop)]

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use crate::geometry::{Device, GEOMETRIES, GEOMETRY_COUNT};
use crate::model::{FresnelCosine, Params, SpecularGeometry, evaluate};
use crate::processing::MeasuredBrdf;
use crate::spectral::{BANDS, Spectrum};

/// Spectral reflectance factors of six ColorChecker patches, 400–700 nm every 10 nm.
///
/// Source: BabelColor average of 30 ColorChecker charts (D. Pascale, "RGB coordinates of the
/// Macbeth ColorChecker", BabelColor, 2012), the `colorchecker_babelcolor_avg_10nm.csv` table.
// Measured data: 0.3180 (yellow green, 630 nm) is a reflectance, not an approximation of 1/π.
#[allow(clippy::approx_constant)]
const PATCHES: [(&str, Spectrum); 6] = [
    (
        "dark skin",
        [
            0.0610, 0.0620, 0.0620, 0.0620, 0.0620, 0.0620, 0.0620, 0.0620, 0.0620, 0.0630, 0.0650,
            0.0700, 0.0760, 0.0790, 0.0810, 0.0840, 0.0910, 0.1030, 0.1190, 0.1340, 0.1430, 0.1470,
            0.1510, 0.1580, 0.1680, 0.1790, 0.1880, 0.1900, 0.1860, 0.1810, 0.1820,
        ],
    ),
    (
        "foliage",
        [
            0.0560, 0.0570, 0.0580, 0.0590, 0.0600, 0.0610, 0.0620, 0.0630, 0.0650, 0.0670, 0.0750,
            0.1010, 0.1450, 0.1780, 0.1840, 0.1700, 0.1490, 0.1330, 0.1220, 0.1150, 0.1090, 0.1050,
            0.1040, 0.1060, 0.1090, 0.1120, 0.1140, 0.1140, 0.1120, 0.1120, 0.1150,
        ],
    ),
    (
        "orange",
        [
            0.0530, 0.0540, 0.0540, 0.0550, 0.0550, 0.0550, 0.0560, 0.0570, 0.0580, 0.0610, 0.0680,
            0.0890, 0.1250, 0.1540, 0.1740, 0.1990, 0.2480, 0.3350, 0.4440, 0.5380, 0.5870, 0.5950,
            0.5910, 0.5870, 0.5840, 0.5840, 0.5900, 0.6030, 0.6200, 0.6390, 0.6550,
        ],
    ),
    (
        "purplish blue",
        [
            0.2290, 0.2860, 0.3270, 0.3610, 0.3880, 0.4000, 0.3920, 0.3620, 0.3160, 0.2600, 0.2090,
            0.1680, 0.1380, 0.1170, 0.1040, 0.0960, 0.0900, 0.0860, 0.0840, 0.0840, 0.0840, 0.0840,
            0.0840, 0.0850, 0.0900, 0.0980, 0.1090, 0.1230, 0.1430, 0.1690, 0.2050,
        ],
    ),
    (
        "yellow green",
        [
            0.0620, 0.0630, 0.0640, 0.0660, 0.0690, 0.0750, 0.0850, 0.1050, 0.1390, 0.1920, 0.2710,
            0.3760, 0.4760, 0.5310, 0.5490, 0.5460, 0.5280, 0.5040, 0.4710, 0.4280, 0.3810, 0.3470,
            0.3270, 0.3180, 0.3120, 0.3100, 0.3140, 0.3270, 0.3450, 0.3630, 0.3760,
        ],
    ),
    (
        "neutral 5 (.70 D)",
        [
            0.1630, 0.1800, 0.1860, 0.1900, 0.1930, 0.1940, 0.1940, 0.1920, 0.1910, 0.1910, 0.1910,
            0.1920, 0.1920, 0.1920, 0.1920, 0.1920, 0.1920, 0.1930, 0.1920, 0.1920, 0.1910, 0.1890,
            0.1880, 0.1860, 0.1840, 0.1820, 0.1810, 0.1790, 0.1780, 0.1760, 0.1740,
        ],
    ),
];

/// The reflectance factor (0–1) of one of the embedded ColorChecker patches, by its name.
pub fn colorchecker(patch: &str) -> Option<Spectrum> {
    PATCHES
        .iter()
        .find(|(name, _)| *name == patch)
        .map(|(_, r)| *r)
}

/// A synthetic sample: a ColorChecker patch as its diffuse colour and its true parameters.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SyntheticCase {
    /// The ColorChecker patch the diffuse spectrum comes from.
    pub patch: &'static str,
    /// The parameters the measured BRDF is built from.
    pub truth: Params,
}

/// Six matt samples: ks 0.05–0.5, α 0.2–0.6, μ 1.4–1.7, spread so that neighbouring cases
/// differ in every specular parameter.
pub fn cases() -> [SyntheticCase; 6] {
    // (ks, α, μ) per patch, in PATCHES order.
    const SPECULAR: [(f64, f64, f64); 6] = [
        (0.10, 0.35, 1.50),
        (0.05, 0.50, 1.45),
        (0.30, 0.25, 1.60),
        (0.20, 0.40, 1.55),
        (0.50, 0.20, 1.70),
        (0.08, 0.60, 1.40),
    ];
    std::array::from_fn(|i| {
        let (patch, reflectance) = PATCHES[i];
        let (ks, alpha, ior) = SPECULAR[i];
        SyntheticCase {
            patch,
            truth: Params {
                kd: reflectance.map(|r| r / std::f64::consts::PI),
                ks,
                alpha,
                ior,
            },
        }
    })
}

/// The model BRDF of `truth` at all 14 geometries, exactly: every geometry spectral.
pub fn consistent(truth: &Params, fresnel: FresnelCosine) -> MeasuredBrdf {
    MeasuredBrdf {
        values: evaluate(truth, fresnel, &SpecularGeometry::all()),
    }
}

/// What the two instruments would measure for `truth`: the model BRDF, with each SRA
/// geometry's spectrum replaced by its mean over the bands (the SRA is achromatic).
pub fn measured(truth: &Params, fresnel: FresnelCosine) -> MeasuredBrdf {
    let mut m = consistent(truth, fresnel);
    for geo in GEOMETRIES.iter().filter(|g| g.device == Device::Sra) {
        let row = &mut m.values[geo.index];
        let mean = row.iter().sum::<f64>() / BANDS as f64;
        *row = [mean; BANDS];
    }
    m
}

/// `measured` with multiplicative Gaussian noise of relative standard deviation
/// `relative_sigma` (0.01 = 1 %), seeded. Each MA-T12 value gets its own draw; each SRA
/// geometry one draw for the whole spectrum, so it stays flat as the instrument reports it.
pub fn with_noise(measured: &MeasuredBrdf, relative_sigma: f64, seed: u64) -> MeasuredBrdf {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut out = *measured;
    for g in 0..GEOMETRY_COUNT {
        match GEOMETRIES[g].device {
            Device::MaT12 => {
                for x in out.values[g].iter_mut() {
                    *x *= 1.0 + relative_sigma * standard_normal(&mut rng);
                }
            }
            Device::Sra => {
                let f = 1.0 + relative_sigma * standard_normal(&mut rng);
                for x in out.values[g].iter_mut() {
                    *x *= f;
                }
            }
        }
    }
    out
}

/// One standard normal draw by the Box–Muller transform (keeps the crate free of rand_distr).
fn standard_normal(rng: &mut ChaCha8Rng) -> f64 {
    // 1 − u lies in (0, 1], so the logarithm is finite.
    let u1: f64 = 1.0 - rng.random::<f64>();
    let u2: f64 = rng.random::<f64>();
    (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::by_name;

    #[test]
    fn cases_use_the_colorchecker_spectra_over_pi() {
        let c = cases();
        // BabelColor average, "orange" at 600 nm (band 20) = 0.5870.
        let orange = c.iter().find(|c| c.patch == "orange").unwrap();
        assert!((orange.truth.kd[20] - 0.5870 / std::f64::consts::PI).abs() < 1e-15);
        assert_eq!(colorchecker("foliage").unwrap()[0], 0.0560);
        assert!(colorchecker("no such patch").is_none());
    }

    #[test]
    fn sra_geometries_are_flat_and_ma_t12_ones_spectral() {
        let truth = cases()[2].truth;
        let m = measured(&truth, FresnelCosine::Incidence);
        let full = consistent(&truth, FresnelCosine::Incidence);
        for name in ["sra-20", "sra-60"] {
            let g = by_name(name).unwrap().index;
            assert!(m.values[g].iter().all(|&x| x == m.values[g][0]));
            let mean = full.values[g].iter().sum::<f64>() / BANDS as f64;
            assert!((m.values[g][0] - mean).abs() < 1e-15);
        }
        let g = by_name("45as15").unwrap().index;
        assert_eq!(m.values[g], full.values[g]);
    }

    #[test]
    fn noise_is_seeded_relative_and_keeps_sra_flat() {
        let m = measured(&cases()[0].truth, FresnelCosine::Incidence);
        let a = with_noise(&m, 0.01, 7);
        assert_eq!(a, with_noise(&m, 0.01, 7));
        assert_ne!(a, with_noise(&m, 0.01, 8));
        let g = by_name("sra-60").unwrap().index;
        assert!(a.values[g].iter().all(|&x| x == a.values[g][0]));
        // 12 × 31 relative deviations of σ = 1 %: their RMS is within 20 % of 0.01.
        let mut sq = 0.0;
        for g in 0..12 {
            for b in 0..BANDS {
                let r = a.values[g][b] / m.values[g][b] - 1.0;
                sq += r * r;
            }
        }
        let rms = (sq / (12.0 * BANDS as f64)).sqrt();
        assert!((rms - 0.01).abs() < 0.002, "rms {rms}");
    }
}
