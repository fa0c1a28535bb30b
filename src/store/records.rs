//! What the store takes in and hands back: life-cycle states, reading values, and the records of
//! instruments, references, scans, processed scans, fit runs and evaluations.
//!
//! Timestamps are `i64` milliseconds since the Unix epoch, UTC (fields named `*_ms`), as stored.
//!
//! The records the HTTP API answers with as they are (provenance, scan and reference summaries)
//! take the types of their closed sets' values (state, status, source) as parameters: the store
//! holds each value as it is (the defaults); the API's client reads the same records with each
//! such value open to the ones a newer daemon adds (`crate::wire::Open`).

use std::fmt;
use std::str::FromStr;

use serde::{Deserialize, Serialize, Serializer};

use crate::cost::CostFunction;
use crate::geometry::{Device, GEOMETRY_COUNT, Geometry};
use crate::processing::{MeasuredBrdf, SpecularStrategy};
use crate::spectral::Spectrum;

use super::ids::{FitRunId, InstrumentId, ProcessedId, ReadingId, ReferenceId, SampleId, ScanId};

macro_rules! text_enum {
    ($(#[$doc:meta])* $name:ident { $($(#[$vdoc:meta])* $variant:ident = $text:literal),+ $(,)? }) => {
        $(#[$doc])*
        #[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, serde::Deserialize)]
        #[serde(rename_all = "snake_case")]
        pub enum $name {
            $($(#[$vdoc])* $variant),+
        }

        impl $name {
            /// The text stored in the database and shown to users.
            pub const fn as_str(self) -> &'static str {
                match self {
                    $($name::$variant => $text),+
                }
            }
        }

        impl fmt::Display for $name {
            fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
                f.write_str(self.as_str())
            }
        }

        impl FromStr for $name {
            type Err = String;

            fn from_str(s: &str) -> Result<Self, Self::Err> {
                match s {
                    $($text => Ok($name::$variant),)+
                    _ => Err(format!(concat!("unknown ", stringify!($name), " \"{}\""), s)),
                }
            }
        }
    };
}

text_enum!(
    /// Where a scan is in its life: requested → measuring → complete | failed | aborted.
    ScanState {
        /// Asked for; no device has started.
        Requested = "requested",
        /// Devices are measuring; readings arrive.
        Measuring = "measuring",
        /// All 14 readings are in.
        Complete = "complete",
        /// Stopped by an error (the reason says which); keeps its readings.
        Failed = "failed",
        /// Stopped by the operator; keeps its readings.
        Aborted = "aborted",
    }
);

text_enum!(
    /// Where a reference set is: measuring → complete | failed.
    ReferenceStatus {
        /// Readings of the tile arrive.
        Measuring = "measuring",
        /// All 14 readings are in; usable for scans.
        Complete = "complete",
        /// Abandoned (the reason says why).
        Failed = "failed",
    }
);

text_enum!(
    /// Where a fit run is: queued → running → done | failed | cancelled.
    FitStatus {
        /// Waiting for the fit worker.
        Queued = "queued",
        /// The optimiser is running.
        Running = "running",
        /// Finished; result and evaluation stored.
        Done = "done",
        /// The optimiser or the evaluation failed (the error says why).
        Failed = "failed",
        /// Cancelled before it finished.
        Cancelled = "cancelled",
    }
);

/// The value(s) of one reading, as the device reports them.
// 256 bytes against 16: kept inline (and `Copy`) rather than boxing the spectrum, since most
// readings are spectra and a box would cost an allocation each.
#[allow(clippy::large_enum_variant)]
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(untagged)]
pub enum ReadingValues {
    /// MA-T12: reflectance factor (0–1 scale) at the 31 bands, 400–700 nm.
    Spectrum(Spectrum),
    /// SRA: one achromatic 1D-BRDF intensity, in the device's unit.
    Intensity(f64),
}

impl ReadingValues {
    /// The numbers, in band order (one for an intensity).
    pub fn as_slice(&self) -> &[f64] {
        match self {
            ReadingValues::Spectrum(s) => s,
            ReadingValues::Intensity(v) => std::slice::from_ref(v),
        }
    }

    /// The kind of value each device reports, for messages.
    pub(crate) const fn kind_name(&self) -> &'static str {
        match self {
            ReadingValues::Spectrum(_) => "a 31-band spectrum",
            ReadingValues::Intensity(_) => "a single intensity",
        }
    }

    /// The kind of value `device` reports, for messages.
    pub(crate) const fn expected_kind(device: Device) -> &'static str {
        match device {
            Device::MaT12 => "a 31-band spectrum",
            Device::Sra => "a single intensity",
        }
    }
}

/// One reading to store, for [`super::Store::add_readings_tx`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NewReading<'a> {
    pub device: Device,
    pub geometry: &'static Geometry,
    pub values: ReadingValues,
    /// The device's reply frame, byte for byte.
    pub raw_frame: &'a [u8],
}

fn hex<S: Serializer>(bytes: &[u8], s: S) -> Result<S::Ok, S::Error> {
    s.serialize_str(&hex::encode(bytes))
}

/// A stored reading of a scan or of a reference set. Its instrument is its geometry's
/// ([`Reading::device`]). Serialises as `{id, device, geometry, values, raw_frame, at_ms}`, with
/// the geometry by name and the raw frame as lowercase hex.
#[derive(Debug, Clone, PartialEq)]
pub struct Reading {
    pub id: ReadingId,
    pub geometry: &'static Geometry,
    pub values: ReadingValues,
    pub raw_frame: Vec<u8>,
    /// When the store received it.
    pub at_ms: i64,
}

impl Reading {
    /// The instrument that measured it: the one its geometry belongs to.
    pub fn device(&self) -> Device {
        self.geometry.device
    }
}

impl Serialize for Reading {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        use serde::ser::SerializeStruct;
        /// The raw frame as lowercase hex.
        struct Hex<'a>(&'a [u8]);
        impl Serialize for Hex<'_> {
            fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
                hex(self.0, s)
            }
        }
        let mut st = s.serialize_struct("Reading", 6)?;
        st.serialize_field("id", &self.id)?;
        st.serialize_field("device", &self.device())?;
        st.serialize_field("geometry", self.geometry.name)?;
        st.serialize_field("values", &self.values)?;
        st.serialize_field("raw_frame", &Hex(&self.raw_frame))?;
        st.serialize_field("at_ms", &self.at_ms)?;
        st.end()
    }
}

/// A known instrument.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct Instrument {
    pub id: InstrumentId,
    pub device: Device,
    pub serial: String,
    /// The device's identification string (model, firmware), as last reported.
    pub identity: String,
    pub first_seen_ms: i64,
    pub last_seen_ms: i64,
}

/// A reference set without its readings; its status is a `Status` and its source a `Src`
/// (module docs).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ReferenceSummary<Status = ReferenceStatus, Src = Source> {
    pub id: ReferenceId,
    /// The tile, e.g. "Munsell N9".
    pub name: String,
    pub status: Status,
    /// Why it failed.
    pub reason: Option<String>,
    /// The tile's calibrated reflectance factor; `None` = 1 in every band (the paper's choice).
    pub rho_ref: Option<Spectrum>,
    /// When it was begun.
    pub taken_at_ms: i64,
    pub completed_at_ms: Option<i64>,
    /// No tile: the instrument's own white calibration (an instrument-software export; the
    /// set has no readings and the MA-T12 values are taken as they are, SCIENCE.md §3).
    pub instrument_calibration: bool,
    /// Whether the set has (or is to have) the SRA's two readings of the tile; without them it
    /// has the 12 MA-T12 geometries (a tile measured with the SRA turned off, or imported with
    /// MA-T12-only scans) and normalises scans without SRA readings only.
    pub specular_readings: bool,
    pub reading_count: usize,
    /// Which instruments measured it, and how its readings came in.
    pub provenance: Provenance<Src>,
}

/// A reference set with its readings in geometry-table order.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ReferenceDetail {
    pub reference: ReferenceSummary,
    pub readings: Vec<Reading>,
}

text_enum!(
    /// How a reference set's or scan's readings entered the store (migration 0010).
    Source {
        /// Measured by the daemon's instruments (real or simulated: see each instrument's
        /// `simulated`).
        Measured = "measured",
        /// Imported from a file (a brdfd.scan/1 file or an instrument-software export).
        Imported = "imported",
        /// `brdfd replay` / `brdfd demo`: recorded session files replayed through the daemon.
        Replay = "replay",
        /// Written before provenance was recorded.
        Unknown = "unknown",
    }
);

text_enum!(
    /// Where one instrument's readings of a scan or reference set came from: the one
    /// provenance every view (store, API, CLI, page, report, exports) shows. Derived from the
    /// stored source, simulated flag and geometries ([`InstrumentOrigin::of`]).
    InstrumentOrigin {
        /// Measured on this bench by a real instrument.
        Measured = "measured",
        /// Real readings imported from a file: an instrument-software export, or a
        /// brdfd.scan/1 file of a scan measured on real instruments.
        Imported = "imported",
        /// Produced by a simulated instrument (a replayed recording, a synthetic sample).
        Simulated = "simulated",
        /// The scan has no readings of this instrument (an export without SRA readings, a scan
        /// measured with the SRA turned off).
        Absent = "absent",
    }
);

impl InstrumentOrigin {
    /// The origin of an instrument whose simulated flag is `simulated` (`None`: not
    /// recorded), of readings that came in by `source`; `present` is false when the scan has
    /// none of its geometries. A replay is simulated whatever its flag; rows from before
    /// provenance was recorded count as measured.
    pub fn of(simulated: Option<bool>, source: Source, present: bool) -> InstrumentOrigin {
        if !present {
            return InstrumentOrigin::Absent;
        }
        match (simulated, source) {
            (Some(true), _) | (_, Source::Replay) => InstrumentOrigin::Simulated,
            (_, Source::Imported) => InstrumentOrigin::Imported,
            _ => InstrumentOrigin::Measured,
        }
    }

    /// Real readings: measured on this bench or imported from real instruments.
    pub fn real(self) -> bool {
        matches!(
            self,
            InstrumentOrigin::Measured | InstrumentOrigin::Imported
        )
    }
}

/// One instrument as it reported itself for a reference set or scan.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, serde::Deserialize)]
pub struct InstrumentProvenance {
    pub model: String,
    pub serial: String,
    pub firmware: String,
    /// A simulated instrument (a replayed recording); `None` when not known (older rows,
    /// imports whose file does not say, an absent instrument).
    pub simulated: Option<bool>,
    /// Measured, imported, simulated or absent ([`InstrumentOrigin`]).
    pub origin: InstrumentOrigin,
}

impl InstrumentProvenance {
    /// Nothing known (rows from before provenance, or an instrument that never answered).
    pub fn unknown() -> InstrumentProvenance {
        InstrumentProvenance {
            model: "unknown".into(),
            serial: "unknown".into(),
            firmware: "unknown".into(),
            simulated: None,
            origin: InstrumentOrigin::Measured,
        }
    }

    /// "MA-T12 serial 123 firmware 1.0 (simulated)", for people; "absent" for an instrument
    /// the scan has no readings of.
    pub fn describe(&self) -> String {
        let origin = match (self.origin, self.simulated) {
            (InstrumentOrigin::Absent, _) => return "absent".into(),
            (InstrumentOrigin::Simulated, _) => " (simulated)",
            (InstrumentOrigin::Imported, _) => " (imported)",
            (InstrumentOrigin::Measured, None) => " (simulated or not: not recorded)",
            (InstrumentOrigin::Measured, Some(_)) => " (measured)",
        };
        format!(
            "{} serial {} firmware {}{origin}",
            self.model, self.serial, self.firmware
        )
    }
}

/// Which instruments measured a reference set or scan, and how its readings came in; its source
/// is a `Src` (module docs).
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct Provenance<Src = Source> {
    pub ma_t12: InstrumentProvenance,
    pub sra: InstrumentProvenance,
    pub source: Src,
    /// The file imported or the sessions replayed.
    pub source_detail: Option<String>,
}

impl<Src> Provenance<Src> {
    /// Whether any instrument was simulated.
    pub fn simulated(&self) -> bool {
        [&self.ma_t12, &self.sra]
            .iter()
            .any(|i| i.origin == InstrumentOrigin::Simulated || i.simulated == Some(true))
    }

    /// Whether the readings are real: no instrument simulated, and the MA-T12's measured on
    /// this bench or imported.
    pub fn real(&self) -> bool {
        !self.simulated() && self.ma_t12.origin.real()
    }
}

impl Provenance {
    pub fn unknown() -> Provenance {
        Provenance {
            ma_t12: InstrumentProvenance::unknown(),
            sra: InstrumentProvenance::unknown(),
            source: Source::Unknown,
            source_detail: None,
        }
    }

    /// The same provenance with each instrument's `origin` derived from its simulated flag
    /// and the source ([`InstrumentOrigin::of`]); `sra_present` is false for a scan or
    /// reference set without SRA readings.
    pub fn settled(mut self, sra_present: bool) -> Provenance {
        self.ma_t12.origin = InstrumentOrigin::of(self.ma_t12.simulated, self.source, true);
        self.sra.origin = InstrumentOrigin::of(self.sra.simulated, self.source, sra_present);
        self
    }

    /// The same provenance with its source mapped by `f`.
    pub fn map_source<Src>(self, f: impl FnOnce(Source) -> Src) -> Provenance<Src> {
        Provenance {
            ma_t12: self.ma_t12,
            sra: self.sra,
            source: f(self.source),
            source_detail: self.source_detail,
        }
    }

    /// One line for people, as exports and the report carry it: whether a simulated
    /// instrument produced the readings and which recording answered ("simulated — replayed
    /// from synthetic-t-sky-blue (T.Sky blue)"), the file they were imported from, or the
    /// instruments that measured them.
    pub fn summary(&self) -> String {
        match (self.simulated(), self.source_detail.as_deref()) {
            (true, Some(d)) if d.starts_with("simulated") => d.to_string(),
            (true, Some(d)) => format!("simulated — {d}"),
            (true, None) => "simulated — replayed from a recording".into(),
            (false, Some(d)) => format!("{}: {d}", self.source),
            (false, None) if self.sra.origin == InstrumentOrigin::Absent => format!(
                "{} by {}; no SRA readings",
                self.source,
                self.ma_t12.describe()
            ),
            (false, None) => format!(
                "{} by {} and {}",
                self.source,
                self.ma_t12.describe(),
                self.sra.describe()
            ),
        }
    }
}

/// The provenance columns as a row (the same names on `reference_sets` and `scans`).
#[derive(Debug, sqlx::FromRow)]
pub(crate) struct ProvenanceRow {
    pub ma_t12_model: String,
    pub ma_t12_serial: String,
    pub ma_t12_firmware: String,
    pub ma_t12_simulated: Option<i64>,
    pub sra_model: String,
    pub sra_serial: String,
    pub sra_firmware: String,
    pub sra_simulated: Option<i64>,
    pub source: String,
    pub source_detail: Option<String>,
}

/// The provenance columns of table alias `a`, for the summaries' SELECTs: each instrument's
/// (MA-T12, then SRA) model, serial, firmware and simulated flag, then the source.
pub(crate) fn provenance_columns(a: &str) -> String {
    let instrument =
        |i: &str| ["model", "serial", "firmware", "simulated"].map(|c| format!("{a}.{i}_{c}"));
    [instrument("ma_t12"), instrument("sra")]
        .concat()
        .into_iter()
        .chain(["source", "source_detail"].map(|c| format!("{a}.{c}")))
        .collect::<Vec<_>>()
        .join(", ")
}

impl ProvenanceRow {
    /// The provenance, each instrument's origin derived (`sra_present`: the row has SRA
    /// geometries).
    pub(crate) fn into_provenance(self, sra_present: bool) -> Result<Provenance, String> {
        let flag = |v: Option<i64>| match v {
            None => Ok(None),
            Some(0) => Ok(Some(false)),
            Some(1) => Ok(Some(true)),
            Some(x) => Err(format!("simulated is {x}, not 0 or 1")),
        };
        Ok(Provenance {
            ma_t12: InstrumentProvenance {
                model: self.ma_t12_model,
                serial: self.ma_t12_serial,
                firmware: self.ma_t12_firmware,
                simulated: flag(self.ma_t12_simulated)?,
                origin: InstrumentOrigin::Measured,
            },
            sra: InstrumentProvenance {
                model: self.sra_model,
                serial: self.sra_serial,
                firmware: self.sra_firmware,
                simulated: flag(self.sra_simulated)?,
                origin: InstrumentOrigin::Measured,
            },
            source: self.source.parse()?,
            source_detail: self.source_detail,
        }
        .settled(sra_present))
    }
}

/// A scan without its readings; its state is a `State` and its source a `Src` (module docs).
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct ScanSummary<State = ScanState, Src = Source> {
    pub id: ScanId,
    pub sample_id: SampleId,
    pub sample: String,
    /// The reference set the scan is normalised by.
    pub reference_id: ReferenceId,
    pub state: State,
    /// Why it failed or was aborted.
    pub reason: Option<String>,
    pub requested_at_ms: i64,
    pub started_at_ms: Option<i64>,
    pub finished_at_ms: Option<i64>,
    pub reading_count: usize,
    /// Whether the scan has (or is to have) the SRA's two readings; without them it has the
    /// 12 MA-T12 geometries only.
    pub specular_readings: bool,
    /// Which instruments measured it, and how its readings came in.
    pub provenance: Provenance<Src>,
}

impl<State, Src> ScanSummary<State, Src> {
    /// The geometries the scan measures.
    pub fn geometries(&self) -> crate::geometry::GeometrySet {
        if self.specular_readings {
            crate::geometry::GeometrySet::ALL
        } else {
            crate::geometry::GeometrySet::MA_T12
        }
    }
}

/// A scan, its readings (geometry-table order) and its reference set.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ScanDetail {
    pub scan: ScanSummary,
    pub readings: Vec<Reading>,
    pub reference: ReferenceDetail,
}

impl ScanDetail {
    /// The one conversion from a stored scan to the scan model (`brdfd.scan/1`), used by the
    /// service's exports and fits, the demo and the study report: every geometry's reading
    /// exactly where the geometry table puts it, with the reference set's readings and name.
    /// A geometry without a reading, or with the other instrument's kind of value, is an
    /// error naming it (a store is only that way when damaged: `complete` needs all 14); the
    /// result is [`Scan::validate`]d like a scan read from a file.
    ///
    /// [`Scan::validate`]: crate::scan::Scan::validate
    pub fn to_scan(&self) -> Result<crate::scan::Scan, crate::scan::ScanError> {
        let geometries = self.scan.geometries();
        let reference = if self.reference.reference.instrument_calibration {
            None
        } else {
            // A tile measured for MA-T12-only scans has no SRA readings either.
            let reference_geometries = if self
                .reference
                .readings
                .iter()
                .any(|r| r.geometry.device == Device::Sra)
            {
                crate::geometry::GeometrySet::ALL
            } else {
                crate::geometry::GeometrySet::MA_T12
            };
            Some(crate::scan::Reference {
                name: self.reference.reference.name.clone(),
                readings: device_readings(
                    &self.reference.readings,
                    "reference.readings",
                    reference_geometries,
                )?,
            })
        };
        let scan = crate::scan::Scan {
            sample: self.scan.sample.clone(),
            reference,
            readings: device_readings(&self.readings, "readings", geometries)?,
            origin: None,
        };
        scan.validate()?;
        Ok(scan)
    }
}

/// Stored readings as the scan model holds them (see [`ScanDetail::to_scan`]).
fn device_readings(
    readings: &[Reading],
    field: &str,
    geometries: crate::geometry::GeometrySet,
) -> Result<crate::scan::DeviceReadings, crate::scan::ScanError> {
    use crate::geometry::{GEOMETRIES, MA_T12_COUNT, SRA_COUNT};
    let mut ma_t12 = [[0.0; crate::spectral::BANDS]; MA_T12_COUNT];
    let mut sra = [0.0; SRA_COUNT];
    let mut seen = [false; GEOMETRY_COUNT];
    for r in readings {
        let g = r.geometry;
        match (g.device, &r.values) {
            _ if !geometries.contains(g.index) => {
                return Err(crate::scan::ScanError::UnknownGeometry {
                    field: field.to_string(),
                    name: g.name.to_string(),
                    expected: "the 12 MA-T12 geometries (a scan without SRA readings)".into(),
                });
            }
            (Device::MaT12, ReadingValues::Spectrum(s)) => ma_t12[g.index] = *s,
            (Device::Sra, ReadingValues::Intensity(v)) => sra[g.index - MA_T12_COUNT] = *v,
            _ => {
                return Err(crate::scan::ScanError::Shape {
                    field: format!("{field}.{}", g.name),
                    message: format!(
                        "{} holds {}",
                        g.device,
                        ReadingValues::expected_kind(g.device)
                    ),
                });
            }
        }
        seen[g.index] = true;
    }
    if let Some(g) = (0..GEOMETRY_COUNT).position(|g| geometries.contains(g) && !seen[g]) {
        return Err(crate::scan::ScanError::MissingGeometry {
            field: field.to_string(),
            geometry: GEOMETRIES[g].name,
        });
    }
    Ok(crate::scan::DeviceReadings {
        ma_t12,
        sra: geometries.has_sra().then_some(sra),
    })
}

/// Which scans [`super::Store::list_scans`] returns, newest first.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ScanFilter {
    pub state: Option<ScanState>,
    pub sample: Option<String>,
    /// At most this many.
    pub limit: u32,
    /// Only scans with a smaller id (the next page after the scan with this id).
    pub before: Option<ScanId>,
}

impl Default for ScanFilter {
    fn default() -> Self {
        ScanFilter {
            state: None,
            sample: None,
            limit: 100,
            before: None,
        }
    }
}

/// A complete scan processed into measured BRDF.
#[derive(Debug, Clone, PartialEq)]
pub struct Processed {
    pub id: ProcessedId,
    pub scan: ScanId,
    pub specular: SpecularStrategy,
    /// sr⁻¹, 14 geometries × 31 bands.
    pub brdf: MeasuredBrdf,
    pub created_at_ms: i64,
}

/// A fit to queue: what the worker will run.
#[derive(Debug, Clone, PartialEq)]
pub struct NewFit {
    /// The optimiser method's name (e.g. "paper").
    pub method: String,
    pub cost_function: CostFunction,
    /// Every optimiser setting, as serde serialises them, so the fit can be re-run exactly.
    pub settings: serde_json::Value,
    pub seed: u64,
    /// The colorimetry its ΔE00 are computed with, recorded with it (migration 0020) so that
    /// the fit does not depend on the configuration when it runs.
    pub colorimetry: crate::colour::Colorimetry,
}

impl NewFit {
    /// The SRA reading model its settings ask for (key `sra.model`; the paper's flat model when
    /// absent), recorded in `fit_runs.sra` (migration 0015).
    pub fn sra_model(&self) -> Result<crate::sra_reading::SraModel, super::StoreError> {
        match self.settings.get("sra") {
            None => Ok(crate::sra_reading::SraModel::default()),
            Some(v) => serde_json::from_value::<crate::sra_reading::SraReading>(v.clone())
                .map(|r| r.model)
                .map_err(|source| super::StoreError::Json {
                    field: "fit settings: sra",
                    source,
                }),
        }
    }
}

/// What a finished fit produced.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct FitResult {
    /// Final cost under the run's cost function.
    pub cost: f64,
    /// The fitted parameters as serde serialises them (`kd` [31], `ks`, `alpha`, `ior`).
    pub params: serde_json::Value,
    pub best_cost_per_generation: Vec<f64>,
    /// Number of cost-function evaluations.
    pub evaluations: u64,
    pub generations: u32,
    /// Wall time of the fit, ms.
    pub wall_ms: f64,
}

/// A fit run with its result when done.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct FitRun {
    pub id: FitRunId,
    pub scan: ScanId,
    pub processed: ProcessedId,
    /// The specular strategy of the processed scan it fits.
    pub specular: SpecularStrategy,
    pub method: String,
    pub cost_function: CostFunction,
    pub settings: serde_json::Value,
    pub seed: u64,
    /// The colorimetry it was queued with; `None` for a fit queued before it was recorded
    /// (migration 0020), which runs with the configured one.
    pub colorimetry: Option<crate::colour::Colorimetry>,
    pub status: FitStatus,
    /// Why it failed.
    pub error: Option<String>,
    /// Set when done.
    pub result: Option<FitResult>,
    pub queued_at_ms: i64,
    pub started_at_ms: Option<i64>,
    pub finished_at_ms: Option<i64>,
}

/// Mean, median and maximum of some ΔE00 values: the evaluation's own summary.
pub use crate::evaluation::Summary as DeltaESummary;

/// The summary the store records of `values` (not empty, all finite): its mean adds them in
/// ascending order.
pub(crate) fn delta_e_summary(values: &[f64]) -> DeltaESummary {
    let mut ascending = values.to_vec();
    ascending.sort_by(f64::total_cmp);
    DeltaESummary::of(&ascending).expect("a summary of at least one value")
}

/// The colour evaluation of a fit (SCIENCE.md §7).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct EvaluationRecord {
    /// ΔE00 at each geometry, in geometry-table order.
    /// NaN at a geometry the scan did not measure (`null` in JSON).
    pub per_geometry: [f64; GEOMETRY_COUNT],
    /// Over every geometry evaluated.
    pub all: DeltaESummary,
    /// Over the 12 MA-T12 geometries.
    pub diffuse: DeltaESummary,
    /// Over the 2 SRA geometries; `None` for a scan without SRA readings.
    pub specular: Option<DeltaESummary>,
}

/// A fit run and, when done, its evaluation.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct FitDetail {
    pub run: FitRun,
    pub evaluation: Option<EvaluationRecord>,
    /// The colorimetry the evaluation was computed with (with the evaluation).
    pub colorimetry: Option<crate::colour::Colorimetry>,
    /// The bootstrap intervals, once computed (SCIENCE.md §10).
    pub uncertainty: Option<crate::uncertainty::Uncertainty>,
    /// The SRA reading model of the fit's cost, from its settings (SCIENCE.md §5.1).
    pub sra: crate::sra_reading::SraReading,
    /// Specular |ΔL*| between model and measured luminance (SCIENCE.md §7.2), for a done fit;
    /// derived from the stored processed BRDF and parameters, as the report derives it.
    pub specular_delta_l: Option<crate::sra_reading::SpecularDeltaL>,
    /// Measured and fitted L*a*b* at each geometry the scan measured and where the model misses
    /// (measured minus fitted ΔL*, ΔC*, ΔH*, ΔE00), under the fit's colorimetry, for a done fit;
    /// derived like `specular_delta_l`.
    pub lab: Option<crate::fit::LabPerGeometry>,
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The API and `brdfd show` read `device` from a reading's JSON; it comes from the geometry.
    #[test]
    fn a_reading_serialises_with_its_geometrys_device() {
        let g = crate::geometry::by_name("sra-20").unwrap();
        let r = Reading {
            id: ReadingId(7),
            geometry: g,
            values: ReadingValues::Intensity(0.5),
            raw_frame: vec![0xab, 0x01],
            at_ms: 12,
        };
        let v = serde_json::to_value(&r).unwrap();
        assert_eq!(
            v,
            serde_json::json!({"id": 7, "device": "sra", "geometry": "sra-20",
                "values": serde_json::to_value(ReadingValues::Intensity(0.5)).unwrap(),
                "raw_frame": "ab01", "at_ms": 12})
        );
        let text = serde_json::to_string(&r).unwrap();
        let keys: Vec<&str> = text.split('"').skip(1).step_by(2).take(2).collect();
        assert_eq!(keys, ["id", "device"], "field order as before");
    }

    #[test]
    fn states_round_trip_through_their_text() {
        for s in [
            ScanState::Requested,
            ScanState::Measuring,
            ScanState::Complete,
            ScanState::Failed,
            ScanState::Aborted,
        ] {
            assert_eq!(s.as_str().parse::<ScanState>().unwrap(), s);
        }
        for s in [FitStatus::Queued, FitStatus::Cancelled] {
            assert_eq!(s.to_string().parse::<FitStatus>().unwrap(), s);
        }
        assert!("done".parse::<ScanState>().is_err());
    }

    #[test]
    fn provenance_columns_list_both_instruments_then_the_source() {
        assert_eq!(
            provenance_columns("s"),
            "s.ma_t12_model, s.ma_t12_serial, s.ma_t12_firmware, s.ma_t12_simulated, \
             s.sra_model, s.sra_serial, s.sra_firmware, s.sra_simulated, s.source, \
             s.source_detail"
        );
    }

    #[test]
    fn summary_of_odd_and_even_counts() {
        let s = delta_e_summary(&[3.0, 1.0, 2.0]);
        assert_eq!((s.mean, s.median, s.max), (2.0, 2.0, 3.0));
        let s = delta_e_summary(&[4.0, 1.0]);
        assert_eq!((s.mean, s.median, s.max), (2.5, 2.5, 4.0));
    }
}
