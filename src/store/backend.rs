//! Everything that is specific to the database backend, in one place: connection options and
//! pragmas, pool sizes, the upsert statements and the recognition of constraint violations.
//!
//! The rest of the store speaks portable SQL (`$n` placeholders, `RETURNING`, `ON CONFLICT`),
//! which SQLite and PostgreSQL both accept, and names the database only through [`Db`] and
//! [`Pool`]. Moving a lab's stations to one PostgreSQL server means: a `postgres` feature on
//! sqlx, these aliases and `open_*` functions for `PgPool`, and a PostgreSQL dialect of
//! `migrations/` (identity columns, BYTEA); the verbs stay as they are.

use std::path::Path;
use std::time::Duration;

use sqlx::sqlite::{SqliteConnectOptions, SqliteJournalMode, SqlitePoolOptions, SqliteSynchronous};

/// The database the store runs on.
pub(crate) type Db = sqlx::Sqlite;
/// A pool of connections to [`Db`].
pub(crate) type Pool = sqlx::SqlitePool;

/// How long a statement waits for a lock held by another connection (a reader checkpointing,
/// the `sqlite3` shell of an operator) before failing with "database is locked".
const BUSY_TIMEOUT: Duration = Duration::from_secs(5);

/// Readers run in their own small pool so a long listing never queues behind a write; WAL lets
/// them read while the writer writes. Two cores, a handful of HTTP clients: four is plenty.
const READERS: u32 = 4;

/// The two pools of an open store. SQLite allows one writer at a time; rather than let several
/// connections contend for the write lock (and hit `SQLITE_BUSY`), every write goes through a
/// pool of exactly one connection, so writes queue in the pool, in order.
pub(crate) struct Pools {
    pub writer: Pool,
    pub reader: Pool,
}

fn file_options(path: &Path) -> SqliteConnectOptions {
    SqliteConnectOptions::new()
        .filename(path)
        .foreign_keys(true)
        .busy_timeout(BUSY_TIMEOUT)
}

/// Opens (creating if missing) the database file at `path`.
///
/// Pragmas, and why:
/// - `journal_mode = WAL`: readers never block the writer nor the writer them, and a commit
///   appends to the log instead of rewriting pages. The mode is persistent in the file.
/// - `synchronous = NORMAL`: in WAL mode this fsyncs at checkpoints, not at every commit. A
///   committed reading survives the daemon crashing or being killed; only a power cut or OS
///   crash can lose the last commits, and never corrupts the file. That trade buys writes in
///   well under a millisecond, which matters because each reading is committed on its own as
///   it arrives (benches/store.rs measures it).
/// - `foreign_keys = ON`: SQLite leaves them off by default; the schema relies on them.
/// - `busy_timeout`: see [`BUSY_TIMEOUT`].
pub(crate) async fn open_file(path: &Path) -> Result<Pools, sqlx::Error> {
    let writer = SqlitePoolOptions::new()
        .max_connections(1)
        .min_connections(1)
        // The single writer is kept open for the life of the store.
        .idle_timeout(None)
        .max_lifetime(None)
        .connect_with(
            file_options(path)
                .create_if_missing(true)
                .journal_mode(SqliteJournalMode::Wal)
                .synchronous(SqliteSynchronous::Normal),
        )
        .await?;
    // Readers open the file only once the writer has created it and switched it to WAL.
    let reader = SqlitePoolOptions::new()
        .max_connections(READERS)
        .connect_with(file_options(path).read_only(true))
        .await?;
    Ok(Pools { writer, reader })
}

/// Opens an existing database file for reading only: no file is created, nothing is written
/// (the write-ahead log of a running daemon is read through its shared-memory index).
pub(crate) async fn open_file_read_only(path: &Path) -> Result<Pool, sqlx::Error> {
    SqlitePoolOptions::new()
        .max_connections(READERS)
        .connect_with(file_options(path).read_only(true).create_if_missing(false))
        .await
}

/// Opens a private in-memory database (tests, dry runs). One connection serves both roles: a
/// second connection would see a different, empty database.
pub(crate) async fn open_memory() -> Result<Pools, sqlx::Error> {
    let pool = SqlitePoolOptions::new()
        .max_connections(1)
        .min_connections(1)
        // Closing the only connection would drop the database.
        .idle_timeout(None)
        .max_lifetime(None)
        .connect_with(
            SqliteConnectOptions::new()
                .in_memory(true)
                .foreign_keys(true),
        )
        .await?;
    Ok(Pools {
        writer: pool.clone(),
        reader: pool,
    })
}

/// Insert an instrument or, if (device, serial) is known, refresh its identity and last-seen
/// time; returns the row id either way. `$1` device, `$2` serial, `$3` identity, `$4` now (ms).
/// (`ON CONFLICT … DO UPDATE … RETURNING` is shared by SQLite ≥ 3.35 and PostgreSQL; a backend
/// without it would need a select-then-insert here.)
pub(crate) const UPSERT_INSTRUMENT: &str = "\
    INSERT INTO instruments (device, serial, identity, first_seen_ms, last_seen_ms)
    VALUES ($1, $2, $3, $4, $4)
    ON CONFLICT (device, serial)
    DO UPDATE SET identity = excluded.identity, last_seen_ms = excluded.last_seen_ms
    RETURNING id";

/// Insert a sample by name unless it exists; returns its row id either way. `$1` name, `$2` now.
/// The no-op update makes `RETURNING` yield the existing row.
pub(crate) const UPSERT_SAMPLE: &str = "\
    INSERT INTO samples (name, created_at_ms) VALUES ($1, $2)
    ON CONFLICT (name) DO UPDATE SET name = excluded.name
    RETURNING id";

/// True when `e` is a UNIQUE (or primary-key) constraint failure.
pub(crate) fn is_unique_violation(e: &sqlx::Error) -> bool {
    matches!(e, sqlx::Error::Database(d) if d.is_unique_violation())
}

/// True when `e` is a FOREIGN KEY constraint failure (the tests check the keys are enforced).
#[cfg(test)]
pub(crate) fn is_foreign_key_violation(e: &sqlx::Error) -> bool {
    matches!(e, sqlx::Error::Database(d) if d.is_foreign_key_violation())
}

/// The statement that checks the database file's structure; yields one row `ok` when sound.
pub(crate) const INTEGRITY_CHECK: &str = "PRAGMA integrity_check";
