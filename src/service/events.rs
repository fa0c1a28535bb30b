//! Progress events: what the daemon tells every subscriber (the HTTP event stream, the CLI's
//! progress bars, the logs) as a reference, a scan or a fit moves along.
//!
//! One [`tokio::sync::broadcast`] channel carries them all. A subscriber that falls more than
//! [`CAPACITY`] events behind loses the oldest (it is told how many), which suits progress: the
//! store, not the event stream, is the record. Every event is also logged through `tracing`
//! when it is sent, so the logs need no subscriber of their own.
//!
//! The same [`Event`] type reads the stream on the client (`brdfd scan`, `brdfd reference`, …
//! follow it through [`crate::client::EventStream`]): it deserialises from the JSON it
//! serialises to, and an event a newer daemon sends that this build does not know becomes
//! [`Event::Unknown`].

use serde::{Deserialize, Deserializer, Serialize};
use tokio::sync::broadcast;

use crate::cost::CostFunction;
use crate::store::{FitRunId, ReferenceId, ScanId};

/// Events kept for a slow subscriber. A scan makes ~20, a fit ~15 plus one per generation of
/// the paper GA (up to 1000): enough for a client that reads at human speed.
pub const CAPACITY: usize = 4096;

/// A stored reading as a live display shows it: when it was committed, and its colour (an
/// MA-T12 spectrum, under D65 and the 2° observer) or its intensity (an SRA reading, which is
/// achromatic).
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(default)]
pub struct ReadingShown {
    /// When the store committed the reading (Unix milliseconds).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub at_ms: Option<i64>,
    /// `#rrggbb` (clipped to the sRGB gamut) and CIELAB, of an MA-T12 spectrum.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub srgb: Option<String>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub lab: Option<[f64; 3]>,
    /// An SRA reading: its 1D-BRDF intensity in the device's unit.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub intensity: Option<f64>,
}

impl ReadingShown {
    /// What to show of a reading committed at `at_ms`.
    pub fn of(values: &crate::store::ReadingValues, at_ms: i64) -> ReadingShown {
        match values {
            crate::store::ReadingValues::Spectrum(s) => {
                let lab = crate::colour::reflectance_to_lab(s);
                let srgb = crate::colour::srgb::xyz_to_srgb8(crate::colour::reflectance_to_xyz(s));
                // Two decimals are plenty for a display and keep the event short.
                let round = |v: f64| (v * 100.0).round() / 100.0;
                ReadingShown {
                    at_ms: Some(at_ms),
                    srgb: Some(srgb.hex()),
                    lab: Some([round(lab.l), round(lab.a), round(lab.b)]),
                    intensity: None,
                }
            }
            crate::store::ReadingValues::Intensity(v) => ReadingShown {
                at_ms: Some(at_ms),
                intensity: Some(*v),
                ..ReadingShown::default()
            },
        }
    }
}

/// One thing that happened. Serialised as JSON with a `"type"` tag (the SSE event name is the
/// same tag); deserialised from the same JSON on the client.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "type", rename_all = "snake_case")]
pub enum Event {
    /// A reference measurement (the Munsell N9 tile) started.
    ReferenceStarted { reference: ReferenceId },
    /// One reference reading was stored (`k` of 14).
    ReferenceReading {
        reference: ReferenceId,
        device: String,
        geometry: String,
        k: usize,
        n: usize,
        /// What was read, for a live display (`None` when the event is not about one value).
        #[serde(flatten)]
        reading: ReadingShown,
    },
    /// The reference set is complete and in force for new scans.
    ReferenceComplete { reference: ReferenceId },
    /// The reference measurement failed; the previous reference (if any) stays in force.
    ReferenceFailed {
        reference: ReferenceId,
        reason: String,
    },
    /// A scan was requested and the instruments are starting.
    ScanStarted {
        scan: ScanId,
        sample: String,
        reference: ReferenceId,
    },
    /// One reading of a scan was stored (`k` of 14).
    ScanReading {
        scan: ScanId,
        device: String,
        geometry: String,
        k: usize,
        n: usize,
        /// What was read, for a live display (`None` when the event is not about one value).
        #[serde(flatten)]
        reading: ReadingShown,
    },
    /// All 14 readings are in; the scan is complete.
    ScanComplete { scan: ScanId },
    /// The scan failed (a device error); it keeps the readings it got.
    ScanFailed { scan: ScanId, reason: String },
    /// The scan was aborted (operator or shutdown); it keeps the readings it got.
    ScanAborted { scan: ScanId, reason: String },
    /// The scan's reference is older than the configured limit: it was not fitted.
    ReferenceStale {
        scan: ScanId,
        reference: ReferenceId,
        #[serde(deserialize_with = "f64_or_nan")]
        age_hours: f64,
        #[serde(deserialize_with = "f64_or_nan")]
        max_age_hours: f64,
    },
    /// A complete scan could not be processed into a measured BRDF: it was not fitted.
    ProcessingFailed { scan: ScanId, reason: String },
    /// A fit was queued.
    FitQueued {
        fit: FitRunId,
        scan: ScanId,
        cost_function: CostFunction,
    },
    /// The fit worker started a fit.
    FitStarted {
        fit: FitRunId,
        scan: ScanId,
        cost_function: CostFunction,
    },
    /// Progress of a running fit, once per optimiser generation.
    FitProgress {
        fit: FitRunId,
        scan: ScanId,
        generation: u32,
        generations_total: u32,
        #[serde(deserialize_with = "f64_or_nan")]
        best_cost: f64,
    },
    /// A fit finished; its result and ΔE00 are stored.
    FitDone {
        fit: FitRunId,
        scan: ScanId,
        cost_function: CostFunction,
        #[serde(deserialize_with = "f64_or_nan")]
        cost: f64,
        #[serde(deserialize_with = "f64_or_nan")]
        delta_e00_mean: f64,
        #[serde(deserialize_with = "f64_or_nan")]
        delta_e00_diffuse_mean: f64,
        /// NaN (`null` on the wire) for a scan without SRA readings.
        #[serde(deserialize_with = "f64_or_nan")]
        delta_e00_specular_mean: f64,
        #[serde(deserialize_with = "f64_or_nan")]
        wall_ms: f64,
    },
    /// A fit failed (an optimiser error or a panic inside the fit); the daemon goes on.
    FitFailed {
        fit: FitRunId,
        scan: ScanId,
        error: String,
    },
    /// A fit was cancelled.
    FitCancelled { fit: FitRunId, scan: ScanId },
    /// An instrument's driver reported a state change.
    Device {
        device: String,
        state: String,
        detail: String,
    },
    /// A file of the watch folder (`[ingest] watch`) was imported and moved to `done/`.
    FileImported {
        /// The file (an export and its SRA CSV: "NAME.cxf and NAME.sra.csv").
        file: String,
        scans: Vec<ScanId>,
        /// SHA-256 of its content.
        sha256: String,
    },
    /// A file of the watch folder was not imported: it moved to `failed/`, with the reason in
    /// `FILE.error.txt`.
    FileRejected { file: String, reason: String },
    /// The daemon is shutting down.
    ShuttingDown,
    /// On the client: an event of a newer daemon that this build does not know. The daemon
    /// never sends it.
    #[serde(other)]
    Unknown,
}

/// A number of an event as serialised: `serde_json` writes a non-finite `f64` as `null`, so a
/// `null` reads back as NaN (what was sent) instead of failing the whole event.
fn f64_or_nan<'de, D: Deserializer<'de>>(deserializer: D) -> Result<f64, D::Error> {
    Ok(Option::<f64>::deserialize(deserializer)?.unwrap_or(f64::NAN))
}

impl Event {
    /// The tag, also used as the SSE event name.
    pub fn kind(&self) -> &'static str {
        match self {
            Event::ReferenceStarted { .. } => "reference_started",
            Event::ReferenceReading { .. } => "reference_reading",
            Event::ReferenceComplete { .. } => "reference_complete",
            Event::ReferenceFailed { .. } => "reference_failed",
            Event::ScanStarted { .. } => "scan_started",
            Event::ScanReading { .. } => "scan_reading",
            Event::ScanComplete { .. } => "scan_complete",
            Event::ScanFailed { .. } => "scan_failed",
            Event::ScanAborted { .. } => "scan_aborted",
            Event::ReferenceStale { .. } => "reference_stale",
            Event::ProcessingFailed { .. } => "processing_failed",
            Event::FitQueued { .. } => "fit_queued",
            Event::FitStarted { .. } => "fit_started",
            Event::FitProgress { .. } => "fit_progress",
            Event::FitDone { .. } => "fit_done",
            Event::FitFailed { .. } => "fit_failed",
            Event::FitCancelled { .. } => "fit_cancelled",
            Event::Device { .. } => "device",
            Event::FileImported { .. } => "file_imported",
            Event::FileRejected { .. } => "file_rejected",
            Event::ShuttingDown => "shutting_down",
            Event::Unknown => "unknown",
        }
    }

    /// The scan the event is about (its `scan` field), if it has one.
    pub fn scan(&self) -> Option<ScanId> {
        match self {
            Event::ScanStarted { scan, .. }
            | Event::ScanReading { scan, .. }
            | Event::ScanComplete { scan }
            | Event::ScanFailed { scan, .. }
            | Event::ScanAborted { scan, .. }
            | Event::ReferenceStale { scan, .. }
            | Event::ProcessingFailed { scan, .. }
            | Event::FitQueued { scan, .. }
            | Event::FitStarted { scan, .. }
            | Event::FitProgress { scan, .. }
            | Event::FitDone { scan, .. }
            | Event::FitFailed { scan, .. }
            | Event::FitCancelled { scan, .. } => Some(*scan),
            Event::ReferenceStarted { .. }
            | Event::ReferenceReading { .. }
            | Event::ReferenceComplete { .. }
            | Event::ReferenceFailed { .. }
            | Event::Device { .. }
            | Event::FileImported { .. }
            | Event::FileRejected { .. }
            | Event::ShuttingDown
            | Event::Unknown => None,
        }
    }

    /// The reference the event names (its `reference` field), if it has one: a reference's
    /// own events, and a scan's start and stale reference.
    pub fn reference(&self) -> Option<ReferenceId> {
        match self {
            Event::ReferenceStarted { reference }
            | Event::ReferenceReading { reference, .. }
            | Event::ReferenceComplete { reference }
            | Event::ReferenceFailed { reference, .. }
            | Event::ScanStarted { reference, .. }
            | Event::ReferenceStale { reference, .. } => Some(*reference),
            _ => None,
        }
    }

    /// The event as one JSON object (what the SSE `data:` line carries).
    pub fn to_json(&self) -> String {
        // Every field is a plain number, string or id: serialisation cannot fail, but a
        // non-finite cost would become `null`, which is what a reader should see.
        serde_json::to_string(self).unwrap_or_else(|e| format!("{{\"error\":\"{e}\"}}"))
    }
}

/// The sending side of the event channel; cheap to clone.
#[derive(Debug, Clone)]
pub struct EventBus {
    tx: broadcast::Sender<Event>,
}

impl Default for EventBus {
    fn default() -> Self {
        EventBus::new()
    }
}

impl EventBus {
    pub fn new() -> EventBus {
        let (tx, _) = broadcast::channel(CAPACITY);
        EventBus { tx }
    }

    /// Sends `event` to every subscriber and logs it. Progress events are logged at debug
    /// level (one per generation would drown the log); failures at warn.
    pub fn send(&self, event: Event) {
        match &event {
            Event::FitProgress { .. }
            | Event::ScanReading { .. }
            | Event::ReferenceReading { .. } => {
                tracing::debug!(event = %event.to_json(), "{}", event.kind())
            }
            Event::ScanFailed { .. }
            | Event::ReferenceFailed { .. }
            | Event::FitFailed { .. }
            | Event::ReferenceStale { .. }
            | Event::ProcessingFailed { .. }
            | Event::FileRejected { .. } => {
                tracing::warn!(event = %event.to_json(), "{}", event.kind())
            }
            _ => tracing::info!(event = %event.to_json(), "{}", event.kind()),
        }
        // No subscriber is not an error.
        let _ = self.tx.send(event);
    }

    /// Events from now on.
    pub fn subscribe(&self) -> broadcast::Receiver<Event> {
        self.tx.subscribe()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn events_serialise_with_their_tag_and_fields() {
        let e = Event::ScanReading {
            scan: ScanId(4),
            device: "sra".into(),
            geometry: "sra-20".into(),
            k: 13,
            n: 14,
            reading: ReadingShown::default(),
        };
        assert_eq!(
            e.to_json(),
            r#"{"type":"scan_reading","scan":4,"device":"sra","geometry":"sra-20","k":13,"n":14}"#
        );
        assert_eq!(e.kind(), "scan_reading");
        let v: serde_json::Value = serde_json::from_str(&Event::ShuttingDown.to_json()).unwrap();
        assert_eq!(v["type"], Event::ShuttingDown.kind());
    }

    #[test]
    fn events_read_back_from_their_json() {
        let events = [
            Event::ScanReading {
                scan: ScanId(4),
                device: "sra".into(),
                geometry: "sra-20".into(),
                k: 13,
                n: 14,
                reading: ReadingShown {
                    at_ms: Some(5),
                    intensity: Some(0.25),
                    ..ReadingShown::default()
                },
            },
            Event::ScanReading {
                scan: ScanId(4),
                device: "ma_t12".into(),
                geometry: "15as15".into(),
                k: 1,
                n: 14,
                reading: ReadingShown {
                    at_ms: Some(6),
                    srgb: Some("#102030".into()),
                    lab: Some([50.0, 1.5, -2.25]),
                    intensity: None,
                },
            },
            Event::ReferenceStale {
                scan: ScanId(2),
                reference: ReferenceId(1),
                age_hours: 30.5,
                max_age_hours: 24.0,
            },
            Event::FitCancelled {
                fit: FitRunId(9),
                scan: ScanId(2),
            },
            Event::FileImported {
                file: "a.cxf".into(),
                scans: vec![ScanId(3), ScanId(4)],
                sha256: "00".into(),
            },
            Event::ShuttingDown,
        ];
        for event in events {
            let back: Event = serde_json::from_str(&event.to_json()).unwrap();
            assert_eq!(back, event);
        }
        // A non-finite number travels as null and reads back as NaN.
        let progress = Event::FitProgress {
            fit: FitRunId(1),
            scan: ScanId(1),
            generation: 3,
            generations_total: 10,
            best_cost: f64::NAN,
        };
        let Event::FitProgress { best_cost, .. } =
            serde_json::from_str(&progress.to_json()).unwrap()
        else {
            panic!("not a fit_progress event")
        };
        assert!(best_cost.is_nan());
        // A newer daemon's event is kept as unknown, not an error.
        let unknown: Event = serde_json::from_str(r#"{"type":"scan_renamed","scan":1}"#).unwrap();
        assert_eq!(unknown, Event::Unknown);
        assert_eq!(unknown.scan(), None);
    }

    #[test]
    fn events_name_their_scan_and_reference() {
        let stale = Event::ReferenceStale {
            scan: ScanId(2),
            reference: ReferenceId(1),
            age_hours: 30.0,
            max_age_hours: 24.0,
        };
        assert_eq!(stale.scan(), Some(ScanId(2)));
        assert_eq!(stale.reference(), Some(ReferenceId(1)));
        let done = Event::ReferenceComplete {
            reference: ReferenceId(5),
        };
        assert_eq!(done.scan(), None);
        assert_eq!(done.reference(), Some(ReferenceId(5)));
    }

    #[tokio::test]
    async fn every_subscriber_gets_every_event() {
        let bus = EventBus::new();
        let mut a = bus.subscribe();
        let mut b = bus.subscribe();
        bus.send(Event::ScanComplete { scan: ScanId(1) });
        assert_eq!(
            a.recv().await.unwrap(),
            Event::ScanComplete { scan: ScanId(1) }
        );
        assert_eq!(
            b.recv().await.unwrap(),
            Event::ScanComplete { scan: ScanId(1) }
        );
    }
}
