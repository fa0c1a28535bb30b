//! Several stations, one lab: forwarding a station's store to the lab's central PostgreSQL
//! database (ARCHITECTURE.md "Several stations, one lab").
//!
//! Acquisition never waits on the network: every reading is committed to the station's SQLite
//! store first, as always. SQLite triggers (`migrations/0014_sync_outbox.sql`) queue every
//! insert and update of a forwarded row in `sync_outbox`, in commit order. The [`Forwarder`]
//! reads the outbox after its cursor, reads the rows it names as they are now, and upserts them
//! into the central database keyed by (station, local id), moving the station's cursor in the
//! same PostgreSQL transaction. Hence:
//! - a resend is a no-op and a row that changed state is updated, never duplicated (upserts);
//! - a crash or outage on either side at any point neither loses nor doubles a row: either the
//!   batch and its cursor committed together or neither did, and after any error the forwarder
//!   reads the cursor back from the central database before going on;
//! - the station's store is only read: the cursor lives centrally, so `brdfd sync --db FILE`
//!   forwards a stopped station's store without writing to it. The daemon alone prunes its
//!   outbox up to the acknowledged cursor.
//!
//! - [`tables`]: what is forwarded, column by column.
//! - [`central`]: the central database: connection, schema (`migrations-central/`, refused when
//!   newer than this brdfd), station registration (one store per station id).
//! - [`lineage`]: the incarnations of a store, and the check that refuses a copy of a store
//!   that went its own way (fork detection), before any of its rows is written.
//! - [`verify`]: per-row digests of the store against the central database; what is missing
//!   or different is sent again (`brdfd sync --verify`, and by itself after a central restore).
//! - [`retire`]: retiring a station's old store to an archive id, so that a copy of it (a bench
//!   moved to a new PC) takes the station id over.
//! - [`forward`]: the forwarder: batches, the loop with back-off, status (backlog, last error).
//!
//! Everything PostgreSQL-specific lives here and in `src/store/central.rs` (reading the
//! central database back for reports); the station side speaks SQLite through `src/store`.

pub mod central;
pub mod forward;
pub mod lineage;
pub mod retire;
pub mod tables;
pub mod verify;

pub use central::{CENTRAL_MIGRATOR, Central};
pub use forward::{BatchReport, Forwarder, ForwarderOptions, Lag, SyncStatus};
pub use verify::VerifyReport;

/// Why forwarding failed. Every message is one line that says what to do.
#[derive(Debug, thiserror::Error)]
pub enum SyncError {
    /// The URL is not a PostgreSQL URL sqlx understands.
    #[error(
        "the central database URL {url} is not valid: {message}; write it as \
         postgres://USER[:PASSWORD]@HOST[:PORT]/DATABASE"
    )]
    BadUrl { url: String, message: String },

    /// The server could not be reached or refused the login.
    #[error(
        "cannot connect to the central database {url}: {message}; the readings stay in the \
         local store and are forwarded once it answers"
    )]
    Connect { url: String, message: String },

    /// The central schema is newer than this brdfd.
    #[error(
        "the central database {url} has schema version {found}, newer than this brdfd knows \
         ({known}); upgrade brdfd on this station before forwarding to it"
    )]
    NewerSchema { url: String, found: i64, known: i64 },

    /// The central schema could not be brought up to date.
    #[error("cannot bring the central database {url} up to date: {message}")]
    Migrate { url: String, message: String },

    /// Another store already forwards under this station id.
    #[error(
        "station id \"{station}\" is already used by another store (registered {registered} \
         from host {host}); give this station its own id with [station] id in brdfd.toml \
         (or --station)"
    )]
    StationTaken {
        station: String,
        registered: String,
        host: String,
    },

    /// This store already forwards under another station id.
    #[error(
        "this store already forwards as station \"{existing}\"; under \"{station}\" too its \
         scans would be counted twice; keep [station] id = \"{existing}\" (or --station \
         {existing})"
    )]
    StoreHasOtherId { station: String, existing: String },

    /// This store is a copy of the station's store that went its own way after the copy, or
    /// the station went on without it (src/sync/lineage.rs): nothing of it is written.
    #[error(
        "station \"{station}\" refuses this store: {detail}; nothing of this store was sent. \
         To keep this copy as a bench of its own, stop its daemon, run `brdfd sync --db FILE \
         --adopt NEW_ID` and set [station] id = \"NEW_ID\"; to make it the station (a bench \
         moved to a new PC), stop the old one and run `brdfd sync --db FILE --retire-old \
         ARCHIVE_ID`"
    )]
    Forked { station: String, detail: String },

    /// The station's cursor is not where this forwarder left it: another forwarder of the
    /// same store moved it, or the central database was restored from a backup. The cursor is
    /// read back and forwarding goes on (after a comparison, when the central database is
    /// behind what this store deleted).
    #[error(
        "station \"{station}\"'s cursor in the central database is not at {expected} any more \
         (another `brdfd sync` of this store, or the database restored from a backup); reading \
         it back"
    )]
    CursorMoved { station: String, expected: i64 },

    /// The station's store has no outbox: written by a brdfd before forwarding existed.
    #[error(
        "the store {path} has no sync outbox (it predates brdfd's forwarding); start `brdfd \
         serve` on it once to bring its schema up to date, then sync it"
    )]
    NoOutbox { path: String },

    /// Reading the station's store failed.
    #[error("reading the station's store: {0}")]
    Local(#[source] sqlx::Error),

    /// Retiring a station's old store (`brdfd sync --retire-old`) was refused.
    #[error("cannot retire station \"{station}\": {why}")]
    Retire { station: String, why: String },

    /// The station id is the archive of a retired station's old store: nothing forwards
    /// under it.
    #[error(
        "station id \"{station}\" is the archive of station \"{from}\"'s retired store; \
         nothing forwards under it; give this station its own id with [station] id in brdfd.toml"
    )]
    Archived { station: String, from: String },

    /// A statement on the central database failed (connection lost, server stopped, …).
    #[error("the central database {url}: {message}")]
    Central { url: String, message: String },
}

impl SyncError {
    /// True for failures that retrying later can cure (the server is down, the network is),
    /// false for those a person must fix (a taken station id, a newer schema).
    pub fn is_transient(&self) -> bool {
        matches!(
            self,
            SyncError::Connect { .. }
                | SyncError::Central { .. }
                | SyncError::Local(_)
                | SyncError::CursorMoved { .. }
        )
    }
}

/// `url` with its password replaced by `***`, for messages and status.
pub fn redact(url: &str) -> String {
    let Some(scheme_end) = url.find("://") else {
        return url.to_string();
    };
    let rest = &url[scheme_end + 3..];
    let authority_end = rest.find(['/', '?']).unwrap_or(rest.len());
    let authority = &rest[..authority_end];
    match (authority.rfind('@'), authority.find(':')) {
        (Some(at), Some(colon)) if colon < at => format!(
            "{}{}:***{}",
            &url[..scheme_end + 3],
            &authority[..colon],
            &rest[at..]
        ),
        _ => url.to_string(),
    }
}

/// True when `s` names a PostgreSQL database rather than a file.
pub fn is_postgres_url(s: &str) -> bool {
    s.starts_with("postgres://") || s.starts_with("postgresql://")
}

/// The default station id: the host name.
pub fn default_station_id() -> String {
    let mut buf = [0u8; 256];
    // SAFETY: gethostname writes at most `len` bytes into the buffer it is given.
    let rc = unsafe { libc::gethostname(buf.as_mut_ptr().cast(), buf.len()) };
    if rc == 0 {
        let end = buf.iter().position(|&b| b == 0).unwrap_or(buf.len());
        if let Ok(name) = std::str::from_utf8(&buf[..end])
            && !name.is_empty()
        {
            return name.to_string();
        }
    }
    "station".to_string()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn passwords_are_redacted() {
        assert_eq!(
            redact("postgres://lab:s3cret@db.lab:5432/brdfd"),
            "postgres://lab:***@db.lab:5432/brdfd"
        );
        assert_eq!(
            redact("postgres://lab@db.lab/brdfd"),
            "postgres://lab@db.lab/brdfd"
        );
        assert_eq!(
            redact("postgres://db.lab:5432/x"),
            "postgres://db.lab:5432/x"
        );
        assert_eq!(redact("not a url"), "not a url");
    }

    #[test]
    fn urls_are_told_from_files() {
        assert!(is_postgres_url("postgres://h/db"));
        assert!(is_postgres_url("postgresql://h/db"));
        assert!(!is_postgres_url("brdfd.db"));
    }

    #[test]
    fn a_host_name_is_the_default_id() {
        assert!(!default_station_id().is_empty());
    }
}
