//! Builds a [`Study`] from a station's store, through its public verbs only, or from the lab's
//! central PostgreSQL database through [`crate::store::central`] (one loader, two sources): per complete scan its
//! readings and reference (→ [`Scan`]), its processed BRDF, and per cost function the latest
//! finished fit run (else the latest run, failed or unfinished, to say why there is none).
//!
//! A scan may have been processed under more than one specular strategy; the study takes the
//! processed version most of the scan's fits were made from. The estimated BRDF is the model at
//! the stored parameters with the stored Fresnel setting, and the ΔE00 is recomputed from
//! measured and estimated (it equals what the fit worker stored; recomputing keeps one code path
//! for in-memory and stored studies).

use std::collections::HashMap;

use crate::cost::CostFunction;
use crate::model::{FresnelCosine, Params};
use crate::processing::{self, ProcessingOptions};
use crate::store::central::{self, CentralSelection};
use crate::store::{
    FitRun, FitStatus, Processed, ScanDetail, ScanFilter, ScanId, ScanState, Store, StoreError,
};

use super::{DoneFit, FitState, FitStudy, Origin, SampleStudy, Study};

/// Which scans a report covers.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Selection {
    /// Every complete scan, oldest first.
    All,
    /// These scans, in this order.
    Scans(Vec<ScanId>),
}

/// Why a study could not be loaded.
#[derive(Debug, thiserror::Error)]
pub enum LoadError {
    #[error(transparent)]
    Store(#[from] StoreError),
    /// A scan asked for by id has no complete set of readings.
    #[error("scan {scan} is {state}, not complete; only complete scans can be reported")]
    NotComplete { scan: ScanId, state: ScanState },
    /// What the store holds does not make a valid scan or fit (a bug or a damaged database).
    #[error("scan {scan}: {message}")]
    Inconsistent { scan: ScanId, message: String },
}

/// What a fit run's stored detail adds to its row (migration 0011): the colorimetry of its
/// evaluation and its bootstrap intervals.
#[derive(Debug, Clone, Default)]
pub(crate) struct FitExtras {
    pub colorimetry: Option<crate::colour::Colorimetry>,
    pub uncertainty: Option<crate::uncertainty::Uncertainty>,
    /// The leave-one-geometry-out cross-validation (migration 0030).
    pub crossval: Option<crate::crossval::CrossValidation>,
}

/// A fit run as a study fit, without its stored extras (the paper's colorimetry, no intervals).
pub(crate) fn fit_state(
    scan: ScanId,
    run: &FitRun,
    measured: &processing::MeasuredBrdf,
) -> Result<FitState, LoadError> {
    fit_state_with(scan, run, measured, &FitExtras::default())
}

/// A fit run as a study fit, evaluated under its stored colorimetry, with its intervals.
fn fit_state_with(
    scan: ScanId,
    run: &FitRun,
    measured: &processing::MeasuredBrdf,
    extras: &FitExtras,
) -> Result<FitState, LoadError> {
    Ok(match run.status {
        FitStatus::Done => {
            let result = run.result.as_ref().ok_or_else(|| LoadError::Inconsistent {
                scan,
                message: format!("fit run {} is done without a result", run.id),
            })?;
            let params: Params = serde_json::from_value(result.params.clone()).map_err(|e| {
                LoadError::Inconsistent {
                    scan,
                    message: format!("fit run {}: parameters: {e}", run.id),
                }
            })?;
            let fresnel: FresnelCosine = run
                .settings
                .get("fresnel")
                .and_then(|v| serde_json::from_value(v.clone()).ok())
                .unwrap_or_default();
            // The SRA reading model is in the settings (absent: the paper's flat model).
            let sra: crate::sra_reading::SraReading = match run.settings.get("sra") {
                None => Default::default(),
                Some(v) => {
                    serde_json::from_value(v.clone()).map_err(|e| LoadError::Inconsistent {
                        scan,
                        message: format!("fit run {}: settings: sra: {e}", run.id),
                    })?
                }
            };
            // The colorimetry and the intervals stored with the fit (migration 0011).
            FitState::Done(Box::new(
                DoneFit::from_params_with(
                    measured,
                    params,
                    fresnel,
                    extras.colorimetry.unwrap_or_default(),
                    extras.uncertainty.clone(),
                )
                .with_model(
                    measured,
                    run.settings
                        .get("model")
                        .and_then(|v| serde_json::from_value(v.clone()).ok())
                        .unwrap_or_default(),
                )
                .with_sra(measured, sra)
                .with_bounds(
                    &run.settings
                        .get("bounds")
                        .and_then(|v| serde_json::from_value(v.clone()).ok())
                        .unwrap_or_default(),
                )
                .with_crossval(extras.crossval.clone()),
            ))
        }
        FitStatus::Failed => FitState::Failed {
            reason: run
                .error
                .clone()
                .unwrap_or_else(|| "no reason recorded".into()),
        },
        other => FitState::Unfinished {
            status: other.to_string(),
        },
    })
}

/// One scan as a study sample, from its stored detail, processed versions and fit runs
/// (the same whichever database they were read from).
fn assemble(
    id: ScanId,
    detail: ScanDetail,
    processed: Vec<Processed>,
    runs: Vec<FitRun>,
    extras: &HashMap<i64, FitExtras>,
) -> Result<SampleStudy, LoadError> {
    if detail.scan.state != ScanState::Complete {
        return Err(LoadError::NotComplete {
            scan: id,
            state: detail.scan.state,
        });
    }
    let scan = detail.to_scan().map_err(|e| LoadError::Inconsistent {
        scan: id,
        message: e.to_string(),
    })?;
    // The processed version most fits were made from; else the first; else process now.
    let mut uses: HashMap<i64, usize> = HashMap::new();
    for r in &runs {
        *uses.entry(r.processed.0).or_default() += 1;
    }
    let chosen = processed.iter().max_by_key(|p| {
        (
            uses.get(&p.id.0).copied().unwrap_or(0),
            std::cmp::Reverse(p.id.0),
        )
    });
    let (measured, specular, processed_id) = match chosen {
        Some(p) => (p.brdf, p.specular, Some(p.id)),
        None => {
            let opts = ProcessingOptions {
                reference_reflectance: detail.reference.reference.rho_ref,
                ..ProcessingOptions::default()
            };
            let m = processing::process(&scan, &opts).map_err(|e| LoadError::Inconsistent {
                scan: id,
                message: e.to_string(),
            })?;
            (m, opts.specular, None)
        }
    };
    let mut fits = Vec::new();
    for cost in CostFunction::ALL {
        let mine: Vec<&FitRun> = runs
            .iter()
            .filter(|r| r.cost_function == cost && Some(r.processed) == processed_id)
            .collect();
        let pick = mine
            .iter()
            .rev()
            .find(|r| r.status == FitStatus::Done)
            .or(mine.last());
        if let Some(run) = pick {
            fits.push(FitStudy {
                cost,
                method: run.method.clone(),
                state: fit_state_with(
                    id,
                    run,
                    &measured,
                    extras.get(&run.id.0).unwrap_or(&FitExtras::default()),
                )?,
            });
        }
    }
    let origin = Origin {
        station: None,
        measured_at_ms: detail
            .scan
            .started_at_ms
            .unwrap_or(detail.scan.requested_at_ms),
        provenance: detail.scan.provenance.clone(),
    };
    Ok(SampleStudy {
        name: scan.sample.clone(),
        scan_id: Some(id.0),
        origin: Some(origin),
        scan,
        specular,
        reference_reflectance: detail.reference.reference.rho_ref,
        measured,
        fits,
    })
}

/// One scan of a station's store as a study sample.
async fn sample(store: &Store, id: ScanId) -> Result<SampleStudy, LoadError> {
    let detail = store.scan_detail(id).await?;
    let processed = store.processed_for_scan(id).await?;
    let runs = store.fits_for_scan(id).await?;
    let mut extras = HashMap::new();
    for run in &runs {
        let d = store.fit_detail(run.id).await?;
        extras.insert(
            run.id.0,
            FitExtras {
                colorimetry: d.colorimetry,
                uncertainty: d.uncertainty,
                crossval: d.crossval,
            },
        );
    }
    assemble(id, detail, processed, runs, &extras)
}

/// The study of the selected scans.
pub async fn from_store(store: &Store, selection: &Selection) -> Result<Study, LoadError> {
    let ids: Vec<ScanId> = match selection {
        Selection::Scans(ids) => ids.clone(),
        Selection::All => {
            let mut list = store
                .list_scans(&ScanFilter {
                    state: Some(ScanState::Complete),
                    sample: None,
                    limit: u32::MAX,
                    before: None,
                })
                .await?;
            list.sort_by_key(|s| s.id.0);
            list.into_iter().map(|s| s.id).collect()
        }
    };
    let mut samples = Vec::new();
    for id in ids {
        samples.push(sample(store, id).await?);
    }
    disambiguate(&mut samples);
    Ok(Study { samples })
}

/// The study of the selected scans of the lab's central database (`brdfd report --db
/// postgres://…`), built by the same [`assemble`] as [`from_store`]: for one station's scans
/// the study, its figures and its statistics are those of that station's own store. Across
/// stations each sample's name carries its station, `T.Sky blue [bench-2]`, so figures and
/// exports say where every sample was measured.
pub async fn from_central(
    pool: &sqlx::PgPool,
    selection: &CentralSelection,
) -> Result<Study, LoadError> {
    let scans = central::load_scans(pool, selection).await?;
    let stations: std::collections::BTreeSet<&str> =
        scans.iter().map(|s| s.station.as_str()).collect();
    let several = stations.len() > 1;
    let mut samples = Vec::with_capacity(scans.len());
    for s in scans {
        let id = s.detail.scan.id;
        let station = s.station.clone();
        // The intervals and colorimetry of migration 0011, forwarded by central step 0002,
        // fetched with the fit runs in the same query.
        let mut extras = HashMap::new();
        for (run, text) in &s.fit_extras {
            let inconsistent = |message: String| LoadError::Inconsistent { scan: id, message };
            let uncertainty = text
                .uncertainty_json
                .as_deref()
                .map(serde_json::from_str)
                .transpose()
                .map_err(|e| inconsistent(format!("fit run {run}: uncertainty_json: {e}")))?;
            let crossval = text
                .crossval_json
                .as_deref()
                .map(serde_json::from_str)
                .transpose()
                .map_err(|e| inconsistent(format!("fit run {run}: crossval_json: {e}")))?;
            let colorimetry = match (&text.observer, &text.weighting) {
                (Some(o), Some(w)) => Some(crate::colour::Colorimetry {
                    observer: o
                        .parse()
                        .map_err(|e| inconsistent(format!("fit run {run}: observer: {e}")))?,
                    weighting: w
                        .parse()
                        .map_err(|e| inconsistent(format!("fit run {run}: weighting: {e}")))?,
                }),
                _ => None,
            };
            extras.insert(
                *run,
                FitExtras {
                    colorimetry,
                    uncertainty,
                    crossval,
                },
            );
        }
        let mut sample = assemble(id, s.detail, s.processed, s.fits, &extras)?;
        if several {
            // As with the name: one station's study is the study of its own store.
            if let Some(origin) = sample.origin.as_mut() {
                origin.station = Some(station.clone());
            }
            sample.name = format!("{} [{station}]", sample.name);
        }
        samples.push(sample);
    }
    disambiguate(&mut samples);
    Ok(Study { samples })
}

/// A sample scanned more than once: tell the scans apart by id.
fn disambiguate(samples: &mut [SampleStudy]) {
    let mut count: HashMap<String, usize> = HashMap::new();
    for s in samples.iter() {
        *count.entry(s.name.clone()).or_default() += 1;
    }
    for s in samples.iter_mut() {
        if count[&s.name] > 1
            && let Some(id) = s.scan_id
        {
            s.name = format!("{} (scan {id})", s.name);
        }
    }
}

/// A study held to the rule of `brdfd report` over a store (`--all` pools the real
/// scans only when it holds both kinds; chosen scans that mix them are refused), with the
/// samples named as the report names them (`T.Sky blue [bench-2]`).
pub fn pool_real_study(
    mut study: Study,
    selection: &Selection,
    include_simulated: bool,
) -> Result<Study, String> {
    let simulated = |s: &SampleStudy| s.origin.as_ref().is_some_and(|o| o.provenance.simulated());
    let (sim, real): (Vec<_>, Vec<_>) = study.samples.iter().partition(|s| simulated(s));
    if include_simulated || sim.is_empty() || real.is_empty() {
        return Ok(study);
    }
    let names = |v: &[&SampleStudy]| {
        let shown: Vec<&str> = v.iter().take(8).map(|s| s.name.as_str()).collect();
        let more = v.len().saturating_sub(8);
        if more > 0 {
            format!("{} and {more} more", shown.join(", "))
        } else {
            shown.join(", ")
        }
    };
    if matches!(selection, Selection::Scans(_)) {
        return Err(format!(
            "the selection mixes scans from simulated instruments ({}) with scans from real ones \
             ({}); select one kind, or pass --include-simulated to study them together",
            names(&sim),
            names(&real)
        ));
    }
    eprintln!(
        "pooling the {} real scans ({}) only; left out {} scans from simulated instruments \
         ({}): pass --include-simulated to pool them too",
        real.len(),
        names(&real),
        sim.len(),
        names(&sim)
    );
    study.samples.retain(|s| !simulated(s));
    Ok(study)
}
