//! Error bars that include the model's misfit (SCIENCE.md §10): the leave-one-geometry-out
//! jackknife of a fit, the 95 % prediction interval of a held-out geometry's L*a*b* built from
//! it, the parameter intervals it widens, and which parameters sit at a bound.
//!
//! Decisions (SCIENCE.md §10 gives the figures):
//! - **Why a jackknife.** On real paint the model cannot reproduce the readings; the
//!   parametric bootstrap ([`crate::uncertainty`]) perturbs the readings by the instrument's
//!   noise only (0.2 % on the real exports) and gives intervals of about ±1 % that a single
//!   dropped geometry moves the parameters far outside. Refitting with each MA-T12 geometry
//!   left out in turn measures how much the parameters depend on which angles happen to be
//!   measured, which is where the misfit shows.
//! - **Refits** as the bootstrap's ([`Refit::for_cost`]): warm-started at the point fit for cf1
//!   and m2, the full search for cf2. The SRA geometries are never left out (the SRA reading
//!   model needs both).
//! - **Parameter intervals**: the hull of the bootstrap interval and the jackknife's normal
//!   interval `θ̂ ± 1.96·se_J`, `se_J² = (n−1)/n · Σ (θ₋ᵢ − θ̄)²` (Efron & Stein), clamped to
//!   the bounds. Under noise alone the jackknife spread is about the bootstrap's, so the
//!   synthetic calibration is kept (the hull only widens).
//! - **Prediction interval of a held-out geometry g** (per L*, a*, b*): the held-out
//!   prediction ± `t(0.975, m−1) · √(1 + 1/m) · s₋g`, where `s₋g` is the root mean square of the
//!   held-out errors at the m other geometries. Geometry g's own error never enters its
//!   interval, so its coverage measured on real scans is an honest out-of-sample figure.
//! - **At a bound**: a parameter within 1e-6 of its range from a bound is reported; an
//!   interval collapsed on a bound says nothing about the parameter and is never calibrated.

use std::sync::atomic::{AtomicBool, Ordering};

use serde::{Deserialize, Serialize};

use crate::colour::{Colorimetry, Lab, brdf_to_reflectance};
use crate::geometry::{Device, GEOMETRIES};
use crate::model::{self, Bounds, Params, SpecularGeometry};
use crate::optimise::refit_local;
use crate::spectral::BANDS;
use crate::uncertainty::{Interval, PointFit, Refit, UncertaintyError};

/// The method's name as written into the `misfit` object of the intervals.
pub const METHOD: &str = "leave-one-geometry-out-jackknife";

/// The normal quantile of a two-sided 95 % interval.
const Z95: f64 = 1.959_963_984_540_054;

/// One geometry left out: the refit without it and its prediction there.
#[derive(Debug, Clone, PartialEq)]
pub struct HeldOut {
    /// Index of the left-out geometry in [`GEOMETRIES`].
    pub geometry: usize,
    /// The refit over the other geometries.
    pub params: Params,
    /// L*a*b* of the measured reading at the geometry, under the fit's colorimetry.
    pub measured: Lab,
    /// L*a*b* the refit predicts there.
    pub predicted: Lab,
}

impl HeldOut {
    /// Predicted minus measured, per L*, a*, b*.
    pub fn error(&self) -> [f64; 3] {
        [
            self.predicted.l - self.measured.l,
            self.predicted.a - self.measured.a,
            self.predicted.b - self.measured.b,
        ]
    }
}

/// The leave-one-geometry-out refits of a fit, one per MA-T12 geometry it measured.
#[derive(Debug, Clone, PartialEq)]
pub struct Jackknife {
    pub held_out: Vec<HeldOut>,
}

/// L*a*b* of a BRDF spectrum (sr⁻¹) under `colorimetry`.
fn lab_of(c: Colorimetry, f: &crate::spectral::Spectrum) -> Lab {
    c.reflectance_to_lab(&brdf_to_reflectance(f))
}

/// Refits `fit` with each of its MA-T12 geometries left out in turn; `cancel` stops it between
/// refits.
pub fn jackknife(fit: PointFit<'_>, cancel: &AtomicBool) -> Result<Jackknife, UncertaintyError> {
    let settings = fit.settings;
    let mut held_out = Vec::new();
    for geo in fit.measured.geometries.iter() {
        if geo.device != Device::MaT12 {
            continue;
        }
        if cancel.load(Ordering::Relaxed) {
            return Err(UncertaintyError::Cancelled);
        }
        let g = geo.index;
        let mut m = *fit.measured;
        m.geometries = m.geometries.without(g);
        let out = match Refit::for_cost(settings.cost) {
            Refit::FullSearch => crate::optimise::fit(&m, settings),
            _ => refit_local(&m, settings, fit.params),
        }
        .map_err(|source| UncertaintyError::Refit {
            index: g as u32,
            source,
        })?;
        let est = model::evaluate_model(
            &out.params,
            settings.model,
            settings.fresnel,
            &SpecularGeometry::all(),
        );
        held_out.push(HeldOut {
            geometry: g,
            params: out.params,
            measured: lab_of(fit.colorimetry, &fit.measured.values[g]),
            predicted: lab_of(fit.colorimetry, &est[g]),
        });
    }
    Ok(Jackknife { held_out })
}

impl Jackknife {
    /// The 95 % prediction intervals `[L*, a*, b*]` of the held-out geometry at position `i` of
    /// [`Jackknife::held_out`], from the held-out errors at the other geometries (module
    /// docs); `None` with fewer than two other geometries.
    pub fn prediction_interval(&self, i: usize) -> Option<[Interval; 3]> {
        let errors: Vec<[f64; 3]> = self.held_out.iter().map(HeldOut::error).collect();
        let p = self.held_out[i].predicted;
        prediction_interval(&errors, i, [p.l, p.a, p.b])
    }

    /// The held-out geometry `geometry` (index in [`GEOMETRIES`]), with its 95 % L* interval.
    pub fn predicted_l_interval(&self, geometry: usize) -> Option<Interval> {
        let i = self.held_out.iter().position(|h| h.geometry == geometry)?;
        self.prediction_interval(i).map(|[l, _, _]| l)
    }

    /// The jackknife's normal 95 % interval of one parameter around the point fit's `value`:
    /// `value ± 1.96 se_J`.
    fn normal_interval(&self, value: f64, of: impl Fn(&Params) -> f64) -> Interval {
        let n = self.held_out.len() as f64;
        if n < 2.0 {
            return [value, value];
        }
        let xs: Vec<f64> = self.held_out.iter().map(|h| of(&h.params)).collect();
        let mean = xs.iter().sum::<f64>() / n;
        let se = ((n - 1.0) / n * xs.iter().map(|x| (x - mean).powi(2)).sum::<f64>()).sqrt();
        [value - Z95 * se, value + Z95 * se]
    }

    /// What the jackknife says of the point fit `point` within `bounds`: its own 95 % intervals
    /// of ks, α, μ and kd per band (clamped to the bounds).
    pub fn misfit(&self, point: &Params, bounds: &Bounds) -> Misfit {
        let clamp = |[lo, hi]: Interval, (a, b): (f64, f64)| [lo.max(a), hi.min(b)];
        Misfit {
            method: METHOD.to_string(),
            refits: self.held_out.len() as u32,
            ks: clamp(self.normal_interval(point.ks, |p| p.ks), bounds.ks),
            alpha: clamp(self.normal_interval(point.alpha, |p| p.alpha), bounds.alpha),
            ior: clamp(self.normal_interval(point.ior, |p| p.ior), bounds.ior),
            kd: (0..BANDS)
                .map(|b| clamp(self.normal_interval(point.kd[b], |p| p.kd[b]), bounds.kd))
                .collect(),
        }
    }
}

/// The 95 % prediction intervals `[L*, a*, b*]` around `predicted`, the held-out prediction at
/// position `i` of `errors` (each held-out geometry's predicted − measured L*, a*, b*), from the
/// errors at the other positions only (module docs); `None` with fewer than two others. `brdfd
/// crossval` gives each held-out geometry its L* interval this way.
pub fn prediction_interval(
    errors: &[[f64; 3]],
    i: usize,
    predicted: [f64; 3],
) -> Option<[Interval; 3]> {
    let others: Vec<[f64; 3]> = errors
        .iter()
        .enumerate()
        .filter(|(j, _)| *j != i)
        .map(|(_, e)| *e)
        .collect();
    let m = others.len();
    if m < 2 {
        return None;
    }
    let t = crate::stats::t_quantile(0.975, (m - 1) as f64)?;
    let k = t * (1.0 + 1.0 / m as f64).sqrt();
    Some(std::array::from_fn(|c| {
        let rms = (others.iter().map(|e| e[c] * e[c]).sum::<f64>() / m as f64).sqrt();
        [predicted[c] - k * rms, predicted[c] + k * rms]
    }))
}

/// The jackknife's own intervals, kept beside the combined ones in the `uncertainty` object.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Misfit {
    /// [`METHOD`].
    pub method: String,
    /// Refits (geometries left out).
    pub refits: u32,
    pub ks: Interval,
    pub alpha: Interval,
    pub ior: Interval,
    pub kd: Vec<Interval>,
}

/// The hull of two intervals.
pub fn hull(a: Interval, b: Interval) -> Interval {
    [a[0].min(b[0]), a[1].max(b[1])]
}

/// The parameters of `p` within 1e-6 of their range from a bound of `bounds`: any of `"ks"`,
/// `"alpha"`, `"ior"` and `"kd"` (any band), in that order.
pub fn at_bound(p: &Params, bounds: &Bounds) -> Vec<String> {
    let near = |v: f64, (lo, hi): (f64, f64)| {
        let tol = 1e-6 * (hi - lo).max(f64::MIN_POSITIVE);
        (v - lo).abs() <= tol || (hi - v).abs() <= tol
    };
    let mut out = Vec::new();
    for (name, v, range) in [
        ("ks", p.ks, bounds.ks),
        ("alpha", p.alpha, bounds.alpha),
        ("ior", p.ior, bounds.ior),
    ] {
        if near(v, range) {
            out.push(name.to_string());
        }
    }
    if p.kd.iter().any(|&v| near(v, bounds.kd)) {
        out.push("kd".to_string());
    }
    out
}

/// The lobe parameters (`"ks"`, `"alpha"`, `"ior"`) whose intervals under two cost functions'
/// fits of one scan do not overlap: where cf1 and cf2 disagree beyond their intervals, the
/// lobe is not identified by the readings and neither interval should be read as the
/// parameter's. Empty when they agree.
pub fn disjoint(
    a: &crate::uncertainty::Uncertainty,
    b: &crate::uncertainty::Uncertainty,
) -> Vec<&'static str> {
    let apart = |x: Interval, y: Interval| x[1] < y[0] || y[1] < x[0];
    [
        ("ks", a.ks, b.ks),
        ("alpha", a.alpha, b.alpha),
        ("ior", a.ior, b.ior),
    ]
    .into_iter()
    .filter(|(_, x, y)| apart(*x, *y))
    .map(|(n, _, _)| n)
    .collect()
}

/// Per-geometry count of the MA-T12, which the jackknife leaves out one by one.
const _: () = assert!(GEOMETRIES.len() == crate::geometry::MA_T12_COUNT + 2);

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cost::CostFunction;
    use crate::optimise::Settings;
    use crate::processing::MeasuredBrdf;
    use crate::processing::{ProcessingOptions, process};
    use crate::synth::{SynthOptions, paper_samples, synth_scan};

    fn measured(sample: usize, noise: f64, seed: u64) -> MeasuredBrdf {
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

    fn held(g: usize, l: f64, err: f64) -> HeldOut {
        let lab = |l| Lab { l, a: 1.0, b: -2.0 };
        HeldOut {
            geometry: g,
            params: paper_samples()[0].params,
            measured: lab(l),
            predicted: lab(l + err),
        }
    }

    #[test]
    fn prediction_interval_uses_the_other_geometries_errors_only() {
        // Errors ±1 at eleven geometries and 50 at the last: the last one's interval is
        // built from the ±1's, so it misses its own measurement; the others' include the 50.
        let mut held_out: Vec<HeldOut> = (0..11)
            .map(|g| held(g, 40.0, if g % 2 == 0 { 1.0 } else { -1.0 }))
            .collect();
        held_out.push(held(11, 40.0, 50.0));
        let j = Jackknife { held_out };
        let k = crate::stats::t_quantile(0.975, 10.0).unwrap() * (1.0 + 1.0 / 11.0f64).sqrt();
        let [l, a, b] = j.prediction_interval(11).unwrap();
        assert!((l[0] - (90.0 - k)).abs() < 1e-9 && (l[1] - (90.0 + k)).abs() < 1e-9);
        assert!(!(l[0] <= 40.0 && 40.0 <= l[1]));
        // a* and b* were predicted exactly: zero width.
        assert_eq!(a, [1.0, 1.0]);
        assert_eq!(b, [-2.0, -2.0]);
        let l0 = j.predicted_l_interval(0).unwrap();
        assert!(l0[0] <= 40.0 && 40.0 <= l0[1], "{l0:?}");
        assert!(l0[1] - l0[0] > 2.0 * 2.2 * (2500.0f64 / 11.0).sqrt());
        assert_eq!(j.predicted_l_interval(12), None);
        let one = Jackknife {
            held_out: vec![held(0, 40.0, 1.0), held(1, 40.0, 1.0)],
        };
        assert_eq!(one.prediction_interval(0), None);
    }

    #[test]
    fn disjoint_names_the_lobe_parameters_whose_intervals_do_not_meet() {
        let p = paper_samples()[0].params;
        let a = crate::test_support::made_up_uncertainty(&p, true);
        let mut b = a.clone();
        assert!(disjoint(&a, &b).is_empty());
        b.ks = [a.ks[1] * 1.01, a.ks[1] * 2.0];
        b.ior = [a.ior[1], a.ior[1] + 1.0];
        // Touching ends overlap.
        assert_eq!(disjoint(&a, &b), ["ks"]);
        assert_eq!(disjoint(&b, &a), ["ks"]);
    }

    #[test]
    fn at_bound_names_the_parameters_on_a_bound() {
        let b = Bounds::default();
        let mut p = paper_samples()[0].params;
        assert!(at_bound(&p, &b).is_empty(), "{:?}", at_bound(&p, &b));
        p.ior = 3.0;
        p.alpha = 0.01 + 1e-9;
        assert_eq!(at_bound(&p, &b), ["alpha", "ior"]);
        p.kd[4] = 0.0;
        p.ks = 10.0;
        assert_eq!(at_bound(&p, &b), ["ks", "alpha", "ior", "kd"]);
    }

    #[test]
    fn noise_free_jackknife_refits_the_truth_and_noise_spreads_it() {
        let settings = Settings {
            cost: CostFunction::Cf1,
            ..Settings::default()
        };
        let truth = paper_samples()[2].params;
        let never = AtomicBool::new(false);
        let run = |m: &MeasuredBrdf| {
            jackknife(
                PointFit {
                    measured: m,
                    settings: &settings,
                    colorimetry: Colorimetry::default(),
                    params: &truth,
                },
                &never,
            )
            .unwrap()
        };
        // Over the 12 MA-T12 geometries a noise-free scan is the model exactly (with the SRA
        // readings the flat SRA model's misfit would grey cf1's kd).
        let mut clean = measured(2, 0.0, 0);
        clean.geometries = crate::geometry::GeometrySet::MA_T12;
        let j = run(&clean);
        assert_eq!(j.held_out.len(), 12);
        for h in &j.held_out {
            assert!(
                (h.params.ks / truth.ks - 1.0).abs() < 1e-3,
                "{}",
                h.params.ks
            );
            assert!(h.error().iter().all(|e| e.abs() < 0.05), "{:?}", h.error());
        }
        let m = j.misfit(&truth, &settings.bounds);
        assert_eq!(m.refits, 12);
        assert!(m.ks[1] - m.ks[0] < 1e-2 * truth.ks, "{:?}", m.ks);
        // 2 % noise: the refits scatter and the intervals open around the point; the SRA
        // geometries are never left out.
        let noisy = measured(2, 0.02, 3);
        let j = run(&noisy);
        assert_eq!(j.held_out.len(), 12);
        assert!(j.held_out.iter().all(|h| h.geometry < 12));
        let m = j.misfit(&truth, &settings.bounds);
        assert!(m.ks[0] < truth.ks && truth.ks < m.ks[1], "{:?}", m.ks);
        assert!(m.ks[1] - m.ks[0] > 1e-3 * truth.ks, "{:?}", m.ks);
        let yes = AtomicBool::new(true);
        let stopped = jackknife(
            PointFit {
                measured: &noisy,
                settings: &settings,
                colorimetry: Colorimetry::default(),
                params: &truth,
            },
            &yes,
        );
        assert_eq!(stopped, Err(UncertaintyError::Cancelled));
    }
}
