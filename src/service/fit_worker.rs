//! The fit worker: runs queued fits off the async runtime, a bounded number at a time, each
//! cancellable, a panic inside one failing that fit only.
//!
//! Shape (sqlx/tokio idiom): a dispatcher task takes fit ids from an unbounded channel, waits
//! for a [`Semaphore`] permit (`[fit] max_concurrent_fits`), and spawns a task per fit that
//! moves the permit into its `spawn_blocking` closure, so the permit is released exactly when
//! the CPU-bound work ends, whoever awaits it. The closure wraps the fit in `catch_unwind`; a
//! panic becomes a `failed` fit with the panic's message, and the worker takes the next fit.
//!
//! [`FitWorker`] owns the worker's state — the queue's sending end, the fits' cancel flags,
//! the queued/running/bootstrap/cross-validation counters, the bootstrap and cross-validation
//! slots and the fit computation — and
//! nothing outside this module changes it; the rest of the service hands it fit ids
//! ([`FitWorker::submit`]), asks it to cancel one ([`FitWorker::cancel_fit`]) and reads its
//! counters.
//!
//! A fit runs on what was recorded when it was queued, never on today's configuration: the
//! processed scan it fits (`fit_runs.processed_id`), every optimiser setting
//! (`settings_json`), and the colorimetry its ΔE00 are computed with (`fit_observer`,
//! `fit_weighting`, `migrations/0020_fit_inputs.sql`); the processing options come from the processed row and
//! the scan's reference set. Only a fit queued before the colorimetry was recorded falls back
//! to the configured one.
//!
//! Cancellation goes through the optimiser's observer, called once per generation: it returns
//! `Break` when the fit's flag is set ([`FitWorker::cancel_fit`]) or the daemon is stopping. A
//! fit stopped by shutdown is left `running`; the next start queues it again (same seed, same
//! result).
//!
//! After a fit is stored, two more computations run on it side by side, each in a slot of its
//! own (one at a time, no fit permit) and counted for `status`: its bootstrap intervals
//! (`[fit] bootstrap`, SCIENCE.md §10) and its leave-one-geometry-out cross-validation
//! (`[fit] crossval`, SCIENCE.md §12.5: the held-out ΔE00 shown beside the fit's). Shutdown stops
//! both; a fit left without intervals shows none, and a done fit left without a
//! cross-validation (stopped, or stored while `[fit] crossval` was off) gets it at the next
//! start ([`FitWorker::crossval_backfill`]).

use std::collections::HashMap;
use std::ops::ControlFlow;
use std::panic::{AssertUnwindSafe, catch_unwind};
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::Instant;

use tokio::sync::{Semaphore, mpsc};

use crate::cost::CostFunction;
use crate::crossval::crossval_held_out;
use crate::fit::{FitReport, FitRequest, FitScanError, fit_measured};
use crate::optimise::{FitError, Progress, Settings};
use crate::processing::{MeasuredBrdf, ProcessingOptions};
use crate::store::{FitResult, FitRunId, FitStatus, ScanId, StoreError};
use crate::uncertainty::{BootstrapOptions, UncertaintyError, bootstrap};

use super::context::Context;
use super::events::Event;
use super::{ServiceError, Timings};

/// One fit, as the worker hands it to the fit computation.
#[derive(Debug, Clone)]
pub struct FitJob {
    pub fit: FitRunId,
    pub scan: ScanId,
    pub sample: String,
    /// What the scan is normalised by (the tile's name, or "instrument calibration").
    pub reference: String,
    /// The processed scan, sr⁻¹.
    pub measured: MeasuredBrdf,
    pub request: FitRequest,
}

/// The fit computation: the job and a per-generation observer (`Break` cancels) → a report.
pub type FitFn = Arc<
    dyn Fn(&FitJob, &mut dyn FnMut(&Progress) -> ControlFlow<()>) -> Result<FitReport, FitScanError>
        + Send
        + Sync,
>;

/// The real computation: [`crate::fit::fit_measured`].
pub fn default_fit_fn() -> FitFn {
    Arc::new(|job, observer| {
        fit_measured(
            &job.sample,
            &job.reference,
            job.measured,
            &job.request,
            observer,
        )
    })
}

/// The text of a panic payload.
fn panic_message(payload: &(dyn std::any::Any + Send)) -> String {
    payload
        .downcast_ref::<&str>()
        .map(|s| s.to_string())
        .or_else(|| payload.downcast_ref::<String>().cloned())
        .unwrap_or_else(|| "a panic without a message".into())
}

/// The fit worker's state (module docs).
pub(crate) struct FitWorker {
    ctx: Context,
    fit_fn: FitFn,
    /// Cancellation flags of queued and running fits.
    cancels: Mutex<HashMap<FitRunId, Arc<AtomicBool>>>,
    tx: mpsc::UnboundedSender<FitRunId>,
    queued: AtomicUsize,
    running: AtomicUsize,
    /// One bootstrap at a time, apart from the fits' permits: a bootstrap never holds up the
    /// point estimate of a later fit (SCIENCE.md §10).
    bootstrap_slot: Arc<Semaphore>,
    /// Bootstraps waiting for the slot or running.
    bootstraps_pending: AtomicUsize,
    /// One cross-validation at a time, apart from the fits' permits and the bootstrap's slot.
    crossval_slot: Arc<Semaphore>,
    /// Cross-validations waiting for the slot or running.
    crossvals_pending: AtomicUsize,
}

impl FitWorker {
    /// The worker's state and the receiving end of its queue, for [`FitWorker::start`].
    pub(super) fn new(
        ctx: Context,
        fit_fn: FitFn,
    ) -> (Arc<FitWorker>, mpsc::UnboundedReceiver<FitRunId>) {
        let (tx, rx) = mpsc::unbounded_channel();
        let worker = Arc::new(FitWorker {
            ctx,
            fit_fn,
            cancels: Mutex::new(HashMap::new()),
            tx,
            queued: AtomicUsize::new(0),
            running: AtomicUsize::new(0),
            bootstrap_slot: Arc::new(Semaphore::new(1)),
            bootstraps_pending: AtomicUsize::new(0),
            crossval_slot: Arc::new(Semaphore::new(1)),
            crossvals_pending: AtomicUsize::new(0),
        });
        (worker, rx)
    }

    /// Hands a queued fit to the worker.
    pub(crate) fn submit(&self, fit: FitRunId) {
        self.cancels()
            .entry(fit)
            .or_insert_with(|| Arc::new(AtomicBool::new(false)));
        self.queued.fetch_add(1, Ordering::Relaxed);
        if self.tx.send(fit).is_err() {
            // The worker has stopped (shutdown): the fit stays queued in the store and runs at
            // the next start.
            self.queued.fetch_sub(1, Ordering::Relaxed);
        }
    }

    /// Fits handed to the worker and not started yet.
    pub(crate) fn queued(&self) -> usize {
        self.queued.load(Ordering::Relaxed)
    }

    /// Fits computing now.
    pub(crate) fn running(&self) -> usize {
        self.running.load(Ordering::Relaxed)
    }

    /// Finished fits whose bootstrap is waiting or running.
    pub(crate) fn bootstraps_pending(&self) -> usize {
        self.bootstraps_pending.load(Ordering::Relaxed)
    }

    /// Finished fits whose cross-validation is waiting or running.
    pub(crate) fn crossvals_pending(&self) -> usize {
        self.crossvals_pending.load(Ordering::Relaxed)
    }

    fn cancels(&self) -> MutexGuard<'_, HashMap<FitRunId, Arc<AtomicBool>>> {
        self.cancels.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// The cancel flag of a fit this worker was handed.
    fn flag(&self, fit: FitRunId) -> Option<Arc<AtomicBool>> {
        self.cancels().get(&fit).cloned()
    }

    fn forget(&self, fit: FitRunId) {
        self.cancels().remove(&fit);
    }
}

/// Why a queued fit could not start, and its scan when the fit could be read far enough to
/// know it.
struct PrepareError {
    scan: Option<ScanId>,
    error: ServiceError,
}

/// How a fit computation ended.
enum Ended {
    Done(Box<FitReport>),
    Failed(String),
    Cancelled,
    Stopped,
}

/// What a cross-validation is computed from: the fit's measurement, request and the mean
/// MA-T12 ΔE00 of the fit to every reading.
struct CrossvalInput {
    sample: String,
    reference: String,
    measured: MeasuredBrdf,
    request: FitRequest,
    fitted_mean: f64,
}

impl CrossvalInput {
    /// A fit needs three MA-T12 readings left when one is held out.
    fn can_hold_out(&self) -> bool {
        self.measured
            .geometries
            .iter()
            .filter(|g| g.device == crate::geometry::Device::MaT12)
            .count()
            >= 4
    }
}

/// Takes one off a `status` counter when dropped: the end of what it counts, on every path.
struct CountedUntilDrop<'a>(&'a AtomicUsize);

impl Drop for CountedUntilDrop<'_> {
    fn drop(&mut self) {
        self.0.fetch_sub(1, Ordering::Relaxed);
    }
}

impl FitWorker {
    /// Starts the dispatcher.
    pub(super) async fn start(self: &Arc<Self>, mut rx: mpsc::UnboundedReceiver<FitRunId>) {
        let Ok((guard, mut stop)) = self.ctx.task_slot().await else {
            return;
        };
        let permits = Arc::new(Semaphore::new(self.ctx.settings.max_concurrent_fits.max(1)));
        let worker = self.clone();
        tokio::spawn(async move {
            loop {
                let fit = tokio::select! {
                    fit = rx.recv() => match fit { Some(f) => f, None => break },
                    _ = stop.recv() => break,
                };
                let permit = tokio::select! {
                    p = permits.clone().acquire_owned() => p.expect("the semaphore is never closed"),
                    _ = stop.recv() => break,
                };
                let Ok((fit_guard, _)) = worker.ctx.task_slot().await else {
                    break;
                };
                let s = worker.clone();
                tokio::spawn(async move {
                    s.run_fit(fit, permit).await;
                    drop(fit_guard);
                });
            }
            drop(guard);
        });
    }

    /// Cancels a queued or running fit. A running fit stops at its next generation.
    pub(super) async fn cancel_fit(&self, fit: FitRunId) -> Result<(), ServiceError> {
        let detail = self.ctx.store.fit_detail(fit).await?;
        match detail.run.status {
            FitStatus::Queued | FitStatus::Running => {}
            status => {
                return Err(ServiceError::BadRequest(format!(
                    "fit run {fit} is {status}: only a queued or running fit can be cancelled"
                )));
            }
        }
        match self.flag(fit) {
            Some(flag) => flag.store(true, Ordering::SeqCst),
            // Queued in the store but not handed to this worker: cancel it there.
            None => {
                self.ctx.store.cancel_fit(fit).await?;
                self.ctx.events.send(Event::FitCancelled {
                    fit,
                    scan: detail.run.scan,
                });
            }
        }
        Ok(())
    }

    async fn run_fit(&self, fit: FitRunId, permit: tokio::sync::OwnedSemaphorePermit) {
        // Running from the moment it leaves the queue until its end is recorded (every return
        // below), so that `status` never shows an idle worker while a fit's row still says
        // queued or running.
        self.running.fetch_add(1, Ordering::Relaxed);
        self.queued.fetch_sub(1, Ordering::Relaxed);
        let running = CountedUntilDrop(&self.running);
        let cancel = self.flag(fit).unwrap_or_default();
        let prepared = self.prepare_fit(fit).await;
        let (job, cost) = match prepared {
            Ok(Some(p)) => p,
            Ok(None) => {
                self.forget(fit);
                return;
            }
            Err(PrepareError { scan, error: e }) => {
                let error = format!("cannot start the fit: {e}");
                self.mark_failed(fit, &error).await;
                match scan {
                    Some(scan) => self.ctx.events.send(Event::FitFailed { fit, scan, error }),
                    // The fit could not even be read: there is no scan to name in an event.
                    None => tracing::warn!(%fit, %error, "fit failed before its scan was known"),
                }
                self.forget(fit);
                return;
            }
        };
        let scan = job.scan;
        if cancel.load(Ordering::SeqCst) {
            self.mark_cancelled(fit).await;
            self.ctx.events.send(Event::FitCancelled { fit, scan });
            self.forget(fit);
            return;
        }
        if let Err(e) = self.ctx.timed_store(self.ctx.store.start_fit(fit)).await {
            tracing::warn!(error = %e, %fit, "fit not started");
            self.forget(fit);
            return;
        }
        self.ctx.events.send(Event::FitStarted {
            fit,
            scan,
            cost_function: cost,
        });

        let events = self.ctx.events.clone();
        let stopping = self.ctx.stop_flag();
        let fit_fn = self.fit_fn.clone();
        let cancel_flag = cancel.clone();
        let started = Instant::now();
        let joined = tokio::task::spawn_blocking(move || {
            // Held for as long as the computation runs, released when this closure returns or
            // unwinds.
            let _permit = permit;
            let mut observer = |p: &Progress| {
                events.send(Event::FitProgress {
                    fit,
                    scan,
                    generation: p.generation,
                    generations_total: p.generations_total,
                    best_cost: p.best_cost,
                });
                if cancel_flag.load(Ordering::Relaxed) || stopping.load(Ordering::Relaxed) {
                    ControlFlow::Break(())
                } else {
                    ControlFlow::Continue(())
                }
            };
            catch_unwind(AssertUnwindSafe(|| fit_fn(&job, &mut observer)))
        })
        .await;
        Timings::add(&self.ctx.timings.fit_ns, started.elapsed());

        let ended = match joined {
            Ok(Ok(Ok(report))) => Ended::Done(Box::new(report)),
            Ok(Ok(Err(FitScanError::Fit {
                source: FitError::Cancelled,
                ..
            }))) => {
                if cancel.load(Ordering::SeqCst) {
                    Ended::Cancelled
                } else {
                    Ended::Stopped
                }
            }
            Ok(Ok(Err(e))) => Ended::Failed(e.to_string()),
            Ok(Err(payload)) => Ended::Failed(format!(
                "the fit panicked ({}); this is a bug in brdfd: report it with the scan \
                 (`brdfd export {scan}`)",
                panic_message(payload.as_ref())
            )),
            Err(join) => Ended::Failed(format!("the fit's thread ended abnormally: {join}")),
        };
        let stored = self.record_fit_end(fit, scan, cost, ended).await;
        self.forget(fit);
        // The fit's end is recorded; its bootstrap and cross-validation are counted on their own.
        drop(running);
        if let Some(report) = stored {
            let report = Arc::new(*report);
            tokio::join!(
                self.bootstrap_fit(fit, report.clone()),
                self.crossval_fit(fit, report)
            );
        }
    }

    /// After a fit is stored: its leave-one-geometry-out cross-validation under the fit's own
    /// configuration (`[fit] crossval`; SCIENCE.md §12.5), reusing the fit just made and
    /// fitting once more per MA-T12 geometry without it, on one blocking thread, one at a time
    /// and without a fit permit, beside the bootstrap; then stored with the fit. Shutdown stops
    /// it within an optimiser generation; the next start computes what it left. A scan with fewer
    /// than four MA-T12 readings has none (a fit needs three left).
    async fn crossval_fit(&self, fit: FitRunId, report: Arc<FitReport>) {
        if !self.ctx.settings.crossval || self.ctx.is_stopping() {
            return;
        }
        let input = CrossvalInput {
            sample: report.sample.clone(),
            reference: report.reference.clone(),
            measured: report.measured,
            request: report.request.clone(),
            fitted_mean: report.evaluation.diffuse.mean,
        };
        if !input.can_hold_out() {
            return;
        }
        self.crossvals_pending.fetch_add(1, Ordering::Relaxed);
        let _pending = CountedUntilDrop(&self.crossvals_pending);
        self.run_crossval(fit, input).await;
    }

    /// At start-up: the cross-validation of every done fit that has none (finished before the
    /// store kept one, or the daemon stopped while it ran), newest first, one after the other
    /// in the cross-validation slot, so a new fit's waits for at most one of them. Each is
    /// counted in `status` from now until it is stored. Shutdown stops the pass; the next
    /// start takes up what is left.
    pub(super) async fn crossval_backfill(self: &Arc<Self>) -> Result<usize, ServiceError> {
        if !self.ctx.settings.crossval {
            return Ok(0);
        }
        let fits = self
            .ctx
            .timed_store(self.ctx.store.done_fits_without_crossval())
            .await?;
        if fits.is_empty() {
            return Ok(0);
        }
        let Ok((guard, _stop)) = self.ctx.task_slot().await else {
            return Ok(0);
        };
        let n = fits.len();
        self.crossvals_pending.fetch_add(n, Ordering::Relaxed);
        let worker = self.clone();
        tokio::spawn(async move {
            for (i, fit) in fits.iter().enumerate() {
                // One counted each, from the start until it ends (or the pass stops).
                let _pending = CountedUntilDrop(&worker.crossvals_pending);
                if worker.ctx.is_stopping() {
                    // The rest are not counted any more either.
                    worker
                        .crossvals_pending
                        .fetch_sub(n - i - 1, Ordering::Relaxed);
                    break;
                }
                match worker.stored_fit_input(*fit).await {
                    Ok(Some(input)) if input.can_hold_out() => {
                        worker.run_crossval(*fit, input).await
                    }
                    Ok(_) => {}
                    Err(e) => {
                        tracing::warn!(error = %e.error, %fit, "no cross-validation for the fit")
                    }
                }
            }
            drop(guard);
        });
        Ok(n)
    }

    /// What the cross-validation of the stored fit `fit` needs, when it is done and has none.
    async fn stored_fit_input(&self, fit: FitRunId) -> Result<Option<CrossvalInput>, PrepareError> {
        let detail = self
            .ctx
            .timed_store(self.ctx.store.fit_detail(fit))
            .await
            .map_err(|e| PrepareError {
                scan: None,
                error: e.into(),
            })?;
        if detail.run.status != FitStatus::Done || detail.crossval.is_some() {
            return Ok(None);
        }
        let Some(fitted_mean) = detail.evaluation.as_ref().map(|e| e.diffuse.mean) else {
            return Ok(None);
        };
        let job = self.job_of(detail.run).await?;
        Ok(Some(CrossvalInput {
            sample: job.sample,
            reference: job.reference,
            measured: job.measured,
            request: job.request,
            fitted_mean,
        }))
    }

    /// Runs one cross-validation in the slot and stores it with the fit.
    async fn run_crossval(&self, fit: FitRunId, input: CrossvalInput) {
        let Ok(permit) = self.crossval_slot.clone().acquire_owned().await else {
            return;
        };
        let stopping = self.ctx.stop_flag();
        let joined = tokio::task::spawn_blocking(move || {
            let _permit = permit;
            catch_unwind(AssertUnwindSafe(|| {
                crossval_held_out(
                    &input.sample,
                    &input.reference,
                    &input.measured,
                    &input.request,
                    input.fitted_mean,
                    &stopping,
                )
            }))
        })
        .await;
        match joined {
            Ok(Ok(Ok(cv))) => {
                if let Err(e) = self
                    .ctx
                    .timed_store(self.ctx.store.set_fit_crossval(fit, &cv))
                    .await
                {
                    tracing::warn!(error = %e, %fit, "cannot store the fit's cross-validation");
                }
            }
            Ok(Ok(Err(FitScanError::Fit {
                source: FitError::Cancelled,
                ..
            }))) => {
                tracing::info!(%fit, "cross-validation interrupted by shutdown; the fit has none");
            }
            Ok(Ok(Err(e))) => tracing::warn!(error = %e, %fit, "no cross-validation for the fit"),
            Ok(Err(payload)) => tracing::error!(
                %fit,
                "the cross-validation panicked ({}); this is a bug in brdfd",
                panic_message(payload.as_ref())
            ),
            Err(e) => {
                tracing::error!(error = %e, %fit, "the cross-validation's thread ended abnormally")
            }
        }
    }

    /// After a fit is stored: its bootstrap intervals (`[fit] bootstrap` resamples, SCIENCE.md
    /// §10) on one blocking thread, one bootstrap at a time and without a fit permit (so the
    /// next scans' point estimates are not held up), then stored with the fit. Shutdown stops
    /// it between refits; a fit left without intervals shows none.
    async fn bootstrap_fit(&self, fit: FitRunId, report: Arc<FitReport>) {
        let resamples = self.ctx.settings.bootstrap;
        if resamples == 0 || self.ctx.is_stopping() {
            return;
        }
        // Counted from now until stored (or given up), for `status`.
        self.bootstraps_pending.fetch_add(1, Ordering::Relaxed);
        let _pending = CountedUntilDrop(&self.bootstraps_pending);
        let Ok(permit) = self.bootstrap_slot.clone().acquire_owned().await else {
            return;
        };
        let stopping = self.ctx.stop_flag();
        let opts = BootstrapOptions {
            resamples,
            seed: report.outcome.seed,
            threads: 1,
            noise: None,
            ..Default::default()
        };
        let joined = tokio::task::spawn_blocking(move || {
            let _permit = permit;
            catch_unwind(AssertUnwindSafe(|| {
                bootstrap(
                    &report.measured,
                    &report.request.settings,
                    report.request.colorimetry,
                    &report.outcome.params,
                    &opts,
                    &stopping,
                )
            }))
        })
        .await;
        match joined {
            Ok(Ok(Ok(u))) => {
                if let Err(e) = self
                    .ctx
                    .timed_store(self.ctx.store.set_fit_uncertainty(fit, &u))
                    .await
                {
                    tracing::warn!(error = %e, %fit, "cannot store the fit's uncertainty");
                }
            }
            Ok(Ok(Err(UncertaintyError::Cancelled))) => {
                tracing::info!(%fit, "bootstrap interrupted by shutdown; the fit has no intervals");
            }
            Ok(Ok(Err(e))) => tracing::warn!(error = %e, %fit, "no intervals for the fit"),
            Ok(Err(payload)) => tracing::error!(
                %fit,
                "the bootstrap panicked ({}); this is a bug in brdfd",
                panic_message(payload.as_ref())
            ),
            Err(e) => tracing::error!(error = %e, %fit, "the bootstrap's thread ended abnormally"),
        }
    }

    /// Stores that `fit` failed with `error`; a store that refuses is logged, as the fit's
    /// event still goes out.
    async fn mark_failed(&self, fit: FitRunId, error: &str) {
        if let Err(e) = self
            .ctx
            .timed_store(self.ctx.store.fail_fit(fit, error))
            .await
        {
            tracing::warn!(error = %e, %fit, reason = %error, "cannot mark the fit failed");
        }
    }

    /// Stores that `fit` was cancelled; a store that refuses is logged, as the fit's event
    /// still goes out.
    async fn mark_cancelled(&self, fit: FitRunId) {
        if let Err(e) = self.ctx.timed_store(self.ctx.store.cancel_fit(fit)).await {
            tracing::warn!(error = %e, %fit, "cannot mark the fit cancelled");
        }
    }

    /// Loads what a queued fit needs. `Ok(None)`: it is no longer queued (cancelled meanwhile).
    async fn prepare_fit(
        &self,
        fit: FitRunId,
    ) -> Result<Option<(FitJob, CostFunction)>, PrepareError> {
        let store = &self.ctx.store;
        let detail = self
            .ctx
            .timed_store(store.fit_detail(fit))
            .await
            .map_err(|e| PrepareError {
                scan: None,
                error: e.into(),
            })?;
        let run = detail.run;
        if run.status != FitStatus::Queued {
            return Ok(None);
        }
        let cost = run.cost_function;
        Ok(Some((self.job_of(run).await?, cost)))
    }

    /// The job of the fit `run` as it was queued: its processed scan, its recorded settings
    /// and colorimetry.
    async fn job_of(&self, run: crate::store::FitRun) -> Result<FitJob, PrepareError> {
        let store = &self.ctx.store;
        let fit = run.id;
        let scan = run.scan;
        let fail = |error: ServiceError| PrepareError {
            scan: Some(scan),
            error,
        };
        let processed = self
            .ctx
            .timed_store(store.processed(run.processed))
            .await
            .map_err(|e| fail(e.into()))?;
        let scan_detail = self
            .ctx
            .timed_store(store.scan_detail(scan))
            .await
            .map_err(|e| fail(e.into()))?;
        // Settings the store cannot read back are a damaged store, not the caller's mistake.
        let settings: Settings = serde_json::from_value(run.settings.clone()).map_err(|e| {
            fail(ServiceError::Store(StoreError::Corrupt {
                table: "fit_runs",
                id: fit.0,
                detail: format!("settings: {e}"),
            }))
        })?;
        let request = FitRequest {
            processing: ProcessingOptions {
                specular: processed.specular,
                reference_reflectance: scan_detail.reference.reference.rho_ref,
            },
            settings,
            // Recorded when queued; a fit queued before it was recorded keeps using the
            // configured one, as it did then.
            colorimetry: run.colorimetry.unwrap_or(self.ctx.settings.colorimetry),
        };
        Ok(FitJob {
            fit,
            scan,
            reference: crate::service::pipeline::scan_from_detail(&scan_detail)
                .map(|s| s.reference_label().to_string())
                .unwrap_or_else(|_| scan_detail.reference.reference.name.clone()),
            sample: scan_detail.scan.sample,
            measured: processed.brdf,
            request,
        })
    }

    /// Stores how a fit ended; the report when it was stored as done.
    async fn record_fit_end(
        &self,
        fit: FitRunId,
        scan: ScanId,
        cost: CostFunction,
        ended: Ended,
    ) -> Option<Box<FitReport>> {
        let store = &self.ctx.store;
        match ended {
            Ended::Done(report) => {
                let outcome = &report.outcome;
                let result = FitResult {
                    cost: outcome.cost,
                    params: serde_json::to_value(outcome.params).unwrap_or_default(),
                    best_cost_per_generation: outcome.best_cost_per_generation.clone(),
                    evaluations: outcome.evaluations,
                    generations: outcome.generations,
                    wall_ms: outcome.wall_ms,
                };
                let e = &report.evaluation;
                match self
                    .ctx
                    .timed_store(store.finish_fit_with(
                        fit,
                        &result,
                        &e.per_geometry,
                        e.geometries,
                        report.request.colorimetry,
                    ))
                    .await
                {
                    Ok(()) => {
                        self.ctx.events.send(Event::FitDone {
                            fit,
                            scan,
                            cost_function: cost,
                            cost: outcome.cost,
                            delta_e00_mean: e.all.mean,
                            delta_e00_diffuse_mean: e.diffuse.mean,
                            delta_e00_specular_mean: e.specular.map_or(f64::NAN, |s| s.mean),
                            wall_ms: outcome.wall_ms,
                        });
                        return Some(report);
                    }
                    Err(err) => {
                        let error = format!("cannot store the result: {err}");
                        self.mark_failed(fit, &error).await;
                        self.ctx.events.send(Event::FitFailed { fit, scan, error });
                    }
                }
            }
            Ended::Failed(error) => {
                if let Err(e) = self.ctx.timed_store(store.fail_fit(fit, &error)).await {
                    tracing::error!(error = %e, %fit, "cannot mark the fit failed");
                }
                self.ctx.events.send(Event::FitFailed { fit, scan, error });
            }
            Ended::Cancelled => {
                self.mark_cancelled(fit).await;
                self.ctx.events.send(Event::FitCancelled { fit, scan });
            }
            Ended::Stopped => {
                tracing::info!(%fit, "fit interrupted by shutdown; it runs again at the next start");
            }
        }
        None
    }
}
