//! Acquisition: the instruments and what the service knows about them.
//!
//! [`Acquisition`] owns, and alone changes:
//! - the instruments' driver handles ([`Devices`]);
//! - the busy claim: one reference or scan at a time, with its abort signal ([`BusyClaim`]);
//! - the reference in force for new scans;
//! - each instrument's last identity and connection state (for `status`, `GET /metrics` and
//!   the provenance of every reference set and scan).
//!
//! The measurement runs (`orchestrator.rs`) claim the instruments through
//! [`Acquisition::claim`]; the device watcher below ([`Acquisition::watch_devices`]) keeps the
//! identities and states up to date from the drivers' events. Nothing else in the service
//! reaches into this state.

use std::collections::BTreeMap;
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::Instant;

use drivers::Instrument;
use serde::{Deserialize, Serialize};
use tokio::sync::{Notify, broadcast};

use crate::store::{
    InstrumentOrigin, InstrumentProvenance, Provenance, ReferenceId, ScanId, Source, now_ms,
};

use super::context::Context;
use super::events::Event;
use super::{Devices, ServiceError};

/// A poisoned lock still holds consistent data here (every critical section is one
/// assignment), so it is used as it is.
fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    m.lock().unwrap_or_else(|p| p.into_inner())
}

/// Where an instrument's entry is in the per-instrument arrays (identities, connection
/// states): MA-T12 first, then the SRA.
fn instrument_slot(instrument: Instrument) -> usize {
    match instrument {
        Instrument::MaT12 => 0,
        Instrument::Sra => 1,
    }
}

/// What the instruments are doing.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum Operation {
    Reference { reference: ReferenceId },
    Scan { scan: ScanId },
}

impl std::fmt::Display for Operation {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Operation::Reference { reference } => write!(f, "reference {reference}"),
            Operation::Scan { scan } => write!(f, "scan {scan}"),
        }
    }
}

/// `status`'s view of the operation in progress: `Op` is the operation ([`Operation`] here;
/// the API's client reads it open to operations a newer daemon adds).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct BusyStatus<Op = Operation> {
    pub operation: Op,
    pub seconds: f64,
}

/// One instrument as `status` shows it. `Dev` and `State` are how it holds its device and its
/// state: their text here; the API's client reads them open to values a newer daemon adds.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DeviceStatus<Dev = &'static str, State = &'static str> {
    /// `ma_t12` or `sra`.
    pub device: Dev,
    /// The instrument's name for people.
    pub instrument: String,
    /// `unknown` (not heard from since start), `connected`, `disconnected`, `reconnecting`,
    /// `error`, or `off` (the SRA turned off in the configuration).
    pub state: State,
    /// What the driver said with the state (identity, reason, attempt).
    pub detail: String,
    /// When the state began (Unix milliseconds).
    pub since_ms: i64,
    pub simulated: bool,
    /// As the instrument last identified itself; `None` if it never answered.
    pub model: Option<String>,
    pub serial: Option<String>,
    pub firmware: Option<String>,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct SimulatedStatus {
    pub ma_t12: bool,
    pub sra: bool,
}

/// The operation in progress and how to stop it.
#[derive(Debug)]
struct Busy {
    operation: Operation,
    since: Instant,
    /// Notified by [`Acquisition::abort`].
    abort: Arc<Notify>,
}

impl Busy {
    fn refusal(&self) -> ServiceError {
        ServiceError::Busy {
            operation: self.operation.to_string(),
            seconds: self.since.elapsed().as_secs_f64(),
        }
    }
}

/// The instruments claimed by one operation ([`Acquisition::claim`]); dropping it frees them.
/// It dereferences to the operation's abort signal.
pub(crate) struct BusyClaim {
    busy: Arc<Mutex<Option<Busy>>>,
    abort: Arc<Notify>,
}

impl std::ops::Deref for BusyClaim {
    type Target = Notify;
    fn deref(&self) -> &Notify {
        &self.abort
    }
}

impl std::fmt::Debug for BusyClaim {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("BusyClaim").finish_non_exhaustive()
    }
}

impl Drop for BusyClaim {
    fn drop(&mut self) {
        *lock(&self.busy) = None;
    }
}

/// An instrument's connection state: state, what the driver said, since (Unix ms).
type ConnectionState = (&'static str, String, i64);

/// The instruments and the service's knowledge of them (module docs).
pub(crate) struct Acquisition {
    /// The store (the instrument table) and the events the device watcher writes to.
    ctx: Context,
    devices: Devices,
    busy: Arc<Mutex<Option<Busy>>>,
    /// The reference new scans use: the last one this daemon (or a previous run) measured.
    /// Imported references (which come with their scans) never take its place.
    reference: Mutex<Option<ReferenceId>>,
    /// Each instrument's identity as it last reported it (MA-T12, SRA), copied onto every
    /// reference set and scan as its provenance.
    identities: Mutex<[Option<drivers::Identity>; 2]>,
    /// Each instrument's last connection state (MA-T12, SRA).
    states: Mutex<[ConnectionState; 2]>,
    /// How often each instrument changed connection state: (instrument, state) → count.
    transitions: Mutex<BTreeMap<(&'static str, &'static str), u64>>,
}

impl Acquisition {
    /// The instruments, idle, with `reference` in force (the newest measured one in the store).
    pub(super) fn new(
        ctx: Context,
        devices: Devices,
        reference: Option<ReferenceId>,
    ) -> Acquisition {
        Acquisition {
            ctx,
            devices,
            busy: Arc::new(Mutex::new(None)),
            reference: Mutex::new(reference),
            identities: Mutex::new([None, None]),
            states: Mutex::new(
                [0, 1].map(|_| ("unknown", "not heard from yet".to_string(), now_ms())),
            ),
            transitions: Mutex::new(BTreeMap::new()),
        }
    }

    pub(crate) fn devices(&self) -> &Devices {
        &self.devices
    }

    /// Claims the instruments for `operation`, or says who has them. The claim holds until the
    /// returned guard is dropped — at the end of the operation's task, or when that task
    /// panics or is cancelled — so the instruments can never stay "busy" with nobody using them.
    pub(crate) fn claim(&self, operation: Operation) -> Result<BusyClaim, ServiceError> {
        let mut busy = lock(&self.busy);
        if let Some(b) = busy.as_ref() {
            return Err(b.refusal());
        }
        let abort = Arc::new(Notify::new());
        *busy = Some(Busy {
            operation,
            since: Instant::now(),
            abort: abort.clone(),
        });
        Ok(BusyClaim {
            busy: self.busy.clone(),
            abort,
        })
    }

    /// Fails with `Busy` if the instruments are in use (checked before writing anything).
    pub(crate) fn check_idle(&self) -> Result<(), ServiceError> {
        match lock(&self.busy).as_ref() {
            Some(b) => Err(b.refusal()),
            None => Ok(()),
        }
    }

    /// What the instruments are doing now.
    pub(crate) fn current_operation(&self) -> Option<Operation> {
        lock(&self.busy).as_ref().map(|b| b.operation)
    }

    /// The operation in progress and how long it has run.
    pub(crate) fn busy_status(&self) -> Option<BusyStatus> {
        lock(&self.busy).as_ref().map(|b| BusyStatus {
            operation: b.operation,
            seconds: b.since.elapsed().as_secs_f64(),
        })
    }

    /// Signals the claimant of the instruments to stop; returns what it is doing.
    pub(crate) fn abort(&self) -> Result<Operation, ServiceError> {
        match lock(&self.busy).as_ref() {
            Some(b) => {
                b.abort.notify_one();
                Ok(b.operation)
            }
            None => Err(ServiceError::Idle),
        }
    }

    /// Sends ABORT to both instruments without waiting for the answers.
    pub(crate) fn abort_devices(&self) {
        for h in self.devices.handles() {
            let h = h.clone();
            tokio::spawn(async move {
                if let Err(e) = h.abort().await {
                    tracing::debug!(error = %e, "abort");
                }
            });
        }
    }

    /// The reference new scans are normalised by.
    pub(crate) fn reference_in_force(&self) -> Option<ReferenceId> {
        *lock(&self.reference)
    }

    /// A reference set just measured to completion takes over for new scans.
    pub(crate) fn put_in_force(&self, reference: ReferenceId) {
        *lock(&self.reference) = Some(reference);
    }

    /// Whether each instrument is simulated.
    pub(crate) fn simulated(&self) -> SimulatedStatus {
        let sims = &self.devices.simulators;
        SimulatedStatus {
            ma_t12: sims.ma_t12.is_some(),
            sra: sims.sra.is_some(),
        }
    }

    /// Each instrument's connection state and identity, MA-T12 first.
    pub(crate) fn device_statuses(&self) -> Vec<DeviceStatus> {
        let states = lock(&self.states).clone();
        let ids = lock(&self.identities).clone();
        let simulated = self.simulated();
        let simulated = [simulated.ma_t12, simulated.sra];
        [Instrument::MaT12, Instrument::Sra]
            .into_iter()
            .enumerate()
            .map(|(i, instrument)| {
                let (state, detail, since_ms) = if self.devices.handle(instrument).is_none() {
                    (
                        "off",
                        "turned off ([devices.sra] transport = \"off\"): scans have the 12 \
                         MA-T12 geometries only"
                            .to_string(),
                        states[i].2,
                    )
                } else {
                    states[i].clone()
                };
                let id = ids[i].as_ref();
                DeviceStatus {
                    device: instrument.key(),
                    instrument: instrument.to_string(),
                    state,
                    detail,
                    since_ms,
                    simulated: simulated[i],
                    model: id.map(|i| i.model.clone()),
                    serial: id.map(|i| i.serial.clone()),
                    firmware: id.map(|i| i.firmware.clone()),
                }
            })
            .collect()
    }

    /// How often each instrument has changed to each connection state since start.
    pub(crate) fn device_transitions(&self) -> Vec<((&'static str, &'static str), u64)> {
        lock(&self.transitions)
            .iter()
            .map(|(k, v)| (*k, *v))
            .collect()
    }

    /// The provenance of a reference set or scan measured now: each instrument's last reported
    /// identity ("unknown" if it never answered) and whether it is simulated.
    pub(crate) fn provenance(&self, source: Source, detail: Option<String>) -> Provenance {
        let ids = lock(&self.identities).clone();
        let one = |id: &Option<drivers::Identity>, simulated: bool| {
            let mut p = InstrumentProvenance::unknown();
            if let Some(id) = id {
                p.model = id.model.clone();
                p.serial = id.serial.clone();
                p.firmware = id.firmware.clone();
            }
            p.simulated = Some(simulated);
            p.origin = if simulated {
                InstrumentOrigin::Simulated
            } else {
                InstrumentOrigin::Measured
            };
            p
        };
        let simulated = self.simulated();
        Provenance {
            ma_t12: one(&ids[0], simulated.ma_t12),
            sra: one(&ids[1], simulated.sra),
            source,
            source_detail: detail,
        }
    }

    /// Keeps `identity` as the instrument's, for the provenance of what it measures next.
    fn note_identity(&self, instrument: Instrument, identity: &drivers::Identity) {
        lock(&self.identities)[instrument_slot(instrument)] = Some(identity.clone());
    }

    /// After a failed command (`error`), the instrument's next answer shows it is connected.
    fn clear_error(&self, instrument: Instrument) {
        let mut states = lock(&self.states);
        let slot = &mut states[instrument_slot(instrument)];
        if slot.0 == "error" {
            *slot = ("connected", "answering again".into(), now_ms());
        }
    }

    /// Counts one connection change of `instrument` for `GET /metrics` and keeps it as the
    /// instrument's state for `status`.
    fn count_transition(&self, instrument: Instrument, state: &'static str, detail: String) {
        lock(&self.states)[instrument_slot(instrument)] = (state, detail, now_ms());
        *lock(&self.transitions)
            .entry((instrument.key(), state))
            .or_default() += 1;
    }

    /// Records the instruments' identities and reports their connection changes as events,
    /// until shutdown.
    pub(super) async fn watch_devices(self: &Arc<Self>) {
        let Ok((guard, mut stop)) = self.ctx.task_slot().await else {
            return;
        };
        let acquisition = self.clone();
        let devices = self.devices();
        let mut rx_m = devices.ma_t12.subscribe();
        let mut rx_s = devices.sra.as_ref().map(|h| h.subscribe());
        tokio::spawn(async move {
            // The drivers connected before anyone subscribed: ask who is there.
            let devices = acquisition.devices();
            for h in devices.handles().cloned() {
                let s = acquisition.clone();
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
            let (mut m_open, mut s_open) = (true, rx_s.is_some());
            while m_open || s_open {
                let ev = tokio::select! {
                    ev = rx_m.recv(), if m_open => ev,
                    ev = super::devices::recv_if_present(&mut rx_s), if s_open => ev,
                    _ = stop.recv() => break,
                };
                match ev {
                    Ok(ev) => acquisition.on_device_event(ev).await,
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
            // A command cut short by the operator's abort is no fault of the instrument: it
            // stays connected (its answer to ABORT says so).
            drivers::Event::Error {
                error: drivers::DriverError::Aborted { .. },
                ..
            } => return,
            drivers::Event::Error { instrument, error } => (instrument, "error", error.to_string()),
            drivers::Event::Measuring { instrument, .. }
            | drivers::Event::Reading { instrument, .. } => {
                // An instrument that answers again after a failed command is connected.
                self.clear_error(instrument);
                return;
            }
        };
        self.count_transition(instrument, state, detail.clone());
        self.ctx.events.send(Event::Device {
            device: instrument.key().to_string(),
            state: state.to_string(),
            detail,
        });
    }

    /// Keeps the instrument's identity and records it in the store's instrument table.
    async fn record_instrument(&self, instrument: Instrument, identity: &drivers::Identity) {
        self.note_identity(instrument, identity);
        let text = format!("{} firmware {}", identity.model, identity.firmware);
        if let Err(e) = self
            .ctx
            .store
            .add_instrument(instrument.into(), &identity.serial, &text)
            .await
        {
            tracing::warn!(error = %e, "cannot record the instrument");
        }
    }
}
