//! The acquisition service: what `brdfd serve` runs, and what `brdfd replay`, `brdfd demo` and
//! the end-to-end tests run in-process.
//!
//! Data flow (ARCHITECTURE.md): an operator's request → the scan orchestrator
//! (`orchestrator.rs`) → both instruments' driver tasks measuring concurrently → every reading
//! stored the moment it arrives (with its raw frame) → the scan completes only with all 14 →
//! the pipeline (`pipeline.rs`): processing against the reference in force (a reference older
//! than the configured limit is flagged, and the scan not fitted) → one fit per configured cost
//! function queued → the fit worker (`fit_worker.rs`: CPU-bound work on blocking threads behind
//! a semaphore, cancellable, a panic failing only that fit) → fits and ΔE00 stored →
//! [`events::Event`]s to every subscriber all along.
//!
//! Each part is a type of its own that holds the handles it uses and owns its state, private
//! to its module; `impl Service` is here alone, and only wires the parts at start and hands
//! each API call to the part that answers it:
//! - `context.rs` ([`context::Context`]): what every part shares — the store, the event bus,
//!   the settings, the timings, and the stop flag with the task tracking; each part holds a
//!   clone;
//! - `acquisition.rs` ([`acquisition::Acquisition`]): the instruments, the busy claim, the
//!   reference in force, each instrument's identity and connection state, and the device
//!   watcher;
//! - `orchestrator.rs` ([`orchestrator::Orchestrator`]): the measurement runs (references and
//!   scans, one path), with the acquisition and the pipeline;
//! - `pipeline.rs` ([`pipeline::Pipeline`]): processing, refits, imports, exports, and the
//!   store ↔ scan-file conversion; it queues fits with everything they need recorded;
//! - `fit_worker.rs` ([`fit_worker::FitWorker`]): the fit queue, permits, cancel flags and
//!   counters, and the bootstraps;
//! - `ingest.rs` ([`ingest::WatchFolder`]): the watch folder and its status;
//! - `import_budget.rs` ([`import_budget::ImportBudget`]): the bound on import bodies held in
//!   memory at once, shared by the watch folder and `POST /scans/import` (in the context);
//! - `forwarder.rs` ([`forwarder::Forwarding`]): forwarding to the central database and its
//!   status.
//!
//! Dependencies point one way: the orchestrator uses the acquisition and the pipeline, the
//! watch folder the pipeline, the pipeline the fit worker; none of them holds the [`Service`].
//!
//! - [`Service`] is the handle (cheap to clone) the HTTP API and the in-process callers use.
//! - [`devices`] builds the instruments (simulated or real, with the recording tap).
//! - [`ingest`] is the watch folder (`[ingest] watch`): exports and scan files dropped there
//!   are imported, fitted, and moved to `done/` or `failed/`.
//! - [`shutdown`] is the mini-redis style stop signal and task tracking.
//! - [`ServiceError`] says why a request was refused.
//!
//! The instruments do one thing at a time: a reference or scan requested while one is being
//! measured is refused with [`ServiceError::Busy`] (HTTP 409), never queued — an operator who
//! has put a new sample on the bench must not get the previous request's readings.

mod acquisition;
mod context;
pub mod devices;
mod error;
pub mod events;
mod fit_worker;
mod forwarder;
pub mod import_budget;
pub mod ingest;
mod orchestrator;
mod pipeline;
pub mod shutdown;

use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::{Duration, Instant};

use serde::{Deserialize, Serialize};
use tokio::sync::broadcast;

use crate::config::Config;
use crate::cost::CostFunction;
use crate::formats::xrite_xlsx::TextureImage;
use crate::optimise::{Method, Settings};
use crate::processing::SpecularStrategy;
use crate::scan::Scan;
use crate::store::{FitRunId, Provenance, ReferenceId, ReferenceSummary, ScanId, ScanState, Store};

pub use acquisition::{BusyStatus, DeviceStatus, Operation, SimulatedStatus};
pub use devices::{DeviceSetupError, Devices};
pub use error::ServiceError;
pub use events::{Event, EventBus, ReadingShown};
pub use fit_worker::{FitFn, FitJob, default_fit_fn};
pub use ingest::{IngestSettings, IngestStatus};
pub use pipeline::{
    FileImported, IMPORTED_SUFFIX, SCAN_FILE, ScanToImport, XRITE_XLSX, already_imported,
    check_name, file_provenance, imported_provenance, scan_from_detail,
};

use acquisition::Acquisition;
use context::Context;
use fit_worker::FitWorker;
use forwarder::Forwarding;
use ingest::WatchFolder;
use orchestrator::Orchestrator;
use pipeline::Pipeline;

/// What the service does with a complete scan, from `[scan]` and `[fit]` of the configuration.
#[derive(Debug, Clone, PartialEq)]
pub struct ServiceSettings {
    /// A scan taken longer than this after its reference was measured is not fitted.
    pub reference_max_age: Duration,
    /// One fit per cost function, per complete scan.
    pub cost_functions: Vec<CostFunction>,
    pub method: Method,
    pub seed: u64,
    /// Fits running at once, each on one blocking thread.
    pub max_concurrent_fits: usize,
    /// How the SRA readings become spectra.
    pub specular: SpecularStrategy,
    /// How an SRA reading enters the cost (`[fit] sra`; a refit may ask for another).
    pub sra: crate::sra_reading::SraModel,
    /// The science defaults (`[fit] preset`): the SRA weight of each cost function when
    /// `sra_weight` is not set.
    pub preset: crate::optimise::Preset,
    /// How much the SRA readings weigh in the cost (`[fit] sra_weight`); `None`: the preset's
    /// for each cost function.
    pub sra_weight: Option<crate::sra_reading::SraWeight>,
    /// The model's form (`[fit] model`); fits with the paper's GA always use the paper's.
    pub model: crate::model::ModelKind,
    /// The lobe's Fresnel factor (`[fit] fresnel`; a refit may ask for another).
    pub fresnel: crate::model::FresnelCosine,
    /// The reference tile's calibrated reflectance (`[reference] reflectance`), recorded with
    /// every reference set measured; `None`: results relative to the tile.
    pub reference_reflectance: Option<crate::spectral::Spectrum>,
    /// How long shutdown waits for the scan in progress and the fits to stop.
    pub shutdown_grace: Duration,
    /// Forwarding to the lab's central database (`[station]`, `[sync]`); `None`: none.
    pub sync: Option<crate::sync::ForwarderOptions>,
    /// How every evaluation turns spectra into L*a*b*.
    pub colorimetry: crate::colour::Colorimetry,
    /// Bootstrap resamples per fit (0: no intervals).
    pub bootstrap: u32,
    /// Leave-one-geometry-out cross-validation of every stored fit (`[fit] crossval`).
    pub crossval: bool,
    /// The watch folder (`[ingest]`); `None`: none.
    pub ingest: Option<IngestSettings>,
    /// The limits every imported file is read within (`[ingest]`), whatever its door.
    pub budget: crate::formats::budget::Budget,
    /// The import bodies held in memory at once, in bytes (`[ingest] max_held_mib`).
    pub max_held_import_bytes: u64,
}

impl ServiceSettings {
    pub fn from_config(config: &Config) -> ServiceSettings {
        ServiceSettings {
            reference_max_age: config.scan.reference_max_age,
            cost_functions: config.fit.cost_functions.clone(),
            method: config.fit.method,
            seed: config.fit.seed,
            max_concurrent_fits: config.fit.max_concurrent_fits.get(),
            specular: config.fit.specular,
            sra: config.fit.sra,
            preset: config.fit.preset,
            sra_weight: config.fit.sra_weight,
            model: config.fit.model,
            fresnel: config.fit.fresnel,
            reference_reflectance: config.reference.reflectance,
            shutdown_grace: Duration::from_secs(10),
            sync: config.sync.url.as_ref().map(|url| {
                let mut o = crate::sync::ForwarderOptions::new(config.station.id.clone(), url);
                o.batch = config.sync.batch;
                o
            }),
            colorimetry: config.colour,
            bootstrap: config.fit.bootstrap,
            crossval: config.fit.crossval,
            ingest: IngestSettings::from_config(&config.ingest),
            budget: config.ingest.budget,
            max_held_import_bytes: config.ingest.max_held_bytes,
        }
    }

    /// The optimiser settings of one fit asked for by `request`: its choices where it makes
    /// them, else its preset's, else the configured ones. A model option with the paper's GA is
    /// refused (the GA fits the paper's model only).
    pub fn refit_settings(
        &self,
        cost: CostFunction,
        request: &RefitRequest,
    ) -> Result<Settings, crate::optimise::SettingsError> {
        let method = request.method.unwrap_or(self.method);
        let mut s = self.fit_settings(cost, method, request.seed.unwrap_or(self.seed));
        let preset = request.preset;
        if let Some(m) = request.sra.or(preset.map(|p| p.sra())) {
            s.sra = s.sra.with_model(m);
        }
        if let Some(w) = request.sra_weight.or(preset.map(|p| p.sra_weight(cost))) {
            s.sra = s.sra.with_weight(w);
        }
        if let Some(f) = request.fresnel.or(preset.map(|p| p.fresnel())) {
            s.fresnel = f;
        }
        match request.model {
            Some(m) => s.model = m,
            None => {
                if let Some(p) = preset {
                    s.model = if method == Method::Separable {
                        p.model()
                    } else {
                        crate::model::ModelKind::Paper
                    };
                }
            }
        }
        s.validate()?;
        Ok(s)
    }

    /// The optimiser settings of one fit.
    pub fn fit_settings(&self, cost: CostFunction, method: Method, seed: u64) -> Settings {
        Settings {
            method,
            cost,
            seed,
            sra: crate::sra_reading::SraReading::default()
                .with_model(self.sra)
                .with_weight(self.sra_weight.unwrap_or(self.preset.sra_weight(cost))),
            // The settings record the model each fit used: the paper GA fits only the paper's.
            model: if method == Method::Separable {
                self.model
            } else {
                crate::model::ModelKind::Paper
            },
            fresnel: self.fresnel,
            ..Settings::default()
        }
    }
}

impl Default for ServiceSettings {
    fn default() -> Self {
        ServiceSettings::from_config(&Config::default())
    }
}

/// Extension points that normal use never sets: only code (tests) can.
#[derive(Clone, Default)]
pub struct ServiceOptions {
    /// Replaces the fit computation (`fit::fit_measured`); the end-to-end tests use it to make
    /// a fit panic and check that only that fit fails.
    pub fit_fn: Option<FitFn>,
}

impl std::fmt::Debug for ServiceOptions {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ServiceOptions")
            .field("fit_fn", &self.fit_fn.as_ref().map(|_| "custom"))
            .finish()
    }
}

/// Where the time went, cumulated since start-up (the demo's timing split).
#[derive(Debug, Default)]
pub struct Timings {
    /// Wall time the instruments spent measuring (from a request to its last reading).
    acquire_ns: AtomicU64,
    /// Time spent in store calls made by the orchestrator and the fit worker.
    store_ns: AtomicU64,
    /// Wall time of the fit computations, summed over fits (they may overlap).
    fit_ns: AtomicU64,
}

/// A snapshot of [`Timings`], in seconds.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct TimingSplit {
    pub acquire_s: f64,
    pub store_s: f64,
    pub fit_s: f64,
}

impl Timings {
    fn add(counter: &AtomicU64, d: Duration) {
        counter.fetch_add(d.as_nanos() as u64, Ordering::Relaxed);
    }

    pub fn split(&self) -> TimingSplit {
        let s = |c: &AtomicU64| c.load(Ordering::Relaxed) as f64 / 1e9;
        TimingSplit {
            acquire_s: s(&self.acquire_ns),
            store_s: s(&self.store_ns),
            fit_s: s(&self.fit_ns),
        }
    }
}

/// `GET /status`. `D` is each instrument's status and `Op` the operation in progress: the
/// service's own here ([`DeviceStatus`], [`Operation`]); the API's client reads them open to
/// values a newer daemon adds.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Status<D = DeviceStatus, Op = Operation> {
    pub version: String,
    /// What the instruments are doing, if anything.
    pub busy: Option<BusyStatus<Op>>,
    /// The reference new scans are normalised by.
    pub reference: Option<ReferenceInForce>,
    pub fits_queued: usize,
    pub fits_running: usize,
    /// Finished fits whose bootstrap intervals are still being computed (SCIENCE.md §10).
    pub bootstraps_pending: usize,
    /// Finished fits whose cross-validation is still being computed (`[fit] crossval`).
    #[serde(default)]
    pub crossvals_pending: usize,
    /// Whether each instrument is simulated.
    pub simulated: SimulatedStatus,
    /// Each instrument: its connection state and identity (MA-T12 first, then the SRA).
    pub devices: Vec<D>,
    pub timings: TimingSplit,
    /// Forwarding to the central database (backlog, last error), when configured.
    pub sync: Option<crate::sync::SyncStatus>,
    /// The watch folder (files waiting, imported, rejected, last error), when configured.
    pub ingest: Option<IngestStatus>,
}

/// The reference in force.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ReferenceInForce {
    pub id: ReferenceId,
    pub name: String,
    pub completed_at_ms: Option<i64>,
    pub age_hours: f64,
    /// Older than `[scan] reference_max_age_hours`: scans will not be fitted.
    pub stale: bool,
}

/// What a refit asks for.
#[derive(Debug, Clone, PartialEq, Default, Deserialize, Serialize)]
#[serde(default, deny_unknown_fields)]
pub struct RefitRequest {
    /// Cost functions to fit; empty = the configured ones.
    pub cost_functions: Vec<CostFunction>,
    /// Optimiser; `None` = the configured one.
    pub method: Option<Method>,
    /// Seed; `None` = the configured one.
    pub seed: Option<u64>,
    /// Science defaults (`measured` or `paper`) for `sra`, `sra_weight`, `model` and `fresnel`;
    /// `None` = the configured choices (`[fit]`).
    pub preset: Option<crate::optimise::Preset>,
    /// SRA reading model (`flat` or `luminance`); `None` = the preset's, else the configured
    /// one (`[fit] sra`).
    pub sra: Option<crate::sra_reading::SraModel>,
    /// The SRA readings' weight in the cost (`paper` or `balanced`); `None` = the preset's for
    /// each cost function, else the configured one (`[fit] sra_weight`).
    pub sra_weight: Option<crate::sra_reading::SraWeight>,
    /// The model's form; `None` = the preset's, else the configured one (`[fit] model`).
    pub model: Option<crate::model::ModelKind>,
    /// The lobe's Fresnel factor; `None` = the preset's, else the configured one
    /// (`[fit] fresnel`).
    pub fresnel: Option<crate::model::FresnelCosine>,
    /// Fit even though the scan's reference is older than the configured limit.
    pub allow_stale_reference: bool,
    /// Queue only the cost functions the scan has no fit of in this configuration yet (done,
    /// queued or running, with the same method, model, Fresnel factor, SRA model and weight): what
    /// `brdfd refit --all` asks, so that a second run, or one after a stop, queues only what
    /// the first did not.
    pub missing_only: bool,
}

/// The running service's parts, wired once at start.
struct Inner {
    /// What every part shares (`context.rs`).
    ctx: Context,
    /// The instruments and what is known of them (`acquisition.rs`).
    acquisition: Arc<Acquisition>,
    /// The measurement runs (`orchestrator.rs`).
    orchestrator: Orchestrator,
    /// Processing, refits, imports and exports (`pipeline.rs`).
    pipeline: Pipeline,
    /// The fit queue and its workers' state (`fit_worker.rs`).
    fits: Arc<FitWorker>,
    /// Forwarding to the central database (`forwarder.rs`), when configured.
    forwarding: Option<Forwarding>,
    /// The watch folder (`ingest.rs`), when configured.
    watch_folder: Option<WatchFolder>,
}

/// The running service; clones share it.
#[derive(Clone)]
pub struct Service {
    inner: Arc<Inner>,
}

impl std::fmt::Debug for Service {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Service").finish_non_exhaustive()
    }
}

impl Service {
    /// Starts the service on an open store and started instruments: marks scans a crash left
    /// half-measured as failed, queues again the fits a crash left running, records the
    /// instruments' identities, starts the fit worker, and has it compute the
    /// cross-validation of done fits that have none.
    pub async fn start(
        store: Store,
        devices: Devices,
        settings: ServiceSettings,
        options: ServiceOptions,
    ) -> Result<Service, ServiceError> {
        let interrupted = store.mark_interrupted_scans_failed().await?;
        if !interrupted.is_empty() {
            tracing::warn!(scans = ?interrupted, "scans left unfinished by the last run marked failed");
        }
        let requeued = store.requeue_interrupted_fits().await?;
        if !requeued.is_empty() {
            tracing::info!(fits = ?requeued, "fits interrupted by the last run queued again");
        }
        // The newest measured reference: a newer one that came with an imported scan is never
        // in force.
        let reference = store.latest_measured_reference().await?.map(|r| r.id);
        let ctx = Context::new(store, settings);
        let (fits, fit_rx) =
            FitWorker::new(ctx.clone(), options.fit_fn.unwrap_or_else(default_fit_fn));
        let acquisition = Arc::new(Acquisition::new(ctx.clone(), devices, reference));
        let pipeline = Pipeline::new(ctx.clone(), fits.clone());
        let orchestrator = Orchestrator::new(ctx.clone(), acquisition.clone(), pipeline.clone());
        fits.start(fit_rx).await;
        acquisition.watch_devices().await;
        for fit in ctx.store.queued_fits().await? {
            fits.submit(fit.id);
        }
        let backfill = fits.crossval_backfill().await?;
        if backfill > 0 {
            tracing::info!(
                fits = backfill,
                "computing the cross-validation of stored fits that have none"
            );
        }
        let forwarding = match ctx.settings.sync.clone() {
            Some(options) => Some(Forwarding::start(&ctx, options).await?),
            None => None,
        };
        let watch_folder = match ctx.settings.ingest.clone() {
            Some(ingest) => Some(WatchFolder::start(ctx.clone(), pipeline.clone(), ingest).await?),
            None => None,
        };
        let inner = Arc::new(Inner {
            ctx,
            acquisition,
            orchestrator,
            pipeline,
            fits,
            forwarding,
            watch_folder,
        });
        Ok(Service { inner })
    }

    /// The store the service writes to.
    pub fn store(&self) -> &Store {
        &self.inner.ctx.store
    }

    /// The instruments.
    pub fn devices(&self) -> &Devices {
        self.inner.acquisition.devices()
    }

    pub fn settings(&self) -> &ServiceSettings {
        &self.inner.ctx.settings
    }

    /// Events from now on.
    pub fn subscribe(&self) -> broadcast::Receiver<Event> {
        self.inner.ctx.events.subscribe()
    }

    /// Cumulated timings since start-up.
    pub fn timings(&self) -> TimingSplit {
        self.inner.ctx.timings.split()
    }

    /// What the instruments are doing now.
    pub fn current_operation(&self) -> Option<Operation> {
        self.inner.acquisition.current_operation()
    }

    /// Stops the reference or scan in progress: the instruments abort, the readings already
    /// stored are kept, and a scan is marked `aborted`. Returns what was aborted.
    pub fn abort(&self) -> Result<Operation, ServiceError> {
        self.inner.acquisition.abort()
    }

    /// Starts measuring the white reference tile on both instruments. Returns at once with the
    /// new reference set's id; progress comes as events. Refused while the instruments are
    /// busy or the daemon is stopping.
    pub async fn request_reference(&self) -> Result<ReferenceId, ServiceError> {
        self.inner.orchestrator.request_reference().await
    }

    /// Starts a scan of sample `sample` against the reference in force. Returns at once with
    /// the scan's id; progress comes as events. Refused while the instruments are busy, before
    /// any reference was measured, or while the daemon is stopping.
    pub async fn request_scan(&self, sample: &str) -> Result<ScanId, ServiceError> {
        self.inner.orchestrator.request_scan(sample).await
    }

    /// Queues fits of a complete scan again (other cost functions, method or seed).
    pub async fn refit(
        &self,
        scan: ScanId,
        request: &RefitRequest,
    ) -> Result<Vec<FitRunId>, ServiceError> {
        self.inner.pipeline.refit(scan, request).await
    }

    /// Cancels a queued or running fit. A running fit stops at its next generation.
    pub async fn cancel_fit(&self, fit: FitRunId) -> Result<(), ServiceError> {
        self.inner.fits.cancel_fit(fit).await
    }

    /// Imports a `brdfd.scan/1` scan: its reference readings become a reference set (named
    /// with [`IMPORTED_SUFFIX`]; never the reference in force for new scans), its readings a
    /// complete scan, all in one transaction, which is then processed and fitted like a
    /// measured one. Returns the scan's id and its fits.
    pub async fn import_scan(&self, file: &Scan) -> Result<(ScanId, Vec<FitRunId>), ServiceError> {
        self.inner.pipeline.import_scan(file).await
    }

    /// [`Service::import_scan`] with what the file says of its origin: the instruments and
    /// source (`provenance`), when the readings were taken (`taken_at_ms`, else now), and the
    /// instrument camera's images of the measurement, kept with the scan.
    pub async fn import_scan_as(
        &self,
        file: &Scan,
        provenance: &Provenance,
        taken_at_ms: Option<i64>,
        textures: &[TextureImage],
    ) -> Result<(ScanId, Vec<FitRunId>), ServiceError> {
        let pipeline = &self.inner.pipeline;
        pipeline
            .import_scan_as(file, provenance, taken_at_ms, textures)
            .await
    }

    /// Imports the scans of one file received whole (`POST /scans/import`), in one
    /// transaction, then fits them: idempotent by content, so a file whose hash (`file`) was
    /// imported before through any door gives that import and writes nothing, unless `again`.
    pub async fn import_file(
        &self,
        file: crate::store::ImportFile<'_>,
        scans: &[ScanToImport<'_>],
        again: bool,
    ) -> Result<FileImported, ServiceError> {
        self.inner
            .pipeline
            .import_file(Some(file), scans, again)
            .await
    }

    /// The file a scan was imported from, when its content hash is known.
    pub async fn scan_import(
        &self,
        scan: ScanId,
    ) -> Result<Option<crate::store::PriorImport>, ServiceError> {
        Ok(self.inner.ctx.store.scan_import(scan).await?)
    }

    /// Exports a complete scan as a `brdfd.scan/1` scan (with its reference readings).
    pub async fn export_scan(&self, scan: ScanId) -> Result<Scan, ServiceError> {
        self.inner.pipeline.export_scan(scan).await
    }

    /// The reference in force, with its age.
    pub async fn reference_in_force(&self) -> Result<Option<ReferenceInForce>, ServiceError> {
        let Some(id) = self.inner.acquisition.reference_in_force() else {
            return Ok(None);
        };
        let detail = self.inner.ctx.store.reference_detail(id).await?;
        Ok(Some(self.in_force_view(&detail.reference)))
    }

    fn in_force_view(&self, r: &ReferenceSummary) -> ReferenceInForce {
        let done = r.completed_at_ms.unwrap_or(r.taken_at_ms);
        let age_hours = (crate::store::now_ms() - done).max(0) as f64 / 3.6e6;
        ReferenceInForce {
            id: r.id,
            name: r.name.clone(),
            completed_at_ms: r.completed_at_ms,
            age_hours,
            stale: age_hours * 3600.0 > self.settings().reference_max_age.as_secs_f64(),
        }
    }

    /// The daemon's state.
    pub async fn status(&self) -> Result<Status, ServiceError> {
        let acquisition = &self.inner.acquisition;
        let fits = &self.inner.fits;
        Ok(Status {
            version: env!("CARGO_PKG_VERSION").to_string(),
            busy: acquisition.busy_status(),
            reference: self.reference_in_force().await?,
            fits_queued: fits.queued(),
            fits_running: fits.running(),
            bootstraps_pending: fits.bootstraps_pending(),
            crossvals_pending: fits.crossvals_pending(),
            simulated: acquisition.simulated(),
            devices: self.device_statuses(),
            timings: self.timings(),
            sync: self.inner.forwarding.as_ref().map(Forwarding::status),
            ingest: self.ingest_status(),
        })
    }

    /// The bound on import bodies held in memory at once, which `POST /scans/import` holds
    /// its body's bytes from before reading it.
    pub fn import_budget(&self) -> &import_budget::ImportBudget {
        &self.inner.ctx.import_budget
    }

    /// The watch folder's state, when one is configured.
    pub fn ingest_status(&self) -> Option<IngestStatus> {
        self.inner.watch_folder.as_ref().map(WatchFolder::status)
    }

    /// Each instrument's connection state and identity, MA-T12 first.
    pub fn device_statuses(&self) -> Vec<DeviceStatus> {
        self.inner.acquisition.device_statuses()
    }

    /// How often each instrument has been connected, disconnected, reconnecting or in error
    /// since start: `((instrument, state), count)`, for `GET /metrics`.
    pub fn device_transitions(&self) -> Vec<((&'static str, &'static str), u64)> {
        self.inner.acquisition.device_transitions()
    }

    /// Whether a scan has nothing more coming: it is not being measured, and none of its fits
    /// is queued or running.
    pub async fn scan_settled(&self, scan: ScanId) -> Result<bool, ServiceError> {
        if self.current_operation() == Some(Operation::Scan { scan }) {
            return Ok(false);
        }
        let store = self.store();
        let detail = store.scan_detail(scan).await?;
        if matches!(
            detail.scan.state,
            ScanState::Requested | ScanState::Measuring
        ) {
            return Ok(false);
        }
        let fits = store.fits_for_scan(scan).await?;
        Ok(fits.iter().all(|f| {
            !matches!(
                f.status,
                crate::store::FitStatus::Queued | crate::store::FitStatus::Running
            )
        }))
    }

    /// Waits until [`Service::scan_settled`], polling; `false` if `timeout` passed first.
    pub async fn wait_settled(
        &self,
        scan: ScanId,
        timeout: Duration,
    ) -> Result<bool, ServiceError> {
        let deadline = Instant::now() + timeout;
        loop {
            if self.scan_settled(scan).await? {
                return Ok(true);
            }
            if Instant::now() >= deadline {
                return Ok(false);
            }
            tokio::time::sleep(Duration::from_millis(10)).await;
        }
    }

    /// Waits until the instruments are free (the reference or scan in progress has ended and
    /// its fits are queued); `false` if `timeout` passed first.
    pub async fn wait_idle(&self, timeout: Duration) -> bool {
        let deadline = Instant::now() + timeout;
        while self.current_operation().is_some() {
            if Instant::now() >= deadline {
                return false;
            }
            tokio::time::sleep(Duration::from_millis(5)).await;
        }
        true
    }

    /// Graceful shutdown: the reference or scan in progress is aborted (its readings kept, a
    /// scan marked `aborted` with the reason), running fits stop at their next generation and
    /// are left to be queued again at the next start, the instruments' connections are closed,
    /// the recordings finished and the store closed. Returns whether every task ended within
    /// the grace period.
    pub async fn shutdown(&self) -> bool {
        let all_ended = self.stop_keeping_store().await;
        self.store().close().await;
        all_ended
    }

    /// [`Service::shutdown`] without closing the store, for callers that read it afterwards
    /// (`brdfd replay`, `brdfd demo`, tests).
    pub async fn stop_keeping_store(&self) -> bool {
        let grace = self.settings().shutdown_grace;
        let all_ended = self.inner.ctx.stop(grace).await;
        if !all_ended {
            tracing::warn!("some tasks did not stop within {} s", grace.as_secs());
        }
        if let Err(e) = self.devices().clone().shutdown().await {
            tracing::warn!(error = %e, "the session recording is incomplete");
        }
        all_ended
    }
}

#[cfg(test)]
mod tests;
