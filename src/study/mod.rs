//! The study model a report, the exchange-format exports and the sphere previews are built
//! from: per sample, the scan, its measured BRDF and one fit per cost function (done, failed or
//! unfinished).
//!
//! It is plain data with no I/O, so the figures, the statistics and the exports are tested on
//! studies built in memory ([`Study::from_fit_reports`], [`Study::from_truth`]); [`load`]
//! builds one from the store or the lab's central database. The estimated BRDF of a fit is
//! always the model evaluated at the fit's parameters (with the Fresnel cosine it was fitted
//! with), and its evaluation is recomputed from measured and estimated, so the three can never
//! disagree.

pub mod load;

use crate::colour::Colorimetry;
use crate::cost::CostFunction;
#[cfg(test)]
use crate::evaluation::evaluate;
use crate::evaluation::{Evaluation, evaluate_with};
use crate::fit::FitReport;
use crate::geometry::GEOMETRY_COUNT;
use crate::model::{self, FresnelCosine, Params, SpecularGeometry};
use crate::processing::{MeasuredBrdf, Scale, SpecularStrategy};
use crate::scan::Scan;
use crate::spectral::Spectrum;
use crate::sra_reading::{SpecularDeltaL, SraReading, specular_delta_l};
use crate::store::Provenance;
use crate::uncertainty::Uncertainty;

/// Every sample of a study, in the order they are reported.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Study {
    pub samples: Vec<SampleStudy>,
}

/// One sample (one scan) of a study.
#[derive(Debug, Clone, PartialEq)]
pub struct SampleStudy {
    /// The name shown in figures and tables: the scan's sample name, made unique within the
    /// study by the loader (a sample scanned twice gets its scan id appended).
    pub name: String,
    /// The store's scan id, when the study was loaded from a store.
    pub scan_id: Option<i64>,
    /// Where, when and by which instruments the scan was measured, when the study was loaded
    /// from a store (`None` for studies made in memory: `brdfd demo`, tests).
    pub origin: Option<Origin>,
    /// The scan: the sample's readings and the reference readings they were normalised by.
    pub scan: Scan,
    /// How the SRA readings were turned into spectra for `measured`.
    pub specular: SpecularStrategy,
    /// The reference tile's calibrated reflectance `measured` was processed with; `None`:
    /// relative to the tile (SCIENCE.md §3). [`SampleStudy::scale`] says which.
    pub reference_reflectance: Option<Spectrum>,
    /// The measured BRDF, sr⁻¹, at the 14 geometries.
    pub measured: MeasuredBrdf,
    /// One entry per cost function the sample was fitted with, in [`CostFunction::ALL`] order.
    pub fits: Vec<FitStudy>,
}

/// Where, when and by what a stored scan was measured: what every export and the report
/// carry per sample, so a file read later still says which instrument (real or simulated)
/// produced its numbers.
#[derive(Debug, Clone, PartialEq)]
pub struct Origin {
    /// The station that measured it, when read from the lab's central database.
    pub station: Option<String>,
    /// When the scan started (else when it was requested), ms since the Unix epoch.
    pub measured_at_ms: i64,
    /// The instruments as they reported themselves, and how the readings came in.
    pub provenance: Provenance,
}

impl SampleStudy {
    /// How the sample's readings came in, for exports and captions ([`Provenance::summary`]);
    /// `None` for a study made in memory (no store, no provenance).
    pub fn provenance_summary(&self) -> Option<String> {
        self.origin.as_ref().map(|o| o.provenance.summary())
    }

    /// Whether a simulated instrument produced the sample's readings, as far as is known.
    pub fn simulated(&self) -> bool {
        self.origin
            .as_ref()
            .is_some_and(|o| o.provenance.simulated())
    }
}

/// The fit of one sample under one cost function.
#[derive(Debug, Clone, PartialEq)]
pub struct FitStudy {
    pub cost: CostFunction,
    /// The optimiser method's name ("paper", "separable").
    pub method: String,
    pub state: FitState,
}

/// Where a fit ended.
#[derive(Debug, Clone, PartialEq)]
pub enum FitState {
    /// Finished, with parameters, estimated BRDF and evaluation.
    Done(Box<DoneFit>),
    /// The optimiser or the evaluation failed; the reason as recorded.
    Failed { reason: String },
    /// Queued, running or cancelled: no result to report (the store's status text).
    Unfinished { status: String },
}

/// A finished fit.
#[derive(Debug, Clone, PartialEq)]
pub struct DoneFit {
    pub params: Params,
    /// The Fresnel cosine the model was fitted with.
    pub fresnel: FresnelCosine,
    /// The model's form the fit was made with (SCIENCE.md §4.1).
    pub model: model::ModelKind,
    /// The model at the fitted parameters, sr⁻¹, at the 14 geometries.
    pub estimated: [Spectrum; GEOMETRY_COUNT],
    /// ΔE00 between measured and estimated colour.
    pub evaluation: Evaluation,
    /// The colorimetry the evaluation was computed with (SCIENCE.md §7.1).
    pub colorimetry: Colorimetry,
    /// The bootstrap intervals, when they were computed (SCIENCE.md §10).
    pub uncertainty: Option<Uncertainty>,
    /// The SRA reading model the fit's cost used (SCIENCE.md §5.1).
    pub sra: SraReading,
    /// |ΔL*| between model and measured luminance at the SRA geometries, under the
    /// instrument of `sra` (SCIENCE.md §7.2); `None` for a scan without SRA readings.
    pub specular_delta_l: Option<SpecularDeltaL>,
    /// The fit's leave-one-geometry-out cross-validation, when it was computed (SCIENCE.md
    /// §12.5): each MA-T12 geometry predicted by a fit without it.
    pub crossval: Option<crate::crossval::CrossValidation>,
    /// The parameters at a bound of the range the fit searched (`"ks"`, `"alpha"`, `"ior"`,
    /// `"kd"`): not identified there, whether or not intervals were computed.
    pub at_bound: Vec<String>,
}

impl DoneFit {
    /// A finished fit from its parameters: the estimated BRDF and the evaluation (the paper's
    /// colorimetry) follow.
    pub fn from_params(measured: &MeasuredBrdf, params: Params, fresnel: FresnelCosine) -> DoneFit {
        DoneFit::from_params_with(measured, params, fresnel, Colorimetry::default(), None)
    }

    /// [`DoneFit::from_params`] under `colorimetry`, with the fit's intervals if any.
    pub fn from_params_with(
        measured: &MeasuredBrdf,
        params: Params,
        fresnel: FresnelCosine,
        colorimetry: Colorimetry,
        uncertainty: Option<Uncertainty>,
    ) -> DoneFit {
        let estimated = model::evaluate(&params, fresnel, &SpecularGeometry::all());
        let evaluation = evaluate_with(
            &measured.values,
            &estimated,
            colorimetry,
            measured.geometries,
        );
        let sra = SraReading::default();
        let at_bound = crate::uncertainty::jackknife::at_bound(&params, &model::Bounds::default());
        DoneFit {
            at_bound,
            params,
            fresnel,
            model: model::ModelKind::Paper,
            estimated,
            evaluation,
            colorimetry,
            uncertainty,
            sra,
            specular_delta_l: measured
                .geometries
                .has_sra()
                .then(|| specular_delta_l(&measured.values, &estimated, sra)),
            crossval: None,
        }
    }

    /// The same fit judged against the bounds it was fitted within (its settings' bounds;
    /// [`DoneFit::from_params_with`] assumes the defaults).
    pub fn with_bounds(mut self, bounds: &model::Bounds) -> DoneFit {
        self.at_bound = crate::uncertainty::jackknife::at_bound(&self.params, bounds);
        self
    }

    /// The same fit with its stored cross-validation.
    pub fn with_crossval(mut self, crossval: Option<crate::crossval::CrossValidation>) -> DoneFit {
        self.crossval = crossval;
        self
    }

    /// The same fit made with the SRA reading model `sra` (its |ΔL*| under that instrument).
    /// The same fit made with model option `kind` (SCIENCE.md §4.1): the estimated BRDF and the
    /// evaluation recomputed with it. The paper's model leaves the fit as it is. Apply before
    /// [`DoneFit::with_sra`].
    pub fn with_model(mut self, measured: &MeasuredBrdf, kind: model::ModelKind) -> DoneFit {
        if kind == model::ModelKind::Paper {
            return self;
        }
        self.model = kind;
        self.estimated =
            model::evaluate_model(&self.params, kind, self.fresnel, &SpecularGeometry::all());
        self.evaluation = evaluate_with(
            &measured.values,
            &self.estimated,
            self.colorimetry,
            measured.geometries,
        );
        let sra = self.sra;
        self.with_sra(measured, sra)
    }

    pub fn with_sra(mut self, measured: &MeasuredBrdf, sra: SraReading) -> DoneFit {
        self.sra = sra;
        self.specular_delta_l = measured
            .geometries
            .has_sra()
            .then(|| specular_delta_l(&measured.values, &self.estimated, sra));
        self
    }
}

impl FitStudy {
    /// The finished fit, if it finished.
    pub fn done(&self) -> Option<&DoneFit> {
        match &self.state {
            FitState::Done(d) => Some(d),
            _ => None,
        }
    }

    /// Why this fit has no result, in words for the report (`None` when done).
    pub fn problem(&self) -> Option<String> {
        match &self.state {
            FitState::Done(_) => None,
            FitState::Failed { reason } => Some(format!("{} fit failed: {reason}", self.cost)),
            FitState::Unfinished { status } => {
                Some(format!("{} fit not finished (status {status})", self.cost))
            }
        }
    }
}

impl SampleStudy {
    /// The scale of the sample's reflectances, as its scan says: the instrument's own
    /// calibration when the scan has no tile reference (an instrument-software export), else
    /// absolute (calibrated tile) or relative to the tile.
    pub fn scale(&self) -> Scale {
        match self.scan.reference {
            None => Scale::InstrumentCalibration,
            Some(_) => Scale::of(self.reference_reflectance.as_ref()),
        }
    }

    /// The fit under `cost`, if the sample was fitted with it.
    pub fn fit(&self, cost: CostFunction) -> Option<&FitStudy> {
        self.fits.iter().find(|f| f.cost == cost)
    }

    /// The finished fit under `cost`.
    pub fn done(&self, cost: CostFunction) -> Option<&DoneFit> {
        self.fit(cost).and_then(FitStudy::done)
    }
}

impl SampleStudy {
    /// "simulated — replayed from …" when the scan was measured on a simulated instrument
    /// (its stored provenance says so), as `brdfd show` says it; `None` for a scan from real
    /// instruments, or one whose provenance is unknown (a study made in memory).
    pub fn simulated_note(&self) -> Option<String> {
        let p = &self.origin.as_ref()?.provenance;
        if !p.simulated() {
            return None;
        }
        Some(match p.source_detail.as_deref() {
            Some(d) if d.starts_with("simulated") => d.to_string(),
            Some(d) => format!("simulated — {d}"),
            None => "simulated — which recording answered was not recorded".into(),
        })
    }

    /// The recording a simulated scan replayed, as its provenance names it
    /// ("synthetic-t-sky-blue (T.Sky blue)"); `None` for a scan that is not simulated or whose
    /// recording was not recorded.
    pub fn recording(&self) -> Option<String> {
        let note = self.simulated_note()?;
        note.strip_prefix("simulated — replayed from ")
            .map(str::to_string)
    }
}

/// What a figure or the summary says of the simulated scans among `samples`: "simulated —
/// replayed from A, B", and whether every one of them is simulated. `None` when none is.
pub fn simulated_statement<'a>(
    samples: impl IntoIterator<Item = &'a SampleStudy>,
) -> Option<(String, bool)> {
    let mut named: Vec<String> = Vec::new();
    let mut other: Vec<String> = Vec::new();
    let (mut simulated, mut total) = (0usize, 0usize);
    for s in samples {
        total += 1;
        let Some(note) = s.simulated_note() else {
            continue;
        };
        simulated += 1;
        match s.recording() {
            Some(r) if !named.contains(&r) => named.push(r),
            Some(_) => {}
            None => {
                let rest = note
                    .strip_prefix("simulated — ")
                    .unwrap_or(&note)
                    .to_string();
                if !other.contains(&rest) {
                    other.push(rest);
                }
            }
        }
    }
    if simulated == 0 {
        return None;
    }
    let mut text = String::from("simulated");
    if !named.is_empty() {
        text.push_str(&format!(" — replayed from {}", named.join(", ")));
    }
    if !other.is_empty() {
        text.push_str(&format!(
            "{}{}",
            if named.is_empty() { " — " } else { "; " },
            other.join("; ")
        ));
    }
    Some((text, simulated == total))
}

impl Study {
    /// Every finished fit of every sample, in sample order.
    pub fn done_fits(&self) -> impl Iterator<Item = &DoneFit> {
        self.samples
            .iter()
            .flat_map(|s| s.fits.iter().filter_map(|f| f.done()))
    }

    /// The cost functions any sample was fitted with, in [`CostFunction::ALL`] order.
    pub fn cost_functions(&self) -> Vec<CostFunction> {
        CostFunction::ALL
            .into_iter()
            .filter(|c| self.samples.iter().any(|s| s.fit(*c).is_some()))
            .collect()
    }

    /// The methods of all fits, deduplicated in order of first use (for captions).
    pub fn methods(&self) -> Vec<String> {
        let mut out: Vec<String> = Vec::new();
        for f in self.samples.iter().flat_map(|s| &s.fits) {
            if !out.contains(&f.method) {
                out.push(f.method.clone());
            }
        }
        out
    }

    /// The methods used under one cost function, joined for a caption ("separable").
    pub fn method_of(&self, cost: CostFunction) -> String {
        let mut out: Vec<&str> = Vec::new();
        for f in self.samples.iter().filter_map(|s| s.fit(cost)) {
            if !out.contains(&f.method.as_str()) {
                out.push(&f.method);
            }
        }
        if out.is_empty() {
            "none".into()
        } else {
            out.join(" + ")
        }
    }

    /// The specular strategies in use, deduplicated (for captions).
    pub fn specular_strategies(&self) -> Vec<SpecularStrategy> {
        let mut out = Vec::new();
        for s in &self.samples {
            if !out.contains(&s.specular) {
                out.push(s.specular);
            }
        }
        out
    }

    /// A study of the first `n` noise-free synthetic paper samples
    /// ([`crate::synth::paper_samples`]) fitted without an optimiser, for tests: sample `i`'s fit
    /// under cost function `k` of [`CostFunction::ALL`] is `fit(i, k, the sample's ground-truth
    /// parameters)`, finished (method "separable") at the parameters it returns or failed for
    /// the reason it gives.
    pub fn from_truth(
        n: usize,
        fit: impl Fn(usize, usize, Params) -> Result<Params, String>,
    ) -> Study {
        let samples = crate::synth::paper_samples()
            .iter()
            .take(n)
            .enumerate()
            .map(|(i, truth)| {
                let scan = crate::synth::synth_scan(truth, &Default::default())
                    .expect("the paper's samples synthesise");
                let measured = crate::processing::process(&scan, &Default::default())
                    .expect("a synthetic scan processes");
                let fits = CostFunction::ALL
                    .iter()
                    .enumerate()
                    .map(|(k, &cost)| FitStudy {
                        cost,
                        method: "separable".into(),
                        state: match fit(i, k, truth.params) {
                            Ok(params) => FitState::Done(Box::new(DoneFit::from_params(
                                &measured,
                                params,
                                FresnelCosine::Incidence,
                            ))),
                            Err(reason) => FitState::Failed { reason },
                        },
                    })
                    .collect();
                SampleStudy {
                    name: scan.sample.clone(),
                    scan_id: None,
                    origin: None,
                    scan,
                    specular: SpecularStrategy::Ratio,
                    reference_reflectance: None,
                    measured,
                    fits,
                }
            })
            .collect();
        Study { samples }
    }

    /// A study from fits made in this process (`brdfd demo`, tests): `reports[i]` are the fits
    /// of `scans[i]`, all made from the same processing of the scan. Panics if the lengths
    /// differ or a sample has no report (a programming error, not a data error).
    pub fn from_fit_reports(scans: &[Scan], reports: &[Vec<FitReport>]) -> Study {
        assert_eq!(
            scans.len(),
            reports.len(),
            "one list of fit reports per scan"
        );
        let samples = scans
            .iter()
            .zip(reports)
            .map(|(scan, reports)| {
                let first = reports.first().expect("every scan has at least one fit");
                let mut fits: Vec<FitStudy> = reports
                    .iter()
                    .map(|r| FitStudy {
                        cost: r.request.settings.cost,
                        method: r.outcome.method.to_string(),
                        state: FitState::Done(Box::new(
                            DoneFit::from_params_with(
                                &r.measured,
                                r.outcome.params,
                                r.request.settings.fresnel,
                                r.request.colorimetry,
                                r.uncertainty.clone(),
                            )
                            .with_model(&r.measured, r.request.settings.model)
                            .with_sra(&r.measured, r.request.settings.sra)
                            .with_bounds(&r.request.settings.bounds),
                        )),
                    })
                    .collect();
                fits.sort_by_key(|f| CostFunction::ALL.iter().position(|c| *c == f.cost));
                SampleStudy {
                    name: scan.sample.clone(),
                    scan_id: None,
                    origin: None,
                    scan: scan.clone(),
                    specular: first.request.processing.specular,
                    reference_reflectance: first.request.processing.reference_reflectance,
                    measured: first.measured,
                    fits,
                }
            })
            .collect();
        Study { samples }
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    /// A small study without running an optimiser: the synthetic samples' ground-truth
    /// parameters, perturbed per cost function so that the fits differ. Sample `failed` (if
    /// any) has its m2 fit failed.
    pub(crate) fn study_from_truth(n: usize, failed: Option<usize>) -> Study {
        Study::from_truth(n, |i, k, mut p| {
            if failed == Some(i) && CostFunction::ALL[k] == CostFunction::M2 {
                return Err("cancelled by the operator".into());
            }
            // Different, sample-dependent errors per cost function.
            let f = 1.0 + 0.03 * (k as f64 + 1.0) * (1.0 + (i % 3) as f64);
            p.kd = p.kd.map(|v| v * f);
            p.alpha *= 1.0 + 0.1 * k as f64;
            Ok(p)
        })
    }

    /// `study` as if loaded from a store whose scans were measured on simulated instruments:
    /// sample `i` replayed from the recording `recordings[i]`, named as the store names it.
    pub(crate) fn simulated(mut study: Study, recordings: &[&str]) -> Study {
        use crate::store::{InstrumentProvenance, Provenance, Source};
        let sim = InstrumentProvenance {
            simulated: Some(true),
            origin: crate::store::InstrumentOrigin::Simulated,
            ..InstrumentProvenance::unknown()
        };
        for (s, r) in study.samples.iter_mut().zip(recordings) {
            s.origin = Some(Origin {
                station: None,
                measured_at_ms: 0,
                provenance: Provenance {
                    ma_t12: sim.clone(),
                    sra: sim.clone(),
                    source: Source::Measured,
                    source_detail: Some(format!("simulated — replayed from {r}")),
                },
            });
        }
        study
    }

    /// The demo run twice into one store: every sample's recording replayed again, the second
    /// run's scans after the first's, both named by scan id as the loader names them.
    pub(crate) fn replayed_twice(n: usize) -> Study {
        let once = study_from_truth(n, None);
        let recordings: Vec<String> = once
            .samples
            .iter()
            .map(|s| format!("synthetic-{} ({})", crate::names::slug(&s.name), s.name))
            .collect();
        let refs: Vec<&str> = recordings.iter().map(String::as_str).collect();
        let mut samples = Vec::new();
        for run in 0..2 {
            let mut copy = simulated(once.clone(), &refs);
            for (i, s) in copy.samples.iter_mut().enumerate() {
                let id = (run * n + i + 1) as i64;
                s.scan_id = Some(id);
                s.name = format!("{} (scan {id})", s.name);
            }
            samples.extend(copy.samples);
        }
        Study { samples }
    }

    #[test]
    fn a_done_fit_is_the_model_at_its_parameters() {
        let study = study_from_truth(2, Some(1));
        let s = &study.samples[0];
        let d = s.done(CostFunction::Cf1).unwrap();
        assert_eq!(
            d.estimated,
            model::evaluate(&d.params, d.fresnel, &SpecularGeometry::all())
        );
        assert_eq!(d.evaluation, evaluate(&s.measured.values, &d.estimated));
        assert!(d.evaluation.all.mean > 0.0);
        assert_eq!(study.cost_functions(), CostFunction::ALL.to_vec());
        assert_eq!(study.methods(), vec!["separable".to_string()]);
        let m2 = study.samples[1].fit(CostFunction::M2).unwrap();
        assert!(m2.done().is_none());
        assert_eq!(
            m2.problem().unwrap(),
            "m2 fit failed: cancelled by the operator"
        );
    }
}
