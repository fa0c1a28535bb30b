//! [`ServiceError`]: why the daemon refused or could not do what an operator asked. One
//! variant per answer a caller can act on; the HTTP API maps each to a status code and sends
//! the message as it is, so every message says what to do next.

use crate::processing::ProcessingError;
use crate::scan::ScanError;
use crate::store::{ReferenceId, ScanId, ScanState, StoreError};

/// Why a service request was refused or failed.
#[derive(Debug, thiserror::Error)]
pub enum ServiceError {
    /// A reference or scan is already being measured: the instruments do one thing at a time.
    #[error(
        "the instruments are busy: {operation} is in progress (started {seconds:.0} s ago); \
         wait for it to finish, or stop it with `brdfd abort`"
    )]
    Busy { operation: String, seconds: f64 },

    /// No complete reference set exists yet.
    #[error(
        "no white reference has been measured: put the Munsell N9 tile on the bench and run \
         `brdfd reference` before the first scan"
    )]
    NoReference,

    /// `abort` with nothing in progress.
    #[error("nothing to abort: no reference or scan is being measured")]
    Idle,

    /// The daemon is stopping and takes no new work.
    #[error("the daemon is shutting down and takes no new work; start it again with `brdfd serve`")]
    ShuttingDown,

    /// A scan that is not complete cannot be exported, processed or fitted.
    #[error("scan {scan} is {state}, not complete: {action} needs all 14 readings")]
    NotComplete {
        scan: ScanId,
        state: ScanState,
        action: &'static str,
    },

    /// The scan's reference is older than `[scan] reference_max_age_hours`.
    #[error(
        "scan {scan} was taken {age_hours:.1} h after its reference was measured (limit \
         {max_age_hours} h): measure a new reference and scan again, or refit with \
         --allow-stale-reference if the tile and instruments were known to be stable"
    )]
    StaleReference {
        scan: ScanId,
        /// The scan's reference set.
        reference: ReferenceId,
        age_hours: f64,
        max_age_hours: f64,
    },

    /// A request with a bad argument; the message names it.
    #[error("{0}")]
    BadRequest(String),

    /// An imported scan file is invalid; the message names the field.
    #[error("invalid scan file: {0}")]
    InvalidScan(#[from] ScanError),

    /// The scan's readings cannot be processed (e.g. a zero reference reading).
    #[error("cannot process the scan: {0}")]
    Processing(#[from] ProcessingError),

    /// A store verb failed (including "does not exist" and life-cycle refusals).
    #[error(transparent)]
    Store(#[from] StoreError),
}

impl ServiceError {
    /// Whether the error means "no such scan / fit / reference".
    pub fn is_not_found(&self) -> bool {
        matches!(self, ServiceError::Store(StoreError::NotFound { .. }))
    }
}
