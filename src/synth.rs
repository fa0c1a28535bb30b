//! Synthetic scans from a known ground truth, reported the way the two instruments report them.
//!
//! This is how brdfd is exercised without instruments and how fits are checked: a
//! [`GroundTruth`] (model parameters) becomes a [`Scan`] with raw device readings and reference
//! readings, which then goes through the same processing and fitting as a measured scan.
//!
//! Forward model, per geometry g with device gain `gain_g` (SCIENCE.md §3 inverted, ρ_ref = 1,
//! so the truth is relative to the N9 tile's scale):
//! - MA-T12 reference `W_g(λ) = gain_g · ρ_N9`, sample `S_g(λ) = gain_g · ρ_N9 · π · f(λ; g)`,
//!   so that `S/W / π = f`.
//! - SRA (one achromatic value): reference `I_ref,g = gain_g · c`, sample
//!   `I_g = gain_g · c · π · Y(f(·; g))`, with `c` = [`SRA_REFERENCE_INTENSITY`] and `Y` the
//!   SRA's response ([`SraResponse`]): the band mean `mean_λ f(λ; g)` (the default, what the
//!   paper's flat model assumes) or the luminance under CIE illuminant C and the 2° V(λ)
//!   (what a gloss meter reads, what the `luminance` SRA model assumes; SCIENCE.md §5.1).
//! - Optional noise: every reported value (sample and reference) is multiplied by an independent
//!   draw of N(1, σ), from a ChaCha8 stream seeded by [`SynthOptions::seed`].
//!
//! The diffuse spectra are real: the 24 ColorChecker patches, BabelColor average of 30 charts
//! (D. Pascale, 2012), 400–700 nm at 10 nm, embedded from `synth/colorchecker_babelcolor_avg_10nm.csv`.
//! The specular parameters of [`paper_samples`] are synthetic choices for matt surfaces.

use std::f64::consts::PI;
use std::sync::LazyLock;

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use crate::geometry::{GEOMETRIES, GEOMETRY_COUNT, MA_T12_COUNT};
use crate::model::{self, FresnelCosine, Params, SpecularGeometry};
use crate::scan::{DeviceReadings, Reference, Scan};
use crate::spectral::{BANDS, Spectrum, wavelengths_nm};
use crate::sra_reading::SraReading;

/// The ColorChecker table, as shipped (source in its first line).
const COLORCHECKER_CSV: &str = include_str!("synth/colorchecker_babelcolor_avg_10nm.csv");

/// The Canon SRA's reading of the N9 reference tile at unit gain: an arbitrary positive device
/// constant (1D-BRDF intensity units). Only ratios to it matter; 0.245 is the value in the scan
/// file example of ARCHITECTURE.md.
pub const SRA_REFERENCE_INTENSITY: f64 = 0.245;

/// Luminous reflectance factor of a Munsell N9 chip: value 9 is Y ≈ 76.7 % (ASTM D1535).
pub const N9_REFLECTANCE: f64 = 0.767;

/// Default per-geometry device gains, in [`GEOMETRIES`] order: a fixed, deliberately uneven set
/// in 0.9–1.1 (LED output and detector response differ per geometry). They cancel in the
/// sample/reference ratio; a processing bug that forgot the reference would not.
pub const DEFAULT_GAINS: [f64; GEOMETRY_COUNT] = [
    1.04, 0.97, 1.08, 0.93, 1.02, 0.95, 1.06, 0.91, 1.00, 1.09, 0.94, 0.98, 1.05, 0.92,
];

/// The 24 ColorChecker patches: (lower-case name as in the table, reflectance factor 0–1).
pub fn colorchecker() -> &'static [(String, Spectrum)] {
    static TABLE: LazyLock<Vec<(String, Spectrum)>> = LazyLock::new(|| {
        let mut lines = COLORCHECKER_CSV.lines().filter(|l| !l.starts_with('#'));
        let header = lines.next().expect("ColorChecker table has a header");
        let grid: Vec<u32> = header
            .split(',')
            .skip(1)
            .map(|s| s.trim().parse().expect("header nm"))
            .collect();
        assert_eq!(
            grid,
            wavelengths_nm(),
            "ColorChecker table is not on the 31-band grid"
        );
        lines
            .filter(|l| !l.trim().is_empty())
            .map(|l| {
                let mut cells = l.split(',');
                let name = cells.next().expect("patch name").trim().to_string();
                let values: Vec<f64> = cells
                    .map(|c| c.trim().parse().expect("reflectance value"))
                    .collect();
                (name, values.try_into().expect("31 values per patch"))
            })
            .collect()
    });
    &TABLE
}

/// One ColorChecker patch by name (case-insensitive), e.g. "moderate red".
pub fn colorchecker_patch(name: &str) -> Option<Spectrum> {
    colorchecker()
        .iter()
        .find(|(n, _)| n.eq_ignore_ascii_case(name))
        .map(|(_, s)| *s)
}

/// A sample's true model parameters and where its colour came from.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct GroundTruth {
    /// Sample name, as written into the scan.
    pub sample: String,
    /// The ColorChecker patch its diffuse spectrum is taken from.
    pub patch: String,
    /// `kd = patch reflectance / π × diffuse_scale`.
    pub diffuse_scale: f64,
    /// The true parameters (kd in sr⁻¹, relative to the N9 tile).
    pub params: Params,
}

impl GroundTruth {
    /// A sample whose kd is a ColorChecker patch's reflectance / π × `diffuse_scale`.
    /// Panics on an unknown patch name (the table is fixed and embedded).
    pub fn from_patch(
        sample: &str,
        patch: &str,
        diffuse_scale: f64,
        ks: f64,
        alpha: f64,
        ior: f64,
    ) -> GroundTruth {
        let rho = colorchecker_patch(patch)
            .unwrap_or_else(|| panic!("no ColorChecker patch named {patch:?}"));
        GroundTruth {
            sample: sample.to_string(),
            patch: patch.to_string(),
            diffuse_scale,
            params: Params {
                kd: rho.map(|r| r / PI * diffuse_scale),
                ks,
                alpha,
                ior,
                extra: [0.0; crate::model::EXTRA],
            },
        }
    }

    /// The true BRDF, sr⁻¹, at the 14 geometries.
    pub fn brdf(&self, fresnel: FresnelCosine) -> [Spectrum; GEOMETRY_COUNT] {
        model::evaluate(&self.params, fresnel, &SpecularGeometry::all())
    }

    /// What an ideal instrument pair would deliver after processing: the true BRDF at the 12
    /// MA-T12 geometries, and the band mean of it, flat, at the 2 SRA ones (the SRA is achromatic).
    pub fn measurable_brdf(&self, fresnel: FresnelCosine) -> [Spectrum; GEOMETRY_COUNT] {
        let mut f = self.brdf(fresnel);
        flatten_sra(&mut f);
        f
    }
}

/// Replaces each SRA geometry's spectrum by its band mean: the SRA reports one achromatic value
/// per geometry (SCIENCE.md §3), which processing spreads flat over the 31 bands.
pub fn flatten_sra(brdf: &mut [Spectrum; GEOMETRY_COUNT]) {
    for s in brdf.iter_mut().skip(MA_T12_COUNT) {
        *s = [s.iter().sum::<f64>() / BANDS as f64; BANDS];
    }
}

/// The file-name slug lives in [`crate::names`]; re-exported here for the callers that name
/// synthetic scans' files.
pub use crate::names::slug;

/// Eight matt samples named like the paper's. The paper names three ("T.Freesia pink",
/// "T.Prairie green", "T.Manzana green"); the other five names are made up in the same style.
/// All parameters are synthetic: kd from a ColorChecker patch chosen to match the name,
/// and matt specular lobes (ks 0.05–0.5, α 0.2–0.6, μ 1.4–1.7) varied across samples.
pub fn paper_samples() -> Vec<GroundTruth> {
    [
        // sample, patch, diffuse scale, ks, α, μ
        ("T.Freesia pink", "moderate red", 1.05, 0.20, 0.35, 1.50),
        ("T.Prairie green", "yellow green", 0.95, 0.35, 0.25, 1.60),
        ("T.Manzana green", "green", 1.10, 0.10, 0.45, 1.45),
        ("T.Mandarin orange", "orange", 1.00, 0.45, 0.30, 1.55),
        ("T.Saffron yellow", "orange yellow", 0.92, 0.05, 0.55, 1.40),
        ("T.Lavender blue", "blue flower", 1.08, 0.25, 0.40, 1.65),
        ("T.Sky blue", "blue sky", 0.97, 0.15, 0.60, 1.70),
        (
            "T.Pebble grey",
            "neutral 6.5 (.44 D)",
            0.90,
            0.50,
            0.20,
            1.50,
        ),
    ]
    .into_iter()
    .map(|(s, p, d, ks, a, mu)| GroundTruth::from_patch(s, p, d, ks, a, mu))
    .collect()
}

/// How the simulated instruments report.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct SynthOptions {
    /// Reflectance factor of the reference tile as the MA-T12 reports it (flat).
    pub n9_reflectance: f64,
    /// Per-geometry device gain, [`GEOMETRIES`] order.
    pub gains: [f64; GEOMETRY_COUNT],
    /// Relative σ of the multiplicative N(1, σ) noise on every reported value; 0 = noise-free.
    pub noise: f64,
    /// Seed of the noise stream.
    pub seed: u64,
    /// Fresnel cosine of the true model.
    pub fresnel: FresnelCosine,
    /// What the simulated SRA reads: the band mean (default) or the luminance.
    #[serde(default)]
    pub sra_response: SraResponse,
}

/// What one reading of the simulated SRA is, given the true spectral BRDF at its geometry.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum SraResponse {
    /// The mean over the 31 bands (the paper's assumption; the default).
    #[default]
    BandMean,
    /// The luminance under CIE illuminant C and the 2° V(λ) ([`SraReading::LUMINANCE`]).
    Luminance,
}

impl SraResponse {
    /// Both, the default first.
    pub const ALL: [SraResponse; 2] = [SraResponse::BandMean, SraResponse::Luminance];

    /// The name used on the command line.
    pub const fn name(self) -> &'static str {
        match self {
            SraResponse::BandMean => "band-mean",
            SraResponse::Luminance => "luminance",
        }
    }

    /// The reading of a true spectral BRDF `f` (sr⁻¹), in sr⁻¹.
    pub fn read(self, f: &Spectrum) -> f64 {
        match self {
            SraResponse::BandMean => f.iter().sum::<f64>() / BANDS as f64,
            SraResponse::Luminance => SraReading::LUMINANCE.luminance(f),
        }
    }
}

impl std::fmt::Display for SraResponse {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl std::str::FromStr for SraResponse {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        SraResponse::ALL
            .into_iter()
            .find(|r| r.name() == s.trim())
            .ok_or_else(|| format!("unknown SRA response \"{s}\"; valid: band-mean, luminance"))
    }
}

impl Default for SynthOptions {
    fn default() -> Self {
        SynthOptions {
            n9_reflectance: N9_REFLECTANCE,
            gains: DEFAULT_GAINS,
            noise: 0.0,
            seed: 0,
            fresnel: FresnelCosine::Incidence,
            sra_response: SraResponse::BandMean,
        }
    }
}

/// A synthesis option that cannot describe an instrument.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SynthError {
    #[error("synth: n9_reflectance {0} must be positive and finite")]
    N9Reflectance(f64),
    #[error("synth: gain {value} at geometry {geometry} must be positive and finite")]
    Gain { geometry: &'static str, value: f64 },
    #[error("synth: noise σ {0} must be finite and in [0, 0.2] (relative, 0.01 = 1 %)")]
    Noise(f64),
    #[error(
        "synth: sample {sample:?}: true BRDF at {geometry} is {value} sr⁻¹, not finite and ≥ 0"
    )]
    Truth {
        sample: String,
        geometry: &'static str,
        value: f64,
    },
}

impl SynthOptions {
    /// Rejects options no instrument could have.
    pub fn validate(&self) -> Result<(), SynthError> {
        if !(self.n9_reflectance.is_finite() && self.n9_reflectance > 0.0) {
            return Err(SynthError::N9Reflectance(self.n9_reflectance));
        }
        for (geo, &value) in GEOMETRIES.iter().zip(&self.gains) {
            if !(value.is_finite() && value > 0.0) {
                return Err(SynthError::Gain {
                    geometry: geo.name,
                    value,
                });
            }
        }
        if !(self.noise.is_finite() && (0.0..=0.2).contains(&self.noise)) {
            return Err(SynthError::Noise(self.noise));
        }
        Ok(())
    }
}

/// The multiplicative noise source: N(1, σ) by Box–Muller, redrawn in the (astronomically rare
/// at σ ≤ 0.2) case of a non-positive factor, since no instrument reports a negative reading.
struct Noise {
    rng: ChaCha8Rng,
    sigma: f64,
}

impl Noise {
    fn factor(&mut self) -> f64 {
        if self.sigma == 0.0 {
            return 1.0;
        }
        loop {
            let f = 1.0 + self.sigma * crate::stats::standard_normal(&mut self.rng);
            if f > 0.0 {
                return f;
            }
        }
    }
}

/// Simulates one scan of `truth` (see the module doc for the forward model). Noise values are
/// drawn in a fixed order — reference MA-T12 (table order, band order), reference SRA, sample
/// MA-T12, sample SRA — so a seed always gives the same scan.
pub fn synth_scan(truth: &GroundTruth, opts: &SynthOptions) -> Result<Scan, SynthError> {
    opts.validate()?;
    let f = truth.brdf(opts.fresnel);
    for (geo, s) in GEOMETRIES.iter().zip(&f) {
        if let Some(&value) = s.iter().find(|v| !(v.is_finite() && **v >= 0.0)) {
            return Err(SynthError::Truth {
                sample: truth.sample.clone(),
                geometry: geo.name,
                value,
            });
        }
    }
    let mut noise = Noise {
        rng: ChaCha8Rng::seed_from_u64(opts.seed),
        sigma: opts.noise,
    };
    let g = &opts.gains;
    let rho = opts.n9_reflectance;
    let c = SRA_REFERENCE_INTENSITY;

    let mut reference_ma_t12 = [[0.0; BANDS]; MA_T12_COUNT];
    for (i, spectrum) in reference_ma_t12.iter_mut().enumerate() {
        *spectrum = std::array::from_fn(|_| g[i] * rho * noise.factor());
    }
    let mut reference_sra = [0.0; 2];
    for (k, v) in reference_sra.iter_mut().enumerate() {
        *v = g[MA_T12_COUNT + k] * c * noise.factor();
    }

    let mut ma_t12 = [[0.0; BANDS]; MA_T12_COUNT];
    for (i, spectrum) in ma_t12.iter_mut().enumerate() {
        *spectrum = std::array::from_fn(|b| g[i] * rho * PI * f[i][b] * noise.factor());
    }
    let mut sra = [0.0; 2];
    for (k, v) in sra.iter_mut().enumerate() {
        let gi = MA_T12_COUNT + k;
        let mean = opts.sra_response.read(&f[gi]);
        *v = g[gi] * c * PI * mean * noise.factor();
    }

    Ok(Scan {
        sample: truth.sample.clone(),
        reference: Some(Reference {
            name: "Munsell N9".to_string(),
            readings: DeviceReadings {
                ma_t12: reference_ma_t12,
                sra: Some(reference_sra),
            },
        }),
        readings: DeviceReadings {
            ma_t12,
            sra: Some(sra),
        },
        origin: None,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::processing::{ProcessingOptions, process};

    #[test]
    fn colorchecker_table_is_complete_and_matches_the_source() {
        let t = colorchecker();
        assert_eq!(t.len(), 24);
        // Spot values from BabelColor's average table (Pascale 2012).
        assert_eq!(colorchecker_patch("dark skin").unwrap()[0], 0.0610);
        assert_eq!(colorchecker_patch("Blue Sky").unwrap()[1], 0.3060);
        assert_eq!(t[23].0, "black 2 (1.5 D)");
        assert!(
            t.iter()
                .all(|(_, s)| s.iter().all(|&r| (0.0..1.0).contains(&r)))
        );
        assert!(colorchecker_patch("chartreuse").is_none());
    }

    #[test]
    fn paper_samples_are_eight_distinct_matt_samples_within_bounds() {
        let samples = paper_samples();
        assert_eq!(samples.len(), 8);
        let b = model::Bounds::default();
        for s in &samples {
            assert!(
                s.params.kd.iter().all(|&k| k > b.kd.0 && k < b.kd.1),
                "{}",
                s.sample
            );
            assert!((0.05..=0.5).contains(&s.params.ks));
            assert!((0.2..=0.6).contains(&s.params.alpha));
            assert!((1.4..=1.7).contains(&s.params.ior));
        }
        let mut slugs: Vec<_> = samples.iter().map(|s| slug(&s.sample)).collect();
        slugs.sort();
        slugs.dedup();
        assert_eq!(slugs.len(), 8);
        assert!(samples.iter().any(|s| s.sample == "T.Prairie green"));
    }

    #[test]
    fn noise_free_scan_processes_back_to_the_truth() {
        // The point of the forward model: processing (ratio, ρ_ref = 1) inverts it exactly.
        for truth in paper_samples() {
            let scan = synth_scan(&truth, &SynthOptions::default()).unwrap();
            scan.validate().unwrap();
            let m = process(&scan, &ProcessingOptions::default()).unwrap();
            let want = truth.measurable_brdf(FresnelCosine::Incidence);
            for (gi, geo) in GEOMETRIES.iter().enumerate() {
                for (b, (&got, &w)) in m.values[gi].iter().zip(&want[gi]).enumerate() {
                    assert!(
                        (got - w).abs() <= 1e-14 * w,
                        "{} {} {b}: {got} vs {w}",
                        truth.sample,
                        geo
                    );
                }
            }
        }
    }

    #[test]
    fn luminance_response_processes_back_to_the_true_luminance() {
        let truth = &paper_samples()[1];
        let opts = SynthOptions {
            sra_response: SraResponse::Luminance,
            ..SynthOptions::default()
        };
        let scan = synth_scan(truth, &opts).unwrap();
        let m = process(&scan, &ProcessingOptions::default()).unwrap();
        let mut want = truth.brdf(FresnelCosine::Incidence);
        crate::sra_reading::luminance_sra(&mut want, SraReading::LUMINANCE);
        for (got, want) in m.values.iter().flatten().zip(want.iter().flatten()) {
            assert!((got - want).abs() <= 1e-14 * want, "{got} vs {want}");
        }
        // The prairie green's spectrum is not flat: its luminance is not its band mean, so
        // the two responses give different SRA readings, and the same MA-T12 readings.
        let band_mean = synth_scan(truth, &SynthOptions::default()).unwrap();
        assert_eq!(band_mean.readings.ma_t12, scan.readings.ma_t12);
        for k in 0..2 {
            let (a, b) = (
                band_mean.readings.sra.unwrap()[k],
                scan.readings.sra.unwrap()[k],
            );
            assert!((a - b).abs() > 1e-3 * a, "{a} vs {b}");
        }
        assert_eq!(
            "luminance".parse::<SraResponse>(),
            Ok(SraResponse::Luminance)
        );
        assert!(
            "mean"
                .parse::<SraResponse>()
                .unwrap_err()
                .contains("band-mean")
        );
    }

    #[test]
    fn readings_carry_the_gains_and_the_reference_scale() {
        let truth = &paper_samples()[0];
        let scan = synth_scan(truth, &SynthOptions::default()).unwrap();
        // MA-T12 reference = gain · 0.767; SRA reference = gain · 0.245.
        assert_eq!(
            scan.reference.as_ref().unwrap().readings.ma_t12[0][0],
            1.04 * 0.767
        );
        assert_eq!(
            scan.reference.as_ref().unwrap().readings.ma_t12[3][30],
            0.93 * 0.767
        );
        assert_eq!(
            scan.reference.as_ref().unwrap().readings.sra.unwrap()[1],
            0.92 * 0.245
        );
        // The raw sample reading is the reflectance factor relative to N9 times the tile's:
        // 15as15 (θi = 0) is kd·π·0.767·gain + specular.
        let f = truth.brdf(FresnelCosine::Incidence);
        let want = 0.93 * 0.767 * PI * f[3][10];
        assert!((scan.readings.ma_t12[3][10] - want).abs() < 1e-15);
    }

    #[test]
    fn noise_is_seeded_and_of_the_requested_size() {
        let truth = &paper_samples()[1];
        let opts = SynthOptions {
            noise: 0.01,
            seed: 42,
            ..Default::default()
        };
        let a = synth_scan(truth, &opts).unwrap();
        assert_eq!(a, synth_scan(truth, &opts).unwrap());
        let b = synth_scan(truth, &SynthOptions { seed: 43, ..opts }).unwrap();
        assert_ne!(a, b);
        // Relative deviations of the 12·31 reference values: mean ≈ 0, sd ≈ 0.01.
        let clean = synth_scan(truth, &SynthOptions::default()).unwrap();
        fn reference_values(s: &Scan) -> impl Iterator<Item = &f64> {
            s.reference
                .as_ref()
                .unwrap()
                .readings
                .ma_t12
                .iter()
                .flatten()
        }
        let dev: Vec<f64> = reference_values(&a)
            .zip(reference_values(&clean))
            .map(|(n, c)| n / c - 1.0)
            .collect();
        let n = dev.len() as f64;
        let mean = dev.iter().sum::<f64>() / n;
        let sd = (dev.iter().map(|d| (d - mean).powi(2)).sum::<f64>() / (n - 1.0)).sqrt();
        assert!(mean.abs() < 0.002, "mean {mean}");
        assert!((sd - 0.01).abs() < 0.0015, "sd {sd}");
    }

    #[test]
    fn rejects_impossible_options() {
        let truth = &paper_samples()[0];
        let mut o = SynthOptions::default();
        o.gains[13] = 0.0;
        assert_eq!(
            synth_scan(truth, &o).unwrap_err().to_string(),
            "synth: gain 0 at geometry sra-60 must be positive and finite"
        );
        let o = SynthOptions {
            noise: -0.1,
            ..Default::default()
        };
        assert!(matches!(synth_scan(truth, &o), Err(SynthError::Noise(_))));
        let o = SynthOptions {
            n9_reflectance: f64::NAN,
            ..Default::default()
        };
        assert!(matches!(
            synth_scan(truth, &o),
            Err(SynthError::N9Reflectance(_))
        ));
    }
}
