//! What every part of the service shares, and nothing else: the store, the event bus, the
//! settings, the timings, the import budget, and the stop signal with its task tracking.
//!
//! Each part (`acquisition.rs`, `orchestrator.rs`, `pipeline.rs`, `fit_worker.rs`,
//! `ingest.rs`, `forwarder.rs`) holds a clone of one [`Context`] beside the handles and state
//! that are its own; a clone is a handful of reference counts. State one part owns never goes
//! in here.

use std::future::Future;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use crate::store::Store;

use super::events::{Event, EventBus};
use super::import_budget::ImportBudget;
use super::shutdown::{Coordinator, Shutdown, TaskGuard};
use super::{ServiceError, ServiceSettings, Timings};

/// The handles every part of the service uses (module docs).
#[derive(Clone)]
pub(super) struct Context {
    pub(super) store: Store,
    pub(super) events: EventBus,
    pub(super) settings: Arc<ServiceSettings>,
    pub(super) timings: Arc<Timings>,
    /// The import bodies held in memory at once, across every door.
    pub(super) import_budget: ImportBudget,
    /// Set at shutdown, before the stop signal: fits break off at their next generation and are
    /// left `running` for the next start to queue again; new requests are refused. An atomic
    /// (not the stop signal) because the fits read it on blocking threads, once a generation.
    stopping: Arc<AtomicBool>,
    /// A tokio mutex: `stop` holds it across the wait for the tasks to end.
    coordinator: Arc<tokio::sync::Mutex<Coordinator>>,
}

impl Context {
    pub(super) fn new(store: Store, settings: ServiceSettings) -> Context {
        Context {
            import_budget: ImportBudget::new(settings.max_held_import_bytes),
            store,
            events: EventBus::new(),
            settings: Arc::new(settings),
            timings: Arc::new(Timings::default()),
            stopping: Arc::new(AtomicBool::new(false)),
            coordinator: Arc::new(tokio::sync::Mutex::new(Coordinator::new())),
        }
    }

    /// Runs a store call, adding its time to the store timing.
    pub(super) async fn timed_store<T>(&self, fut: impl Future<Output = T>) -> T {
        let t = Instant::now();
        let out = fut.await;
        Timings::add(&self.timings.store_ns, t.elapsed());
        out
    }

    /// A guard and a stop listener for a new task, or `ShuttingDown`.
    pub(super) async fn task_slot(&self) -> Result<(TaskGuard, Shutdown), ServiceError> {
        if self.is_stopping() {
            return Err(ServiceError::ShuttingDown);
        }
        let c = self.coordinator.lock().await;
        let guard = c.guard().ok_or(ServiceError::ShuttingDown)?;
        Ok((guard, c.listener()))
    }

    /// Whether shutdown has begun.
    pub(super) fn is_stopping(&self) -> bool {
        self.stopping.load(Ordering::SeqCst)
    }

    /// The stopping flag itself, for work on blocking threads that polls it.
    pub(super) fn stop_flag(&self) -> Arc<AtomicBool> {
        self.stopping.clone()
    }

    /// Begins shutdown (the flag, then the event, then the stop signal) and waits up to
    /// `grace` for every task to end; whether they all did.
    pub(super) async fn stop(&self, grace: Duration) -> bool {
        self.stopping.store(true, Ordering::SeqCst);
        self.events.send(Event::ShuttingDown);
        self.coordinator.lock().await.stop(grace).await
    }
}
