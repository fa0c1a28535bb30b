//! How well a fit's parameters are determined: a parametric bootstrap with warm-started refits
//! (SCIENCE.md §10), giving 95 % intervals for ks, α, μ and kd per band, and the spread of the
//! ΔE00 summaries; [`bootstrap`] widens them by the leave-one-geometry-out jackknife
//! ([`crate::uncertainty::jackknife`]) so that they include the model's misfit, and rates them calibrated
//! only where both the synthetic coverage and the held-out coverage on real paint hold.
//!
//! Decisions (SCIENCE.md §10 gives the reasons in full):
//! - **Parametric, not residual, resampling.** The model cannot reproduce the achromatic SRA
//!   readings, so the residuals hold a systematic misfit besides the noise (up to the whole
//!   specular mismatch for cf2, which leaves the diffuse residuals at exactly zero). Resampled
//!   residuals would recycle that misfit as if it were noise, and for cf2 would recycle nothing
//!   on the diffuse side. Instead each resample perturbs the *measured* BRDF with the
//!   instrument's documented noise model: multiplicative N(1, σ) per value, independent per
//!   band at the 12 MA-T12 geometries, one factor for all 31 bands at each SRA geometry (one
//!   reading spread flat).
//! - **σ from the scan itself**, by a contrast in which the model cancels exactly: at one band
//!   the 12 MA-T12 values differ only by the spectrally flat specular term, so each geometry's
//!   deviation from the 12-geometry mean is flat in λ; its second difference along λ holds
//!   noise only ([`estimate_noise`]). A noise-free scan gives σ = 0 and zero-width intervals.
//! - **Warm-started local refits** ([`crate::optimise::refit_local`]) from the point fit: the
//!   point fit's global search picked the basin; a resample moves the optimum by about the noise.
//! - **Percentile intervals** (2.5 % and 97.5 % quantiles of the refitted values), with the
//!   same cost function, bounds and Fresnel choice as the point fit.
//! - **Deterministic**: resample `i` draws from ChaCha8 stream `i` of the seed, so the result
//!   does not depend on the number of threads.

use std::sync::atomic::{AtomicBool, Ordering};

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use crate::colour::Colorimetry;
use crate::cost::CostFunction;
use crate::evaluation::evaluate_with;
use crate::geometry::{Device, GEOMETRIES, GEOMETRY_COUNT, MA_T12_COUNT};
use crate::model::{self, FresnelCosine, Params, SpecularGeometry};
use crate::optimise::{FitError, Settings, refit_local};
use crate::processing::MeasuredBrdf;
use crate::spectral::BANDS;
use crate::sra_reading::{SraModel, SraWeight};

pub mod jackknife;

/// The method's name as written into the `uncertainty` object.
pub const METHOD: &str = "parametric-bootstrap";

/// How a bootstrap runs.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BootstrapOptions {
    /// Resamples (refits). 200 gives 95 % percentile intervals whose ends move by a few per
    /// cent of their width from one seed to another.
    pub resamples: u32,
    /// Seed of the resampling noise.
    pub seed: u64,
    /// Threads to refit on (results do not depend on it); at least 1.
    pub threads: usize,
    /// Relative noise σ per processed value; `None` estimates it from the scan.
    pub noise: Option<f64>,
    /// How each resample is refitted.
    pub refit: Refit,
}

/// How a bootstrap refits its resamples.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Refit {
    /// What each cost function needs ([`Refit::for_cost`]).
    #[default]
    ByCost,
    /// A local search warm-started at the point fit ([`refit_local`]).
    WarmStart,
    /// The point fit's own global search ([`crate::optimise::fit`]).
    FullSearch,
}

impl Refit {
    /// cf2 refits with the full search, whose survey and continuation let a resample move to
    /// another basin of cf2's many-basined cost (SCIENCE.md §10); cf1 and m2, whose costs are
    /// smooth around the optimum, refit warm-started (the full search gives them the same
    /// intervals at several times the cost).
    pub fn for_cost(cost: CostFunction) -> Refit {
        match cost {
            CostFunction::Cf2 => Refit::FullSearch,
            CostFunction::Cf1 | CostFunction::M2 => Refit::WarmStart,
        }
    }
}

impl Default for BootstrapOptions {
    fn default() -> Self {
        BootstrapOptions {
            resamples: 200,
            seed: 1,
            threads: 1,
            noise: None,
            refit: Refit::default(),
        }
    }
}

/// A 95 % interval `[lo, hi]`.
pub type Interval = [f64; 2];

/// The `uncertainty` object of a fit.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Uncertainty {
    /// [`METHOD`].
    pub method: String,
    /// Resamples refitted.
    pub resamples: u32,
    /// Relative noise σ per processed value the resamples were drawn with.
    pub noise: f64,
    /// Seed of the resampling noise.
    pub seed: u64,
    /// The share of the refitted values between each interval's ends ([`percentile_level`]):
    /// the percentile level whose intervals hold the truth 95 % of the time.
    #[serde(default = "nominal")]
    pub percentile_level: f64,
    pub ks: Interval,
    pub alpha: Interval,
    pub ior: Interval,
    /// One interval per band, 400–700 nm, sr⁻¹.
    pub kd: Vec<Interval>,
    /// The spread of the ΔE00 summaries: each resample's fit evaluated against its resample.
    pub delta_e00_mean: Interval,
    pub delta_e00_diffuse_mean: Interval,
    /// `None` for a scan without SRA readings.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub delta_e00_specular_mean: Option<Interval>,
    /// Whether these are calibrated 95 % intervals: true only for a cost function, SRA reading
    /// model and Fresnel choice whose measured coverage holds ([`calibration`]). Intervals
    /// stored before brdfd rated them read as `false`.
    #[serde(default)]
    pub calibrated: bool,
    /// Why the intervals are not calibrated 95 % intervals (`None` when they are).
    #[serde(default = "unrated")]
    pub note: Option<String>,
    /// The point fit's parameters at a bound of their range ([`crate::uncertainty::jackknife::at_bound`]);
    /// empty when none. An interval collapsed on a bound is not calibrated.
    #[serde(default)]
    pub at_bound: Vec<String>,
    /// The leave-one-geometry-out jackknife's own intervals ([`crate::uncertainty::jackknife`]); ks, α, μ and
    /// kd above are the hull of these and the bootstrap's. `None` for intervals of the
    /// bootstrap alone (stored before the jackknife, or from [`Uncertainty::from_draws`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub misfit: Option<crate::uncertainty::jackknife::Misfit>,
}

fn nominal() -> f64 {
    0.95
}

/// The percentile level of the refitted values that makes a 95 % interval, per cost function
/// (SCIENCE.md §10): 0.99 for cf1 and m2, 0.95 for cf2.
///
/// One scan's refits scatter more or less than the estimator does across noise draws, as the
/// curvature of the cost at the scan's own optimum happens to be: around the noise-free truth
/// the resampled refits reproduce the estimator's scatter, around one noisy scan their spread
/// is off by up to ±50 % for the weakly determined samples. Nominal 95 % percentile intervals
/// of cf1 and m2 therefore hold the truth in only 89–91 % of synthetic trials. The level is
/// calibrated (W.-Y. Loh, "Calibrating confidence coefficients", JASA 82, 1987): the nominal
/// level whose intervals cover 95 % on synthetic truths ([`CALIBRATION`] is measured at it on
/// other noise draws). cf2's full-search refits switch basins as the estimator does and cover
/// 95 % at the nominal level.
pub fn percentile_level(cost: CostFunction) -> f64 {
    match cost {
        CostFunction::Cf1 | CostFunction::M2 => 0.99,
        CostFunction::Cf2 => 0.95,
    }
}

fn unrated() -> Option<String> {
    Some("bootstrapped before brdfd rated its intervals' calibration; refit to rate them".into())
}

/// The measured coverage of the 95 % intervals (per cent of trials whose interval holds the
/// truth) for one cost function on one kind of scan, from the release tool `coverage` of
/// `brdfd-tools` (the commands are in [`CALIBRATION`]): ks, α, μ, and the lowest over the 31 kd bands.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Coverage {
    pub cost: CostFunction,
    /// The Fresnel factor of the synthetic truths and of their fits.
    pub fresnel: FresnelCosine,
    /// The SRA reading model; `None`: scans without SRA readings (the 12 MA-T12 geometries),
    /// where no SRA model enters the cost.
    pub sra: Option<SraModel>,
    /// The SRA readings' weight in the cost (SCIENCE.md §5.2); the paper's for scans without
    /// SRA readings, where it changes nothing.
    pub weight: SraWeight,
    /// Synthetic trials measured.
    pub trials: u32,
    pub ks: f64,
    pub alpha: f64,
    pub ior: f64,
    pub kd_lowest: f64,
}

impl Coverage {
    /// Whether every cell reaches [`CALIBRATED_AT`].
    pub fn holds(&self) -> bool {
        [self.ks, self.alpha, self.ior, self.kd_lowest]
            .iter()
            .all(|c| *c >= CALIBRATED_AT)
    }

    /// "with the luminance SRA model", "with the luminance SRA model, balanced" or "on scans
    /// without SRA readings".
    fn scans(&self) -> String {
        match self.sra {
            Some(m) if self.weight.is_paper() => format!("with the {m} SRA model"),
            Some(m) => format!("with the {m} SRA model, {}", self.weight),
            None => "on scans without SRA readings".into(),
        }
    }
}

/// The coverage (per cent) every parameter must reach for intervals to count as calibrated 95 %
/// intervals.
pub const CALIBRATED_AT: f64 = 90.0;

const fn row(
    cost: CostFunction,
    fresnel: FresnelCosine,
    sra: Option<SraModel>,
    trials: u32,
    [ks, alpha, ior, kd_lowest]: [f64; 4],
) -> Coverage {
    Coverage {
        cost,
        fresnel,
        sra,
        weight: SraWeight::Paper,
        trials,
        ks,
        alpha,
        ior,
        kd_lowest,
    }
}

/// `c` measured with the SRA readings balanced (SCIENCE.md §5.2).
const fn balanced(c: Coverage) -> Coverage {
    Coverage {
        weight: SraWeight::Balanced,
        ..c
    }
}

const LUMINANCE: Option<SraModel> = Some(SraModel::Luminance);
const FLAT: Option<SraModel> = Some(SraModel::Flat);
const SCHLICK: FresnelCosine = FresnelCosine::Incidence;
const EXACT: FresnelCosine = FresnelCosine::Exact;

/// Measured coverage per cost function, Fresnel factor and kind of scan, 1 % noise per reading,
/// the paper's model form, 200 resamples refitted as the daemon does, seeds 0 onwards: `cargo
/// run --release -p brdfd-tools --bin coverage` (200 trials; the simulated SRA reads the
/// luminance), `-- --trials 96 --sra flat` (the simulated SRA reads the band mean, what the flat
/// model assumes), `-- --trials 96 --no-sra` (MA-T12-only scans), and `-- --fresnel exact
/// --trials 96` with and without `--no-sra` (truths and fits under the exact Fresnel: the
/// default of measured scans; cf1 and m2 there with the SRA readings both balanced, the
/// default, and weighed as the paper's, `--sra-weight paper`). SCIENCE.md §12.3 quotes the
/// same runs; CI reruns the exact-Fresnel defaults on other seeds.
pub const CALIBRATION: [Coverage; 17] = [
    row(
        CostFunction::Cf1,
        SCHLICK,
        LUMINANCE,
        200,
        [95.5, 96.5, 94.5, 94.5],
    ),
    row(
        CostFunction::Cf2,
        SCHLICK,
        LUMINANCE,
        200,
        [94.5, 95.5, 94.0, 98.5],
    ),
    row(
        CostFunction::M2,
        SCHLICK,
        LUMINANCE,
        200,
        [95.5, 96.5, 94.5, 94.0],
    ),
    row(
        CostFunction::Cf1,
        SCHLICK,
        FLAT,
        96,
        [94.8, 94.8, 93.8, 9.4],
    ),
    row(
        CostFunction::Cf2,
        SCHLICK,
        FLAT,
        96,
        [70.8, 65.6, 83.3, 71.9],
    ),
    row(CostFunction::M2, SCHLICK, FLAT, 96, [56.2, 54.2, 69.8, 9.4]),
    row(
        CostFunction::Cf1,
        SCHLICK,
        None,
        96,
        [96.9, 95.8, 97.9, 94.8],
    ),
    row(
        CostFunction::Cf2,
        SCHLICK,
        None,
        96,
        [100.0, 100.0, 100.0, 99.0],
    ),
    row(
        CostFunction::M2,
        SCHLICK,
        None,
        96,
        [96.9, 95.8, 96.9, 94.8],
    ),
    row(
        CostFunction::Cf1,
        EXACT,
        LUMINANCE,
        96,
        [94.8, 94.8, 94.8, 96.9],
    ),
    row(
        CostFunction::Cf2,
        EXACT,
        LUMINANCE,
        96,
        [92.7, 90.6, 90.6, 94.8],
    ),
    row(
        CostFunction::M2,
        EXACT,
        LUMINANCE,
        96,
        [93.8, 94.8, 94.8, 95.8],
    ),
    balanced(row(
        CostFunction::Cf1,
        EXACT,
        LUMINANCE,
        96,
        [94.8, 94.8, 95.8, 95.8],
    )),
    balanced(row(
        CostFunction::M2,
        EXACT,
        LUMINANCE,
        96,
        [94.8, 95.8, 95.8, 95.8],
    )),
    row(
        CostFunction::Cf1,
        EXACT,
        None,
        96,
        [100.0, 96.9, 95.8, 92.7],
    ),
    row(
        CostFunction::Cf2,
        EXACT,
        None,
        96,
        [100.0, 100.0, 100.0, 99.0],
    ),
    row(CostFunction::M2, EXACT, None, 96, [100.0, 97.9, 96.9, 93.8]),
];

/// The measured coverage of the 95 % held-out prediction intervals on real paint
/// ([`crate::uncertainty::jackknife`]): per cent of held-out geometries of the real MA-T12 exports whose
/// measured L* (and L*, a* and b* at once) lies in its interval, for one cost function and
/// Fresnel factor under the paper's model form.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HeldOutCoverage {
    pub cost: CostFunction,
    pub fresnel: FresnelCosine,
    /// Real exports measured (12 held-out geometries each).
    pub files: u32,
    pub l: f64,
    pub lab: f64,
}

const fn held_out(cost: CostFunction, fresnel: FresnelCosine, l: f64, lab: f64) -> HeldOutCoverage {
    HeldOutCoverage {
        cost,
        fresnel,
        files: 47,
        l,
        lab,
    }
}

/// Held-out coverage per cost function and Fresnel factor on the 47 real exports of
/// `tests/data/real-mat12/` and `more/`: `cargo run --release -p brdfd-tools --bin heldout`
/// and `-- --fresnel exact` (SCIENCE.md §10 quotes the same runs; CI reruns the exact one on
/// the first exports with `--require`).
pub const HELD_OUT: [HeldOutCoverage; 6] = [
    held_out(CostFunction::Cf1, SCHLICK, 93.3, 88.7),
    held_out(CostFunction::Cf2, SCHLICK, 93.6, 89.5),
    held_out(CostFunction::M2, SCHLICK, 93.3, 88.3),
    held_out(CostFunction::Cf1, EXACT, 94.7, 88.1),
    held_out(CostFunction::Cf2, EXACT, 94.3, 88.5),
    held_out(CostFunction::M2, EXACT, 94.7, 87.9),
];

/// The row of [`HELD_OUT`] for a cost function and Fresnel factor; `None` where it was not
/// measured.
pub fn held_out_coverage(
    cost: CostFunction,
    fresnel: FresnelCosine,
) -> Option<&'static HeldOutCoverage> {
    HELD_OUT
        .iter()
        .find(|c| c.cost == cost && c.fresnel == fresnel)
}

/// The row of [`CALIBRATION`] for a fit with `settings` of a scan with or without SRA readings;
/// `None` where the coverage was not measured.
pub fn coverage(settings: &Settings, has_sra: bool) -> Option<&'static Coverage> {
    let sra = has_sra.then_some(settings.sra.model);
    // Without SRA readings there is nothing to weigh: those rows hold for either weight.
    let weight = if has_sra {
        settings.sra.weight
    } else {
        SraWeight::Paper
    };
    CALIBRATION.iter().find(|c| {
        c.cost == settings.cost
            && c.sra == sra
            && c.weight == weight
            && c.fresnel == settings.fresnel
    })
}

/// Whether the bootstrap intervals of a fit with these settings, of a scan with or without SRA
/// readings, are calibrated 95 % intervals, and if not, why: `Ok(())` or `Err(note)`.
pub fn calibration(settings: &Settings, has_sra: bool) -> Result<(), String> {
    if settings.model != crate::model::ModelKind::Paper {
        return Err(format!(
            "coverage was measured with the paper's model, not {} (its extra parameters are \
             held at the point fit's): these are bootstrap intervals, not calibrated 95 % \
             intervals",
            settings.model.name()
        ));
    }
    if !CALIBRATION.iter().any(|c| c.fresnel == settings.fresnel) {
        return Err(format!(
            "coverage was measured with the exact and the paper's (incidence) Fresnel factors, \
             not {}: these are bootstrap intervals, not calibrated 95 % intervals",
            settings.fresnel.name()
        ));
    }
    let Some(c) = coverage(settings, has_sra) else {
        let scans = if has_sra && settings.sra.weight.is_paper() {
            format!("with the {} SRA model", settings.sra.model)
        } else if has_sra {
            format!(
                "with the {} SRA model, {}",
                settings.sra.model, settings.sra.weight
            )
        } else {
            "on scans without SRA readings".to_string()
        };
        return Err(format!(
            "coverage under {} and the {} Fresnel factor was not measured {scans}: these are \
             bootstrap intervals, not calibrated 95 % intervals",
            settings.cost,
            settings.fresnel.name()
        ));
    };
    if c.holds() {
        // Synthetic truths say the noise is covered; real paint says whether the misfit is.
        let real = held_out_coverage(settings.cost, settings.fresnel)
            .expect("every Fresnel factor with synthetic coverage has a held-out row");
        if real.l >= CALIBRATED_AT {
            return Ok(());
        }
        return Err(format!(
            "not calibrated 95 % intervals: under {} the 95 % prediction intervals of held-out \
             geometries held the measured L* in only {:.1} % of the {} real exports' geometries \
             (SCIENCE.md §10); read them as a lower bound on the uncertainty",
            settings.cost, real.l, real.files,
        ));
    }
    let low: Vec<String> = [
        ("ks", c.ks),
        ("alpha", c.alpha),
        ("ior", c.ior),
        ("kd (lowest band)", c.kd_lowest),
    ]
    .iter()
    .filter(|(_, v)| *v < CALIBRATED_AT)
    .map(|(n, v)| format!("{n} {v:.1} %"))
    .collect();
    Err(format!(
        "not calibrated 95 % intervals: under {} {} they held the truth in only {} of {} \
         synthetic trials (SCIENCE.md §10); read them as a lower bound on the uncertainty",
        c.cost,
        c.scans(),
        low.join(", "),
        c.trials,
    ))
}

impl Uncertainty {
    /// Whether `value` of parameter `name` ("ks", "alpha", "ior") lies within its interval.
    pub fn contains(&self, name: &str, value: f64) -> bool {
        let [lo, hi] = match name {
            "ks" => self.ks,
            "alpha" => self.alpha,
            "ior" => self.ior,
            _ => return false,
        };
        lo <= value && value <= hi
    }
}

/// Why a bootstrap did not finish.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum UncertaintyError {
    #[error("bootstrap needs at least 2 resamples, got {0}; use 200 for 95 % intervals")]
    TooFewResamples(u32),
    #[error("bootstrap noise σ {0} must be finite and between 0 and 0.5")]
    Noise(f64),
    #[error("bootstrap refit {index}: {source}")]
    Refit {
        index: u32,
        #[source]
        source: FitError,
    },
    #[error("bootstrap cancelled")]
    Cancelled,
}

/// The relative noise σ of one processed value, estimated from the 12 MA-T12 spectra.
///
/// At band b the MA-T12 values are `kd(b) + s_g` times noise, so `d_g(b) = M_g(b) − mean_g M(b)`
/// is `s_g − mean s` (flat in λ) plus noise, and its second difference
/// `D = d(b) − (d(b−1) + d(b+1))/2` is noise only. Each D is divided by its standard deviation
/// under σ = 1 (computed from the measured values as the noise's scale), and σ is the RMS of
/// the 12 × 29 standardised contrasts.
pub fn estimate_noise(measured: &MeasuredBrdf) -> f64 {
    let n = MA_T12_COUNT as f64;
    let m = &measured.values;
    // Var(d_g(b)) / σ² = M_g² (1 − 2/n) + Σ_g' M_g'² / n².
    let var_d = |g: usize, b: usize| {
        let sum_sq: f64 = (0..MA_T12_COUNT).map(|h| m[h][b] * m[h][b]).sum();
        m[g][b] * m[g][b] * (1.0 - 2.0 / n) + sum_sq / (n * n)
    };
    let mean = |b: usize| (0..MA_T12_COUNT).map(|h| m[h][b]).sum::<f64>() / n;
    let (mut sum, mut count) = (0.0, 0usize);
    for g in 0..MA_T12_COUNT {
        for b in 1..BANDS - 1 {
            let d = |b: usize| m[g][b] - mean(b);
            let contrast = d(b) - 0.5 * (d(b - 1) + d(b + 1));
            // The three d's are independent apart from their shared means, whose covariance
            // is of order 1/n²; it is left out (a 1 % effect on σ at n = 12).
            let var = var_d(g, b) + 0.25 * (var_d(g, b - 1) + var_d(g, b + 1));
            if var > 0.0 && var.is_finite() {
                sum += contrast * contrast / var;
                count += 1;
            }
        }
    }
    if count == 0 {
        0.0
    } else {
        (sum / count as f64).sqrt()
    }
}

/// One resample: `measured` with multiplicative N(1, σ) noise, per band at the MA-T12
/// geometries and one factor per SRA geometry.
pub fn resample(measured: &MeasuredBrdf, sigma: f64, rng: &mut ChaCha8Rng) -> MeasuredBrdf {
    let mut out = *measured;
    for (g, geo) in GEOMETRIES.iter().enumerate() {
        match geo.device {
            Device::MaT12 => {
                for v in out.values[g].iter_mut() {
                    *v *= factor(sigma, rng);
                }
            }
            Device::Sra => {
                let f = factor(sigma, rng);
                for v in out.values[g].iter_mut() {
                    *v *= f;
                }
            }
        }
    }
    out
}

/// N(1, σ), redrawn if not positive (a reading is never negative; rare below σ = 0.2).
fn factor(sigma: f64, rng: &mut ChaCha8Rng) -> f64 {
    if sigma == 0.0 {
        return 1.0;
    }
    loop {
        let f = 1.0 + sigma * crate::stats::standard_normal(rng);
        if f > 0.0 {
            return f;
        }
    }
}

/// The `q` quantile (0..1) of `xs` by linear interpolation between order statistics
/// (Hyndman & Fan type 7, the default of R and NumPy).
pub fn quantile(xs: &mut [f64], q: f64) -> f64 {
    xs.sort_by(f64::total_cmp);
    at_position(xs, (xs.len() - 1) as f64 * q)
}

/// The value at 0-based position `h` of the sorted `xs`, interpolated between its neighbours.
fn at_position(sorted: &[f64], h: f64) -> f64 {
    let (lo, hi) = (h.floor() as usize, h.ceil() as usize);
    sorted[lo] + (h - lo as f64) * (sorted[hi] - sorted[lo])
}

/// The central `level` share of `xs`: its (1 − level)/2 and (1 + level)/2 quantiles (type 7),
/// the upper taken at the mirror position of the lower, so that both ends are exact order
/// statistics wherever the level puts them on one (0.95 of 201 values: the 6th and the 196th).
fn interval(xs: &mut [f64], level: f64) -> Interval {
    xs.sort_by(f64::total_cmp);
    // (1 − 0.95)/2 is 0.025000000000000022 in binary; rounded to 1e-9 it is 0.025.
    let tail = ((1.0 - level) / 2.0 * 1e9).round() / 1e9;
    let last = (xs.len() - 1) as f64;
    [
        at_position(xs, last * tail),
        at_position(xs, last - last * tail),
    ]
}

/// What one refit contributes: its parameters and its ΔE00 summaries against its resample.
#[derive(Debug, Clone, PartialEq)]
pub struct Draw {
    pub params: Params,
    pub de_mean: f64,
    pub de_diffuse: f64,
    pub de_specular: Option<f64>,
}

/// The refits of a bootstrap: the noise σ the resamples were drawn with and one [`Draw`] per
/// resample, in resample order.
#[derive(Debug, Clone, PartialEq)]
pub struct Draws {
    pub sigma: f64,
    pub draws: Vec<Draw>,
}

/// The point fit a bootstrap starts from: the measured BRDF it was fitted to, the settings it was
/// made with, the colorimetry of its ΔE00 summaries, and its parameters.
#[derive(Debug, Clone, Copy)]
pub struct PointFit<'a> {
    pub measured: &'a MeasuredBrdf,
    pub settings: &'a Settings,
    pub colorimetry: Colorimetry,
    pub params: &'a Params,
}

/// Draws the resamples of the point fit's measured BRDF and refits each from the point fit;
/// `cancel` stops it between refits. [`bootstrap`] turns them into intervals.
pub fn draw(
    fit: PointFit<'_>,
    opts: &BootstrapOptions,
    cancel: &AtomicBool,
) -> Result<Draws, UncertaintyError> {
    if opts.resamples < 2 {
        return Err(UncertaintyError::TooFewResamples(opts.resamples));
    }
    let sigma = opts.noise.unwrap_or_else(|| estimate_noise(fit.measured));
    if !(sigma.is_finite() && (0.0..=0.5).contains(&sigma)) {
        return Err(UncertaintyError::Noise(sigma));
    }
    let n = opts.resamples;
    let threads = opts.threads.clamp(1, n as usize);
    let one = |i: u32| -> Result<Draw, UncertaintyError> {
        if cancel.load(Ordering::Relaxed) {
            return Err(UncertaintyError::Cancelled);
        }
        let mut rng = ChaCha8Rng::seed_from_u64(opts.seed);
        rng.set_stream(u64::from(i));
        let m = resample(fit.measured, sigma, &mut rng);
        let refit = match opts.refit {
            Refit::ByCost => Refit::for_cost(fit.settings.cost),
            r => r,
        };
        let out = match refit {
            Refit::FullSearch => crate::optimise::fit(&m, fit.settings),
            _ => refit_local(&m, fit.settings, fit.params),
        }
        .map_err(|source| UncertaintyError::Refit { index: i, source })?;
        let est = model::evaluate_model(
            &out.params,
            fit.settings.model,
            fit.settings.fresnel,
            &SpecularGeometry::all(),
        );
        let e = evaluate_with(&m.values, &est, fit.colorimetry, m.geometries);
        Ok(Draw {
            params: out.params,
            de_mean: e.all.mean,
            de_diffuse: e.diffuse.mean,
            de_specular: e.specular.map(|s| s.mean),
        })
    };
    // Resample i goes to thread i mod threads; every draw is independent of the split.
    let mut draws: Vec<Option<Result<Draw, UncertaintyError>>> = (0..n).map(|_| None).collect();
    std::thread::scope(|scope| {
        let handles: Vec<_> = (0..threads)
            .map(|t| {
                let one = &one;
                scope.spawn(move || {
                    (t as u32..n)
                        .step_by(threads)
                        .map(|i| (i, one(i)))
                        .collect::<Vec<_>>()
                })
            })
            .collect();
        for h in handles {
            for (i, d) in h.join().expect("bootstrap thread panicked") {
                draws[i as usize] = Some(d);
            }
        }
    });
    let draws = draws
        .into_iter()
        .map(|d| d.expect("every resample ran"))
        .collect::<Result<_, _>>()?;
    Ok(Draws { sigma, draws })
}

/// Bootstraps the fit `point` of `measured` (made with `settings`) and widens the intervals by
/// its leave-one-geometry-out jackknife ([`crate::uncertainty::jackknife`]), so that they include the
/// model's misfit; `cancel` stops it between refits.
pub fn bootstrap(
    measured: &MeasuredBrdf,
    settings: &Settings,
    colorimetry: Colorimetry,
    point: &Params,
    opts: &BootstrapOptions,
    cancel: &AtomicBool,
) -> Result<Uncertainty, UncertaintyError> {
    let fit = PointFit {
        measured,
        settings,
        colorimetry,
        params: point,
    };
    let draws = draw(fit, opts, cancel)?;
    let jk = crate::uncertainty::jackknife::jackknife(fit, cancel)?;
    Ok(
        Uncertainty::from_draws(&draws, settings, measured.geometries.has_sra(), opts)
            .with_jackknife(&jk, point, settings),
    )
}

impl Uncertainty {
    /// The intervals of the bootstrap `draws` of a fit made with `settings`, of a scan with or
    /// without SRA readings, drawn with `opts`.
    pub fn from_draws(
        draws: &Draws,
        settings: &Settings,
        has_sra: bool,
        opts: &BootstrapOptions,
    ) -> Uncertainty {
        let level = percentile_level(settings.cost);
        let col = |f: &dyn Fn(&Draw) -> f64| -> Interval {
            let mut xs: Vec<f64> = draws.draws.iter().map(f).collect();
            interval(&mut xs, level)
        };
        let kd: Vec<Interval> = (0..BANDS).map(|b| col(&|d| d.params.kd[b])).collect();
        let rated = calibration(settings, has_sra);
        Uncertainty {
            calibrated: rated.is_ok(),
            note: rated.err(),
            method: METHOD.to_string(),
            resamples: opts.resamples,
            noise: draws.sigma,
            seed: opts.seed,
            percentile_level: level,
            ks: col(&|d| d.params.ks),
            alpha: col(&|d| d.params.alpha),
            ior: col(&|d| d.params.ior),
            kd,
            delta_e00_mean: col(&|d| d.de_mean),
            delta_e00_diffuse_mean: col(&|d| d.de_diffuse),
            delta_e00_specular_mean: has_sra.then(|| col(&|d| d.de_specular.unwrap_or(f64::NAN))),
            at_bound: Vec::new(),
            misfit: None,
        }
    }

    /// These bootstrap intervals widened by the jackknife `jk` of the point fit `point` made
    /// with `settings` (each interval the hull of both), with the parameters at a bound named
    /// and the verdict withdrawn where one is.
    pub fn with_jackknife(
        mut self,
        jk: &crate::uncertainty::jackknife::Jackknife,
        point: &Params,
        settings: &Settings,
    ) -> Uncertainty {
        use crate::uncertainty::jackknife::hull;
        let misfit = jk.misfit(point, &settings.bounds);
        self.ks = hull(self.ks, misfit.ks);
        self.alpha = hull(self.alpha, misfit.alpha);
        self.ior = hull(self.ior, misfit.ior);
        for (iv, m) in self.kd.iter_mut().zip(&misfit.kd) {
            *iv = hull(*iv, *m);
        }
        self.misfit = Some(misfit);
        self.at_bound = crate::uncertainty::jackknife::at_bound(point, &settings.bounds);
        if !self.at_bound.is_empty() {
            self.calibrated = false;
            self.note = Some(format!(
                "{} at a bound of the range: the fit is not identified there and an interval \
                 collapsed on the bound says nothing about the parameter; these are not \
                 calibrated 95 % intervals",
                self.at_bound.join(", ")
            ));
        }
        self
    }
}

/// Per-geometry count, kept next to the resampling so a changed geometry table fails here.
const _: () = assert!(GEOMETRY_COUNT == MA_T12_COUNT + 2);

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cost::CostFunction;
    use crate::fit::{FitRequest, fit_scan};
    use crate::processing::{ProcessingOptions, process};
    use crate::synth::{SynthOptions, paper_samples, synth_scan};

    fn scan_measured(sample: usize, noise: f64, seed: u64) -> MeasuredBrdf {
        let scan = synth_scan(
            &paper_samples()[sample],
            &SynthOptions {
                noise,
                seed,
                ..Default::default()
            },
        )
        .unwrap();
        process(&scan, &ProcessingOptions::default()).unwrap()
    }

    #[test]
    fn quantiles_follow_type_7() {
        let mut xs = [3.0, 1.0, 2.0, 4.0, 5.0];
        assert_eq!(quantile(&mut xs, 0.0), 1.0);
        assert_eq!(quantile(&mut xs, 0.5), 3.0);
        assert_eq!(quantile(&mut xs, 1.0), 5.0);
        assert_eq!(quantile(&mut xs, 0.125), 1.5);
        let mut ys: Vec<f64> = (0..=200).map(f64::from).collect();
        assert_eq!(interval(&mut ys, 0.95), [5.0, 195.0]);
        assert_eq!(interval(&mut ys, 0.99), [1.0, 199.0]);
    }

    #[test]
    fn noise_estimate_is_zero_on_a_noise_free_scan_and_recovers_sigma() {
        let clean = scan_measured(0, 0.0, 0);
        assert!(estimate_noise(&clean) < 1e-12, "{}", estimate_noise(&clean));
        // Readings carry σ on sample and reference alike: a processed value has √2·σ.
        for (sigma, seed) in [(0.01, 5), (0.03, 6), (0.003, 7)] {
            let m = scan_measured(2, sigma, seed);
            let got = estimate_noise(&m);
            let want = sigma * 2f64.sqrt();
            assert!(
                (got / want - 1.0).abs() < 0.15,
                "σ {sigma}: estimated {got}, want {want}"
            );
        }
    }

    #[test]
    fn resampling_is_multiplicative_flat_at_the_sra_and_seeded() {
        let m = scan_measured(1, 0.0, 0);
        let mut a = ChaCha8Rng::seed_from_u64(9);
        let mut b = ChaCha8Rng::seed_from_u64(9);
        let ra = resample(&m, 0.02, &mut a);
        assert_eq!(ra, resample(&m, 0.02, &mut b));
        // The SRA spectra stay flat: one factor for the 31 bands.
        for g in MA_T12_COUNT..GEOMETRY_COUNT {
            let f = ra.values[g][0] / m.values[g][0];
            assert!(
                ra.values[g]
                    .iter()
                    .zip(&m.values[g])
                    .all(|(r, v)| (r / v - f).abs() < 1e-12)
            );
        }
        // MA-T12 relative deviations have sd ≈ σ.
        let dev: Vec<f64> = (0..MA_T12_COUNT)
            .flat_map(|g| (0..BANDS).map(move |b| (g, b)))
            .map(|(g, b)| ra.values[g][b] / m.values[g][b] - 1.0)
            .collect();
        let sd = (dev.iter().map(|d| d * d).sum::<f64>() / dev.len() as f64).sqrt();
        assert!((sd - 0.02).abs() < 0.003, "sd {sd}");
        assert_eq!(resample(&m, 0.0, &mut a), m);
    }

    #[test]
    fn intervals_bracket_the_point_fit_and_do_not_depend_on_threads() {
        let scan = synth_scan(
            &paper_samples()[0],
            &SynthOptions {
                noise: 0.01,
                seed: 11,
                ..Default::default()
            },
        )
        .unwrap();
        let request = FitRequest {
            settings: Settings {
                cost: CostFunction::Cf1,
                ..Settings::default()
            },
            ..FitRequest::default()
        };
        let report = fit_scan(&scan, &request).unwrap();
        let never = AtomicBool::new(false);
        let opts = BootstrapOptions {
            resamples: 24,
            ..Default::default()
        };
        let run = |threads| {
            bootstrap(
                &report.measured,
                &request.settings,
                request.colorimetry,
                &report.outcome.params,
                &BootstrapOptions { threads, ..opts },
                &never,
            )
            .unwrap()
        };
        let u = run(1);
        assert_eq!(u, run(2));
        assert_eq!(u.method, METHOD);
        assert_eq!(u.kd.len(), BANDS);
        let p = &report.outcome.params;
        for (name, v, iv) in [
            ("ks", p.ks, u.ks),
            ("alpha", p.alpha, u.alpha),
            ("ior", p.ior, u.ior),
        ] {
            assert!(iv[0] < iv[1], "{name}: {iv:?}");
            // 24 draws centred on the point fit: it lies inside.
            assert!(iv[0] <= v && v <= iv[1], "{name} {v} not in {iv:?}");
        }
        for (b, iv) in u.kd.iter().enumerate() {
            assert!(iv[0] <= p.kd[b] && p.kd[b] <= iv[1], "kd[{b}]");
        }
        assert!(u.delta_e00_mean[0] <= u.delta_e00_mean[1]);
        assert!((u.noise / (0.01 * 2f64.sqrt()) - 1.0).abs() < 0.2);
        // The verdict of `calibration` travels with the intervals, in the JSON too.
        assert_eq!(u.calibrated, calibration(&request.settings, true).is_ok());
        assert_eq!(u.note, calibration(&request.settings, true).err());
        let json = serde_json::to_value(&u).unwrap();
        assert_eq!(json["calibrated"], u.calibrated);
        // Intervals stored before the verdict existed read as not calibrated, with a note.
        let mut old = json.clone();
        old.as_object_mut().unwrap().remove("calibrated");
        old.as_object_mut().unwrap().remove("note");
        let read: Uncertainty = serde_json::from_value(old).unwrap();
        assert!(!read.calibrated);
        assert!(read.note.unwrap().contains("refit to rate them"));
    }

    #[test]
    fn intervals_say_whether_their_coverage_was_measured_to_hold() {
        use crate::sra_reading::SraReading;
        let settings = |cost, sra| Settings {
            cost,
            sra: SraReading::default().with_model(sra),
            ..Settings::default()
        };
        // Every cost function has a measurement under each SRA model, and the verdict follows
        // it.
        for cost in CostFunction::ALL {
            for sra in SraModel::ALL {
                let c = coverage(&settings(cost, sra), true).unwrap();
                assert_eq!((c.cost, c.sra), (cost, Some(sra)));
                let real =
                    held_out_coverage(cost, FresnelCosine::Incidence).unwrap().l >= CALIBRATED_AT;
                match calibration(&settings(cost, sra), true) {
                    Ok(()) => assert!(c.holds() && real, "{cost} {sra}"),
                    Err(note) if !c.holds() => {
                        assert!(note.contains("not calibrated 95 % intervals"), "{note}");
                        let scans = format!("under {cost} with the {sra} SRA model");
                        assert!(note.contains(&scans), "{note}");
                    }
                    Err(note) => {
                        assert!(!real, "{cost} {sra}");
                        assert!(note.contains("held-out"), "{note}");
                    }
                }
            }
            // Without SRA readings the SRA model does not enter: one verdict per cost
            // function, not calibrated until measured.
            for sra in SraModel::ALL {
                let got = calibration(&settings(cost, sra), false);
                match coverage(&settings(cost, sra), false) {
                    Some(c) => assert_eq!(
                        got.is_ok(),
                        c.holds() && held_out_coverage(cost, c.fresnel).unwrap().l >= CALIBRATED_AT
                    ),
                    None => assert!(
                        got.unwrap_err()
                            .contains("not measured on scans without SRA")
                    ),
                }
            }
        }
        // The exact Fresnel (the default of measured scans) was measured with the luminance
        // SRA model and without SRA readings, each with its held-out row on real paint; the
        // flat SRA model under it and Schlick on l·h were not.
        for cost in CostFunction::ALL {
            let exact = |sra| Settings {
                fresnel: FresnelCosine::Exact,
                ..settings(cost, sra)
            };
            for has_sra in [true, false] {
                let s = exact(SraModel::Luminance);
                let c = coverage(&s, has_sra).unwrap();
                assert_eq!(c.fresnel, FresnelCosine::Exact);
                let real = held_out_coverage(cost, FresnelCosine::Exact).unwrap();
                assert_eq!(
                    calibration(&s, has_sra).is_ok(),
                    c.holds() && real.l >= CALIBRATED_AT
                );
            }
            let flat = calibration(&exact(SraModel::Flat), true).unwrap_err();
            assert!(
                flat.contains("was not measured with the flat SRA model"),
                "{flat}"
            );
            let half = Settings {
                fresnel: FresnelCosine::LightHalf,
                ..settings(cost, SraModel::Luminance)
            };
            assert!(
                calibration(&half, true)
                    .unwrap_err()
                    .contains("not light-half")
            );
            // The measured preset's own choices, its SRA weight for this cost function
            // included, were measured; the other weight is not taken for it.
            let p = crate::optimise::Preset::Measured;
            let weighed = |weight| Settings {
                sra: SraReading::default()
                    .with_model(p.sra())
                    .with_weight(weight),
                ..exact(p.sra())
            };
            let c = coverage(&weighed(p.sra_weight(cost)), true).unwrap();
            assert_eq!(c.weight, p.sra_weight(cost));
            if let Some(other) = coverage(&weighed(SraWeight::Balanced), true) {
                assert_eq!(other.weight, SraWeight::Balanced);
            }
        }
    }

    #[test]
    fn a_fit_at_a_bound_is_not_calibrated() {
        use crate::colour::Lab;
        use crate::uncertainty::jackknife::{HeldOut, Jackknife};
        let settings = Settings::default();
        let mut point = paper_samples()[0].params;
        point.ior = settings.bounds.ior.1;
        let lab = Lab {
            l: 50.0,
            a: 0.0,
            b: 0.0,
        };
        // Twelve left-out refits that move ks by up to 11 % and leave μ on its bound.
        let held_out = (0..MA_T12_COUNT)
            .map(|g| {
                let mut p = point;
                p.ks *= 1.0 + 0.01 * g as f64;
                HeldOut {
                    geometry: g,
                    params: p,
                    measured: lab,
                    predicted: lab,
                }
            })
            .collect();
        let jk = Jackknife { held_out };
        let mut u = crate::test_support::made_up_uncertainty(&point, true);
        // A bootstrap that claims no spread of ks at all.
        u.ks = [point.ks, point.ks];
        let u = u.with_jackknife(&jk, &point, &settings);
        assert!(!u.calibrated);
        assert_eq!(u.at_bound, ["ior"]);
        assert!(
            u.note.as_deref().unwrap().contains("ior at a bound"),
            "{:?}",
            u.note
        );
        // The jackknife's spread widens ks to hold every left-out refit.
        for h in &jk.held_out {
            assert!(
                u.contains("ks", h.params.ks),
                "{} not in {:?}",
                h.params.ks,
                u.ks
            );
        }
        let misfit = u.misfit.as_ref().unwrap();
        assert_eq!(misfit.refits, 12);
        // μ's own interval collapses on the bound.
        assert_eq!(misfit.ior, [3.0, 3.0]);
        let json = serde_json::to_value(&u).unwrap();
        assert_eq!(json["at_bound"], serde_json::json!(["ior"]));
        assert_eq!(
            json["misfit"]["method"],
            crate::uncertainty::jackknife::METHOD
        );
        // Intervals stored before the jackknife read with no parameter at a bound.
        let mut old = json.clone();
        old.as_object_mut().unwrap().remove("at_bound");
        old.as_object_mut().unwrap().remove("misfit");
        let read: Uncertainty = serde_json::from_value(old).unwrap();
        assert!(read.at_bound.is_empty() && read.misfit.is_none());
    }

    #[test]
    fn noise_free_scans_give_intervals_of_zero_width_at_the_truth() {
        let m = scan_measured(3, 0.0, 0);
        let truth = &paper_samples()[3].params;
        let settings = Settings {
            cost: CostFunction::Cf1,
            ..Settings::default()
        };
        let never = AtomicBool::new(false);
        let u = bootstrap(
            &m,
            &settings,
            Colorimetry::default(),
            truth,
            &BootstrapOptions {
                resamples: 4,
                ..Default::default()
            },
            &never,
        )
        .unwrap();
        assert!(u.noise < 1e-12, "{}", u.noise);
        assert!((u.ks[1] - u.ks[0]).abs() < 1e-4 * truth.ks, "{:?}", u.ks);
    }

    #[test]
    fn refuses_bad_options_and_stops_when_cancelled() {
        let m = scan_measured(0, 0.01, 1);
        let p = paper_samples()[0].params;
        let s = Settings::default();
        let never = AtomicBool::new(false);
        let c = Colorimetry::default();
        let one = BootstrapOptions {
            resamples: 1,
            ..Default::default()
        };
        assert_eq!(
            bootstrap(&m, &s, c, &p, &one, &never),
            Err(UncertaintyError::TooFewResamples(1))
        );
        let noisy = BootstrapOptions {
            noise: Some(f64::NAN),
            ..Default::default()
        };
        assert!(matches!(
            bootstrap(&m, &s, c, &p, &noisy, &never),
            Err(UncertaintyError::Noise(_))
        ));
        let yes = AtomicBool::new(true);
        assert_eq!(
            bootstrap(&m, &s, c, &p, &BootstrapOptions::default(), &yes),
            Err(UncertaintyError::Cancelled)
        );
    }
}
