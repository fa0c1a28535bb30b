//! Builds a [`Study`] from the store, through its public verbs only: per complete scan its
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
use crate::geometry::{Device, GEOMETRIES, MA_T12_COUNT};
use crate::model::{FresnelCosine, Params};
use crate::processing::{self, ProcessingOptions};
use crate::scan::{DeviceReadings, Reference, Scan};
use crate::spectral::BANDS;
use crate::store::{
    FitRun, FitStatus, Reading, ReadingValues, ScanFilter, ScanId, ScanState, Store, StoreError,
};

use super::study::{DoneFit, FitState, FitStudy, SampleStudy, Study};

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

fn readings_of(
    scan: ScanId,
    readings: &[Reading],
    what: &str,
) -> Result<DeviceReadings, LoadError> {
    let mut out = DeviceReadings {
        ma_t12: [[0.0; BANDS]; MA_T12_COUNT],
        sra: [0.0; crate::geometry::SRA_COUNT],
    };
    let mut seen = [false; crate::geometry::GEOMETRY_COUNT];
    for r in readings {
        let g = r.geometry;
        match (g.device, &r.values) {
            (Device::MaT12, ReadingValues::Spectrum(s)) => out.ma_t12[g.index] = *s,
            (Device::Sra, ReadingValues::Intensity(v)) => out.sra[g.index - MA_T12_COUNT] = *v,
            _ => {
                return Err(LoadError::Inconsistent {
                    scan,
                    message: format!("{what} reading at {} has the wrong kind of value", g.name),
                });
            }
        }
        seen[g.index] = true;
    }
    if let Some(g) = seen.iter().position(|s| !s) {
        return Err(LoadError::Inconsistent {
            scan,
            message: format!("no {what} reading at {}", GEOMETRIES[g].name),
        });
    }
    Ok(out)
}

pub(crate) fn fit_state(
    scan: ScanId,
    run: &FitRun,
    measured: &processing::MeasuredBrdf,
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
            FitState::Done(Box::new(DoneFit::from_params(measured, params, fresnel)))
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

/// One scan as a study sample.
async fn sample(store: &Store, id: ScanId) -> Result<SampleStudy, LoadError> {
    let detail = store.scan_detail(id).await?;
    if detail.scan.state != ScanState::Complete {
        return Err(LoadError::NotComplete {
            scan: id,
            state: detail.scan.state,
        });
    }
    let scan = Scan {
        sample: detail.scan.sample.clone(),
        reference: Reference {
            name: detail.reference.reference.name.clone(),
            readings: readings_of(id, &detail.reference.readings, "reference")?,
        },
        readings: readings_of(id, &detail.readings, "sample")?,
    };
    let processed = store.processed_for_scan(id).await?;
    let runs = store.fits_for_scan(id).await?;
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
                state: fit_state(id, run, &measured)?,
            });
        }
    }
    Ok(SampleStudy {
        name: scan.sample.clone(),
        scan_id: Some(id.0),
        scan,
        specular,
        reference_reflectance: detail.reference.reference.rho_ref,
        measured,
        fits,
    })
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
    // A sample scanned more than once: tell the scans apart by id.
    let mut count: HashMap<String, usize> = HashMap::new();
    for s in &samples {
        *count.entry(s.name.clone()).or_default() += 1;
    }
    for s in &mut samples {
        if count[&s.name] > 1
            && let Some(id) = s.scan_id
        {
            s.name = format!("{} (scan {id})", s.name);
        }
    }
    Ok(Study { samples })
}
