//! Synthetic measured BRDFs with known parameters, for the optimiser's tests, its benchmark and
//! its reliability harness (`tools/src/bin/reliability.rs`).
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

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

use crate::geometry::{Device, GEOMETRIES, GEOMETRY_COUNT};
use crate::model::{FresnelCosine, Params, SpecularGeometry, evaluate};
use crate::processing::MeasuredBrdf;
use crate::spectral::Spectrum;

/// The six ColorChecker patches the cases take their diffuse colour from (BabelColor average
/// of 30 charts, D. Pascale 2012, embedded by [`crate::synth`]).
const PATCHES: [&str; 6] = [
    "dark skin",
    "foliage",
    "orange",
    "purplish blue",
    "yellow green",
    "neutral 5 (.70 D)",
];

/// The reflectance factor (0–1) of one of the embedded ColorChecker patches, by its name.
pub fn colorchecker(patch: &str) -> Option<Spectrum> {
    crate::synth::colorchecker_patch(patch)
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
        let patch = PATCHES[i];
        let reflectance = colorchecker(patch).expect("the six case patches are in the table");
        let (ks, alpha, ior) = SPECULAR[i];
        SyntheticCase {
            patch,
            truth: Params {
                kd: reflectance.map(|r| r / std::f64::consts::PI),
                ks,
                alpha,
                ior,
                extra: [0.0; crate::model::EXTRA],
            },
        }
    })
}

/// The model BRDF of `truth` at all 14 geometries, exactly: every geometry spectral.
pub fn consistent(truth: &Params, fresnel: FresnelCosine) -> MeasuredBrdf {
    MeasuredBrdf::full(evaluate(truth, fresnel, &SpecularGeometry::all()))
}

/// What the two instruments would measure for `truth`: the model BRDF, with each SRA
/// geometry's spectrum replaced by its mean over the bands (the SRA is achromatic).
pub fn measured(truth: &Params, fresnel: FresnelCosine) -> MeasuredBrdf {
    let mut m = consistent(truth, fresnel);
    crate::synth::flatten_sra(&mut m.values);
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
                    *x *= 1.0 + relative_sigma * crate::stats::standard_normal(&mut rng);
                }
            }
            Device::Sra => {
                let f = 1.0 + relative_sigma * crate::stats::standard_normal(&mut rng);
                for x in out.values[g].iter_mut() {
                    *x *= f;
                }
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::by_name;
    use crate::spectral::BANDS;

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
