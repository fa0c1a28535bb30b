//! Store verbs for fit runs and their colour evaluations.
//!
//! A fit run goes queued → running → done | failed | cancelled, each move one conditional
//! UPDATE. `finish_fit` writes the result, the 14 ΔE00 values and their summary in one
//! transaction, so a fit is never `done` without its evaluation.

use crate::colour::Colorimetry;
use crate::crossval::CrossValidation;
use crate::geometry::{Device, GEOMETRIES, GEOMETRY_COUNT, Geometry, GeometrySet, MA_T12_COUNT};
use crate::model::{self, FresnelCosine, Params, SpecularGeometry};
use crate::processing::MeasuredBrdf;
use crate::spectral::Spectrum;
use crate::sra_reading::{SraReading, specular_delta_l};
use crate::uncertainty::Uncertainty;

use super::codec;
use super::guarded::refused;
use super::ids::{FitRunId, ProcessedId, ScanId};
use super::records::{
    DeltaESummary, EvaluationRecord, FitDetail, FitResult, FitRun, FitStatus, NewFit,
    delta_e_summary,
};
use super::{Store, StoreError, now_ms};

#[derive(sqlx::FromRow)]
pub(super) struct FitRow {
    id: i64,
    scan_id: i64,
    processed_id: i64,
    specular: String,
    method: String,
    cost_function: String,
    settings_json: String,
    seed: String,
    /// Migration 0020; absent from a central row read before its step 9, NULL before then.
    #[sqlx(default)]
    fit_observer: Option<String>,
    #[sqlx(default)]
    fit_weighting: Option<String>,
    status: String,
    error: Option<String>,
    cost: Option<f64>,
    params_json: Option<String>,
    best_cost_per_generation_json: Option<String>,
    evaluations: Option<i64>,
    generations: Option<i64>,
    wall_ms: Option<f64>,
    queued_at_ms: i64,
    started_at_ms: Option<i64>,
    finished_at_ms: Option<i64>,
}

const FIT_RUN: &str = "\
    SELECT f.id, f.scan_id, f.processed_id, p.specular, f.method, f.cost_function,
           f.settings_json, f.seed, f.fit_observer, f.fit_weighting, f.status, f.error, f.cost,
           f.params_json, f.best_cost_per_generation_json, f.evaluations, f.generations, f.wall_ms,
           f.queued_at_ms, f.started_at_ms, f.finished_at_ms
    FROM fit_runs f JOIN processed p ON p.id = f.processed_id";

impl FitRow {
    pub(super) fn into_run(self) -> Result<FitRun, StoreError> {
        let id = self.id;
        let corrupt = |detail: String| StoreError::Corrupt {
            table: "fit_runs",
            id,
            detail,
        };
        let json = |field: &str, text: &str| {
            serde_json::from_str::<serde_json::Value>(text)
                .map_err(|e| corrupt(format!("{field}: {e}")))
        };
        let status: FitStatus = self.status.parse().map_err(corrupt)?;
        let colorimetry = match (&self.fit_observer, &self.fit_weighting) {
            (Some(observer), Some(weighting)) => Some(Colorimetry {
                observer: observer
                    .parse()
                    .map_err(|e: crate::colour::ColorimetryError| corrupt(e.to_string()))?,
                weighting: weighting
                    .parse()
                    .map_err(|e: crate::colour::ColorimetryError| corrupt(e.to_string()))?,
            }),
            (None, None) => None,
            _ => {
                return Err(corrupt(
                    "fit_observer and fit_weighting: one is set without the other".into(),
                ));
            }
        };
        let result = match (
            self.cost,
            &self.params_json,
            &self.best_cost_per_generation_json,
            self.evaluations,
            self.generations,
            self.wall_ms,
        ) {
            (
                Some(cost),
                Some(params),
                Some(best),
                Some(evaluations),
                Some(generations),
                Some(wall_ms),
            ) => Some(FitResult {
                cost,
                params: json("params_json", params)?,
                best_cost_per_generation: serde_json::from_str(best)
                    .map_err(|e| corrupt(format!("best_cost_per_generation_json: {e}")))?,
                evaluations: evaluations as u64,
                generations: generations as u32,
                wall_ms,
            }),
            _ => None,
        };
        Ok(FitRun {
            id: FitRunId(id),
            scan: ScanId(self.scan_id),
            processed: ProcessedId(self.processed_id),
            specular: self
                .specular
                .parse()
                .map_err(|e: crate::processing::UnknownSpecularStrategy| corrupt(e.to_string()))?,
            method: self.method,
            cost_function: self
                .cost_function
                .parse()
                .map_err(|e: crate::cost::ParseCostFunctionError| corrupt(e.to_string()))?,
            settings: json("settings_json", &self.settings_json)?,
            seed: self
                .seed
                .parse()
                .map_err(|e| corrupt(format!("seed \"{}\": {e}", self.seed)))?,
            colorimetry,
            status,
            error: self.error,
            result,
            queued_at_ms: self.queued_at_ms,
            started_at_ms: self.started_at_ms,
            finished_at_ms: self.finished_at_ms,
        })
    }
}

fn to_json(field: &'static str, value: &impl serde::Serialize) -> Result<String, StoreError> {
    serde_json::to_string(value).map_err(|source| StoreError::Json { field, source })
}

impl Store {
    /// Queues a fit of processed scan `processed`; status `queued`. Returns its id.
    pub async fn queue_fit(
        &self,
        processed: ProcessedId,
        fit: &NewFit,
    ) -> Result<FitRunId, StoreError> {
        if fit.method.trim().is_empty() {
            return Err(StoreError::Empty {
                field: "fit method",
            });
        }
        let id: Option<i64> = sqlx::query_scalar(
            "INSERT INTO fit_runs (scan_id, processed_id, method, cost_function, settings_json,
                                   seed, status, queued_at_ms, sra, fit_observer, fit_weighting)
             SELECT p.scan_id, p.id, $2, $3, $4, $5, 'queued', $6, $7, $8, $9
             FROM processed p WHERE p.id = $1
             RETURNING id",
        )
        .bind(processed.0)
        .bind(&fit.method)
        .bind(fit.cost_function.name())
        .bind(to_json("fit settings", &fit.settings)?)
        .bind(fit.seed.to_string())
        .bind(now_ms())
        .bind(fit.sra_model()?.name())
        .bind(fit.colorimetry.observer.to_string())
        .bind(fit.colorimetry.weighting.to_string())
        .fetch_optional(&self.writer)
        .await?;
        id.map(FitRunId).ok_or(StoreError::NotFound {
            what: ProcessedId::WHAT,
            id: processed.0,
        })
    }

    /// queued → running: the worker picked it up.
    pub async fn start_fit(&self, fit: FitRunId) -> Result<(), StoreError> {
        let done = sqlx::query(
            "UPDATE fit_runs SET status = 'running', started_at_ms = $2
             WHERE id = $1 AND status = 'queued'",
        )
        .bind(fit.0)
        .bind(now_ms())
        .execute(&self.writer)
        .await?;
        self.changed(fit, done.rows_affected(), "queued", "start it")
            .await
    }

    /// running → done, with the optimiser's result and the ΔE00 at each geometry (table
    /// order); the store adds the mean/median/max summaries. One transaction. The ΔE00 are
    /// recorded as computed with the paper's colorimetry; see [`Store::finish_fit_with`].
    pub async fn finish_fit(
        &self,
        fit: FitRunId,
        outcome: &FitResult,
        delta_e00: &[f64; GEOMETRY_COUNT],
    ) -> Result<(), StoreError> {
        self.finish_fit_with(
            fit,
            outcome,
            delta_e00,
            GeometrySet::ALL,
            Colorimetry::default(),
        )
        .await
    }

    /// [`Store::finish_fit`] for a scan that measured `geometries` (the ΔE00 at the others are
    /// not stored, and the specular summary is NULL without SRA geometries), recording the
    /// colorimetry the ΔE00 values were computed with.
    pub async fn finish_fit_with(
        &self,
        fit: FitRunId,
        outcome: &FitResult,
        delta_e00: &[f64; GEOMETRY_COUNT],
        geometries: GeometrySet,
        colorimetry: Colorimetry,
    ) -> Result<(), StoreError> {
        let owner = || format!("fit run {fit}");
        codec::check_finite(&owner, &[outcome.cost], |_| "the cost".into())?;
        codec::check_finite(&owner, &[outcome.wall_ms], |_| "the wall time".into())?;
        codec::check_finite(&owner, &outcome.best_cost_per_generation, |i| {
            format!("the best cost of generation {i}")
        })?;
        let measured: Vec<(&Geometry, f64)> =
            geometries.iter().map(|g| (g, delta_e00[g.index])).collect();
        for (g, de) in &measured {
            codec::check_finite(&owner, &[*de], |_| format!("ΔE00 at {}", g.name))?;
        }
        if geometries.is_empty() || !(0..MA_T12_COUNT).all(|g| geometries.contains(g)) {
            return Err(StoreError::Empty {
                field: "the MA-T12 geometries of the evaluation",
            });
        }
        let values = |device: Option<Device>| -> Vec<f64> {
            measured
                .iter()
                .filter(|(g, _)| device.is_none_or(|d| g.device == d))
                .map(|(_, de)| *de)
                .collect()
        };
        let specular = values(Some(Device::Sra));
        let evaluation = EvaluationRecord {
            per_geometry: *delta_e00,
            all: delta_e_summary(&values(None)),
            diffuse: delta_e_summary(&values(Some(Device::MaT12))),
            specular: (!specular.is_empty()).then(|| delta_e_summary(&specular)),
        };
        let params = to_json("fit parameters", &outcome.params)?;
        let best = to_json(
            "best cost per generation",
            &outcome.best_cost_per_generation,
        )?;

        let mut tx = self.writer.begin().await?;
        let done = sqlx::query(
            "UPDATE fit_runs SET status = 'done', cost = $2, params_json = $3,
                 best_cost_per_generation_json = $4, evaluations = $5, generations = $6,
                 wall_ms = $7, finished_at_ms = $8
             WHERE id = $1 AND status = 'running'",
        )
        .bind(fit.0)
        .bind(outcome.cost)
        .bind(params)
        .bind(best)
        // u64 → i64: 2⁶³ cost evaluations is beyond any fit.
        .bind(outcome.evaluations as i64)
        .bind(i64::from(outcome.generations))
        .bind(outcome.wall_ms)
        .bind(now_ms())
        .execute(&mut *tx)
        .await?;
        if done.rows_affected() != 1 {
            return Err(refused(&mut *tx, fit, "running", "finish it").await);
        }
        for (g, de) in &measured {
            sqlx::query(
                "INSERT INTO evaluations (fit_run_id, geometry, delta_e00) VALUES ($1, $2, $3)",
            )
            .bind(fit.0)
            .bind(g.name)
            .bind(de)
            .execute(&mut *tx)
            .await?;
        }
        let (a, d, s) = (evaluation.all, evaluation.diffuse, evaluation.specular);
        sqlx::query(
            "INSERT INTO evaluation_summaries (fit_run_id, mean, median, max, diffuse_mean,
                 diffuse_median, diffuse_max, specular_mean, specular_median, specular_max,
                 observer, weighting)
             VALUES ($1, $2, $3, $4, $5, $6, $7, $8, $9, $10, $11, $12)",
        )
        .bind(fit.0)
        .bind(a.mean)
        .bind(a.median)
        .bind(a.max)
        .bind(d.mean)
        .bind(d.median)
        .bind(d.max)
        .bind(s.map(|s| s.mean))
        .bind(s.map(|s| s.median))
        .bind(s.map(|s| s.max))
        .bind(colorimetry.observer.to_string())
        .bind(colorimetry.weighting.to_string())
        .execute(&mut *tx)
        .await?;
        tx.commit().await?;
        Ok(())
    }

    /// Stores the bootstrap intervals of a done fit (they are computed after it is stored).
    pub async fn set_fit_uncertainty(
        &self,
        fit: FitRunId,
        uncertainty: &Uncertainty,
    ) -> Result<(), StoreError> {
        let owner = || format!("fit run {fit}");
        let mut values = vec![uncertainty.noise];
        for iv in [uncertainty.ks, uncertainty.alpha, uncertainty.ior]
            .iter()
            .chain(&uncertainty.kd)
        {
            values.extend_from_slice(iv);
        }
        codec::check_finite(&owner, &values, |_| "an uncertainty interval".into())?;
        let json = to_json("fit uncertainty", uncertainty)?;
        let done = sqlx::query(
            "UPDATE fit_runs SET uncertainty_json = $2 WHERE id = $1 AND status = 'done'",
        )
        .bind(fit.0)
        .bind(json)
        .execute(&self.writer)
        .await?;
        self.changed(fit, done.rows_affected(), "done", "store its uncertainty")
            .await
    }

    /// Stores the leave-one-geometry-out cross-validation of a done fit (computed after it is
    /// stored): the whole of it and its mean held-out ΔE00 in a column of its own.
    pub async fn set_fit_crossval(
        &self,
        fit: FitRunId,
        crossval: &CrossValidation,
    ) -> Result<(), StoreError> {
        let owner = || format!("fit run {fit}");
        let mut values = vec![crossval.fitted_mean, crossval.held_out_mean];
        for h in &crossval.held_out {
            values.push(h.delta_e00);
            values.extend_from_slice(&h.measured_lab);
            values.extend_from_slice(&h.predicted_lab);
        }
        codec::check_finite(&owner, &values, |_| "a held-out prediction".into())?;
        if crossval.held_out.is_empty() {
            return Err(StoreError::Empty {
                field: "cross-validation's held-out predictions",
            });
        }
        let json = to_json("fit cross-validation", crossval)?;
        let done = sqlx::query(
            "UPDATE fit_runs SET crossval_json = $2, held_out_mean = $3
             WHERE id = $1 AND status = 'done'",
        )
        .bind(fit.0)
        .bind(json)
        .bind(crossval.held_out_mean)
        .execute(&self.writer)
        .await?;
        self.changed(
            fit,
            done.rows_affected(),
            "done",
            "store its cross-validation",
        )
        .await
    }

    /// queued | running → failed, with the error.
    pub async fn fail_fit(&self, fit: FitRunId, reason: &str) -> Result<(), StoreError> {
        if reason.trim().is_empty() {
            return Err(StoreError::Empty {
                field: "failure reason",
            });
        }
        let done = sqlx::query(
            "UPDATE fit_runs SET status = 'failed', error = $2, finished_at_ms = $3
             WHERE id = $1 AND status IN ('queued', 'running')",
        )
        .bind(fit.0)
        .bind(reason)
        .bind(now_ms())
        .execute(&self.writer)
        .await?;
        self.changed(fit, done.rows_affected(), "queued or running", "fail it")
            .await
    }

    /// queued | running → cancelled.
    pub async fn cancel_fit(&self, fit: FitRunId) -> Result<(), StoreError> {
        let done = sqlx::query(
            "UPDATE fit_runs SET status = 'cancelled', finished_at_ms = $2
             WHERE id = $1 AND status IN ('queued', 'running')",
        )
        .bind(fit.0)
        .bind(now_ms())
        .execute(&self.writer)
        .await?;
        self.changed(fit, done.rows_affected(), "queued or running", "cancel it")
            .await
    }

    /// At start-up: fits a crash left `running` go back to `queued` (a fit is deterministic
    /// by its seed, so running it again loses nothing). Returns their ids, oldest first.
    pub async fn requeue_interrupted_fits(&self) -> Result<Vec<FitRunId>, StoreError> {
        let mut ids: Vec<i64> = sqlx::query_scalar(
            "UPDATE fit_runs SET status = 'queued', started_at_ms = NULL
             WHERE status = 'running' RETURNING id",
        )
        .fetch_all(&self.writer)
        .await?;
        ids.sort_unstable();
        Ok(ids.into_iter().map(FitRunId).collect())
    }

    /// Done fits that have no cross-validation stored (finished before the store kept one,
    /// or the daemon stopped while it ran), newest first: the daemon computes theirs at
    /// start-up.
    pub async fn done_fits_without_crossval(&self) -> Result<Vec<FitRunId>, StoreError> {
        let ids: Vec<i64> = sqlx::query_scalar(
            "SELECT id FROM fit_runs
             WHERE status = 'done' AND crossval_json IS NULL ORDER BY id DESC",
        )
        .fetch_all(&self.reader)
        .await?;
        Ok(ids.into_iter().map(FitRunId).collect())
    }

    /// Fits waiting for the worker, oldest first.
    pub async fn queued_fits(&self) -> Result<Vec<FitRun>, StoreError> {
        let rows: Vec<FitRow> = sqlx::query_as(&format!(
            "{FIT_RUN} WHERE f.status = 'queued' ORDER BY f.id"
        ))
        .fetch_all(&self.reader)
        .await?;
        rows.into_iter().map(FitRow::into_run).collect()
    }

    /// Every fit run of a scan, oldest first.
    pub async fn fits_for_scan(&self, scan: ScanId) -> Result<Vec<FitRun>, StoreError> {
        let rows: Vec<FitRow> =
            sqlx::query_as(&format!("{FIT_RUN} WHERE f.scan_id = $1 ORDER BY f.id"))
                .bind(scan.0)
                .fetch_all(&self.reader)
                .await?;
        rows.into_iter().map(FitRow::into_run).collect()
    }

    /// A fit run and, when done, its evaluation.
    pub async fn fit_detail(&self, fit: FitRunId) -> Result<FitDetail, StoreError> {
        let row: Option<FitRow> = sqlx::query_as(&format!("{FIT_RUN} WHERE f.id = $1"))
            .bind(fit.0)
            .fetch_optional(&self.reader)
            .await?;
        let run = row
            .ok_or(StoreError::NotFound {
                what: FitRunId::WHAT,
                id: fit.0,
            })?
            .into_run()?;
        let (uncertainty, crossval): (Option<String>, Option<String>) =
            sqlx::query_as("SELECT uncertainty_json, crossval_json FROM fit_runs WHERE id = $1")
                .bind(fit.0)
                .fetch_one(&self.reader)
                .await?;
        let crossval = crossval
            .map(|text| {
                serde_json::from_str::<CrossValidation>(&text).map_err(|e| StoreError::Corrupt {
                    table: "fit_runs",
                    id: fit.0,
                    detail: format!("crossval_json: {e}"),
                })
            })
            .transpose()?;
        let uncertainty = uncertainty
            .map(|text| {
                serde_json::from_str::<Uncertainty>(&text).map_err(|e| StoreError::Corrupt {
                    table: "fit_runs",
                    id: fit.0,
                    detail: format!("uncertainty_json: {e}"),
                })
            })
            .transpose()?;
        let rows: Vec<(String, f64)> =
            sqlx::query_as("SELECT geometry, delta_e00 FROM evaluations WHERE fit_run_id = $1")
                .bind(fit.0)
                .fetch_all(&self.reader)
                .await?;
        let mut colorimetry = None;
        let evaluation = if rows.is_empty() {
            None
        } else {
            let mut per_geometry = [f64::NAN; GEOMETRY_COUNT];
            for (name, de) in &rows {
                let g = codec::geometry(name).map_err(|_| StoreError::Corrupt {
                    table: "evaluations",
                    id: fit.0,
                    detail: format!("unknown geometry \"{name}\""),
                })?;
                per_geometry[g.index] = *de;
            }
            // Every MA-T12 geometry, and both SRA ones or neither.
            let no_sra = per_geometry[MA_T12_COUNT..].iter().all(|v| v.is_nan());
            let missing = (0..GEOMETRY_COUNT)
                .find(|&g| per_geometry[g].is_nan() && !(no_sra && g >= MA_T12_COUNT));
            if let Some(g) = missing {
                return Err(StoreError::Corrupt {
                    table: "evaluations",
                    id: fit.0,
                    detail: format!("no ΔE00 at {}", GEOMETRIES[g].name),
                });
            }
            // Read back what finish_fit stored, rather than recomputing it.
            type Row = (
                f64,
                f64,
                f64,
                f64,
                f64,
                f64,
                Option<f64>,
                Option<f64>,
                Option<f64>,
                String,
                String,
            );
            let s: Row = sqlx::query_as(
                "SELECT mean, median, max, diffuse_mean, diffuse_median, diffuse_max,
                        specular_mean, specular_median, specular_max, observer, weighting
                 FROM evaluation_summaries WHERE fit_run_id = $1",
            )
            .bind(fit.0)
            .fetch_optional(&self.reader)
            .await?
            .ok_or_else(|| StoreError::Corrupt {
                table: "evaluation_summaries",
                id: fit.0,
                detail: "missing summary".into(),
            })?;
            let corrupt = |e: crate::colour::ColorimetryError| StoreError::Corrupt {
                table: "evaluation_summaries",
                id: fit.0,
                detail: e.to_string(),
            };
            colorimetry = Some(Colorimetry {
                observer: s.9.parse().map_err(corrupt)?,
                weighting: s.10.parse().map_err(corrupt)?,
            });
            Some(EvaluationRecord {
                per_geometry,
                all: DeltaESummary {
                    mean: s.0,
                    median: s.1,
                    max: s.2,
                },
                diffuse: DeltaESummary {
                    mean: s.3,
                    median: s.4,
                    max: s.5,
                },
                specular: match (s.6, s.7, s.8) {
                    (Some(mean), Some(median), Some(max)) => {
                        Some(DeltaESummary { mean, median, max })
                    }
                    _ => None,
                },
            })
        };
        let (sra, derived) = self.derived(&run).await?;
        let (specular_delta_l, lab) = match (derived, &evaluation, colorimetry) {
            (Some((measured, estimated)), Some(e), Some(c)) => (
                measured
                    .geometries
                    .has_sra()
                    .then(|| specular_delta_l(&measured.values, &estimated, sra)),
                Some(crate::fit::LabPerGeometry::of(
                    &measured,
                    &estimated,
                    c,
                    &e.per_geometry,
                )),
            ),
            _ => (None, None),
        };
        Ok(FitDetail {
            run,
            evaluation,
            colorimetry,
            uncertainty,
            crossval,
            sra,
            specular_delta_l,
            lab,
        })
    }

    /// A fit's SRA reading model (its settings' `sra`, the paper's flat model when absent) and,
    /// when it is done, the processed BRDF it fitted and its model's BRDF at the fitted
    /// parameters, from which its specular |ΔL*| and its L*a*b* residuals are derived.
    async fn derived(
        &self,
        run: &FitRun,
    ) -> Result<
        (
            SraReading,
            Option<(MeasuredBrdf, [Spectrum; GEOMETRY_COUNT])>,
        ),
        StoreError,
    > {
        let sra: SraReading = match run.settings.get("sra") {
            None => SraReading::default(),
            Some(v) => serde_json::from_value(v.clone()).map_err(|e| StoreError::Corrupt {
                table: "fit_runs",
                id: run.id.0,
                detail: format!("settings_json: sra: {e}"),
            })?,
        };
        let Some(params) = run
            .result
            .as_ref()
            .and_then(|r| serde_json::from_value::<Params>(r.params.clone()).ok())
        else {
            return Ok((sra, None));
        };
        let fresnel: FresnelCosine = run
            .settings
            .get("fresnel")
            .and_then(|v| serde_json::from_value(v.clone()).ok())
            .unwrap_or_default();
        let measured = self.processed(run.processed).await?.brdf;
        let kind: model::ModelKind = run
            .settings
            .get("model")
            .and_then(|v| serde_json::from_value(v.clone()).ok())
            .unwrap_or_default();
        let estimated = model::evaluate_model(&params, kind, fresnel, &SpecularGeometry::all());
        Ok((sra, Some((measured, estimated))))
    }
}
