//! The scan orchestrator: measures a reference or a scan on both instruments at once, stores
//! every reading the moment its event arrives, decides how the measurement ends (complete,
//! failed with the devices' reasons, or aborted), and hands a complete scan to the pipeline
//! (`pipeline.rs`). References and scans take one path, [`Orchestrator::start_measurement`]
//! then `run`, parameterised by the [`Target`] they fill; the instruments are claimed through
//! `acquisition.rs`.
//!
//! [`Orchestrator`] holds no state of its own between measurements: what one run knows lives
//! in its task ([`Acquired`]); the instruments and the busy claim are the acquisition's, the
//! fits the pipeline's.
//!
//! Decisions:
//! - Readings are taken from the drivers' event stream, not from the result of
//!   `measure_all`, so each is committed as it arrives; the result is used afterwards only to
//!   store any reading whose event was lost to a lagging channel.
//! - The raw frame stored with a reading is the reply frame exactly as the driver received it
//!   ([`drivers::ReceivedReading::raw`]), never a re-encoding: when a vendor's real codec is
//!   written, the store shows what the instrument actually sent, including anything brdfd's
//!   codec would have written differently. Imported readings (from a scan file) had no device
//!   traffic and store an empty frame.
//! - One instrument failing does not stop the other: its readings are stored too, and the scan
//!   fails with every device's reason.
//! - A scan is complete only through `Store::complete_scan`, which refuses fewer readings than
//!   its geometries (14, or the 12 MA-T12 ones when the SRA is turned off); an abort or shutdown marks it `aborted` with the reason (a reference set, which
//!   has no such state, `failed`).

use std::collections::HashSet;
use std::future::Future;
use std::sync::Arc;
use std::time::{Duration, Instant};

use drivers::{DriverError, Instrument, ReadingValue, ReceivedReading};
use tokio::sync::{Notify, broadcast};

use crate::geometry::{self, Device, GEOMETRY_COUNT, Geometry};
use crate::store::{Provenance, ReadingValues, ReferenceId, ScanId, Source, Store, StoreError};

use super::acquisition::{Acquisition, BusyClaim, Operation};
use super::context::Context;
use super::events::{Event, ReadingShown};
use super::pipeline::{Pipeline, check_name};
use super::shutdown::{Shutdown, TaskGuard};
use super::{RefitRequest, ServiceError, Timings};

/// What a measurement is for: the store row its readings go to.
#[derive(Debug, Clone, Copy)]
enum Target {
    Reference(ReferenceId),
    Scan(ScanId),
}

impl Target {
    fn operation(self) -> Operation {
        match self {
            Target::Reference(reference) => Operation::Reference { reference },
            Target::Scan(scan) => Operation::Scan { scan },
        }
    }

    /// The row's kind and id, for log lines.
    fn named(self) -> (&'static str, i64) {
        match self {
            Target::Reference(r) => ("reference", r.0),
            Target::Scan(s) => ("scan", s.0),
        }
    }

    async fn set_provenance(self, store: &Store, p: &Provenance) -> Result<(), StoreError> {
        match self {
            Target::Reference(r) => store.set_reference_provenance(r, p).await,
            Target::Scan(s) => store.set_scan_provenance(s, p).await,
        }
    }

    async fn complete(self, store: &Store) -> Result<(), StoreError> {
        match self {
            Target::Reference(r) => store.complete_reference(r).await,
            Target::Scan(s) => store.complete_scan(s).await,
        }
    }

    /// Marks the row failed with `reason`, keeping its readings.
    async fn fail(self, store: &Store, reason: &str) -> Result<(), StoreError> {
        match self {
            Target::Reference(r) => store.fail_reference(r, reason).await,
            Target::Scan(s) => store.fail_scan(s, reason).await,
        }
    }

    /// Marks the row stopped early (abort, shutdown): a scan `aborted`; a reference set, which
    /// has no such state, `failed`.
    async fn stop(self, store: &Store, reason: &str) -> Result<(), StoreError> {
        match self {
            Target::Reference(r) => store.fail_reference(r, reason).await,
            Target::Scan(s) => store.abort_scan_because(s, reason).await,
        }
    }

    fn failed(self, reason: String) -> Event {
        match self {
            Target::Reference(reference) => Event::ReferenceFailed { reference, reason },
            Target::Scan(scan) => Event::ScanFailed { scan, reason },
        }
    }

    fn stopped(self, reason: String) -> Event {
        match self {
            Target::Reference(reference) => Event::ReferenceFailed { reference, reason },
            Target::Scan(scan) => Event::ScanAborted { scan, reason },
        }
    }

    /// The failure reason of a row whose request lost the instruments to another one between
    /// the idle check and the claim.
    fn lost_the_instruments(self) -> &'static str {
        match self {
            Target::Reference(_) => "the instruments were busy",
            Target::Scan(_) => "refused: the instruments were busy with another scan",
        }
    }
}

/// How the instruments' part of a measurement went.
#[derive(Debug, Default)]
struct Acquired {
    /// How many geometries the measurement takes (14, or 12 with the SRA turned off).
    geometries: usize,
    /// Geometries stored.
    stored: HashSet<&'static str>,
    /// Device and store errors, each naming its instrument and geometry.
    errors: Vec<String>,
    /// Why it was stopped early, if it was.
    aborted: Option<String>,
}

/// A driver reading as the store takes it: device, geometry, values (the raw frame goes to the
/// store as received).
fn convert(
    instrument: Instrument,
    reading: &drivers::Reading,
) -> Result<(Device, &'static Geometry, ReadingValues), String> {
    let geometry = geometry::by_name(reading.geometry).ok_or_else(|| {
        format!(
            "{instrument} reported geometry {} which is not in the geometry table",
            reading.geometry
        )
    })?;
    let values = match reading.value {
        ReadingValue::Reflectance(s) => ReadingValues::Spectrum(s),
        ReadingValue::Intensity(v) => ReadingValues::Intensity(v),
    };
    Ok((instrument.into(), geometry, values))
}

/// What an operator asked the instruments to measure.
enum Plan<'a> {
    /// The white reference tile.
    Reference,
    /// A sample, against the reference in force.
    Scan { sample: &'a str },
}

/// How often [`retry_store_write`] tries a write.
pub(crate) const END_WRITE_ATTEMPTS: u32 = 5;

/// Runs `write` until it succeeds, fails for a reason a retry cannot fix (a life-cycle
/// refusal, a missing row), or has been tried [`END_WRITE_ATTEMPTS`] times; waits 100 ms,
/// 200 ms, 400 ms, 800 ms between tries.
pub(crate) async fn retry_store_write<F, Fut>(mut write: F) -> Result<(), StoreError>
where
    F: FnMut() -> Fut,
    Fut: Future<Output = Result<(), StoreError>>,
{
    let mut wait = Duration::from_millis(100);
    let mut attempt = 1;
    loop {
        match write().await {
            Err(StoreError::Database(e)) if attempt < END_WRITE_ATTEMPTS => {
                tracing::warn!(error = %e, attempt, "store write failed; trying again");
                tokio::time::sleep(wait).await;
                wait *= 2;
                attempt += 1;
            }
            other => return other,
        }
    }
}

/// The measurement runs (module docs).
#[derive(Clone)]
pub(super) struct Orchestrator {
    ctx: Context,
    acquisition: Arc<Acquisition>,
    /// Where a complete scan goes.
    pipeline: Pipeline,
}

impl Orchestrator {
    pub(super) fn new(
        ctx: Context,
        acquisition: Arc<Acquisition>,
        pipeline: Pipeline,
    ) -> Orchestrator {
        Orchestrator {
            ctx,
            acquisition,
            pipeline,
        }
    }

    /// Starts measuring the white reference tile on both instruments. Returns at once with the
    /// new reference set's id; progress comes as events. Refused while the instruments are
    /// busy or the daemon is stopping.
    pub(super) async fn request_reference(&self) -> Result<ReferenceId, ServiceError> {
        match self.start_measurement(Plan::Reference).await? {
            Target::Reference(reference) => Ok(reference),
            Target::Scan(scan) => unreachable!("a reference request started scan {scan}"),
        }
    }

    /// Starts a scan of sample `sample` against the reference in force. Returns at once with
    /// the scan's id; progress comes as events. Refused while the instruments are busy, before
    /// any reference was measured, or while the daemon is stopping.
    pub(super) async fn request_scan(&self, sample: &str) -> Result<ScanId, ServiceError> {
        let sample = sample.trim();
        if sample.is_empty() {
            return Err(ServiceError::BadRequest(
                "the sample name is empty: give the sample's name (e.g. --sample \"T.Sky blue\")"
                    .into(),
            ));
        }
        check_name("sample name", sample)?;
        match self.start_measurement(Plan::Scan { sample }).await? {
            Target::Scan(scan) => Ok(scan),
            Target::Reference(r) => unreachable!("a scan request started reference {r}"),
        }
    }

    /// The one path of a reference or scan request: checks that the daemon and the
    /// instruments are free, creates the row with its provenance, claims the instruments, cues
    /// simulated ones, announces the start and spawns the run. A row created but not run (its
    /// provenance refused, or another request won the instruments between the check and the
    /// claim) is marked failed with the reason.
    async fn start_measurement(&self, plan: Plan<'_>) -> Result<Target, ServiceError> {
        let (guard, listener) = self.ctx.task_slot().await?;
        let acquisition = &self.acquisition;
        acquisition.check_idle()?;
        let store = &self.ctx.store;
        // With the SRA turned off, references and scans have the 12 MA-T12 geometries.
        let with_sra = acquisition.devices().has_sra();
        let (target, started) = match plan {
            Plan::Reference => {
                let reference = self
                    .ctx
                    .timed_store(store.begin_reference_of(
                        "Munsell N9",
                        self.ctx.settings.reference_reflectance.as_ref(),
                        with_sra,
                    ))
                    .await?;
                (
                    Target::Reference(reference),
                    Event::ReferenceStarted { reference },
                )
            }
            Plan::Scan { sample } => {
                let reference = acquisition
                    .reference_in_force()
                    .ok_or(ServiceError::NoReference)?;
                let scan = self
                    .ctx
                    .timed_store(store.request_scan_of(sample, reference, with_sra))
                    .await?;
                let started = Event::ScanStarted {
                    scan,
                    sample: sample.to_string(),
                    reference,
                };
                (Target::Scan(scan), started)
            }
        };
        let provenance = acquisition.provenance(Source::Measured, None);
        if let Err(e) = self
            .ctx
            .timed_store(target.set_provenance(store, &provenance))
            .await
        {
            let reason = e.to_string();
            if let Err(fail) = target.fail(store, &reason).await {
                tracing::warn!(error = %fail, ?target, %reason,
                    "cannot mark the {} failed after its provenance was refused", target.named().0);
            }
            return Err(e.into());
        }
        let claim = match acquisition.claim(target.operation()) {
            Ok(claim) => claim,
            Err(e) => {
                // Another request won the race between the check and the claim.
                if let Err(fail) = target.fail(store, target.lost_the_instruments()).await {
                    tracing::warn!(error = %fail, ?target,
                        "cannot mark the {} failed after losing the instruments to another request",
                        target.named().0);
                }
                return Err(e);
            }
        };
        let replayed = acquisition.devices().cue_simulators(match plan {
            Plan::Reference => None,
            Plan::Scan { sample } => Some(sample),
        });
        // Simulated instruments: the row says which recording answers.
        if let Some(detail) = replayed {
            let provenance = acquisition.provenance(Source::Measured, Some(detail));
            if let Err(e) = self
                .ctx
                .timed_store(target.set_provenance(store, &provenance))
                .await
            {
                tracing::warn!(error = %e, ?target, "cannot record which recording answers");
            }
        }
        self.ctx.events.send(started);
        let orchestrator = self.clone();
        tokio::spawn(orchestrator.run_claimed(target, claim, guard, listener));
        Ok(target)
    }

    /// Runs a claimed measurement to its end, then frees the instruments and the task slot.
    async fn run_claimed(
        self,
        target: Target,
        claim: BusyClaim,
        guard: TaskGuard,
        mut listener: Shutdown,
    ) {
        self.run(target, &claim, &mut listener).await;
        drop(claim);
        drop(guard);
    }

    /// Writes how a reference or scan ended (failed or aborted), retrying while the store
    /// fails for a reason that may pass (a locked or full disk, an I/O error): up to
    /// [`END_WRITE_ATTEMPTS`] tries, backing off from 100 ms to 1.6 s. The readings are already
    /// committed one by one, so nothing measured is lost either way; if every try fails the row
    /// stays `measuring`, and the next start marks it failed ("daemon stopped during the scan").
    async fn record_end<F, Fut>(&self, what: &str, id: i64, write: F)
    where
        F: FnMut() -> Fut,
        Fut: Future<Output = Result<(), StoreError>>,
    {
        if let Err(e) = self.ctx.timed_store(retry_store_write(write)).await {
            tracing::error!(
                error = %e,
                what,
                id,
                "cannot record how the {what} ended; the next start marks it failed"
            );
        }
    }

    /// Measures `target` and records how it ended: complete (a reference set then in force, a
    /// scan handed to the pipeline), failed with every device's reason, or stopped early.
    async fn run(&self, target: Target, abort: &Notify, stop: &mut Shutdown) {
        let store = &self.ctx.store;
        if let Target::Scan(scan) = target
            && let Err(e) = self.ctx.timed_store(store.start_measuring(scan)).await
        {
            let reason = format!("cannot start measuring: {e}");
            self.end_failed(target, reason).await;
            return;
        }
        let acquired = self.acquire(target, abort, stop).await;
        if let Some(reason) = acquired.aborted {
            let (what, id) = target.named();
            self.record_end(what, id, || target.stop(store, &reason))
                .await;
            self.ctx.events.send(target.stopped(reason));
            return;
        }
        if !acquired.errors.is_empty() {
            self.end_failed(target, acquired.errors.join("; ")).await;
            return;
        }
        if let Err(e) = self.ctx.timed_store(target.complete(store)).await {
            self.end_failed(target, e.to_string()).await;
            return;
        }
        match target {
            Target::Reference(reference) => {
                self.acquisition.put_in_force(reference);
                self.ctx.events.send(Event::ReferenceComplete { reference });
            }
            Target::Scan(scan) => {
                self.ctx.events.send(Event::ScanComplete { scan });
                self.fit_measured_scan(scan).await;
            }
        }
    }

    /// Records that `target` failed with `reason` and says so.
    async fn end_failed(&self, target: Target, reason: String) {
        let store = &self.ctx.store;
        let (what, id) = target.named();
        self.record_end(what, id, || target.fail(store, &reason))
            .await;
        self.ctx.events.send(target.failed(reason));
    }

    /// Hands a scan just measured to the pipeline. A failure here leaves a complete scan
    /// without fits; the event says why, and `brdfd refit` can try again.
    async fn fit_measured_scan(&self, scan: ScanId) {
        match self
            .pipeline
            .process_and_queue(scan, &RefitRequest::default())
            .await
        {
            Ok(_) => {}
            Err(ServiceError::StaleReference {
                reference,
                age_hours,
                max_age_hours,
                ..
            }) => {
                self.ctx.events.send(Event::ReferenceStale {
                    scan,
                    reference,
                    age_hours,
                    max_age_hours,
                });
            }
            Err(e) => self.ctx.events.send(Event::ProcessingFailed {
                scan,
                reason: e.to_string(),
            }),
        }
    }

    /// Runs MEASURE-ALL on both instruments at once, storing every reading as its event
    /// arrives, until both are done (or aborted).
    async fn acquire(&self, target: Target, abort: &Notify, stop: &mut Shutdown) -> Acquired {
        let started = Instant::now();
        let devices = self.acquisition.devices();
        // Subscribe before the commands go out, so no reading event can be missed.
        let mut rx_m = devices.ma_t12.subscribe();
        let mut rx_s = devices.sra.as_ref().map(|h| h.subscribe());
        let m = devices.ma_t12.measure_all_received();
        let s = async {
            match &devices.sra {
                Some(h) => h.measure_all_received().await,
                None => Ok(Vec::new()),
            }
        };
        tokio::pin!(m, s);
        let mut m_done: Option<Result<Vec<ReceivedReading>, DriverError>> = None;
        let mut s_done: Option<Result<Vec<ReceivedReading>, DriverError>> = None;
        let (mut m_open, mut s_open) = (true, rx_s.is_some());
        let mut acquired = Acquired {
            geometries: if devices.has_sra() {
                GEOMETRY_COUNT
            } else {
                geometry::MA_T12_COUNT
            },
            ..Acquired::default()
        };
        while m_done.is_none() || s_done.is_none() {
            tokio::select! {
                // Events first: a reading is stored before the command's end is looked at.
                biased;
                ev = rx_m.recv(), if m_open => {
                    m_open = self.on_event(target, ev, &mut acquired).await;
                }
                ev = super::devices::recv_if_present(&mut rx_s), if s_open => {
                    s_open = self.on_event(target, ev, &mut acquired).await;
                }
                r = &mut m, if m_done.is_none() => m_done = Some(r),
                r = &mut s, if s_done.is_none() => s_done = Some(r),
                _ = abort.notified(), if acquired.aborted.is_none() => {
                    acquired.aborted = Some("aborted by the operator".into());
                    self.acquisition.abort_devices();
                }
                _ = stop.recv(), if acquired.aborted.is_none() => {
                    acquired.aborted = Some("the daemon was shut down during the measurement".into());
                    self.acquisition.abort_devices();
                }
            }
        }
        // Events sent before the commands returned are still in the channels.
        for rx in std::iter::once(&mut rx_m).chain(rx_s.as_mut()) {
            while let Ok(ev) = rx.try_recv() {
                self.on_event(target, Ok(ev), &mut acquired).await;
            }
        }
        for (instrument, done) in [(Instrument::MaT12, m_done), (Instrument::Sra, s_done)] {
            match done.expect("both commands finished") {
                Ok(readings) => {
                    for r in &readings {
                        if !acquired.stored.contains(r.reading.geometry) {
                            tracing::warn!(
                                geometry = r.reading.geometry,
                                "reading event lost; storing it from the command's result"
                            );
                            self.store_reading(target, instrument, r, &mut acquired)
                                .await;
                        }
                    }
                }
                Err(DriverError::Aborted { .. }) if acquired.aborted.is_some() => {}
                Err(e) => acquired.errors.push(e.to_string()),
            }
        }
        Timings::add(&self.ctx.timings.acquire_ns, started.elapsed());
        acquired
    }

    /// Handles one driver event during a measurement; returns whether the channel is open.
    async fn on_event(
        &self,
        target: Target,
        ev: Result<drivers::Event, broadcast::error::RecvError>,
        acquired: &mut Acquired,
    ) -> bool {
        match ev {
            Ok(drivers::Event::Reading {
                instrument,
                reading,
            }) => {
                if !acquired.stored.contains(reading.reading.geometry) {
                    self.store_reading(target, instrument, &reading, acquired)
                        .await;
                }
                true
            }
            Ok(_) => true,
            Err(broadcast::error::RecvError::Lagged(n)) => {
                tracing::warn!(
                    missed = n,
                    "driver events lagged; readings come from the command's result"
                );
                true
            }
            Err(broadcast::error::RecvError::Closed) => false,
        }
    }

    async fn store_reading(
        &self,
        target: Target,
        instrument: Instrument,
        received: &ReceivedReading,
        acquired: &mut Acquired,
    ) {
        let (device, geometry, values) = match convert(instrument, &received.reading) {
            Ok(c) => c,
            Err(e) => {
                acquired.errors.push(e);
                return;
            }
        };
        let raw = &received.raw;
        let store = &self.ctx.store;
        let stored = match target {
            Target::Scan(scan) => {
                self.ctx
                    .timed_store(store.add_reading(scan, device, geometry, &values, raw))
                    .await
            }
            Target::Reference(r) => {
                self.ctx
                    .timed_store(store.add_reference_reading(r, device, geometry, &values, raw))
                    .await
            }
        };
        match stored {
            Ok(_) => {
                acquired.stored.insert(geometry.name);
                let (k, n) = (acquired.stored.len(), acquired.geometries);
                let device = device.key().to_string();
                let geometry = geometry.name.to_string();
                let reading = ReadingShown::of(&values, crate::store::now_ms());
                self.ctx.events.send(match target {
                    Target::Scan(scan) => Event::ScanReading {
                        scan,
                        device,
                        geometry,
                        k,
                        n,
                        reading,
                    },
                    Target::Reference(reference) => Event::ReferenceReading {
                        reference,
                        device,
                        geometry,
                        k,
                        n,
                        reading,
                    },
                });
            }
            Err(e) => acquired.errors.push(e.to_string()),
        }
    }
}
