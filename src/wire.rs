//! The HTTP API's wire contract: the request and answer body of every route, as the daemon
//! sends them and as [`crate::client::Client`] reads them back. The daemon's handlers
//! (`src/api/`) answer with these types, built from the service's and the store's records (the
//! conversions are in `src/api/answer.rs`); the command line deserialises the same types, so a
//! renamed or missing field is an error at the client, not a "?" on the terminal.
//!
//! This module holds data only, with no dependency on the server (axum, the handlers): a client
//! needs nothing else. Where a newer daemon may send a value this one does not know (a state, a
//! kind of operation, a cost function), the field is an [`Open`], which keeps the unknown text,
//! or an enum with an `Unknown` variant; unknown fields are ignored.
//!
//! An answer whose JSON is a record's own (a scan's summary, the status, the forwarding's
//! state) is that record, not a copy of it. The records that hold a value of a closed set take
//! its type as a parameter: the daemon sends them as the store and the service hold them, and
//! the aliases here read each such value as an [`Open`] (or as [`Operation`], which has its
//! `Unknown`). [`ScanView`] and [`ReferenceDetail`] take the summaries they hold as parameters
//! too, so that the daemon sends its records in them unconverted.
//!
//! | route | request | answer |
//! |---|---|---|
//! | `GET /healthz` | | [`Health`] |
//! | `GET /status` | | [`Status`] |
//! | `GET /metrics` | | Prometheus text (not JSON) |
//! | `POST /reference` | | [`ReferenceAccepted`] |
//! | `POST /scans` | [`ScanRequest`] | [`ScanAccepted`] |
//! | `GET /scans` | [`ScanQuery`] (query string) | `Vec<`[`ScanSummary`]`>` |
//! | `POST /scans/import` | a [`ScanFile`] (or an X-Rite `.xlsx`) | [`Imported`] |
//! | `GET /scans/{id}` | | [`ScanView`] |
//! | `GET /scans/{id}/export` | | [`ScanFile`] |
//! | `POST /scans/{id}/refit` | [`RefitRequest`] | [`RefitAccepted`] |
//! | `GET /scans/{id}/textures/{n}.png` | | PNG |
//! | `GET /scans/{id}/swatches` | | [`Swatches`] |
//! | `GET /scans/{id}/readings` | | `Vec<`[`BenchReading`]`>` |
//! | `GET /scans/{id}/export/{format}` | | the exchange format's file |
//! | `POST /abort` | | [`Aborted`] |
//! | `GET /fits/{id}` | | [`FitDetail`] |
//! | `POST /fits/{id}/cancel` | | [`Cancelling`] |
//! | `GET /fits/{id}/preview.png` | | PNG |
//! | `GET /events` | | server-sent [`crate::service::Event`]s |
//! | `GET /bench` | | [`Bench`] |
//! | `POST /session/ticket` | | [`Ticket`] |
//! | `GET /session` | | [`Session`] |
//! | `POST /session/logout` | | [`LoggedOut`] |
//! | `GET /`, `/app.js`, `/app.css`, `/login`, `/report.html` | | the page (HTML, CSS, JS) |
//! | every refusal | | [`ErrorBody`] |
//!
//! Times are Unix milliseconds (`*_ms`); a number that is not finite travels as `null` and is
//! an `Option` here.

use std::fmt;

use serde::{Deserialize, Serialize};

pub use crate::colour::Colorimetry;
pub use crate::cost::CostFunction;
pub use crate::fit::LabPerGeometry;
pub use crate::geometry::Device;
pub use crate::processing::SpecularStrategy;
pub use crate::scan::Scan as ScanFile;
pub use crate::service::{
    IngestStatus, ReadingShown, ReferenceInForce, RefitRequest, SimulatedStatus as Simulated,
    TimingSplit as Timings,
};
pub use crate::spectral::Spectrum;
pub use crate::sra_reading::{SpecularDeltaL, SraReading};
pub use crate::store::{
    DeltaESummary, FitRunId, FitStatus, InstrumentOrigin, InstrumentProvenance, ReadingValues,
    ReferenceId, ReferenceStatus, ScanId, ScanState, Source, TextureSummary,
};
pub use crate::sync::{Lag, SyncStatus};
pub use crate::uncertainty::Uncertainty;

/// A value of a closed set this client knows (`Known`), or the text of one a newer daemon
/// added (`Unknown`). Serialises as the value's own text either way.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(untagged)]
pub enum Open<T> {
    Known(T),
    Unknown(String),
}

impl<T> Open<T> {
    /// The known value, if it is one.
    pub fn known(&self) -> Option<&T> {
        match self {
            Open::Known(t) => Some(t),
            Open::Unknown(_) => None,
        }
    }
}

impl<T: PartialEq> Open<T> {
    /// Whether this is `value`.
    pub fn is(&self, value: T) -> bool {
        self.known() == Some(&value)
    }
}

impl Open<Device> {
    /// The device's key (`ma_t12`, `sra`) as the API sends it.
    pub fn key(&self) -> &str {
        match self {
            Open::Known(d) => d.key(),
            Open::Unknown(s) => s,
        }
    }
}

impl<T> From<T> for Open<T> {
    fn from(t: T) -> Self {
        Open::Known(t)
    }
}

impl<T: fmt::Display> fmt::Display for Open<T> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Open::Known(t) => t.fmt(f),
            Open::Unknown(s) => f.pad(s),
        }
    }
}

/// The body of every refusal: the message for people, and for refusals of the service a
/// machine-readable `kind` (see `ApiError::kind`) so that scripts can tell "busy, retry
/// later" from "refused".
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ErrorBody {
    pub error: String,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub kind: Option<String>,
}

impl ErrorBody {
    /// A refusal with a message and no kind.
    pub fn message(error: impl Into<String>) -> ErrorBody {
        ErrorBody {
            error: error.into(),
            kind: None,
        }
    }
}

/// `GET /healthz`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Health {
    pub ok: bool,
}

// ---------------------------------------------------------------------------------------------
// GET /status

/// `GET /status`: the daemon's state.
pub type Status = crate::service::Status<DeviceStatus, Operation>;

impl Status {
    /// Whether the daemon runs with its SRA turned off (`[devices.sra] transport = "off"`):
    /// references and scans on the 12 MA-T12 geometries only.
    pub fn sra_off(&self) -> bool {
        self.devices
            .iter()
            .any(|d| d.device.is(Device::Sra) && d.state.is(DeviceState::Off))
    }
}

/// What the instruments are doing: a reference or a scan.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum Operation {
    Reference {
        reference: ReferenceId,
    },
    Scan {
        scan: ScanId,
    },
    /// An operation of a newer daemon.
    #[serde(other)]
    Unknown,
}

impl fmt::Display for Operation {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Operation::Reference { reference } => write!(f, "reference {reference}"),
            Operation::Scan { scan } => write!(f, "scan {scan}"),
            Operation::Unknown => f.write_str("an operation this client does not know"),
        }
    }
}

/// The operation in progress and for how long.
pub type Busy = crate::service::BusyStatus<Operation>;

/// One instrument as `status` shows it.
pub type DeviceStatus = crate::service::DeviceStatus<Open<Device>, Open<DeviceState>>;

/// An instrument's connection state.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum DeviceState {
    /// Not heard from since start.
    #[serde(rename = "unknown")]
    NotHeardFrom,
    Connected,
    Disconnected,
    Reconnecting,
    Error,
    /// Turned off in the configuration (the SRA).
    Off,
}

impl DeviceState {
    pub const fn as_str(self) -> &'static str {
        match self {
            DeviceState::NotHeardFrom => "unknown",
            DeviceState::Connected => "connected",
            DeviceState::Disconnected => "disconnected",
            DeviceState::Reconnecting => "reconnecting",
            DeviceState::Error => "error",
            DeviceState::Off => "off",
        }
    }
}

impl fmt::Display for DeviceState {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.pad(self.as_str())
    }
}

// ---------------------------------------------------------------------------------------------
// Requests and their acknowledgements

/// `POST /reference`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct ReferenceAccepted {
    pub reference: ReferenceId,
}

/// `POST /scans` body.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ScanRequest {
    pub sample: String,
}

/// `POST /scans`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct ScanAccepted {
    pub scan: ScanId,
}

/// `GET /scans` query.
#[derive(Debug, Clone, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ScanQuery {
    pub state: Option<String>,
    pub sample: Option<String>,
    /// Only samples whose name holds this text, ignoring case.
    pub sample_contains: Option<String>,
    pub limit: Option<u32>,
    /// Only scans with a smaller id: the last id of one page gives the next.
    pub before: Option<i64>,
}

/// `POST /scans/{id}/refit`.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct RefitAccepted {
    pub fits: Vec<FitRunId>,
}

/// `POST /abort`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct Aborted {
    pub aborted: Operation,
}

/// `POST /fits/{id}/cancel`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct Cancelling {
    pub cancelling: FitRunId,
}

/// `POST /scans/import`: the scan (the first, for an `.xlsx`) and the fits queued; an
/// `.xlsx` adds every scan and each measurement's colorimetry check. A file imported before
/// (the same bytes, through any door) is not imported again unless asked (`again=true`): the
/// answer (200, not 201) names the earlier import's scans in `scan` and `scans`, queues no fit,
/// and says so in `already_imported`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Imported {
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub already_imported: Option<AlreadyImported>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub colorimetry_checks: Option<Vec<ColorimetryCheck>>,
    pub fits: Vec<FitRunId>,
    /// `null` only for an `.xlsx` without measurements.
    pub scan: Option<ScanId>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub scans: Option<Vec<ScanId>>,
}

/// In [`Imported`]: the file was imported before, and not again.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct AlreadyImported {
    /// "already imported as scan 3 on 2026-12-04T19:14:14Z from PAR_1.xlsx (the same content,
    /// SHA-256 …); nothing was imported again; add again=true to import it anyway".
    pub message: String,
    /// The earlier import's file name, when known.
    pub file_name: Option<String>,
    /// When the earlier import was made, ms since the epoch.
    pub imported_at_ms: i64,
    /// SHA-256 of the content, 64 lower-case hex digits.
    pub sha256: String,
}

/// `POST /scans/import` query: `?file=NAME&again=true`, both optional.
#[derive(Debug, Clone, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ImportQuery {
    /// The file's name (its directory is dropped), recorded with its scans and named in their
    /// provenance.
    pub file: Option<String>,
    /// Import it even if the same content was imported before.
    #[serde(default)]
    pub again: bool,
}

/// How closely brdfd's L*a*b* of one imported X-Rite measurement matches the file's.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ColorimetryCheck {
    /// The geometry of the largest difference.
    pub at: String,
    pub largest_delta_e00: f64,
    pub sample: String,
    pub scan: ScanId,
    pub warning: Option<String>,
}

// ---------------------------------------------------------------------------------------------
// Scans

/// Which instruments measured a reference set or scan, and how its readings came in.
pub type Provenance = crate::store::Provenance<Open<Source>>;

/// One element of `GET /scans`: a scan without its readings.
pub type ScanSummary = crate::store::ScanSummary<Open<ScanState>, Open<Source>>;

/// A reference set without its readings.
pub type ReferenceSummary = crate::store::ReferenceSummary<Open<ReferenceStatus>, Open<Source>>;

/// A stored reading.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Reading {
    pub id: i64,
    pub device: Open<Device>,
    pub geometry: String,
    pub values: ReadingValues,
    /// The instrument's frame, lowercase hex.
    pub raw_frame: String,
    pub at_ms: i64,
}

/// A reference set with its readings; `R` as for [`ScanView`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ReferenceDetail<R = ReferenceSummary> {
    pub reference: R,
    pub readings: Vec<Reading>,
}

/// `GET /scans/{id}`: a scan, its readings, its reference and its fits. `S` and `R` are the
/// scan's and the reference's summaries: the store's records as the daemon sends them, read
/// here as [`ScanSummary`] and [`ReferenceSummary`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ScanView<S = ScanSummary, R = ReferenceSummary> {
    pub scan: S,
    pub readings: Vec<Reading>,
    pub reference: ReferenceDetail<R>,
    /// Every fit run of the scan, oldest first.
    pub fits: Vec<FitDetail>,
    /// Hours between the reference's completion and the scan's request.
    pub reference_age_hours: f64,
    /// Whether that is over `[scan] reference_max_age_hours` (the scan is not fitted then).
    pub reference_stale: bool,
    /// The instrument camera's images kept with an imported scan.
    pub textures: Vec<TextureSummary>,
}

impl ScanView {
    /// The fits still queued or running.
    pub fn pending_fits(&self) -> Vec<FitRunId> {
        self.fits
            .iter()
            .filter(|f| f.run.status.is(FitStatus::Queued) || f.run.status.is(FitStatus::Running))
            .map(|f| f.run.id)
            .collect()
    }
}

// ---------------------------------------------------------------------------------------------
// Fits

/// What a finished fit produced.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FitResult {
    pub cost: f64,
    /// The fitted parameters (`kd` [31], `ks`, `alpha`, `ior`).
    pub params: serde_json::Value,
    pub best_cost_per_generation: Vec<Option<f64>>,
    pub evaluations: u64,
    pub generations: u32,
    pub wall_ms: f64,
}

/// A fit run.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FitRun {
    pub id: FitRunId,
    pub scan: ScanId,
    pub processed: i64,
    pub specular: Open<SpecularStrategy>,
    pub method: String,
    pub cost_function: Open<CostFunction>,
    /// Every optimiser setting, as the daemon's optimiser names them.
    pub settings: serde_json::Value,
    pub seed: u64,
    pub status: Open<FitStatus>,
    pub error: Option<String>,
    pub result: Option<FitResult>,
    pub queued_at_ms: i64,
    pub started_at_ms: Option<i64>,
    pub finished_at_ms: Option<i64>,
}

/// The colour evaluation of a fit (SCIENCE.md §7).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Evaluation {
    /// ΔE00 at each geometry, in geometry-table order; `null` where the scan has no reading.
    pub per_geometry: Vec<Option<f64>>,
    pub all: DeltaESummary,
    pub diffuse: DeltaESummary,
    /// `None` for a scan without SRA readings.
    pub specular: Option<DeltaESummary>,
}

/// `GET /fits/{id}`: a fit run and, when done, its evaluation.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FitDetail {
    pub run: FitRun,
    pub evaluation: Option<Evaluation>,
    pub colorimetry: Option<Colorimetry>,
    /// The bootstrap intervals, once computed (SCIENCE.md §10).
    pub uncertainty: Option<Uncertainty>,
    /// Leave-one-geometry-out cross-validation of the fit's configuration, once computed: each
    /// MA-T12 geometry predicted by a fit without it (SCIENCE.md §12.5). Absent from a daemon
    /// that does not compute it.
    #[serde(default)]
    pub crossval: Option<crate::crossval::CrossValidation>,
    /// The SRA reading model of the fit's cost (SCIENCE.md §5.1).
    pub sra: SraReading,
    /// Specular |ΔL*| between model and measured luminance (SCIENCE.md §7.2), for a done fit.
    pub specular_delta_l: Option<SpecularDeltaL>,
    /// Measured and fitted L*a*b* per geometry, for a done fit.
    pub lab: Option<LabPerGeometry>,
    /// Whether the material is in the model's reach, with the prediction error to expect
    /// (SCIENCE.md §12.7): derived when the fit is read, from its measured L*, its ΔE00 and
    /// its cross-validation; absent before the fit is done and from a daemon that does not
    /// derive it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub reach: Option<crate::reach::Reach>,
    /// The done fit's parameters at a bound of the range it was fitted within (`"ks"`,
    /// `"alpha"`, `"ior"`, `"kd"`), from its parameters and its settings' bounds, whether or
    /// not intervals were computed: a parameter there is not identified.
    #[serde(default)]
    pub at_bound: Vec<String>,
}

// ---------------------------------------------------------------------------------------------
// The web page's answers

/// One colour as the page shows it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Swatch {
    /// `#rrggbb`, clipped to the sRGB gamut.
    pub srgb: String,
    /// Whether the colour was outside the sRGB gamut.
    pub clipped: bool,
    /// CIELAB (D65, 2°), two decimals.
    pub lab: [f64; 3],
}

/// The latest finished fit of one cost function, as the page's result view shows it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FittedSwatches {
    pub cost_function: Open<CostFunction>,
    pub method: String,
    /// The fitted model's colour at each geometry.
    pub estimated: Vec<Swatch>,
    /// ΔE00 at each geometry; `null` at a geometry the scan did not measure.
    pub delta_e00: Vec<Option<f64>>,
    pub delta_e00_diffuse: f64,
    /// `null` without specular readings.
    pub delta_e00_specular: Option<f64>,
    pub delta_e00_all: f64,
}

/// `GET /scans/{id}/swatches`: measured and fitted colour per geometry.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Swatches {
    pub scan: ScanId,
    pub sample: String,
    /// The geometries the scan measured; every list below is in this order.
    pub geometries: Vec<String>,
    /// The tile's name, or "instrument calibration".
    pub reference: String,
    pub specular_readings: bool,
    pub measured: Vec<Swatch>,
    /// One entry per cost function with a finished fit.
    pub fits: Vec<FittedSwatches>,
}

/// One stored reading as the bench shows it (`GET /scans/{id}/readings` is a list of them):
/// the same fields as a `scan_reading` or `reference_reading` event.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct BenchReading {
    pub geometry: String,
    pub device: Open<Device>,
    #[serde(flatten)]
    pub shown: ReadingShown,
}

/// One fit of the scan on the bench.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct BenchFit {
    pub fit: FitRunId,
    pub cost_function: Open<CostFunction>,
    pub status: Open<FitStatus>,
    pub error: Option<String>,
    pub cost: Option<f64>,
    pub wall_ms: Option<f64>,
    pub delta_e00_diffuse_mean: Option<f64>,
    pub delta_e00_specular_mean: Option<f64>,
    pub delta_e00_mean: Option<f64>,
}

/// What the bench shows: a reference or a scan.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum BenchKind {
    Reference,
    Scan,
}

/// The state of a reference set or a scan on the bench.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum MeasurementState {
    Requested,
    Measuring,
    Complete,
    Failed,
    Aborted,
}

/// The reference or scan the bench shows.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct BenchOperation {
    pub kind: Open<BenchKind>,
    pub id: i64,
    /// The sample's name (for a reference, the tile's).
    pub sample: String,
    pub state: Open<MeasurementState>,
    pub reason: Option<String>,
    /// Whether the instruments are measuring it now.
    pub in_progress: bool,
    pub provenance: Provenance,
    /// The readings stored so far, in geometry-table order.
    pub readings: Vec<BenchReading>,
    /// The scan's fits, oldest first (none for a reference).
    pub fits: Vec<BenchFit>,
}

/// `GET /bench`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Bench {
    /// The operation in progress; when idle, the last scan the instruments measured.
    pub operation: Option<BenchOperation>,
}

/// `POST /session/ticket`: a one-time login link for `brdfd open`.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct Ticket {
    pub expires_in_s: u64,
    /// `/login?ticket=…`.
    pub path: String,
    pub ticket: String,
}

/// `GET /session`: whether the request carries a session; if so what the page's script
/// needs to send POSTs, else why not.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(untagged)]
pub enum Session {
    SignedIn(SignedIn),
    SignedOut(SignedOut),
}

/// A session of this daemon, from its own page.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct SignedIn {
    /// The value to send in [`SignedIn::csrf_header`] with every POST.
    pub csrf: String,
    pub csrf_header: String,
    /// When the session ends; `null` if its expiry cannot be read from the cookie.
    pub expires_at_ms: Option<u64>,
    /// `true`.
    pub signed_in: bool,
}

/// No session, and why.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct SignedOut {
    pub message: String,
    /// `false`.
    pub signed_in: bool,
}

/// `POST /session/logout`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct LoggedOut {
    pub logged_out: bool,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_unknown_state_keeps_its_text() {
        let s: Open<ScanState> = serde_json::from_str("\"paused\"").unwrap();
        assert_eq!(s, Open::Unknown("paused".into()));
        assert_eq!(s.to_string(), "paused");
        assert_eq!(serde_json::to_string(&s).unwrap(), "\"paused\"");
        let k: Open<ScanState> = serde_json::from_str("\"complete\"").unwrap();
        assert!(k.is(ScanState::Complete));
    }

    #[test]
    fn an_unknown_operation_is_read_as_unknown() {
        let op: Operation = serde_json::from_str(r#"{"kind":"calibration","id":3}"#).unwrap();
        assert_eq!(op, Operation::Unknown);
        let op: Operation = serde_json::from_str(r#"{"kind":"scan","scan":3}"#).unwrap();
        assert_eq!(op, Operation::Scan { scan: ScanId(3) });
    }

    #[test]
    fn a_missing_field_is_an_error() {
        let r = serde_json::from_str::<ReferenceInForce>(
            r#"{"id":1,"name":"N9","completed_at_ms":null,"stale":false}"#,
        );
        assert!(r.unwrap_err().to_string().contains("age_hours"));
    }

    #[test]
    fn device_states_read_back_with_their_text() {
        let s: Open<DeviceState> = serde_json::from_str("\"unknown\"").unwrap();
        assert!(s.is(DeviceState::NotHeardFrom));
        assert_eq!(s.to_string(), "unknown");
    }
}
