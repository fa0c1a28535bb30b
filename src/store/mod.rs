//! The store: every instrument, reference set, scan, reading, processed scan, fit run and
//! evaluation brdfd knows, in SQLite through sqlx.
//!
//! - [`Store`] is the handle (cheap to clone); its methods are the verbs, grouped by subject in
//!   `references.rs` (instruments and reference sets), `scans.rs` (scans, readings, processed
//!   scans) and `fits.rs` (fit runs and evaluations).
//! - [`ids`] holds the row-id newtypes, [`records`] what goes in and comes out, [`StoreError`]
//!   every failure. `backend.rs` holds every SQLite-specific bit (pragmas, pools, upserts).
//! - [`central`] reads the lab's central PostgreSQL database (see `src/sync/`) back into
//!   these same records, for reports across stations.
//! - The schema lives in `migrations/` (one commented step per file), embedded in the binary
//!   and applied by [`Store::open`].
//!
//! Decisions:
//! - Timestamps are INTEGER milliseconds since the Unix epoch, UTC: portable (BIGINT in
//!   PostgreSQL), ordered, and free of text-format ambiguity.
//! - Spectra and other f64 arrays are BLOBs of little-endian f64 (31 → 248 bytes): exact bit
//!   for bit by construction, compact, and BYTEA in PostgreSQL. JSON text is kept for what is
//!   read by people or varies in shape (fit settings, parameters, per-generation costs).
//! - Life-cycle rules (a scan completes only from `measuring` and only with its 14 readings, a
//!   reading only joins a `measuring` scan, …) are enforced by the verbs with conditional
//!   updates, so they hold whoever calls; the schema's CHECKs back them up.
//! - Every write goes through one connection (SQLite has one writer at a time); reads use a
//!   separate pool, which WAL lets run alongside the writer.

mod backend;
pub mod central;
mod codec;
mod error;
mod fits;
pub mod ids;
pub mod records;
mod references;
mod scans;

use std::path::Path;
use std::time::{SystemTime, UNIX_EPOCH};

use sqlx::Row;

pub use error::StoreError;
pub use ids::{FitRunId, InstrumentId, ProcessedId, ReadingId, ReferenceId, SampleId, ScanId};
pub use records::{
    DeltaESummary, EvaluationRecord, FitDetail, FitResult, FitRun, FitStatus, Instrument, NewFit,
    NewReading, Processed, Reading, ReadingValues, ReferenceDetail, ReferenceStatus,
    ReferenceSummary, ScanDetail, ScanFilter, ScanState, ScanSummary,
};

use backend::Pool;

/// The schema, from `migrations/`, embedded at compile time (`build.rs` makes Cargo rebuild
/// when a migration is added or changed).
pub static MIGRATOR: sqlx::migrate::Migrator = sqlx::migrate!();

/// A handle on the store. Clones share the same connections.
#[derive(Debug, Clone)]
pub struct Store {
    /// The one connection every write goes through (see `backend.rs`).
    writer: Pool,
    /// Connections for reads; the same pool as `writer` for an in-memory store.
    reader: Pool,
}

impl Store {
    /// Opens the database file at `path`, creating it if missing, and applies any migration it
    /// lacks. Migrations already applied are left alone (sqlx checks their checksums).
    pub async fn open(path: impl AsRef<Path>) -> Result<Store, StoreError> {
        let path = path.as_ref();
        let pools = backend::open_file(path)
            .await
            .map_err(|source| StoreError::Open {
                path: path.to_path_buf(),
                source,
            })?;
        MIGRATOR.run(&pools.writer).await?;
        Ok(Store {
            writer: pools.writer,
            reader: pools.reader,
        })
    }

    /// Opens a fresh, private in-memory store with the full schema (tests, dry runs).
    pub async fn open_in_memory() -> Result<Store, StoreError> {
        let pools = backend::open_memory()
            .await
            .map_err(|source| StoreError::Open {
                path: ":memory:".into(),
                source,
            })?;
        MIGRATOR.run(&pools.writer).await?;
        Ok(Store {
            writer: pools.writer,
            reader: pools.reader,
        })
    }

    /// Runs the database's own consistency check; returns its report lines, `["ok"]` when the
    /// file is sound.
    pub async fn integrity_check(&self) -> Result<Vec<String>, StoreError> {
        let rows = sqlx::query(backend::INTEGRITY_CHECK)
            .fetch_all(&self.writer)
            .await?;
        rows.iter()
            .map(|r| r.try_get::<String, _>(0).map_err(StoreError::from))
            .collect()
    }

    /// The writer and reader pools, for the sync forwarder (`src/sync/`), which reads the
    /// outbox and the rows it names and prunes acknowledged entries.
    pub(crate) fn sync_pools(&self) -> (&Pool, &Pool) {
        (&self.writer, &self.reader)
    }

    /// Closes every connection, waiting for queries under way. Call at shutdown: the last
    /// connection to close checkpoints the write-ahead log into the database file.
    pub async fn close(&self) {
        self.reader.close().await;
        self.writer.close().await;
    }
}

/// Now, in milliseconds since the Unix epoch (UTC).
pub(crate) fn now_ms() -> i64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map(|d| d.as_millis() as i64)
        .unwrap_or(0)
}

/// The life-cycle column (`state` or `status`) of row `id` of `table`, parsed; `NotFound`
/// naming `what` when there is no such row, `Corrupt` when the stored word is unknown.
/// `table` and `column` are always constants of this module, never outside input.
async fn lifecycle<'e, E, T>(
    ex: E,
    table: &'static str,
    column: &'static str,
    what: &'static str,
    id: i64,
) -> Result<T, StoreError>
where
    E: sqlx::Executor<'e, Database = backend::Db>,
    T: std::str::FromStr<Err = String>,
{
    let sql = format!("SELECT {column} FROM {table} WHERE id = $1");
    let word: Option<String> = sqlx::query_scalar(&sql).bind(id).fetch_optional(ex).await?;
    let word = word.ok_or(StoreError::NotFound { what, id })?;
    word.parse()
        .map_err(|detail| StoreError::Corrupt { table, id, detail })
}

#[cfg(test)]
mod tests;
