//! The scan orchestrator: measures a reference or a scan on both instruments at once, stores
//! every reading the moment its event arrives, decides how the measurement ends (complete,
//! failed with the devices' reasons, or aborted), and hands a complete scan to processing and
//! the fit worker. Also imports, refits, and the device watcher that records instruments.
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
//! - A scan is complete only through `Store::complete_scan`, which refuses fewer than 14
//!   readings; an abort or shutdown marks it `aborted` with the reason.

use std::collections::HashSet;
use std::future::Future;
use std::time::{Duration, Instant};

use drivers::{DriverError, Instrument, ReadingValue, ReceivedReading};
use tokio::sync::{Notify, broadcast};

use crate::geometry::{self, Device, GEOMETRY_COUNT, Geometry, MA_T12_COUNT, SRA_COUNT};
use crate::processing::{self, ProcessingOptions};
use crate::scan::{DeviceReadings, Reference, Scan, ScanError};
use crate::store::{
    FitRunId, InstrumentProvenance, NewFit, NewReading, Provenance, ReadingValues, ReferenceId,
    ScanDetail, ScanId, ScanState, Source, StoreError,
};

use super::events::{Event, ReadingShown};
use super::shutdown::Shutdown;
use super::{Operation, RefitRequest, Service, ServiceError, Timings};

/// Appended to the name of a reference set that came with an imported scan; such a set is
/// never the reference in force for new scans.
pub const IMPORTED_SUFFIX: &str = " (imported)";

/// What a measurement is for.
#[derive(Debug, Clone, Copy)]
enum Target {
    Reference(ReferenceId),
    Scan(ScanId),
}

/// How the instruments' part of a measurement went.
#[derive(Debug, Default)]
struct Acquired {
    /// Geometries stored.
    stored: HashSet<&'static str>,
    /// Device and store errors, each naming its instrument and geometry.
    errors: Vec<String>,
    /// Why it was stopped early, if it was.
    aborted: Option<String>,
}

fn device_of(instrument: Instrument) -> Device {
    match instrument {
        Instrument::MaT12 => Device::MaT12,
        Instrument::Sra => Device::Sra,
    }
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
    Ok((device_of(instrument), geometry, values))
}

/// A stored scan (complete, with its reference) as a `brdfd.scan/1` scan.
pub fn scan_from_detail(detail: &ScanDetail) -> Result<Scan, ScanError> {
    let readings = device_readings(&detail.readings);
    let reference = device_readings(&detail.reference.readings);
    let name = detail
        .reference
        .reference
        .name
        .trim_end_matches(IMPORTED_SUFFIX)
        .to_string();
    let scan = Scan {
        sample: detail.scan.sample.clone(),
        reference: Reference {
            name,
            readings: reference,
        },
        readings,
    };
    scan.validate()?;
    Ok(scan)
}

/// Readings in table order; a missing geometry is left NaN, which `Scan::validate` names.
fn device_readings(readings: &[crate::store::Reading]) -> DeviceReadings {
    let mut out = DeviceReadings {
        ma_t12: [[f64::NAN; crate::spectral::BANDS]; MA_T12_COUNT],
        sra: [f64::NAN; SRA_COUNT],
    };
    for r in readings {
        match r.values {
            ReadingValues::Spectrum(s) if r.geometry.index < MA_T12_COUNT => {
                out.ma_t12[r.geometry.index] = s
            }
            ReadingValues::Intensity(v) if r.geometry.index >= MA_T12_COUNT => {
                out.sra[r.geometry.index - MA_T12_COUNT] = v
            }
            _ => {}
        }
    }
    out
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

impl Service {
    /// Starts measuring the white reference tile on both instruments. Returns at once with the
    /// new reference set's id; progress comes as events. Refused while the instruments are
    /// busy or the daemon is stopping.
    pub async fn request_reference(&self) -> Result<ReferenceId, ServiceError> {
        let (guard, listener) = self.task_slot().await?;
        self.check_idle()?;
        let reference = self
            .timed_store(self.inner.store.begin_reference(
                "Munsell N9",
                self.inner.settings.reference_reflectance.as_ref(),
            ))
            .await?;
        let provenance = self.provenance(Source::Measured, None);
        if let Err(e) = self
            .timed_store(
                self.inner
                    .store
                    .set_reference_provenance(reference, &provenance),
            )
            .await
        {
            let reason = e.to_string();
            if let Err(fail) = self.inner.store.fail_reference(reference, &reason).await {
                tracing::warn!(error = %fail, %reference, %reason,
                    "cannot mark the reference failed after its provenance was refused");
            }
            return Err(e.into());
        }
        let abort = match self.claim(Operation::Reference { reference }) {
            Ok(a) => a,
            Err(e) => {
                // Another request won the race between the check and the claim.
                if let Err(fail) = self
                    .inner
                    .store
                    .fail_reference(reference, "the instruments were busy")
                    .await
                {
                    tracing::warn!(error = %fail, %reference,
                        "cannot mark the reference failed after losing the instruments to another request");
                }
                return Err(e);
            }
        };
        self.inner.devices.cue_simulators(None);
        self.inner
            .events
            .send(Event::ReferenceStarted { reference });
        let service = self.clone();
        tokio::spawn(async move {
            let mut listener = listener;
            service
                .run_reference(reference, &abort, &mut listener)
                .await;
            drop(abort);
            drop(guard);
        });
        Ok(reference)
    }

    /// Starts a scan of sample `sample` against the reference in force. Returns at once with
    /// the scan's id; progress comes as events. Refused while the instruments are busy, before
    /// any reference was measured, or while the daemon is stopping.
    pub async fn request_scan(&self, sample: &str) -> Result<ScanId, ServiceError> {
        let sample = sample.trim();
        if sample.is_empty() {
            return Err(ServiceError::BadRequest(
                "the sample name is empty: give the sample's name (e.g. --sample \"T.Sky blue\")"
                    .into(),
            ));
        }
        check_name("sample name", sample)?;
        let (guard, listener) = self.task_slot().await?;
        self.check_idle()?;
        let reference = (*self
            .inner
            .reference
            .lock()
            .unwrap_or_else(|p| p.into_inner()))
        .ok_or(ServiceError::NoReference)?;
        let scan = self
            .timed_store(self.inner.store.request_scan(sample, reference))
            .await?;
        let provenance = self.provenance(Source::Measured, None);
        if let Err(e) = self
            .timed_store(self.inner.store.set_scan_provenance(scan, &provenance))
            .await
        {
            let reason = e.to_string();
            if let Err(fail) = self.inner.store.fail_scan(scan, &reason).await {
                tracing::warn!(error = %fail, %scan, %reason,
                    "cannot mark the scan failed after its provenance was refused");
            }
            return Err(e.into());
        }
        let abort = match self.claim(Operation::Scan { scan }) {
            Ok(a) => a,
            Err(e) => {
                if let Err(fail) = self
                    .inner
                    .store
                    .fail_scan(scan, "refused: the instruments were busy with another scan")
                    .await
                {
                    tracing::warn!(error = %fail, %scan,
                        "cannot mark the scan failed after losing the instruments to another request");
                }
                return Err(e);
            }
        };
        self.inner.devices.cue_simulators(Some(sample));
        self.inner.events.send(Event::ScanStarted {
            scan,
            sample: sample.to_string(),
            reference,
        });
        let service = self.clone();
        tokio::spawn(async move {
            let mut listener = listener;
            service.run_scan(scan, &abort, &mut listener).await;
            drop(abort);
            drop(guard);
        });
        Ok(scan)
    }

    /// A guard and a stop listener for a new task, or `ShuttingDown`.
    pub(super) async fn task_slot(
        &self,
    ) -> Result<(super::shutdown::TaskGuard, Shutdown), ServiceError> {
        if self
            .inner
            .stopping
            .load(std::sync::atomic::Ordering::SeqCst)
        {
            return Err(ServiceError::ShuttingDown);
        }
        let c = self.inner.coordinator.lock().await;
        let guard = c.guard().ok_or(ServiceError::ShuttingDown)?;
        Ok((guard, c.listener()))
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
        if let Err(e) = self.timed_store(retry_store_write(write)).await {
            tracing::error!(
                error = %e,
                what,
                id,
                "cannot record how the {what} ended; the next start marks it failed"
            );
        }
    }

    async fn run_reference(&self, reference: ReferenceId, abort: &Notify, stop: &mut Shutdown) {
        let acquired = self
            .acquire(Target::Reference(reference), abort, stop)
            .await;
        let store = &self.inner.store;
        let reason = acquired
            .aborted
            .clone()
            .or_else(|| (!acquired.errors.is_empty()).then(|| acquired.errors.join("; ")));
        if let Some(reason) = reason {
            self.record_end("reference", reference.0, || {
                store.fail_reference(reference, &reason)
            })
            .await;
            self.inner
                .events
                .send(Event::ReferenceFailed { reference, reason });
            return;
        }
        match self.timed_store(store.complete_reference(reference)).await {
            Ok(()) => {
                *self
                    .inner
                    .reference
                    .lock()
                    .unwrap_or_else(|p| p.into_inner()) = Some(reference);
                self.inner
                    .events
                    .send(Event::ReferenceComplete { reference });
            }
            Err(e) => {
                let reason = e.to_string();
                self.record_end("reference", reference.0, || {
                    store.fail_reference(reference, &reason)
                })
                .await;
                self.inner
                    .events
                    .send(Event::ReferenceFailed { reference, reason });
            }
        }
    }

    async fn run_scan(&self, scan: ScanId, abort: &Notify, stop: &mut Shutdown) {
        let store = &self.inner.store;
        if let Err(e) = self.timed_store(store.start_measuring(scan)).await {
            let reason = format!("cannot start measuring: {e}");
            self.record_end("scan", scan.0, || store.fail_scan(scan, &reason))
                .await;
            self.inner.events.send(Event::ScanFailed { scan, reason });
            return;
        }
        let acquired = self.acquire(Target::Scan(scan), abort, stop).await;
        if let Some(reason) = acquired.aborted {
            self.record_end("scan", scan.0, || store.abort_scan_because(scan, &reason))
                .await;
            self.inner.events.send(Event::ScanAborted { scan, reason });
            return;
        }
        if !acquired.errors.is_empty() {
            let reason = acquired.errors.join("; ");
            self.record_end("scan", scan.0, || store.fail_scan(scan, &reason))
                .await;
            self.inner.events.send(Event::ScanFailed { scan, reason });
            return;
        }
        if let Err(e) = self.timed_store(store.complete_scan(scan)).await {
            let reason = e.to_string();
            self.record_end("scan", scan.0, || store.fail_scan(scan, &reason))
                .await;
            self.inner.events.send(Event::ScanFailed { scan, reason });
            return;
        }
        self.inner.events.send(Event::ScanComplete { scan });
        // A failure here leaves a complete scan without fits; the event says why, and
        // `brdfd refit` can try again.
        match self.process_and_queue(scan, &RefitRequest::default()).await {
            Ok(_) => {}
            Err(ServiceError::StaleReference {
                reference,
                age_hours,
                max_age_hours,
                ..
            }) => {
                self.inner.events.send(Event::ReferenceStale {
                    scan,
                    reference,
                    age_hours,
                    max_age_hours,
                });
            }
            Err(e) => self.inner.events.send(Event::ProcessingFailed {
                scan,
                reason: e.to_string(),
            }),
        }
    }

    /// Runs MEASURE-ALL on both instruments at once, storing every reading as its event
    /// arrives, until both are done (or aborted).
    async fn acquire(&self, target: Target, abort: &Notify, stop: &mut Shutdown) -> Acquired {
        let started = Instant::now();
        let devices = &self.inner.devices;
        // Subscribe before the commands go out, so no reading event can be missed.
        let mut rx_m = devices.ma_t12.subscribe();
        let mut rx_s = devices.sra.subscribe();
        let m = devices.ma_t12.measure_all_received();
        let s = devices.sra.measure_all_received();
        tokio::pin!(m, s);
        let mut m_done: Option<Result<Vec<ReceivedReading>, DriverError>> = None;
        let mut s_done: Option<Result<Vec<ReceivedReading>, DriverError>> = None;
        let (mut m_open, mut s_open) = (true, true);
        let mut acquired = Acquired::default();
        while m_done.is_none() || s_done.is_none() {
            tokio::select! {
                // Events first: a reading is stored before the command's end is looked at.
                biased;
                ev = rx_m.recv(), if m_open => {
                    m_open = self.on_event(target, ev, &mut acquired).await;
                }
                ev = rx_s.recv(), if s_open => {
                    s_open = self.on_event(target, ev, &mut acquired).await;
                }
                r = &mut m, if m_done.is_none() => m_done = Some(r),
                r = &mut s, if s_done.is_none() => s_done = Some(r),
                _ = abort.notified(), if acquired.aborted.is_none() => {
                    acquired.aborted = Some("aborted by the operator".into());
                    self.abort_devices();
                }
                _ = stop.recv(), if acquired.aborted.is_none() => {
                    acquired.aborted = Some("the daemon was shut down during the measurement".into());
                    self.abort_devices();
                }
            }
        }
        // Events sent before the commands returned are still in the channels.
        for rx in [&mut rx_m, &mut rx_s] {
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
        Timings::add(&self.inner.timings.acquire_ns, started.elapsed());
        acquired
    }

    /// Sends ABORT to both instruments without waiting for the answers.
    fn abort_devices(&self) {
        for h in [&self.inner.devices.ma_t12, &self.inner.devices.sra] {
            let h = h.clone();
            tokio::spawn(async move {
                if let Err(e) = h.abort().await {
                    tracing::debug!(error = %e, "abort");
                }
            });
        }
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
        let store = &self.inner.store;
        let stored = match target {
            Target::Scan(scan) => {
                self.timed_store(store.add_reading(scan, device, geometry, &values, raw))
                    .await
            }
            Target::Reference(r) => {
                self.timed_store(store.add_reference_reading(r, device, geometry, &values, raw))
                    .await
            }
        };
        match stored {
            Ok(_) => {
                acquired.stored.insert(geometry.name);
                let (k, n) = (acquired.stored.len(), GEOMETRY_COUNT);
                let device = device.key().to_string();
                let geometry = geometry.name.to_string();
                let reading = ReadingShown::of(&values, crate::store::now_ms());
                self.inner.events.send(match target {
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

    /// Processes a complete scan (once per specular strategy) and queues one fit per cost
    /// function asked for. Refused when the scan's reference is too old, unless allowed.
    pub(crate) async fn process_and_queue(
        &self,
        scan: ScanId,
        request: &RefitRequest,
    ) -> Result<Vec<FitRunId>, ServiceError> {
        let settings = &self.inner.settings;
        let store = &self.inner.store;
        let detail = self.timed_store(store.scan_detail(scan)).await?;
        if detail.scan.state != ScanState::Complete {
            return Err(ServiceError::NotComplete {
                scan,
                state: detail.scan.state,
                action: "fitting it",
            });
        }
        let reference = &detail.reference.reference;
        let reference_done = reference.completed_at_ms.unwrap_or(reference.taken_at_ms);
        let age_ms = (detail.scan.requested_at_ms - reference_done).max(0);
        let max = settings.reference_max_age;
        if age_ms as u128 > max.as_millis() && !request.allow_stale_reference {
            return Err(ServiceError::StaleReference {
                scan,
                reference: reference.id,
                age_hours: age_ms as f64 / 3.6e6,
                max_age_hours: max.as_secs_f64() / 3600.0,
            });
        }
        let processed = match self
            .timed_store(store.processed_for_scan(scan))
            .await?
            .into_iter()
            .find(|p| p.specular == settings.specular)
        {
            Some(p) => p.id,
            None => {
                let file = scan_from_detail(&detail)?;
                let options = ProcessingOptions {
                    specular: settings.specular,
                    reference_reflectance: reference.rho_ref,
                };
                let brdf = processing::process(&file, &options)?;
                self.timed_store(store.add_processed(scan, settings.specular, &brdf))
                    .await?
            }
        };
        let costs = if request.cost_functions.is_empty() {
            settings.cost_functions.clone()
        } else {
            request.cost_functions.clone()
        };
        let method = request.method.unwrap_or(settings.method);
        let seed = request.seed.unwrap_or(settings.seed);
        let mut ids = Vec::with_capacity(costs.len());
        for cost in costs {
            let mut fit_settings = settings.fit_settings(cost, method, seed);
            if let Some(model) = request.sra {
                fit_settings.sra = fit_settings.sra.with_model(model);
            }
            let new = NewFit {
                method: method.name().to_string(),
                cost_function: cost,
                settings: serde_json::to_value(fit_settings).map_err(|e| {
                    ServiceError::Store(StoreError::Json {
                        field: "fit settings",
                        source: e,
                    })
                })?,
                seed,
            };
            let id = self.timed_store(store.queue_fit(processed, &new)).await?;
            self.inner.events.send(Event::FitQueued {
                fit: id,
                scan,
                cost_function: cost,
            });
            self.submit_fit(id);
            ids.push(id);
        }
        Ok(ids)
    }

    /// Queues fits of a complete scan again (other cost functions, method or seed).
    pub async fn refit(
        &self,
        scan: ScanId,
        request: &RefitRequest,
    ) -> Result<Vec<FitRunId>, ServiceError> {
        // A request naming a cost function many times queues it once: the list is a set.
        let mut request = request.clone();
        let mut seen = Vec::with_capacity(request.cost_functions.len().min(8));
        request.cost_functions.retain(|cf| {
            let first = !seen.contains(cf);
            if first {
                seen.push(*cf);
            }
            first
        });
        self.process_and_queue(scan, &request).await
    }

    /// Imports a `brdfd.scan/1` scan: its reference readings become a reference set (named
    /// with [`IMPORTED_SUFFIX`]; never the reference in force for new scans), its readings a
    /// complete scan, all in one transaction, which is then processed and fitted like a
    /// measured one. Returns the scan's id and its fits.
    pub async fn import_scan(&self, file: &Scan) -> Result<(ScanId, Vec<FitRunId>), ServiceError> {
        file.validate()?;
        check_name("sample name", &file.sample)?;
        check_name("reference name", &file.reference.name)?;
        let store = &self.inner.store;
        // A brdfd.scan/1 file does not say which instruments measured it.
        let provenance = Provenance {
            source: Source::Imported,
            source_detail: Some("brdfd.scan/1 file".into()),
            ..Provenance::unknown()
        };
        let name = format!("{}{IMPORTED_SUFFIX}", file.reference.name);
        // One transaction: a failure leaves no half-imported reference or scan behind.
        let (_reference, scan) = self
            .timed_store(store.import_scan(
                &file.sample,
                &name,
                &provenance,
                &new_readings(&file.reference.readings),
                &new_readings(&file.readings),
            ))
            .await?;
        self.inner.events.send(Event::ScanComplete { scan });
        let fits = self
            .process_and_queue(scan, &RefitRequest::default())
            .await?;
        Ok((scan, fits))
    }

    /// Records the instruments' identities and reports their connection changes as events,
    /// until shutdown.
    pub(crate) async fn watch_devices(&self) {
        let Ok((guard, mut stop)) = self.task_slot().await else {
            return;
        };
        let service = self.clone();
        let mut rx_m = self.inner.devices.ma_t12.subscribe();
        let mut rx_s = self.inner.devices.sra.subscribe();
        tokio::spawn(async move {
            // The drivers connected before anyone subscribed: ask who is there.
            for h in [
                service.inner.devices.ma_t12.clone(),
                service.inner.devices.sra.clone(),
            ] {
                let s = service.clone();
                tokio::spawn(async move {
                    match h.identify().await {
                        Ok(identity) => {
                            s.count_transition(h.instrument(), "connected", identity.to_string());
                            s.record_instrument(h.instrument(), &identity).await
                        }
                        Err(e) => tracing::warn!(error = %e, "instrument not available at start"),
                    }
                });
            }
            let (mut m_open, mut s_open) = (true, true);
            while m_open || s_open {
                let ev = tokio::select! {
                    ev = rx_m.recv(), if m_open => ev,
                    ev = rx_s.recv(), if s_open => ev,
                    _ = stop.recv() => break,
                };
                match ev {
                    Ok(ev) => service.on_device_event(ev).await,
                    Err(broadcast::error::RecvError::Lagged(_)) => {}
                    Err(broadcast::error::RecvError::Closed) => {
                        // Which one closed is not said; stop watching both (the drivers only
                        // stop at shutdown).
                        m_open = false;
                        s_open = false;
                    }
                }
            }
            drop(guard);
        });
    }

    /// After a failed command (`error`), the instrument's next answer shows it is connected.
    fn clear_device_error(&self, instrument: Instrument) {
        let slot = instrument_slot(instrument);
        let mut states = self
            .inner
            .device_states
            .lock()
            .unwrap_or_else(|p| p.into_inner());
        if states[slot].0 == "error" {
            states[slot] = (
                "connected",
                "answering again".into(),
                crate::store::now_ms(),
            );
        }
    }

    /// Counts one connection change of `instrument` for `GET /metrics` and keeps it as the
    /// instrument's state for `status`.
    fn count_transition(&self, instrument: Instrument, state: &'static str, detail: String) {
        let slot = instrument_slot(instrument);
        self.inner
            .device_states
            .lock()
            .unwrap_or_else(|p| p.into_inner())[slot] = (state, detail, crate::store::now_ms());
        *self
            .inner
            .device_transitions
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .entry((instrument.key(), state))
            .or_default() += 1;
    }

    async fn on_device_event(&self, ev: drivers::Event) {
        let (instrument, state, detail) = match ev {
            drivers::Event::Connected {
                instrument,
                identity,
            } => {
                self.record_instrument(instrument, &identity).await;
                (instrument, "connected", identity.to_string())
            }
            drivers::Event::Disconnected { instrument, reason } => {
                (instrument, "disconnected", reason)
            }
            drivers::Event::Reconnecting {
                instrument,
                attempt,
                delay,
            } => (
                instrument,
                "reconnecting",
                format!("attempt {attempt} after {} ms", delay.as_millis()),
            ),
            drivers::Event::Error { instrument, error } => (instrument, "error", error.to_string()),
            drivers::Event::Measuring { instrument, .. }
            | drivers::Event::Reading { instrument, .. } => {
                // An instrument that answers again after a failed command is connected.
                self.clear_device_error(instrument);
                return;
            }
        };
        self.count_transition(instrument, state, detail.clone());
        self.inner.events.send(Event::Device {
            device: instrument.key().to_string(),
            state: state.to_string(),
            detail,
        });
    }

    /// The provenance of a reference set or scan measured now: each instrument's last reported
    /// identity ("unknown" if it never answered) and whether it is simulated.
    pub(crate) fn provenance(&self, source: Source, detail: Option<String>) -> Provenance {
        let ids = self
            .inner
            .identities
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .clone();
        let one = |id: &Option<drivers::Identity>, simulated: bool| {
            let mut p = InstrumentProvenance::unknown();
            if let Some(id) = id {
                p.model = id.model.clone();
                p.serial = id.serial.clone();
                p.firmware = id.firmware.clone();
            }
            p.simulated = Some(simulated);
            p
        };
        let sims = &self.inner.devices.simulators;
        Provenance {
            ma_t12: one(&ids[0], sims.ma_t12.is_some()),
            sra: one(&ids[1], sims.sra.is_some()),
            source,
            source_detail: detail,
        }
    }

    async fn record_instrument(&self, instrument: Instrument, identity: &drivers::Identity) {
        {
            let mut ids = self
                .inner
                .identities
                .lock()
                .unwrap_or_else(|p| p.into_inner());
            let slot = instrument_slot(instrument);
            ids[slot] = Some(identity.clone());
        }
        let text = format!("{} firmware {}", identity.model, identity.firmware);
        if let Err(e) = self
            .inner
            .store
            .add_instrument(device_of(instrument), &identity.serial, &text)
            .await
        {
            tracing::warn!(error = %e, "cannot record the instrument");
        }
    }
}

/// Where an instrument's entry is in the per-instrument arrays of the service (identities,
/// connection states): MA-T12 first, then the SRA.
pub(crate) fn instrument_slot(instrument: Instrument) -> usize {
    match instrument {
        Instrument::MaT12 => 0,
        Instrument::Sra => 1,
    }
}

/// The longest sample or reference name accepted.
pub const MAX_NAME_CHARS: usize = 200;

/// Names end up in terminals (`brdfd scans`), file names and reports: at most
/// [`MAX_NAME_CHARS`] characters, and no control characters (an escape sequence in a sample
/// name would otherwise reach the operator's terminal).
pub fn check_name(what: &str, name: &str) -> Result<(), ServiceError> {
    let count = name.chars().count();
    if count > MAX_NAME_CHARS {
        return Err(ServiceError::BadRequest(format!(
            "the {what} has {count} characters: at most {MAX_NAME_CHARS}"
        )));
    }
    if let Some(c) = name.chars().find(|c| c.is_control()) {
        return Err(ServiceError::BadRequest(format!(
            "the {what} {:?} holds the control character U+{:04X}: names are printable text",
            name.escape_debug().to_string(),
            c as u32
        )));
    }
    Ok(())
}

/// A scan file's readings as store readings, in table order, with empty raw frames.
pub(super) fn new_readings(r: &DeviceReadings) -> Vec<NewReading<'static>> {
    geometry::GEOMETRIES
        .iter()
        .map(|g| NewReading {
            device: g.device,
            geometry: g,
            values: match g.device {
                Device::MaT12 => ReadingValues::Spectrum(r.ma_t12[g.index]),
                Device::Sra => ReadingValues::Intensity(r.sra[g.index - MA_T12_COUNT]),
            },
            raw_frame: &[],
        })
        .collect()
}
