//! The store: every instrument, reference set, scan, reading, processed scan, fit run and
//! evaluation brdfd knows, in SQLite through sqlx.
//!
//! - [`Store`] is the handle (cheap to clone); its methods are the verbs, grouped by subject in
//!   `references.rs` (instruments and reference sets), `scans.rs` (scans, readings, processed
//!   scans) and `fits.rs` (fit runs and evaluations).
//! - [`ids`] holds the row-id newtypes, [`records`] what goes in and comes out, [`StoreError`]
//!   every failure. `backend.rs` holds every SQLite-specific bit (pragmas, pools, upserts).
//! - `ingest.rs` holds the watch folder's verbs: a dropped file's scans and its content hash
//!   in one transaction (`[ingest] watch`).
//! - `lineage.rs` records each opening for writing as a new incarnation of the store, which
//!   the sync's fork check reads (`src/sync/lineage.rs`).
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
mod guarded;
pub mod ids;
mod ingest;
mod lineage;
pub mod lock;
pub mod records;
mod references;
mod scans;
mod textures;

use std::path::Path;
use std::sync::{Arc, Mutex};
use std::time::{SystemTime, UNIX_EPOCH};

use sqlx::Row;

pub use error::StoreError;
pub use ids::{FitRunId, InstrumentId, ProcessedId, ReadingId, ReferenceId, SampleId, ScanId};
pub use ingest::{FileImport, ImportFile, IngestedFile, PriorImport, ScansImport};
pub use lineage::begin_incarnation;
pub use lock::{LockError, StoreLock};
pub use records::{
    DeltaESummary, EvaluationRecord, FitDetail, FitResult, FitRun, FitStatus, Instrument,
    InstrumentOrigin, InstrumentProvenance, NewFit, NewReading, Processed, Provenance, Reading,
    ReadingValues, ReferenceDetail, ReferenceStatus, ReferenceSummary, ScanDetail, ScanFilter,
    ScanState, ScanSummary, Source,
};
pub use scans::ImportedScan;
pub use textures::{NewTexture, TextureSummary};

use backend::Pool;

/// The schema, from `migrations/`, embedded at compile time (`build.rs` makes Cargo rebuild
/// when a migration is added or changed).
pub static MIGRATOR: sqlx::migrate::Migrator = sqlx::migrate!();

/// Applied migrations whose file was later reworded without changing what it does (its
/// comments only): the version and the SHA-384 checksum that stores recorded when they applied
/// the earlier wording. sqlx refuses a store whose recorded checksum differs from the embedded
/// file's, so [`adopt_reworded_migrations`] moves such a store to the current checksum first.
/// Only a comment may ever be reworded this way; a change to what a step does is a new step.
const REWORDED_MIGRATIONS: &[(i64, &str)] = &[(
    15,
    "78e8e5f8fbfb9ce3c9af1e21f0be8af5a9397c1c4d44ec608f60ae099862bd1510a990cdba274afeca6547fbc04726ea",
)];

/// Records the current checksum of each [`REWORDED_MIGRATIONS`] step in a store that applied
/// its earlier wording, so that [`MIGRATOR`] accepts the store. A step recorded with any other
/// checksum is left alone (sqlx then refuses the store, as it should).
async fn adopt_reworded_migrations(pool: &Pool) -> Result<(), StoreError> {
    let has_table: i64 = sqlx::query_scalar(
        "SELECT count(*) FROM sqlite_master WHERE type = 'table' AND name = '_sqlx_migrations'",
    )
    .fetch_one(pool)
    .await?;
    if has_table == 0 {
        return Ok(());
    }
    for (version, earlier) in REWORDED_MIGRATIONS {
        let Some(current) = MIGRATOR.iter().find(|m| m.version == *version) else {
            continue;
        };
        let earlier = hex::decode(earlier).expect("a checksum in hex");
        sqlx::query("UPDATE _sqlx_migrations SET checksum = ? WHERE version = ? AND checksum = ?")
            .bind(current.checksum.as_ref())
            .bind(version)
            .bind(earlier)
            .execute(pool)
            .await?;
    }
    Ok(())
}

/// A handle on the store. Clones share the same connections.
#[derive(Debug, Clone)]
pub struct Store {
    /// The one connection every write goes through (see `backend.rs`).
    writer: Pool,
    /// Connections for reads; the same pool as `writer` for an in-memory store.
    reader: Pool,
    /// The store's owner lock, held until [`Store::close`] (none for in-memory and read-only
    /// stores). A std mutex: it is only touched at open, close and [`Store::describe_owner`].
    lock: Arc<Mutex<Option<StoreLock>>>,
}

impl Store {
    /// Opens the database file at `path` as its one owner: takes the store's lock (refused at
    /// once if another process or handle holds it, naming the holder), creates the file if
    /// missing, and applies any migration it lacks. Migrations already applied are left alone
    /// (sqlx checks their checksums).
    pub async fn open(path: impl AsRef<Path>) -> Result<Store, StoreError> {
        let path = path.as_ref();
        let lock = StoreLock::acquire(path, "brdfd").map_err(|e| match e {
            // A directory that is missing or not writable: the same advice as for the file.
            LockError::Io { source, .. } => StoreError::Open {
                path: path.to_path_buf(),
                source: sqlx::Error::Io(source),
            },
            held => StoreError::Locked(held),
        })?;
        // Created private (SQLite gives -wal and -shm the same mode); nothing brdfd writes
        // elsewhere may land on these files.
        crate::safe_fs::protect_store(path);
        crate::safe_fs::prepare_private_file(path).map_err(|source| StoreError::Open {
            path: path.to_path_buf(),
            source: sqlx::Error::Io(source),
        })?;
        let pools = backend::open_file(path)
            .await
            .map_err(|source| StoreError::Open {
                path: path.to_path_buf(),
                source,
            })?;
        adopt_reworded_migrations(&pools.writer).await?;
        MIGRATOR.run(&pools.writer).await?;
        // A writer opened it: a new incarnation of the store (lineage.rs).
        lineage::begin_incarnation(&pools.writer, lineage::file_id(path).as_deref()).await?;
        Ok(Store {
            writer: pools.writer,
            reader: pools.reader,
            lock: Arc::new(Mutex::new(Some(lock))),
        })
    }

    /// Opens an existing database file read-only, for reports and exports while a daemon runs:
    /// no lock, no migration, no write possible. Refused when the file's schema is not exactly
    /// this brdfd's (older: it must be migrated by its owner first; newer: this brdfd cannot
    /// read it).
    pub async fn open_read_only(path: impl AsRef<Path>) -> Result<Store, StoreError> {
        let path = path.as_ref();
        crate::safe_fs::protect_store(path);
        let pool = backend::open_file_read_only(path)
            .await
            .map_err(|source| StoreError::Open {
                path: path.to_path_buf(),
                source,
            })?;
        let applied: Vec<i64> = sqlx::query_scalar(
            "SELECT version FROM _sqlx_migrations WHERE success ORDER BY version",
        )
        .fetch_all(&pool)
        .await
        .map_err(|e| StoreError::SchemaMismatch {
            path: path.to_path_buf(),
            detail: format!("has no brdfd schema ({e})"),
        })?;
        let ours: Vec<i64> = MIGRATOR.iter().map(|m| m.version).collect();
        if applied != ours {
            let newer = applied.iter().any(|v| !ours.contains(v));
            let detail = if newer {
                format!(
                    "was written by a newer brdfd (schema steps {applied:?}, this one knows {ours:?})"
                )
            } else {
                format!(
                    "has an older schema (steps {applied:?} of {ours:?}) and a read-only open cannot migrate it"
                )
            };
            return Err(StoreError::SchemaMismatch {
                path: path.to_path_buf(),
                detail,
            });
        }
        Ok(Store {
            writer: pool.clone(),
            reader: pool,
            lock: Arc::new(Mutex::new(None)),
        })
    }

    /// Says in the lock file what owns the store (e.g. "brdfd serve on http://…"), for the
    /// message a second owner gets.
    pub fn describe_owner(&self, what: &str) {
        if let Some(lock) = self.lock.lock().unwrap_or_else(|p| p.into_inner()).as_mut()
            && let Err(e) = lock.describe(what)
        {
            tracing::warn!(error = %e, file = %lock.path().display(), "cannot write the store's lock file");
        }
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
            lock: Arc::new(Mutex::new(None)),
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

    /// Closes every connection, waiting for queries under way. Call at shutdown: the
    /// write-ahead log is checkpointed into the database file first.
    pub async fn close(&self) {
        // A clean end of this incarnation (lineage.rs); a store already closed has nothing
        // to mark.
        if !self.writer.is_closed()
            && let Err(e) = lineage::end_incarnation(&self.writer).await
        {
            tracing::debug!(error = %e, "marking the store's incarnation closed");
        }
        self.reader.close().await;
        // The write-ahead log folded into the database file now, while this handle still
        // holds the writer: the file alone is then the whole store (a copy of it made once
        // the daemon stopped is complete), whatever order the connections end in. A
        // read-only or in-memory store has nothing to fold.
        if !self.writer.is_closed()
            && let Err(e) = sqlx::query("PRAGMA wal_checkpoint(TRUNCATE)")
                .execute(&self.writer)
                .await
        {
            tracing::debug!(error = %e, "checkpointing the store at close");
        }
        self.writer.close().await;
        // Only now may another owner open it.
        self.lock.lock().unwrap_or_else(|p| p.into_inner()).take();
    }
}

/// What [`Store::metric_counts`] counts.
#[derive(Debug, Clone, PartialEq)]
pub struct MetricCounts {
    /// (state, scans).
    pub scans: Vec<(String, i64)>,
    /// (status, cost function, fit runs, summed wall time in ms of those that recorded one).
    pub fits: Vec<(String, String, i64, Option<f64>)>,
    pub readings: i64,
}

impl Store {
    /// Records which instruments measured scan `scan` and how its readings came in.
    pub async fn set_scan_provenance(
        &self,
        scan: ScanId,
        provenance: &Provenance,
    ) -> Result<(), StoreError> {
        self.set_provenance("scans", ScanId::WHAT, scan.0, provenance)
            .await
    }

    /// Records which instruments measured reference set `reference`.
    pub async fn set_reference_provenance(
        &self,
        reference: ReferenceId,
        provenance: &Provenance,
    ) -> Result<(), StoreError> {
        self.set_provenance("reference_sets", ReferenceId::WHAT, reference.0, provenance)
            .await
    }

    /// How many rows `table` holds: one of the store's own tables (tests, `brdfd doctor`).
    pub async fn count_rows(&self, table: &str) -> Result<i64, StoreError> {
        const TABLES: [&str; 10] = [
            "instruments",
            "reference_sets",
            "reference_readings",
            "samples",
            "scans",
            "readings",
            "processed",
            "fit_runs",
            "evaluations",
            "evaluation_summaries",
        ];
        let Some(table) = TABLES.iter().find(|t| **t == table) else {
            return Err(StoreError::NotFound {
                what: "table",
                id: -1,
            });
        };
        Ok(sqlx::query_scalar(&format!("SELECT COUNT(*) FROM {table}"))
            .fetch_one(&self.reader)
            .await?)
    }

    /// The counts `GET /metrics` reports: scans by state, fit runs by status with the wall time
    /// of the finished ones, and stored readings.
    pub async fn metric_counts(&self) -> Result<MetricCounts, StoreError> {
        let scans: Vec<(String, i64)> =
            sqlx::query_as("SELECT state, COUNT(*) FROM scans GROUP BY state ORDER BY state")
                .fetch_all(&self.reader)
                .await?;
        let fits: Vec<(String, String, i64, Option<f64>)> = sqlx::query_as(
            "SELECT status, cost_function, COUNT(*), SUM(CAST(wall_ms AS REAL))
             FROM fit_runs GROUP BY status, cost_function ORDER BY status, cost_function",
        )
        .fetch_all(&self.reader)
        .await?;
        let readings: i64 = sqlx::query_scalar("SELECT COUNT(*) FROM readings")
            .fetch_one(&self.reader)
            .await?;
        Ok(MetricCounts {
            scans,
            fits,
            readings,
        })
    }

    async fn set_provenance(
        &self,
        table: &'static str,
        what: &'static str,
        id: i64,
        p: &Provenance,
    ) -> Result<(), StoreError> {
        write_provenance(&self.writer, table, what, id, p).await
    }
}

/// Sets the provenance columns of row `id` of `table` (`scans` or `reference_sets`) through
/// `ex` (the writer, or a transaction). `table` is always a constant of this module, never
/// outside input.
pub(crate) async fn write_provenance<'e, E>(
    ex: E,
    table: &'static str,
    what: &'static str,
    id: i64,
    p: &Provenance,
) -> Result<(), StoreError>
where
    E: sqlx::Executor<'e, Database = backend::Db>,
{
    {
        let flag = |s: Option<bool>| s.map(i64::from);
        let sql = format!(
            "UPDATE {table} SET ma_t12_model = $2, ma_t12_serial = $3, ma_t12_firmware = $4,
                 ma_t12_simulated = $5, sra_model = $6, sra_serial = $7, sra_firmware = $8,
                 sra_simulated = $9, source = $10, source_detail = $11
             WHERE id = $1"
        );
        let done = sqlx::query(&sql)
            .bind(id)
            .bind(&p.ma_t12.model)
            .bind(&p.ma_t12.serial)
            .bind(&p.ma_t12.firmware)
            .bind(flag(p.ma_t12.simulated))
            .bind(&p.sra.model)
            .bind(&p.sra.serial)
            .bind(&p.sra.firmware)
            .bind(flag(p.sra.simulated))
            .bind(p.source.as_str())
            .bind(p.source_detail.as_deref())
            .execute(ex)
            .await?;
        if done.rows_affected() == 0 {
            return Err(StoreError::NotFound { what, id });
        }
        Ok(())
    }
}

/// Now, in milliseconds since the Unix epoch (UTC): the one clock of the store, the service and
/// every timestamp brdfd writes.
pub fn now_ms() -> i64 {
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
