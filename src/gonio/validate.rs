//! The handheld estimate against a measured BRDF (`brdfd validate`, SCIENCE.md §12.6): derive
//! the 14 readings the two instruments would give on the measured material, fit them under
//! every cost function and model option, predict every measured direction (ASTM) or a dense
//! grid (RGL), and report ΔE00 beside two references: the oracle (the same model form fitted
//! to all directions: the model's own limit) and the Lambert baseline (one reading
//! everywhere).
//!
//! - Readings: MA-T12 reflectance factor `π·f` at its 12 geometries (processed back to `f`,
//!   sr⁻¹, as an instrument-calibrated export is); SRA the luminance `Y` of `f` at its two
//!   geometries under the SRA model [`Options::sra`] (ISO 2813: illuminant C, 2°).
//! - Predictions: the fitted model at each direction pair ([`crate::model::evaluate_at`]),
//!   ΔE00 against the measured BRDF, both as reflectance factor `π·f`, under
//!   [`Options::colorimetry`] (D65/10°, ASTM E308). Near-specular: half vector within
//!   [`NEAR_SPECULAR_DEG`] of the normal.
//! - Oracle: the same model form fitted to every prediction direction, minimising the
//!   prediction metric itself, the mean ΔE00 over the directions ([`oracle`]): the limit of
//!   the form, apart from what the readings pin down. Nelder–Mead in kd's XYZ (kd moves by the
//!   least-norm spectrum that changes its tristimulus values; only they reach ΔE00), ks, α, μ
//!   [and σ], started from the best of: the report's fits of the same form, a weighted
//!   least-squares fit over every direction (kd and ks linear for each (α, μ[, σ]) of a
//!   grid refined once, weights `1/ȳ²`) and the Lambert baseline. So the oracle is never worse
//!   than any prediction of its form in the same report, nor than Lambert.

use std::collections::BTreeMap;
use std::ops::ControlFlow;
use std::time::Instant;

use serde::Serialize;

use super::{Channels, Measurement, RGB_UPSAMPLING, Steps, direction};
use crate::colour::{Colorimetry, Lab, Observer, Weighting, Xyz, ciede2000, xyz_to_lab};
use crate::cost::CostFunction;
use crate::fit::{FitRequest, ParamsDocument, fit_measured};
use crate::geometry::{GEOMETRIES, GEOMETRY_COUNT, GeometrySet, MA_T12_COUNT, Vec3};
use crate::model::{
    Bounds, EXTRA, FresnelCosine, ModelKind, OREN_NAYAR_SIGMA, Params, SpecularGeometry,
    evaluate_at, oren_nayar_coefficients, oren_nayar_geometry_at, specular_term,
};
use crate::optimise::{Settings, nelder_mead};
use crate::processing::MeasuredBrdf;
use crate::reach::Reach;
use crate::spectral::{BANDS, Spectrum};
use crate::sra_reading::{SraReading, SraWeight, luminance_with};

/// Half-vector angle below which a direction counts as near-specular, degrees.
pub const NEAR_SPECULAR_DEG: f64 = 10.0;

/// The MA-T12 geometry whose reading the Lambert baseline predicts everywhere (0°/45°).
pub const LAMBERT_GEOMETRY: &str = "45as45";

/// The RGL prediction grid, degrees: θi 0–75 every 5, θr 5–80 every 5, φ 0–180 every 15.
pub const RGL_GRID: (Steps, Steps, Steps) =
    ((0.0, 75.0, 5.0), (5.0, 80.0, 5.0), (0.0, 180.0, 15.0));

/// What a validation runs with.
#[derive(Debug, Clone, Copy)]
pub struct Options {
    /// How spectra become L*a*b* (D65/10°, ASTM E308 by default).
    pub colorimetry: Colorimetry,
    /// The SRA reading model the readings are derived and fitted with.
    pub sra: SraReading,
    /// The optimiser's seed.
    pub seed: u64,
    /// The model forms an oracle is fitted for (the first is the report's `oracle`).
    pub oracle_forms: &'static [(ModelKind, FresnelCosine)],
    /// Cross-validate each default fit and hold its prediction interval against every
    /// direction ([`IntervalCoverage`]; 12 more fits per cost function, about doubling the
    /// run). Default false.
    pub intervals: bool,
}

/// Every model form the fits use: the paper's, exact Fresnel, Oren–Nayar.
pub const ORACLE_FORMS: &[(ModelKind, FresnelCosine)] = &[
    (ModelKind::Paper, FresnelCosine::Incidence),
    (ModelKind::Paper, FresnelCosine::Exact),
    (ModelKind::OrenNayar, FresnelCosine::Incidence),
];

impl Default for Options {
    fn default() -> Self {
        Options {
            colorimetry: Colorimetry {
                observer: Observer::Cie1964TenDegree,
                weighting: Weighting::AstmE308,
            },
            sra: SraReading::LUMINANCE,
            seed: Settings::default().seed,
            oracle_forms: ORACLE_FORMS,
            intervals: false,
        }
    }
}

/// One fit a validation makes: cost function, model form, Fresnel factor, which readings.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Variant {
    pub cost: CostFunction,
    pub model: ModelKind,
    pub fresnel: FresnelCosine,
    /// All 14 readings, or the 12 MA-T12 ones alone.
    pub geometries: GeometrySet,
    /// The SRA readings' weight in the cost (SCIENCE.md §5.2).
    pub sra_weight: SraWeight,
}

impl Variant {
    /// What a measured scan is fitted with by default (`--preset measured`: the paper's model
    /// form with the exact Fresnel and the preset's SRA weight) on all 14 readings.
    pub fn is_default(&self) -> bool {
        let measured = crate::optimise::Preset::Measured;
        self.model == measured.model()
            && self.fresnel == measured.fresnel()
            && self.sra_weight == measured.sra_weight(self.cost)
            && self.geometries == GeometrySet::ALL
    }
}

/// Every fit `brdfd validate` makes: per cost function the paper's model with the paper's
/// Schlick on cos θi and with the exact Fresnel (the default of measured scans), Oren–Nayar, and
/// the paper's model with either Fresnel factor from the 12 MA-T12 readings alone. The exact
/// Fresnel fits weigh the SRA readings as the measured preset does for the cost function, the
/// others as the paper; where the measured preset balances them (cf1, m2), the exact Fresnel
/// fit with the paper's weights is made too.
pub fn variants() -> Vec<Variant> {
    variants_of(&CostFunction::ALL)
}

/// [`variants`] for the cost functions `costs` only.
pub fn variants_of(costs: &[CostFunction]) -> Vec<Variant> {
    let mut out = Vec::new();
    for &cost in costs {
        for (model, fresnel, geometries) in [
            (ModelKind::Paper, FresnelCosine::Incidence, GeometrySet::ALL),
            (ModelKind::Paper, FresnelCosine::Exact, GeometrySet::ALL),
            (
                ModelKind::OrenNayar,
                FresnelCosine::Incidence,
                GeometrySet::ALL,
            ),
            (
                ModelKind::Paper,
                FresnelCosine::Incidence,
                GeometrySet::MA_T12,
            ),
            (ModelKind::Paper, FresnelCosine::Exact, GeometrySet::MA_T12),
        ] {
            let measured = crate::optimise::Preset::Measured;
            let sra_weight = if fresnel == measured.fresnel() {
                measured.sra_weight(cost)
            } else {
                SraWeight::Paper
            };
            out.push(Variant {
                cost,
                model,
                fresnel,
                geometries,
                sra_weight,
            });
            if sra_weight != SraWeight::Paper && geometries == GeometrySet::ALL {
                out.push(Variant {
                    cost,
                    model,
                    fresnel,
                    geometries,
                    sra_weight: SraWeight::Paper,
                });
            }
        }
    }
    out
}

/// ΔE00 over a set of predicted directions.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Prediction {
    pub mean: f64,
    pub median: f64,
    /// 95th percentile (nearest rank).
    pub p95: f64,
    pub max: f64,
    /// Mean over the near-specular directions (θh < 10°); `None` when there are none.
    pub near_specular_mean: Option<f64>,
    /// Mean over the other directions.
    pub rest_mean: Option<f64>,
}

impl Prediction {
    /// Summarises ΔE00 values; `near[k]` says whether direction k is near-specular.
    pub fn of(de: &[f64], near: &[bool]) -> Prediction {
        let mut s = de.to_vec();
        s.sort_by(f64::total_cmp);
        let n = s.len().max(1);
        let mean_of = |it: &mut dyn Iterator<Item = f64>| {
            let (sum, count) = it.fold((0.0, 0usize), |(a, c), x| (a + x, c + 1));
            (count > 0).then(|| sum / count as f64)
        };
        Prediction {
            mean: mean_of(&mut de.iter().copied()).unwrap_or(f64::NAN),
            median: if s.len() % 2 == 1 {
                s[s.len() / 2]
            } else if s.is_empty() {
                f64::NAN
            } else {
                0.5 * (s[s.len() / 2 - 1] + s[s.len() / 2])
            },
            p95: s
                .get((0.95 * n as f64).ceil() as usize - 1)
                .copied()
                .unwrap_or(f64::NAN),
            max: s.last().copied().unwrap_or(f64::NAN),
            near_specular_mean: mean_of(
                &mut de.iter().zip(near).filter(|(_, n)| **n).map(|(d, _)| *d),
            ),
            rest_mean: mean_of(&mut de.iter().zip(near).filter(|(_, n)| !**n).map(|(d, _)| *d)),
        }
    }
}

/// One reading the instruments would give.
#[derive(Debug, Clone, Serialize)]
pub struct Reading {
    /// The BRDF in sr⁻¹ exactly as the file gives it at this geometry (interpolated between
    /// measured directions for ASTM), one value per channel, before any conversion.
    pub raw: Vec<f64>,
    /// What the instrument reads: the reflectance factor π·f per band (MA-T12), or the
    /// luminance Y of f, sr⁻¹ (SRA).
    pub reading: Vec<f64>,
}

/// One fit and its prediction.
#[derive(Debug, Clone, Serialize)]
pub struct FitResult {
    pub cost: CostFunction,
    pub model: ModelKind,
    pub fresnel: FresnelCosine,
    /// `ma-t12+sra` (all 14) or `ma-t12` (the 12 MA-T12 readings alone).
    pub readings: &'static str,
    /// The SRA readings' weight in the cost (`paper` or `balanced`).
    pub sra_weight: SraWeight,
    /// What a measured scan is fitted with by default ([`Variant::is_default`]).
    pub default: bool,
    /// Mean ΔE00 at the MA-T12 geometries fitted (the spectral readings; the SRA's are
    /// achromatic and have no colour to compare).
    pub fit_delta_e00_mean: f64,
    pub params: ParamsDocument,
    pub prediction: Prediction,
    /// Wall-clock time of the fit, ms.
    pub wall_ms: f64,
    /// The reach verdict this fit gives the material from its readings alone
    /// ([`crate::reach`]): what a scan of it would be told, to hold against `prediction`.
    pub reach: Option<Reach>,
    /// How often the 95 % prediction interval of a direction's L*a*b*, built from the
    /// readings' own cross-validation, holds the measured colour (the default configuration's
    /// fits to all 14 readings, with [`Options::intervals`]; `None` for the others).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub interval_coverage: Option<IntervalCoverage>,
}

/// The prediction interval of a measured direction, held against the measurement: the fit's
/// prediction there ± `t(0.975, m − 1)·√(1 + 1/m)·s` per L*, a*, b*, `s` the root mean square
/// of the held-out errors at the m = 12 MA-T12 geometries (each predicted by a fit without it;
/// [`crate::crossval::crossval_held_out`]), the interval `brdfd crossval` gives a held-out
/// geometry (SCIENCE.md §10), applied to directions no reading was taken at.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct IntervalCoverage {
    /// Fraction of the predicted directions whose measured L* lies in its interval.
    pub l: f64,
    pub a: f64,
    pub b: f64,
    /// ... whose measured L*, a* and b* all lie in theirs.
    pub all: f64,
    /// The same for L* over the near-specular directions alone; `None` when there are none.
    pub near_specular_l: Option<f64>,
    /// The intervals' half-widths `t·√(1 + 1/m)·s`, L*, a*, b*.
    pub half_width: [f64; 3],
    /// The cross-validation's mean held-out ΔE00 at the MA-T12 geometries.
    pub held_out_mean: f64,
}

/// [`IntervalCoverage`] of the fit `p` over `targets`, from its cross-validation `cv`.
fn interval_coverage(
    targets: &[Target],
    colorimetry: Colorimetry,
    predicted: &dyn Fn(&Target) -> Spectrum,
    cv: &crate::crossval::CrossValidation,
) -> Option<IntervalCoverage> {
    let errors: Vec<[f64; 3]> = cv
        .held_out
        .iter()
        .map(|h| std::array::from_fn(|c| h.predicted_lab[c] - h.measured_lab[c]))
        .collect();
    // No position is left out of the errors: every held-out geometry is another direction.
    let widths = crate::uncertainty::jackknife::prediction_interval(&errors, usize::MAX, [0.0; 3])?;
    let half_width: [f64; 3] = std::array::from_fn(|c| widths[c][1]);
    let mut inside = [0usize; 4];
    let (mut near, mut near_inside) = (0usize, 0usize);
    for t in targets {
        let lab = colorimetry.reflectance_to_lab(&predicted(t).map(|x| std::f64::consts::PI * x));
        let err = [lab.l - t.lab.l, lab.a - t.lab.a, lab.b - t.lab.b];
        let ok: [bool; 3] = std::array::from_fn(|c| err[c].abs() <= half_width[c]);
        for c in 0..3 {
            inside[c] += usize::from(ok[c]);
        }
        inside[3] += usize::from(ok.iter().all(|&o| o));
        if t.near {
            near += 1;
            near_inside += usize::from(ok[0]);
        }
    }
    let n = targets.len().max(1) as f64;
    Some(IntervalCoverage {
        l: inside[0] as f64 / n,
        a: inside[1] as f64 / n,
        b: inside[2] as f64 / n,
        all: inside[3] as f64 / n,
        near_specular_l: (near > 0).then(|| near_inside as f64 / near as f64),
        half_width,
        held_out_mean: cv.held_out_mean,
    })
}

/// The oracle of one model form: fitted to every prediction direction.
#[derive(Debug, Clone, Serialize)]
pub struct Oracle {
    pub model: ModelKind,
    pub fresnel: FresnelCosine,
    pub params: ParamsDocument,
    /// What the polish started from: the best by mean ΔE00 of this form's fits in the
    /// report, the least-squares fit over every direction and the Lambert baseline.
    pub start: String,
    /// Mean ΔE00 at that start.
    pub start_mean: f64,
    /// Mean-ΔE00 evaluations the polish made.
    pub evaluations: u32,
    /// Wall-clock time of this oracle, ms.
    pub wall_ms: f64,
    #[serde(flatten)]
    pub prediction: Prediction,
}

/// The interpolation's own error (ASTM): every measured direction predicted from the others.
#[derive(Debug, Clone, Serialize)]
pub struct Interpolation {
    pub method: String,
    pub leave_one_out: Prediction,
}

/// The Lambert baseline.
#[derive(Debug, Clone, Serialize)]
pub struct Lambert {
    /// The geometry whose reading is predicted everywhere.
    pub geometry: &'static str,
    #[serde(flatten)]
    pub prediction: Prediction,
}

/// A whole validation (`brdfd validate --json`).
#[derive(Debug, Clone, Serialize)]
pub struct Report {
    pub material: String,
    /// The file, as named on the command line (set by the caller).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub file: Option<String>,
    pub format: &'static str,
    /// `spectral` or `rgb`.
    pub channels: &'static str,
    /// The spectral upsampling of an RGB file (measured and predicted alike).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub rgb_upsampling: Option<&'static str>,
    pub colorimetry: String,
    pub sra: SraReading,
    /// What was predicted: every measured direction, or the RGL grid.
    pub prediction_set: String,
    pub directions: usize,
    pub near_specular_directions: usize,
    pub readings: BTreeMap<&'static str, Reading>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub interpolation: Option<Interpolation>,
    pub fits: Vec<FitResult>,
    /// The oracle of the paper's model form (Schlick on cos θi).
    pub oracle: Oracle,
    /// The oracle of every model form the fits use.
    pub oracles: Vec<Oracle>,
    pub lambert: Lambert,
    /// The reach verdict of the cf2 fit to all 14 readings with exact Fresnel (the verdict's
    /// calibration; else the first such fit of another cost, else the first fit): what a scan
    /// of this material would be told.
    pub reach: Option<Reach>,
    pub wall_ms: f64,
    /// Every predicted direction under the default configuration's fit (cf2's when cf2 was
    /// run, else the first cost function's), for `brdfd validate --figures`; not in the JSON.
    #[serde(skip)]
    pub directions_of_default: Vec<DirectionError>,
    /// The cost function of that fit.
    #[serde(skip)]
    pub figures_cost: Option<CostFunction>,
}

/// One predicted direction of the default fit: where it is, and how the prediction did.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DirectionError {
    /// Incidence θi, degrees.
    pub theta_i_deg: f64,
    /// View θr, degrees.
    pub theta_r_deg: f64,
    /// Azimuth of the view from the plane of incidence, degrees in [0, 180]: 180 is the
    /// mirror side (the specular direction), 0 the side the light comes from.
    pub phi_deg: f64,
    pub delta_e00: f64,
    pub measured_l: f64,
    pub predicted_l: f64,
}

impl DirectionError {
    fn of(t: &Target, predicted: Lab) -> DirectionError {
        let theta = |w: Vec3| w[2].clamp(-1.0, 1.0).acos().to_degrees();
        let azimuth = |w: Vec3| w[1].atan2(w[0]).to_degrees();
        let mut phi = (azimuth(t.wo) - azimuth(t.wi)).rem_euclid(360.0);
        if phi > 180.0 {
            phi = 360.0 - phi;
        }
        // A view along the normal has no azimuth: put it in the plane.
        if t.wo[0].hypot(t.wo[1]) < 1e-9 {
            phi = 180.0;
        }
        DirectionError {
            theta_i_deg: theta(t.wi),
            theta_r_deg: theta(t.wo),
            phi_deg: phi,
            delta_e00: ciede2000(t.lab, predicted),
            measured_l: t.lab.l,
            predicted_l: predicted.l,
        }
    }
}

/// A direction pair to predict and its measured colour.
pub struct Target {
    pub wi: Vec3,
    pub wo: Vec3,
    pub measured: Spectrum,
    lab: Lab,
    near: bool,
}

/// The prediction directions of a measurement (module text) with their measured spectra.
pub fn targets(m: &Measurement, colorimetry: Colorimetry) -> (Vec<Target>, String) {
    let mk = |wi: Vec3, wo: Vec3, measured: Spectrum| {
        let h = super::normalize([wi[0] + wo[0], wi[1] + wo[1], wi[2] + wo[2]]);
        Target {
            wi,
            wo,
            measured,
            lab: colorimetry.reflectance_to_lab(&measured.map(|x| std::f64::consts::PI * x)),
            near: h[2] > NEAR_SPECULAR_DEG.to_radians().cos(),
        }
    };
    match m {
        Measurement::Astm(a) => (
            a.points
                .iter()
                .map(|p| {
                    let (wi, wo) = p.directions();
                    mk(wi, wo, a.channels.to_spectrum(&p.values))
                })
                .collect(),
            "every measured direction".to_string(),
        ),
        Measurement::Rgl(_) => {
            let ((ti0, ti1, tis), (tr0, tr1, trs), (p0, p1, ps)) = RGL_GRID;
            let steps = |a: f64, b: f64, s: f64| {
                (0..=((b - a) / s).round() as usize).map(move |k| a + s * k as f64)
            };
            let mut out = Vec::new();
            for ti in steps(ti0, ti1, tis) {
                for tr in steps(tr0, tr1, trs) {
                    for p in steps(p0, p1, ps) {
                        let wi = direction(ti.to_radians(), 0.0);
                        // φ = 180°: the far side of the normal (toward the mirror direction).
                        let wo = direction(tr.to_radians(), (180.0 - p).to_radians());
                        out.push(mk(wi, wo, m.spectrum(wi, wo)));
                    }
                }
            }
            (
                out,
                format!(
                    "grid θi {ti0}–{ti1}°, θr {tr0}–{tr1}°, φ {p0}–{p1}° every {tis}°/{trs}°/{ps}°"
                ),
            )
        }
    }
}

/// ΔE00 of a predicted BRDF at every target.
pub fn predict(
    targets: &[Target],
    colorimetry: Colorimetry,
    f: &dyn Fn(&Target) -> Spectrum,
) -> Prediction {
    let de: Vec<f64> = targets
        .iter()
        .map(|t| {
            let lab = colorimetry.reflectance_to_lab(&f(t).map(|x| std::f64::consts::PI * x));
            ciede2000(t.lab, lab)
        })
        .collect();
    let near: Vec<bool> = targets.iter().map(|t| t.near).collect();
    Prediction::of(&de, &near)
}

/// The measured BRDF the instruments' readings make (module text), and the readings.
pub fn readings(
    m: &Measurement,
    sra: SraReading,
) -> (MeasuredBrdf, BTreeMap<&'static str, Reading>) {
    let weights = sra.weights();
    let mut values = [[0.0; BANDS]; GEOMETRY_COUNT];
    let mut docs = BTreeMap::new();
    for g in &GEOMETRIES {
        let raw = m.raw(g.light(), g.view());
        let f = m.channels().to_spectrum(&raw);
        let reading = if g.index < MA_T12_COUNT {
            values[g.index] = f;
            f.iter().map(|x| std::f64::consts::PI * x).collect()
        } else {
            let y = luminance_with(&weights, &f);
            values[g.index] = [y; BANDS];
            vec![y]
        };
        docs.insert(g.name, Reading { raw, reading });
    }
    (MeasuredBrdf::full(values), docs)
}

/// The least-squares start of the oracle (module text): kd (31 bands) and ks by weighted linear
/// least squares, weights `1/ȳ²` (relative error), for each (α, μ[, σ]) of a grid refined once
/// around its best.
fn least_squares(problem: &OracleProblem) -> Params {
    let (targets, kind, fresnel) = (problem.targets, problem.kind, problem.fresnel);
    let bounds = Bounds::default();
    let w: Vec<f64> = targets
        .iter()
        .map(|t| {
            let y = t.measured.iter().sum::<f64>() / BANDS as f64;
            1.0 / y.max(1e-4).powi(2)
        })
        .collect();
    let sigmas: Vec<f64> = if kind == ModelKind::OrenNayar {
        vec![0.0, 0.5, 1.0]
    } else {
        vec![0.0]
    };
    let solve = |alpha: f64, ior: f64, sigma: f64| -> (f64, Params) {
        let mut extra = [0.0; EXTRA];
        if kind == ModelKind::OrenNayar {
            extra[0] = sigma;
        }
        let (mut sa, mut sb, mut sc, mut q) = (0.0, 0.0, 0.0, 0.0);
        let mut pl = [0.0; BANDS];
        let mut av = Vec::with_capacity(targets.len());
        let (on_a, on_b) = oren_nayar_coefficients(sigma);
        for (((t, &wt), g), on) in targets
            .iter()
            .zip(&w)
            .zip(&problem.geometry)
            .zip(&problem.oren_nayar)
        {
            let s = specular_term(1.0, alpha, ior, fresnel, g);
            let a = if kind == ModelKind::OrenNayar {
                on_a + on_b * on
            } else {
                1.0
            };
            sa += wt * a * a;
            sb += wt * a * s;
            sc += wt * s * s;
            for (p, y) in pl.iter_mut().zip(&t.measured) {
                *p += wt * a * y;
                q += wt * s * y;
            }
            av.push((a, s));
        }
        let psum: f64 = pl.iter().sum();
        let den = BANDS as f64 * (sc - sb * sb / sa);
        let ks = if den > 0.0 {
            ((q - sb * psum / sa) / den).clamp(bounds.ks.0, bounds.ks.1)
        } else {
            0.0
        };
        let kd: Spectrum = pl.map(|p| ((p - ks * sb) / sa).clamp(bounds.kd.0, bounds.kd.1));
        let mut sse = 0.0;
        for ((t, &wt), (a, s)) in targets.iter().zip(&w).zip(&av) {
            for (k, y) in kd.iter().zip(&t.measured) {
                let r = k * a + ks * s - y;
                sse += wt * r * r;
            }
        }
        (
            sse,
            Params {
                kd,
                ks,
                alpha,
                ior,
                extra,
            },
        )
    };
    let alphas: Vec<f64> = (0..24)
        .map(|k| (0.01f64.ln() + (1.0f64.ln() - 0.01f64.ln()) * k as f64 / 23.0).exp())
        .collect();
    let iors: Vec<f64> = (0..11).map(|k| 1.05 + 0.195 * k as f64).collect();
    let mut best = (f64::INFINITY, None, (0.0, 0.0, 0.0));
    for &sigma in &sigmas {
        for &a in &alphas {
            for &n in &iors {
                let (sse, p) = solve(a, n, sigma);
                if sse < best.0 {
                    best = (sse, Some(p), (a, n, sigma));
                }
            }
        }
    }
    // One refinement around the best grid point.
    let (a0, n0, s0) = best.2;
    let ratio = alphas[1] / alphas[0];
    for i in -4..=4 {
        for j in -4..=4 {
            for k in -2i32..=2 {
                let a = (a0 * ratio.powf(i as f64 / 4.0)).clamp(bounds.alpha.0, bounds.alpha.1);
                let n = (n0 + 0.195 * j as f64 / 4.0).clamp(bounds.ior.0, bounds.ior.1);
                let s = if kind == ModelKind::OrenNayar {
                    (s0 + 0.25 * k as f64 / 2.0).clamp(0.0, 1.0)
                } else if k != 0 {
                    continue;
                } else {
                    0.0
                };
                let (sse, p) = solve(a, n, s);
                if sse < best.0 {
                    best = (sse, Some(p), (a, n, s));
                }
            }
        }
    }
    best.1.expect("the grid is not empty")
}

/// What the oracle's polish may start from: a fit of the same form, the least-squares fit over
/// every direction, or the Lambert baseline.
#[derive(Debug, Clone)]
pub struct OracleStart {
    /// What it is, as the report names it (`cf2 fit, ma-t12+sra`, `least squares`, `lambert`).
    pub label: String,
    pub params: Params,
}

/// The oracle of one model form (module text): where it started and what it reached.
#[derive(Debug, Clone)]
pub struct OracleFit {
    pub params: Params,
    /// The start the polish began from (the best of the starts by mean ΔE00).
    pub start: String,
    /// Mean ΔE00 at that start, before the polish.
    pub start_mean: f64,
    /// Mean-ΔE00 evaluations the polish made.
    pub evaluations: u32,
}

/// The colour half-width of the oracle's kd search, in tristimulus values relative to the
/// white (the search moves kd's X, Y, Z by at most this much from the start, per polish run).
const ORACLE_COLOUR_RANGE: f64 = 0.25;

/// Most mean-ΔE00 evaluations of one Nelder–Mead run of the oracle's polish.
const ORACLE_RUN_EVALUATIONS: u32 = 500;

/// Most Nelder–Mead runs of the polish (each restarts from the best so far with a smaller step).
const ORACLE_RUNS: usize = 3;

/// The oracle's objective: mean ΔE00 over the targets of the model form `kind` with any
/// parameters. The model's colour at a target is `π (a·XYZ(kd) + s·XYZ(1))`, `a` the diffuse
/// factor (1, or Oren–Nayar's) and `s` the grey lobe: tristimulus values are linear in the
/// spectrum, so kd enters only through its own XYZ, computed once per evaluation.
struct OracleProblem<'a> {
    targets: &'a [Target],
    geometry: Vec<SpecularGeometry>,
    /// Oren–Nayar's directional part per target ([`oren_nayar_geometry_at`]).
    oren_nayar: Vec<f64>,
    colorimetry: Colorimetry,
    white: Xyz,
    kind: ModelKind,
    fresnel: FresnelCosine,
    bounds: Bounds,
    /// Per XYZ coordinate, the least-norm reflectance spectrum that moves that coordinate
    /// (relative to the white) by 1 and leaves the other two: how the polish moves kd.
    colour_basis: [Spectrum; 3],
}

impl<'a> OracleProblem<'a> {
    fn new(
        targets: &'a [Target],
        colorimetry: Colorimetry,
        kind: ModelKind,
        fresnel: FresnelCosine,
    ) -> Self {
        let white = colorimetry.white_point();
        // M (3 × 31): band b's contribution to X/Xw, Y/Yw, Z/Zw.
        let m: [Spectrum; 3] = {
            let per_band: Vec<Xyz> = (0..BANDS)
                .map(|b| {
                    let mut e = [0.0; BANDS];
                    e[b] = 1.0;
                    colorimetry.reflectance_to_xyz(&e)
                })
                .collect();
            [
                std::array::from_fn(|b| per_band[b].x / white.x),
                std::array::from_fn(|b| per_band[b].y / white.y),
                std::array::from_fn(|b| per_band[b].z / white.z),
            ]
        };
        let gram: [[f64; 3]; 3] = std::array::from_fn(|i| {
            std::array::from_fn(|j| (0..BANDS).map(|b| m[i][b] * m[j][b]).sum())
        });
        let inv = invert3(gram);
        // Mᵀ (M Mᵀ)⁻¹ e_j.
        let colour_basis = std::array::from_fn(|j| {
            std::array::from_fn(|b| (0..3).map(|i| m[i][b] * inv[i][j]).sum())
        });
        OracleProblem {
            targets,
            geometry: targets
                .iter()
                .map(|t| SpecularGeometry::from_directions(t.wi, t.wo))
                .collect(),
            oren_nayar: targets
                .iter()
                .map(|t| oren_nayar_geometry_at(t.wi, t.wo))
                .collect(),
            colorimetry,
            white,
            kind,
            fresnel,
            bounds: Bounds::default(),
            colour_basis,
        }
    }

    /// Mean ΔE00 over the targets: what [`predict`] reports as `mean`, computed through XYZ.
    fn mean_delta_e00(&self, p: &Params) -> f64 {
        let pi = std::f64::consts::PI;
        let xd = self.colorimetry.reflectance_to_xyz(&p.kd.map(|k| pi * k));
        let w = self.white;
        let (on_a, on_b) = oren_nayar_coefficients(p.extra[0]);
        let mut sum = 0.0;
        for ((t, g), on) in self
            .targets
            .iter()
            .zip(&self.geometry)
            .zip(&self.oren_nayar)
        {
            let lab = if g.cos_i <= 0.0 || g.cos_r <= 0.0 {
                xyz_to_lab(
                    Xyz {
                        x: 0.0,
                        y: 0.0,
                        z: 0.0,
                    },
                    w,
                )
            } else {
                let s = pi * specular_term(p.ks, p.alpha, p.ior, self.fresnel, g);
                let a = if self.kind == ModelKind::OrenNayar {
                    on_a + on_b * on
                } else {
                    1.0
                };
                xyz_to_lab(
                    Xyz {
                        x: a * xd.x + s * w.x,
                        y: a * xd.y + s * w.y,
                        z: a * xd.z + s * w.z,
                    },
                    w,
                )
            };
            sum += ciede2000(t.lab, lab);
        }
        sum / self.targets.len().max(1) as f64
    }

    /// The unit-cube coordinates of `p` relative to the kd it starts from (colour offsets 0).
    fn coordinates<const D: usize>(&self, p: &Params) -> [f64; D] {
        let b = &self.bounds;
        let mut u = [0.5; D];
        u[3] = (p.ks / b.ks.1).clamp(0.0, 1.0).cbrt();
        u[4] =
            ((p.alpha.ln() - b.alpha.0.ln()) / (b.alpha.1.ln() - b.alpha.0.ln())).clamp(0.0, 1.0);
        u[5] = ((p.ior - b.ior.0) / (b.ior.1 - b.ior.0)).clamp(0.0, 1.0);
        if D > 6 {
            u[6] = ((p.extra[0] - OREN_NAYAR_SIGMA.0) / (OREN_NAYAR_SIGMA.1 - OREN_NAYAR_SIGMA.0))
                .clamp(0.0, 1.0);
        }
        u
    }

    /// The parameters at unit-cube coordinates `u` around the diffuse spectrum `kd0`.
    fn params_at<const D: usize>(&self, kd0: &Spectrum, u: &[f64; D]) -> Params {
        let b = &self.bounds;
        let c: [f64; 3] = std::array::from_fn(|j| (u[j] - 0.5) * 2.0 * ORACLE_COLOUR_RANGE);
        let kd = std::array::from_fn(|k| {
            let d: f64 = (0..3).map(|j| c[j] * self.colour_basis[j][k]).sum();
            (kd0[k] + d / std::f64::consts::PI).clamp(b.kd.0, b.kd.1)
        });
        let mut extra = [0.0; EXTRA];
        if D > 6 {
            extra[0] = OREN_NAYAR_SIGMA.0 + u[6] * (OREN_NAYAR_SIGMA.1 - OREN_NAYAR_SIGMA.0);
        }
        Params {
            kd,
            ks: b.ks.1 * u[3].powi(3),
            alpha: (b.alpha.0.ln() + u[4] * (b.alpha.1.ln() - b.alpha.0.ln())).exp(),
            ior: b.ior.0 + u[5] * (b.ior.1 - b.ior.0),
            extra,
        }
    }

    /// Nelder–Mead runs from `start`, each from the best so far with a smaller step, until a
    /// run gains less than 0.001 ΔE00: the best parameters, their mean ΔE00, evaluations.
    fn polish<const D: usize>(&self, start: &Params, f_start: f64) -> (Params, f64, u32) {
        let (mut best, mut f_best, mut evaluations) = (*start, f_start, 0u32);
        let mut step = 0.1;
        for _ in 0..ORACLE_RUNS {
            let kd0 = best.kd;
            let x0 = self.coordinates::<D>(&best);
            // The coordinates of `best` map back to it but for rounding: its cost there.
            let p0 = self.params_at(&kd0, &x0);
            let f0 = self.mean_delta_e00(&p0);
            let mut count = 1u32;
            let out = nelder_mead::minimise(
                &mut |u: &[f64; D]| {
                    count += 1;
                    self.mean_delta_e00(&self.params_at(&kd0, u))
                },
                x0,
                f0,
                &nelder_mead::Options {
                    initial_step: step,
                    max_evaluations: ORACLE_RUN_EVALUATIONS,
                    x_tolerance: 1e-4,
                    f_tolerance: 1e-5,
                },
            );
            evaluations += count;
            let gain = f_best - out.f;
            if out.f < f_best {
                best = self.params_at(&kd0, &out.x);
                f_best = out.f;
            }
            if gain < 1e-3 {
                break;
            }
            step *= 0.5;
        }
        (best, f_best, evaluations)
    }
}

/// The inverse of a 3 × 3 matrix (the colour basis's Gram matrix, well conditioned).
fn invert3(a: [[f64; 3]; 3]) -> [[f64; 3]; 3] {
    let c = |i: usize, j: usize| {
        let (r0, r1) = ((i + 1) % 3, (i + 2) % 3);
        let (c0, c1) = ((j + 1) % 3, (j + 2) % 3);
        a[r0][c0] * a[r1][c1] - a[r0][c1] * a[r1][c0]
    };
    let det = a[0][0] * c(0, 0) + a[0][1] * c(0, 1) + a[0][2] * c(0, 2);
    std::array::from_fn(|i| std::array::from_fn(|j| c(j, i) / det))
}

/// The oracle of the model form (`kind`, `fresnel`) on `targets` (module text): the mean
/// ΔE00 over every direction minimised from the best of `starts` and of the least-squares fit.
/// Never worse than any start: the polish keeps the best point it has seen, and the result
/// is checked against the best start by [`predict`] itself.
pub fn oracle(
    targets: &[Target],
    colorimetry: Colorimetry,
    kind: ModelKind,
    fresnel: FresnelCosine,
    starts: &[OracleStart],
) -> OracleFit {
    let problem = OracleProblem::new(targets, colorimetry, kind, fresnel);
    let mut candidates = starts.to_vec();
    candidates.push(OracleStart {
        label: "least squares".into(),
        params: least_squares(&problem),
    });
    let (start, f_start) = candidates
        .iter()
        .map(|c| (c, problem.mean_delta_e00(&c.params)))
        .min_by(|a, b| a.1.total_cmp(&b.1))
        .expect("the least-squares start at least");
    let (params, _, evaluations) = if kind == ModelKind::OrenNayar {
        problem.polish::<7>(&start.params, f_start)
    } else {
        problem.polish::<6>(&start.params, f_start)
    };
    let mean = |p: &Params| {
        predict(targets, colorimetry, &|t| {
            evaluate_at(p, kind, fresnel, t.wi, t.wo)
        })
        .mean
    };
    let start_mean = mean(&start.params);
    OracleFit {
        params: if mean(&params) <= start_mean {
            params
        } else {
            start.params
        },
        start: start.label.clone(),
        start_mean,
        evaluations,
    }
}

/// Validates the handheld estimate against one measurement, with every fit of [`variants`].
pub fn validate(m: &Measurement, opts: &Options) -> Result<Report, crate::fit::FitScanError> {
    validate_with(m, opts, &variants())
}

/// [`validate`] with the fits of `variants` only.
pub fn validate_with(
    m: &Measurement,
    opts: &Options,
    variants: &[Variant],
) -> Result<Report, crate::fit::FitScanError> {
    let start = Instant::now();
    let colorimetry = opts.colorimetry;
    let (targets, prediction_set) = targets(m, colorimetry);
    let (measured, reading_docs) = readings(m, opts.sra);
    let lambert_f = {
        let g = crate::geometry::by_name(LAMBERT_GEOMETRY).expect("a table geometry");
        measured.values[g.index]
    };
    let mut fits = Vec::new();
    let mut fitted: Vec<(Variant, Params)> = Vec::new();
    let mut directions_of_default = Vec::new();
    let mut figures_cost = None;
    for &v in variants {
        let request = FitRequest {
            settings: Settings {
                cost: v.cost,
                model: v.model,
                fresnel: v.fresnel,
                sra: opts.sra.with_weight(v.sra_weight),
                seed: opts.seed,
                ..Settings::default()
            },
            colorimetry,
            ..FitRequest::default()
        };
        let mb = MeasuredBrdf {
            geometries: v.geometries,
            ..measured
        };
        let report = fit_measured(
            m.material(),
            "goniometric measurement",
            mb,
            &request,
            &mut |_| ControlFlow::Continue(()),
        )?;
        let p = report.outcome.params;
        let interval_coverage = if opts.intervals && v.is_default() {
            let cv = crate::crossval::crossval_held_out(
                m.material(),
                "goniometric measurement",
                &mb,
                &request,
                report.evaluation.diffuse.mean,
                &std::sync::atomic::AtomicBool::new(false),
            )?;
            interval_coverage(
                &targets,
                colorimetry,
                &|t| evaluate_at(&p, v.model, v.fresnel, t.wi, t.wo),
                &cv,
            )
        } else {
            None
        };
        fitted.push((v, p));
        if v.is_default()
            && (figures_cost.is_none()
                || (v.cost == CostFunction::Cf2 && figures_cost != Some(CostFunction::Cf2)))
        {
            figures_cost = Some(v.cost);
            directions_of_default = targets
                .iter()
                .map(|t| {
                    let f = evaluate_at(&p, v.model, v.fresnel, t.wi, t.wo);
                    let lab = colorimetry.reflectance_to_lab(&f.map(|x| std::f64::consts::PI * x));
                    DirectionError::of(t, lab)
                })
                .collect();
        }
        let prediction = predict(&targets, colorimetry, &|t| {
            evaluate_at(&p, v.model, v.fresnel, t.wi, t.wo)
        });
        fits.push(FitResult {
            cost: v.cost,
            model: v.model,
            fresnel: v.fresnel,
            readings: if v.geometries == GeometrySet::ALL {
                "ma-t12+sra"
            } else {
                "ma-t12"
            },
            sra_weight: v.sra_weight,
            default: v.is_default(),
            fit_delta_e00_mean: report.evaluation.diffuse.mean,
            params: ParamsDocument::new(&p, v.model),
            prediction,
            wall_ms: report.outcome.wall_ms,
            reach: crate::reach::of_report(&report),
            interval_coverage,
        });
    }
    let mut oracles = Vec::new();
    let mut oracle_params: Vec<(ModelKind, FresnelCosine, Params)> = Vec::new();
    for &(model, fresnel) in opts.oracle_forms {
        let mut starts: Vec<OracleStart> = fitted
            .iter()
            .filter(|(v, _)| v.model == model && v.fresnel == fresnel)
            .map(|(v, p)| OracleStart {
                label: format!(
                    "{} fit, {}",
                    v.cost.name(),
                    if v.geometries == GeometrySet::ALL {
                        "ma-t12+sra"
                    } else {
                        "ma-t12"
                    }
                ),
                params: *p,
            })
            .collect();
        // The Lambert baseline is the form with no lobe (and σ = 0).
        starts.push(OracleStart {
            label: "lambert".into(),
            params: Params {
                kd: lambert_f,
                ks: 0.0,
                alpha: 0.1,
                ior: 1.5,
                extra: [0.0; EXTRA],
            },
        });
        // A form that holds another (Oren–Nayar with σ = 0 is the paper's model) starts from
        // that form's fits and oracle too.
        if model == ModelKind::OrenNayar {
            starts.extend(
                fitted
                    .iter()
                    .filter(|(v, _)| v.model == ModelKind::Paper && v.fresnel == fresnel)
                    .map(|(v, p)| OracleStart {
                        label: format!("{} paper fit", v.cost.name()),
                        params: Params {
                            extra: [0.0; EXTRA],
                            ..*p
                        },
                    }),
            );
            starts.extend(
                oracle_params
                    .iter()
                    .filter(|(m, f, _)| *m == ModelKind::Paper && *f == fresnel)
                    .map(|(_, _, p)| OracleStart {
                        label: "paper oracle".into(),
                        params: Params {
                            extra: [0.0; EXTRA],
                            ..*p
                        },
                    }),
            );
        }
        let started = Instant::now();
        let o = oracle(&targets, colorimetry, model, fresnel, &starts);
        let p = o.params;
        oracle_params.push((model, fresnel, p));
        let prediction = predict(&targets, colorimetry, &|t| {
            evaluate_at(&p, model, fresnel, t.wi, t.wo)
        });
        oracles.push(Oracle {
            model,
            fresnel,
            params: ParamsDocument::new(&p, model),
            start: o.start,
            start_mean: o.start_mean,
            evaluations: o.evaluations,
            wall_ms: started.elapsed().as_secs_f64() * 1e3,
            prediction,
        });
    }
    let lambert = Lambert {
        geometry: LAMBERT_GEOMETRY,
        prediction: predict(&targets, colorimetry, &|_| lambert_f),
    };
    let interpolation = match m {
        Measurement::Astm(a) => {
            let loo = a.leave_one_out();
            let de: Vec<f64> = a
                .points
                .iter()
                .zip(&loo)
                .map(|(p, q)| {
                    let lab = |v: &[f64]| {
                        colorimetry.reflectance_to_lab(
                            &a.channels.to_spectrum(v).map(|x| std::f64::consts::PI * x),
                        )
                    };
                    ciede2000(lab(&p.values), lab(q))
                })
                .collect();
            let near: Vec<bool> = targets.iter().map(|t| t.near).collect();
            Some(Interpolation {
                method: format!(
                    "inverse-square-distance weighting of the {} nearest measured pairs, isotropy and reciprocity folded in",
                    super::astm::NEIGHBOURS
                ),
                leave_one_out: Prediction::of(&de, &near),
            })
        }
        Measurement::Rgl(_) => None,
    };
    let near_specular_directions = targets.iter().filter(|t| t.near).count();
    let exact_all =
        |f: &&FitResult| f.fresnel == FresnelCosine::Exact && f.readings == "ma-t12+sra";
    let reach = fits
        .iter()
        .filter(exact_all)
        .find(|f| f.cost == CostFunction::Cf2)
        .or(fits.iter().find(exact_all))
        .or(fits.first())
        .and_then(|f| f.reach.clone());
    Ok(Report {
        material: m.material().to_string(),
        file: None,
        format: m.format(),
        channels: match m.channels() {
            Channels::Rgb => "rgb",
            Channels::Spectral(_) => "spectral",
        },
        rgb_upsampling: (*m.channels() == Channels::Rgb).then_some(RGB_UPSAMPLING),
        colorimetry: colorimetry.to_string(),
        sra: opts.sra,
        prediction_set,
        directions: targets.len(),
        near_specular_directions,
        readings: reading_docs,
        interpolation,
        fits,
        oracle: oracles
            .first()
            .cloned()
            .expect("at least one oracle form (Options::oracle_forms)"),
        oracles,
        lambert,
        reach,
        wall_ms: start.elapsed().as_secs_f64() * 1e3,
        directions_of_default,
        figures_cost,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn prediction_summary_splits_near_specular() {
        let p = Prediction::of(&[1.0, 2.0, 3.0, 10.0], &[false, false, false, true]);
        assert_eq!(p.mean, 4.0);
        assert_eq!(p.median, 2.5);
        assert_eq!(p.p95, 10.0);
        assert_eq!(p.near_specular_mean, Some(10.0));
        assert_eq!(p.rest_mean, Some(2.0));
        let q = Prediction::of(&[1.0], &[false]);
        assert_eq!(q.near_specular_mean, None);
    }

    #[test]
    #[allow(clippy::needless_range_loop)]
    fn the_colour_basis_moves_one_tristimulus_value_each() {
        let c = Options::default().colorimetry;
        let p = OracleProblem::new(&[], c, ModelKind::Paper, FresnelCosine::Exact);
        let w = c.white_point();
        for (j, basis) in p.colour_basis.iter().enumerate() {
            let xyz = c.reflectance_to_xyz(basis);
            let rel = [xyz.x / w.x, xyz.y / w.y, xyz.z / w.z];
            for (i, v) in rel.iter().enumerate() {
                let want = if i == j { 1.0 } else { 0.0 };
                assert!((v - want).abs() < 1e-9, "basis {j}: {rel:?}");
            }
        }
        let a = [[2.0, 1.0, 0.0], [1.0, 3.0, 1.0], [0.0, 1.0, 4.0]];
        let inv = invert3(a);
        for i in 0..3 {
            for j in 0..3 {
                let v: f64 = (0..3).map(|k| a[i][k] * inv[k][j]).sum();
                assert!((v - if i == j { 1.0 } else { 0.0 }).abs() < 1e-12);
            }
        }
    }

    #[test]
    fn a_direction_is_covered_when_its_error_is_within_the_held_out_interval() {
        let c = Options::default().colorimetry;
        let f: Spectrum = std::array::from_fn(|b| 0.1 + 0.002 * b as f64);
        let lab = c.reflectance_to_lab(&f.map(|x| std::f64::consts::PI * x));
        // Held-out errors ±1 in L*, none in a* and b*: s = 1, m = 12.
        let cv = crate::crossval::CrossValidation {
            cost: CostFunction::Cf2,
            model: ModelKind::Paper,
            fresnel: FresnelCosine::Exact,
            fitted_mean: 0.5,
            held_out_mean: 1.25,
            held_out: (0..12)
                .map(|i| crate::crossval::HeldOut {
                    geometry: GEOMETRIES[i].name.into(),
                    delta_e00: 1.0,
                    measured_lab: [50.0, 0.0, 0.0],
                    predicted_lab: [50.0 + if i % 2 == 0 { 1.0 } else { -1.0 }, 0.0, 0.0],
                    predicted_l_interval: None,
                })
                .collect(),
        };
        let half = crate::stats::t_quantile(0.975, 11.0).unwrap() * (1.0 + 1.0 / 12.0f64).sqrt();
        // Measured L* off the prediction by 0.5, 2.2 (inside: half ≈ 2.29), 2.4 and −3 (not).
        let targets: Vec<Target> = [0.5, 2.2, 2.4, -3.0]
            .iter()
            .enumerate()
            .map(|(k, d)| Target {
                wi: direction(0.3, 0.0),
                wo: direction(0.5, 1.0),
                measured: f,
                lab: Lab {
                    l: lab.l + d,
                    ..lab
                },
                near: k == 0,
            })
            .collect();
        let got = interval_coverage(&targets, c, &|_| f, &cv).unwrap();
        assert!((got.half_width[0] - half).abs() < 1e-12, "{got:?}");
        assert_eq!(got.half_width[1..], [0.0, 0.0]);
        assert_eq!((got.l, got.a, got.b, got.all), (0.5, 1.0, 1.0, 0.5));
        assert_eq!(got.near_specular_l, Some(1.0));
        assert_eq!(got.held_out_mean, 1.25);
    }

    #[test]
    fn the_oracle_objective_is_the_reported_mean() {
        let c = Options::default().colorimetry;
        let p = Params {
            kd: std::array::from_fn(|b| 0.05 + 0.004 * b as f64),
            ks: 0.4,
            alpha: 0.2,
            ior: 1.6,
            extra: [0.3, 0.0],
        };
        let truth = Params {
            ks: 0.2,
            alpha: 0.1,
            ..p
        };
        let targets: Vec<Target> = (0..40)
            .map(|k| {
                let wi = direction((5.0 + 1.7 * k as f64).to_radians(), 0.0);
                let wo = direction(
                    (70.0 - 1.5 * k as f64).to_radians(),
                    (9.0 * k as f64).to_radians(),
                );
                let f = evaluate_at(&truth, ModelKind::OrenNayar, FresnelCosine::Exact, wi, wo);
                Target {
                    wi,
                    wo,
                    measured: f,
                    lab: c.reflectance_to_lab(&f.map(|x| std::f64::consts::PI * x)),
                    near: false,
                }
            })
            .collect();
        for kind in [ModelKind::Paper, ModelKind::OrenNayar] {
            let problem = OracleProblem::new(&targets, c, kind, FresnelCosine::Exact);
            let want = predict(&targets, c, &|t| {
                evaluate_at(&p, kind, FresnelCosine::Exact, t.wi, t.wo)
            })
            .mean;
            let got = problem.mean_delta_e00(&p);
            assert!(
                (got - want).abs() < 1e-9 * want,
                "{kind:?}: {got} vs {want}"
            );
            // The coordinates of a point map back to it.
            let back = if kind == ModelKind::OrenNayar {
                problem.params_at(&p.kd, &problem.coordinates::<7>(&p))
            } else {
                problem.params_at(&p.kd, &problem.coordinates::<6>(&p))
            };
            assert!((back.ks - p.ks).abs() < 1e-12 && (back.alpha - p.alpha).abs() < 1e-12);
            assert!((back.ior - p.ior).abs() < 1e-12 && back.kd == p.kd);
        }
    }

    #[test]
    fn seventeen_variants_one_default_per_cost() {
        let v = variants();
        assert_eq!(v.len(), 17);
        assert_eq!(v.iter().filter(|v| v.is_default()).count(), 3);
        // The default is what a measured scan is fitted with: the exact Fresnel, 14 readings,
        // the measured preset's SRA weight; beside it under cf1 and m2 the paper's weights.
        for d in v.iter().filter(|v| v.is_default()) {
            assert!(d.fresnel == FresnelCosine::Exact && d.geometries == GeometrySet::ALL);
            assert_eq!(
                d.sra_weight,
                crate::optimise::Preset::Measured.sra_weight(d.cost)
            );
        }
        let paper_weighted_exact = v
            .iter()
            .filter(|v| {
                v.fresnel == FresnelCosine::Exact
                    && v.geometries == GeometrySet::ALL
                    && v.sra_weight == SraWeight::Paper
            })
            .count();
        assert_eq!(paper_weighted_exact, 3);
    }
}
