//! The one conversion from each of the service's and the store's records that the API does not
//! send as it is to the wire type ([`crate::wire`]) a handler answers with. The JSON is the
//! record's own serialisation, field for field: a wire type only owns its strings, opens its
//! closed sets of values, and leaves out what the record keeps for the service.

use crate::wire;

/// A number that serialises as `null` when not finite, as the record's `f64` did.
fn finite(v: f64) -> Option<f64> {
    v.is_finite().then_some(v)
}

impl From<crate::service::Operation> for wire::Operation {
    fn from(op: crate::service::Operation) -> Self {
        match op {
            crate::service::Operation::Reference { reference } => {
                wire::Operation::Reference { reference }
            }
            crate::service::Operation::Scan { scan } => wire::Operation::Scan { scan },
        }
    }
}

/// A text the service gives as `&'static str`, read as the closed set it belongs to.
pub(super) fn open<T: serde::de::DeserializeOwned>(text: &str) -> wire::Open<T> {
    serde_json::from_value(serde_json::Value::String(text.to_string()))
        .unwrap_or_else(|_| wire::Open::Unknown(text.to_string()))
}

impl From<&crate::store::Reading> for wire::Reading {
    fn from(r: &crate::store::Reading) -> Self {
        wire::Reading {
            id: r.id.0,
            device: r.device().into(),
            geometry: r.geometry.name.to_string(),
            values: r.values,
            raw_frame: hex::encode(&r.raw_frame),
            at_ms: r.at_ms,
        }
    }
}

impl From<crate::store::ReferenceDetail> for wire::ReferenceDetail<crate::store::ReferenceSummary> {
    fn from(d: crate::store::ReferenceDetail) -> Self {
        wire::ReferenceDetail {
            reference: d.reference,
            readings: d.readings.iter().map(Into::into).collect(),
        }
    }
}

impl From<crate::store::FitDetail> for wire::FitDetail {
    fn from(d: crate::store::FitDetail) -> Self {
        let run = d.run;
        // The reach verdict from what is stored (SCIENCE.md §12.7): measured L*, the MA-T12
        // ΔE00, the held-out ΔE00 once cross-validated, the Fresnel factor of the settings.
        let reach = match (&d.lab, &d.evaluation) {
            (Some(lab), Some(e)) => {
                let fresnel = run
                    .settings
                    .get("fresnel")
                    .and_then(|f| serde_json::from_value(f.clone()).ok())
                    .unwrap_or_default();
                crate::reach::Evidence::of(
                    lab,
                    e.diffuse.mean,
                    d.crossval.as_ref().map(|c| c.held_out_mean),
                    fresnel,
                )
                .map(|ev| crate::reach::assess(&ev))
            }
            _ => None,
        };
        let at_bound = run
            .result
            .as_ref()
            .and_then(|r| serde_json::from_value::<crate::model::Params>(r.params.clone()).ok())
            .map(|p| {
                let bounds = run
                    .settings
                    .get("bounds")
                    .and_then(|b| serde_json::from_value(b.clone()).ok())
                    .unwrap_or_default();
                crate::uncertainty::jackknife::at_bound(&p, &bounds)
            })
            .unwrap_or_default();
        wire::FitDetail {
            at_bound,
            run: wire::FitRun {
                id: run.id,
                scan: run.scan,
                processed: run.processed.0,
                specular: run.specular.into(),
                method: run.method,
                cost_function: run.cost_function.into(),
                settings: run.settings,
                seed: run.seed,
                status: run.status.into(),
                error: run.error,
                result: run.result.map(|r| wire::FitResult {
                    cost: r.cost,
                    params: r.params,
                    best_cost_per_generation: r
                        .best_cost_per_generation
                        .into_iter()
                        .map(finite)
                        .collect(),
                    evaluations: r.evaluations,
                    generations: r.generations,
                    wall_ms: r.wall_ms,
                }),
                queued_at_ms: run.queued_at_ms,
                started_at_ms: run.started_at_ms,
                finished_at_ms: run.finished_at_ms,
            },
            evaluation: d.evaluation.map(|e| wire::Evaluation {
                per_geometry: e.per_geometry.into_iter().map(finite).collect(),
                all: e.all,
                diffuse: e.diffuse,
                specular: e.specular,
            }),
            colorimetry: d.colorimetry,
            uncertainty: d.uncertainty,
            crossval: d.crossval,
            sra: d.sra,
            specular_delta_l: d.specular_delta_l,
            lab: d.lab,
            reach,
        }
    }
}
