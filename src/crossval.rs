//! Prediction of readings a fit has not seen: fits with geometries held out, and
//! leave-one-geometry-out cross-validation (SCIENCE.md §12.5).
//!
//! A fit's ΔE00 says how well the model reproduces the readings it was fitted to; on real paint
//! that says little about the material at other angles. [`fit_holding_out`] fits a scan without
//! some of its MA-T12 readings and predicts them ([`HeldOut`]: ΔE00 and L*a*b* measured and
//! predicted, under the fit's colorimetry); [`crossval_measured`] holds out each MA-T12
//! geometry in turn (12 more fits of one configuration) and reports every prediction and
//! their mean ([`CrossValidation`]). `brdfd fit --hold-out`, `brdfd crossval` and the Python
//! package's `brdfd.crossval` call these.
//!
//! Only MA-T12 geometries are held out: the two SRA readings enter the cost together (one
//! luminance pair, SCIENCE.md §5.1), so a fit cannot be made with one of them alone.

use std::ops::ControlFlow;
use std::sync::atomic::{AtomicBool, Ordering};

use serde::{Deserialize, Serialize};

use crate::colour::Lab;
use crate::cost::CostFunction;
use crate::evaluation::{evaluate_with, lab_per_geometry_with};
pub use crate::fit::HeldOut;
use crate::fit::{FitReport, FitRequest, FitScanError, fit_measured};
use crate::geometry::{Device, GEOMETRIES, GeometrySet, by_name};
use crate::model::{FresnelCosine, ModelKind};
use crate::optimise::Progress;
use crate::processing::{self, MeasuredBrdf};
use crate::scan::Scan;

/// Leave-one-geometry-out cross-validation of one configuration (cost function, model,
/// Fresnel factor) on one scan.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CrossValidation {
    pub cost: CostFunction,
    pub model: ModelKind,
    pub fresnel: FresnelCosine,
    /// Mean ΔE00 at the MA-T12 geometries of the fit to every reading: the in-sample figure
    /// over the same geometries as `held_out_mean`, for comparison.
    pub fitted_mean: f64,
    /// Mean held-out ΔE00 over the geometries held out.
    pub held_out_mean: f64,
    /// One prediction per MA-T12 geometry the scan measured, in table order.
    pub held_out: Vec<HeldOut>,
}

/// Why geometries cannot be held out.
#[derive(Debug, thiserror::Error)]
pub enum HoldOutError {
    /// A name that is no geometry.
    #[error(
        "\"{0}\" is not a geometry; hold out MA-T12 geometries by name: 15as-45, 15as-30, \
         15as-15, 15as15, 15as45, 15as80, 45as-15, 45as15, 45as25, 45as45, 45as75, 45as110"
    )]
    Unknown(String),
    /// An SRA geometry.
    #[error(
        "{0} is an SRA geometry, and the two SRA readings enter the fit together; hold out \
         MA-T12 geometries only"
    )]
    Sra(String),
    /// A geometry the scan has no reading at.
    #[error("the scan has no reading at {0}, so there is nothing to hold out there")]
    NotMeasured(String),
    /// Nothing, or too much, left to fit.
    #[error(
        "holding out {held} of the scan's {measured} MA-T12 geometries leaves fewer than 3 to \
         fit; hold out fewer"
    )]
    TooMany { held: usize, measured: usize },
    /// The fit failed.
    #[error(transparent)]
    Fit(#[from] FitScanError),
}

/// Table indices of the geometries named (comma-separated lists are split by the CLI), checked
/// against the geometries `measured` has; duplicates are kept once, in table order.
pub fn parse_hold_out(names: &[String], measured: GeometrySet) -> Result<Vec<usize>, HoldOutError> {
    let mut held = Vec::new();
    for name in names {
        let g = by_name(name.trim()).ok_or_else(|| HoldOutError::Unknown(name.clone()))?;
        if g.device == Device::Sra {
            return Err(HoldOutError::Sra(g.name.to_string()));
        }
        if !measured.contains(g.index) {
            return Err(HoldOutError::NotMeasured(g.name.to_string()));
        }
        held.push(g.index);
    }
    held.sort_unstable();
    held.dedup();
    let ma = measured
        .iter()
        .filter(|g| g.device == Device::MaT12)
        .count();
    if held.is_empty() || ma - held.len() < 3 {
        return Err(HoldOutError::TooMany {
            held: held.len(),
            measured: ma,
        });
    }
    Ok(held)
}

/// The predictions of `report` (a fit made without the geometries `held`) at those geometries,
/// against `full`, the measurement with every reading.
pub fn predictions(full: &MeasuredBrdf, report: &FitReport, held: &[usize]) -> Vec<HeldOut> {
    let colorimetry = report.request.colorimetry;
    let e = evaluate_with(
        &full.values,
        &report.estimated,
        colorimetry,
        full.geometries,
    );
    let lab_m = lab_per_geometry_with(&full.values, colorimetry);
    let lab_p = lab_per_geometry_with(&report.estimated, colorimetry);
    let arr = |l: Lab| [l.l, l.a, l.b];
    held.iter()
        .map(|&g| HeldOut {
            geometry: GEOMETRIES[g].name.to_string(),
            delta_e00: e.per_geometry[g],
            measured_lab: arr(lab_m[g]),
            predicted_lab: arr(lab_p[g]),
            predicted_l_interval: None,
        })
        .collect()
}

/// Fits `measured` without the geometries `held` (table indices, MA-T12 only, e.g. from
/// [`parse_hold_out`]) and predicts them: the report is the fit over the remaining readings
/// (its evaluation is over those), with [`FitReport::held_out`] set.
pub fn fit_holding_out(
    sample: &str,
    reference: &str,
    measured: &MeasuredBrdf,
    request: &FitRequest,
    held: &[usize],
) -> Result<FitReport, FitScanError> {
    fit_holding_out_with(sample, reference, measured, request, held, &mut |_| {
        ControlFlow::Continue(())
    })
}

/// [`fit_holding_out`] with the optimiser's per-generation observer (`Break` cancels the fit).
pub fn fit_holding_out_with(
    sample: &str,
    reference: &str,
    measured: &MeasuredBrdf,
    request: &FitRequest,
    held: &[usize],
    observer: &mut dyn FnMut(&Progress) -> ControlFlow<()>,
) -> Result<FitReport, FitScanError> {
    let mut geometries = measured.geometries;
    for &g in held {
        geometries = geometries.without(g);
    }
    let reduced = MeasuredBrdf {
        geometries,
        ..*measured
    };
    let mut report = fit_measured(sample, reference, reduced, request, observer)?;
    report.held_out = Some(predictions(measured, &report, held));
    Ok(report)
}

/// Leave-one-geometry-out cross-validation of `request`'s configuration on `measured`: one fit
/// to every reading (for [`CrossValidation::fitted_mean`]) and one per MA-T12 geometry
/// measured, with that geometry held out and predicted.
pub fn crossval_measured(
    sample: &str,
    reference: &str,
    measured: &MeasuredBrdf,
    request: &FitRequest,
) -> Result<CrossValidation, FitScanError> {
    let full = fit_measured(sample, reference, *measured, request, &mut |_| {
        ControlFlow::Continue(())
    })?;
    crossval_of_fit(&full, &AtomicBool::new(false))
}

/// Leave-one-geometry-out cross-validation of a fit already made to every reading (`full`, as
/// [`fit_measured`] returns it): its measurement, configuration and colorimetry, with its own
/// evaluation as [`CrossValidation::fitted_mean`], so only the held-out fits are made (one per
/// MA-T12 geometry measured). `stop`, read once per optimiser generation, cancels it
/// (`FitError::Cancelled`); the fit worker runs this after every stored fit.
pub fn crossval_of_fit(
    full: &FitReport,
    stop: &AtomicBool,
) -> Result<CrossValidation, FitScanError> {
    crossval_held_out(
        &full.sample,
        &full.reference,
        &full.measured,
        &full.request,
        full.evaluation.diffuse.mean,
        stop,
    )
}

/// The held-out half of a cross-validation: one fit of `request`'s configuration per MA-T12
/// geometry `measured` has, that geometry held out and predicted, beside `fitted_mean`, the
/// mean MA-T12 ΔE00 of the fit to every reading (as stored with it). What
/// [`crossval_of_fit`] runs, and what the daemon runs for a stored fit that has no
/// cross-validation yet. `stop`, read once per optimiser generation, cancels it.
pub fn crossval_held_out(
    sample: &str,
    reference: &str,
    measured: &MeasuredBrdf,
    request: &FitRequest,
    fitted_mean: f64,
    stop: &AtomicBool,
) -> Result<CrossValidation, FitScanError> {
    let mut observer = |_: &Progress| {
        if stop.load(Ordering::Relaxed) {
            ControlFlow::Break(())
        } else {
            ControlFlow::Continue(())
        }
    };
    let mut held_out = Vec::new();
    for g in measured
        .geometries
        .iter()
        .filter(|g| g.device == Device::MaT12)
    {
        let r = fit_holding_out_with(
            sample,
            reference,
            measured,
            request,
            &[g.index],
            &mut observer,
        )?;
        held_out.extend(r.held_out.expect("set by fit_holding_out_with"));
    }
    // Each geometry's 95 % L* interval from the other geometries' held-out errors.
    let errors: Vec<[f64; 3]> = held_out
        .iter()
        .map(|h| std::array::from_fn(|c| h.predicted_lab[c] - h.measured_lab[c]))
        .collect();
    for (i, h) in held_out.iter_mut().enumerate() {
        h.predicted_l_interval =
            crate::uncertainty::jackknife::prediction_interval(&errors, i, h.predicted_lab)
                .map(|[l, _, _]| l);
    }
    let held_out_mean = held_out.iter().map(|h| h.delta_e00).sum::<f64>() / held_out.len() as f64;
    Ok(CrossValidation {
        cost: request.settings.cost,
        model: request.settings.model,
        fresnel: request.settings.fresnel,
        fitted_mean,
        held_out_mean,
        held_out,
    })
}

/// [`crossval_measured`] of a scan, processed as `request` says.
pub fn crossval_scan(scan: &Scan, request: &FitRequest) -> Result<CrossValidation, FitScanError> {
    let measured = processing::process(scan, &request.processing)?;
    crossval_measured(&scan.sample, scan.reference_label(), &measured, request)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::optimise::{Settings, synthetic};

    fn request(cost: CostFunction) -> FitRequest {
        FitRequest {
            settings: Settings {
                cost,
                ..Settings::default()
            },
            ..FitRequest::default()
        }
    }

    #[test]
    fn names_are_checked() {
        let all = GeometrySet::ALL;
        let s = |v: &[&str]| v.iter().map(|x| x.to_string()).collect::<Vec<_>>();
        assert_eq!(
            parse_hold_out(&s(&["45as-15", "15as-45", "45as-15"]), all).unwrap(),
            vec![0, 6]
        );
        assert!(matches!(
            parse_hold_out(&s(&["45as-16"]), all),
            Err(HoldOutError::Unknown(_))
        ));
        assert!(matches!(
            parse_hold_out(&s(&["sra-20"]), all),
            Err(HoldOutError::Sra(_))
        ));
        assert!(matches!(
            parse_hold_out(&s(&["15as15"]), GeometrySet::MA_T12.without(3)),
            Err(HoldOutError::NotMeasured(_))
        ));
        let ten: Vec<String> = GEOMETRIES[..10].iter().map(|g| g.name.into()).collect();
        assert!(matches!(
            parse_hold_out(&ten, all),
            Err(HoldOutError::TooMany { held: 10, .. })
        ));
        assert!(parse_hold_out(&[], all).is_err());
    }

    #[test]
    fn a_noiseless_model_scan_is_predicted_where_it_was_held_out() {
        // The model's own BRDF: the fit without a geometry still finds the material, so the
        // held-out reading is predicted (nearly) exactly; a scan whose held-out reading is
        // altered is predicted as the model says, not as altered. Over the 12 MA-T12
        // geometries, as a real export (the synthetic SRA readings are grey, not the model's).
        let truth = synthetic::cases()[2].truth;
        let m = MeasuredBrdf {
            geometries: GeometrySet::MA_T12,
            ..synthetic::measured(&truth, FresnelCosine::Incidence)
        };
        let req = request(CostFunction::Cf1);
        let r = fit_holding_out("s", "N9", &m, &req, &[6]).unwrap();
        let h = r.held_out.as_ref().unwrap();
        assert_eq!(h.len(), 1);
        assert_eq!(h[0].geometry, "45as-15");
        assert!(h[0].delta_e00 < 0.05, "{h:?}");
        assert!(!r.measured.geometries.contains(6));
        assert!(r.evaluation.at(6).is_none());

        let mut altered = m;
        for v in altered.values[6].iter_mut() {
            *v *= 1.5;
        }
        let r2 = fit_holding_out("s", "N9", &altered, &req, &[6]).unwrap();
        let h2 = &r2.held_out.unwrap()[0];
        assert!(h2.delta_e00 > 3.0, "{h2:?}");
        assert!(h2.measured_lab[0] > h2.predicted_lab[0] + 3.0, "{h2:?}");
        // The reading held out did not steer the fit.
        assert!((h2.predicted_lab[0] - h[0].predicted_lab[0]).abs() < 0.05);
    }

    #[test]
    fn crossval_of_a_fit_reuses_it_and_stops_when_asked() {
        let truth = synthetic::cases()[2].truth;
        let m = MeasuredBrdf {
            geometries: GeometrySet::MA_T12,
            ..synthetic::measured(&truth, FresnelCosine::Incidence)
        };
        let req = request(CostFunction::Cf1);
        let mut full =
            fit_measured("s", "N9", m, &req, &mut |_| ControlFlow::Continue(())).unwrap();
        // The fitted mean is the given fit's own, whatever it says.
        full.evaluation.diffuse.mean = 7.5;
        let cv = crossval_of_fit(&full, &AtomicBool::new(false)).unwrap();
        assert_eq!(cv.fitted_mean, 7.5);
        assert_eq!(cv.held_out.len(), 12);
        assert!(cv.held_out_mean < 0.1, "{cv:?}");
        let stopped = crossval_of_fit(&full, &AtomicBool::new(true)).unwrap_err();
        assert!(
            matches!(
                stopped,
                FitScanError::Fit {
                    source: crate::optimise::FitError::Cancelled,
                    ..
                }
            ),
            "{stopped}"
        );
    }

    #[test]
    fn crossval_holds_out_each_ma_t12_geometry() {
        let truth = synthetic::cases()[2].truth;
        let m = synthetic::with_noise(
            &synthetic::measured(&truth, FresnelCosine::Incidence),
            0.01,
            3,
        );
        // All 14 geometries, the SRA readings under the measured scans' luminance model: only
        // the 12 MA-T12 ones are held out.
        let mut req = request(CostFunction::M2);
        req.settings.sra.model = crate::sra_reading::SraModel::Luminance;
        let cv = crossval_measured("s", "N9", &m, &req).unwrap();
        let names: Vec<&str> = cv.held_out.iter().map(|h| h.geometry.as_str()).collect();
        let ma: Vec<&str> = GEOMETRIES[..12].iter().map(|g| g.name).collect();
        assert_eq!(names, ma);
        let mean = cv.held_out.iter().map(|h| h.delta_e00).sum::<f64>() / 12.0;
        assert_eq!(cv.held_out_mean, mean);
        // Held out is never better than fitted on average on a noisy scan.
        assert!(cv.held_out_mean >= cv.fitted_mean * 0.9, "{cv:?}");
        assert!(cv.held_out_mean < 1.0, "{cv:?}");
        assert_eq!(cv.cost, CostFunction::M2);
        // Each held-out L* has a 95 % interval centred on its prediction, and the scale comes
        // from the other geometries' errors.
        let errors: Vec<[f64; 3]> = cv
            .held_out
            .iter()
            .map(|h| std::array::from_fn(|c| h.predicted_lab[c] - h.measured_lab[c]))
            .collect();
        for (i, h) in cv.held_out.iter().enumerate() {
            let [lo, hi] = h.predicted_l_interval.unwrap();
            assert!(lo < h.predicted_lab[0] && h.predicted_lab[0] < hi, "{h:?}");
            assert!(((lo + hi) / 2.0 - h.predicted_lab[0]).abs() < 1e-9);
            let want =
                crate::uncertainty::jackknife::prediction_interval(&errors, i, h.predicted_lab)
                    .unwrap();
            assert_eq!([lo, hi], want[0]);
        }
    }
}
