//! [`StoreError`]: every way a store verb can fail, one variant per failure a caller can act on,
//! each message naming the scan, reference, fit run, geometry or field concerned.

use std::path::PathBuf;

use crate::geometry::Device;
use crate::processing::SpecularStrategy;

use super::ids::{FitRunId, ReferenceId, ScanId};
use super::records::{FitStatus, ReferenceStatus, ScanState};

/// Why a store verb failed.
#[derive(Debug, thiserror::Error)]
pub enum StoreError {
    /// The database file could not be opened or created.
    #[error(
        "cannot open the store at {path}: {source}; check that the directory exists and that \
         the daemon's user may write to it (the [store] path setting)"
    )]
    Open {
        path: PathBuf,
        #[source]
        source: sqlx::Error,
    },

    /// The schema could not be brought up to date.
    #[error(
        "cannot bring the store's schema up to date: {0}; a file written by a newer brdfd needs \
         that version (or point [store] path at another file)"
    )]
    Migrate(#[from] sqlx::migrate::MigrateError),

    /// Another process owns the store (see `lock.rs`).
    #[error(transparent)]
    Locked(#[from] super::lock::LockError),

    /// A read-only open of a store whose schema is not this brdfd's.
    #[error(
        "the store at {path} {detail}; open it once with this version's `brdfd serve` (which \
         migrates it), or use the brdfd that wrote it"
    )]
    SchemaMismatch { path: PathBuf, detail: String },

    /// No row with that id.
    #[error("{what} {id} does not exist in the store")]
    NotFound { what: &'static str, id: i64 },

    /// A scan verb was called in a state that does not allow it.
    #[error("scan {scan} is {state}, not {expected}: cannot {action}")]
    ScanState {
        scan: ScanId,
        state: ScanState,
        expected: &'static str,
        action: &'static str,
    },

    /// `complete_scan` on a scan that does not hold a reading at each of its geometries (14,
    /// or the 12 MA-T12 ones of a scan without SRA readings).
    #[error(
        "scan {scan} holds {have} of {want} readings (missing {missing}): cannot complete it; \
         measure the missing geometries, or fail or abort the scan"
    )]
    ScanIncomplete {
        scan: ScanId,
        have: usize,
        want: usize,
        missing: String,
    },

    /// A reference verb was called in a status that does not allow it.
    #[error("reference {reference} is {status}, not {expected}: cannot {action}")]
    ReferenceState {
        reference: ReferenceId,
        status: ReferenceStatus,
        expected: &'static str,
        action: &'static str,
    },

    /// `complete_reference` on a reference set that does not hold a reading at each of its
    /// geometries (14, or the 12 MA-T12 ones of a tile measured with the SRA turned off).
    #[error(
        "reference {reference} holds {have} of {want} readings (missing {missing}): cannot \
         complete it; measure the missing geometries on the reference tile"
    )]
    ReferenceIncomplete {
        reference: ReferenceId,
        have: usize,
        want: usize,
        missing: String,
    },

    /// An SRA reading for a scan or reference set that measures the 12 MA-T12 geometries only.
    #[error(
        "{owner} measures the 12 MA-T12 geometries only (the SRA was turned off when it was \
         started): it takes no reading at {geometry}"
    )]
    GeometryNotMeasured {
        owner: String,
        geometry: &'static str,
    },

    /// A texture image handed in that is not a PNG file.
    #[error("{what} is not a PNG file: the export's image is damaged; export the file again")]
    NotPng { what: String },

    /// A scan with SRA readings asked for against a reference set measured without the SRA.
    #[error(
        "reference {reference} was measured without the SRA (12 MA-T12 geometries), so it \
         cannot normalise a scan with SRA readings: measure the reference tile again \
         (`brdfd reference`) with the SRA connected"
    )]
    ReferenceWithoutSpecular { reference: ReferenceId },

    /// A fit verb was called in a status that does not allow it.
    #[error("fit run {fit} is {status}, not {expected}: cannot {action}")]
    FitState {
        fit: FitRunId,
        status: FitStatus,
        expected: &'static str,
        action: &'static str,
    },

    /// A second reading at a geometry that already has one.
    #[error("{owner} already holds a reading at {geometry}: each geometry is measured once")]
    DuplicateReading {
        owner: String,
        geometry: &'static str,
    },

    /// A geometry name that is not one of SCIENCE.md §2.
    #[error("unknown geometry \"{0}\": expected one of the 14 names of the geometry table")]
    UnknownGeometry(String),

    /// A reading handed in for a geometry of the other instrument.
    #[error(
        "geometry {geometry} is measured by the {expected}, not the {device}: check the \
         driver's geometry mapping"
    )]
    WrongDevice {
        geometry: &'static str,
        expected: Device,
        device: Device,
    },

    /// A spectrum for an SRA geometry or an intensity for an MA-T12 one.
    #[error("a reading at {geometry} ({device}) is {expected}, got {got}")]
    WrongValueKind {
        geometry: &'static str,
        device: Device,
        expected: &'static str,
        got: &'static str,
    },

    /// A NaN or infinite number.
    #[error("{owner}: {what} is {value}, not a finite number; the data is corrupt, re-measure")]
    NonFinite {
        owner: String,
        what: String,
        value: f64,
    },

    /// A reference reading or calibration value that is zero or negative (SCIENCE.md §3: the
    /// sample is divided by it).
    #[error(
        "{owner}: {what} is {value}; a reference value must be positive: clean the tile, check \
         the instrument and re-measure"
    )]
    NonPositiveReference {
        owner: String,
        what: String,
        value: f64,
    },

    /// A required text is empty.
    #[error("{field} must not be empty")]
    Empty { field: &'static str },

    /// The scan was already processed under this specular strategy.
    #[error("scan {scan} is already processed with specular strategy {specular}")]
    AlreadyProcessed {
        scan: ScanId,
        specular: SpecularStrategy,
    },

    /// A stored row that the store cannot read back.
    #[error(
        "{table} row {id} cannot be read: {detail}; the file was changed outside brdfd, \
         restore it from a backup"
    )]
    Corrupt {
        table: &'static str,
        id: i64,
        detail: String,
    },

    /// A JSON value that could not be serialised.
    #[error("cannot store {field} as JSON: {source}")]
    Json {
        field: &'static str,
        #[source]
        source: serde_json::Error,
    },

    /// Any other database failure (disk full, I/O error, file locked past the busy timeout).
    #[error("store query failed: {0}")]
    Database(#[from] sqlx::Error),
}
