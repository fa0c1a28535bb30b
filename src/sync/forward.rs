//! The forwarder: a station's outbox → the central database, one batch per transaction.
//!
//! One step: read up to `batch` outbox entries after the cursor and the rows they name, in one
//! SQLite read transaction (a consistent snapshot: the rows are at least as new as the
//! entries); upsert the rows table by table, parents first, and compare-and-set the station's
//! cursor, in one PostgreSQL transaction. A row named several times in a batch is sent once,
//! as it is now. After any error the cursor is read back from the central database (a COMMIT
//! whose acknowledgement was lost may or may not have happened), then the step is retried with
//! back-off (0.5 s doubling to 30 s, cut short when the server answers again); acquisition never waits on any of it.
//!
//! The daemon's forwarder also deletes the entries the central database has acknowledged
//! (`sync_outbox.seq <= cursor`), through the store's single writer; `brdfd sync --db FILE`
//! opens the file read-only and leaves it as it is.

use std::collections::HashSet;
use std::path::Path;
use std::sync::{Arc, Mutex};
use std::time::Duration;

use serde::{Deserialize, Serialize};
use sqlx::sqlite::{SqliteConnectOptions, SqlitePoolOptions};
use sqlx::{QueryBuilder, Row, SqlitePool};

use super::central::{Central, one_line};
use super::lineage;
use super::tables::{Kind, TABLES, Table, tables_for};
use super::{SyncError, redact};
use crate::store::Store;

/// How a forwarder runs.
#[derive(Debug, Clone, PartialEq)]
pub struct ForwarderOptions {
    /// This station's id, recorded on every row it forwards.
    pub station: String,
    /// The central database, `postgres://…`.
    pub url: String,
    /// Outbox entries per batch (one PostgreSQL transaction).
    pub batch: usize,
    /// How often an idle forwarder looks for new entries.
    pub poll: Duration,
    /// Longest wait between retries after an error.
    pub max_backoff: Duration,
}

impl ForwarderOptions {
    pub fn new(station: impl Into<String>, url: impl Into<String>) -> ForwarderOptions {
        ForwarderOptions {
            station: station.into(),
            url: url.into(),
            batch: 500,
            poll: Duration::from_millis(100),
            max_backoff: Duration::from_secs(30),
        }
    }
}

/// What `brdfd status` shows of forwarding.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SyncStatus {
    pub station: String,
    /// The central database, password removed.
    pub central: String,
    /// Whether the last attempt reached the central database.
    pub connected: bool,
    /// Outbox entries not yet acknowledged by the central database.
    pub backlog: i64,
    /// The last outbox entry the central database acknowledged.
    pub cursor: Option<i64>,
    /// Rows forwarded since start-up.
    pub rows_forwarded: u64,
    pub last_forwarded_ms: Option<i64>,
    /// The last failure, until the next success.
    pub last_error: Option<String>,
    pub last_error_ms: Option<i64>,
    /// True while the central database refuses this store for the station (a copy of the
    /// station's store that went its own way: `last_error` says how to adopt it).
    pub refused: bool,
    /// The last `--verify` comparison with the central database, in one line.
    pub last_verify: Option<String>,
    pub last_verify_ms: Option<i64>,
    /// How long the last [`LAG_WINDOW`] forwarded outbox entries took from their local commit
    /// to the central commit (none forwarded yet: `None`; also when a daemon's status leaves it
    /// out).
    #[serde(default)]
    pub lag: Option<Lag>,
}

/// Outbox entries the lag of [`SyncStatus::lag`] is taken over: the most recent ones.
pub const LAG_WINDOW: usize = 1000;

/// The lag from a row's local commit to its central commit (ms, the station's clock for both
/// ends), over the most recent forwarded outbox entries. An entry queued during an outage
/// counts the outage: this is what a scientist querying the central database waits for.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Lag {
    pub entries: usize,
    pub p50_ms: f64,
    pub p99_ms: f64,
    pub max_ms: f64,
}

impl Lag {
    /// The summary of `lags` (ms), `None` when empty.
    pub fn of(lags: impl IntoIterator<Item = i64>) -> Option<Lag> {
        let mut xs: Vec<f64> = lags.into_iter().map(|l| l.max(0) as f64).collect();
        if xs.is_empty() {
            return None;
        }
        let max = xs.iter().copied().fold(0.0, f64::max);
        Some(Lag {
            entries: xs.len(),
            p50_ms: crate::uncertainty::quantile(&mut xs, 0.50),
            p99_ms: crate::uncertainty::quantile(&mut xs, 0.99),
            max_ms: max,
        })
    }
}

/// What one batch did.
#[derive(Debug, Clone, PartialEq)]
pub struct BatchReport {
    /// Outbox entries covered.
    pub entries: usize,
    /// Rows upserted, per table (tables with none left out), in upsert order.
    pub rows: Vec<(&'static str, usize)>,
    /// The cursor after the batch.
    pub cursor: i64,
    /// Per entry, ms from its local commit to the central commit of its batch.
    pub lags_ms: Vec<i64>,
}

impl BatchReport {
    pub fn total_rows(&self) -> usize {
        self.rows.iter().map(|(_, n)| n).sum()
    }
}

impl std::fmt::Display for BatchReport {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let parts: Vec<String> = self.rows.iter().map(|(t, n)| format!("{n} {t}")).collect();
        write!(
            f,
            "sent {} rows ({}) for {} outbox entries; cursor {}",
            self.total_rows(),
            parts.join(", "),
            self.entries,
            self.cursor
        )
    }
}

/// A column value on its way from SQLite to PostgreSQL.
#[derive(Debug, Clone, PartialEq)]
pub(super) enum Value {
    Int(Option<i64>),
    Text(Option<String>),
    Blob(Option<Vec<u8>>),
    Real(Option<f64>),
}

struct Entry {
    seq: i64,
    table_name: String,
    row_id: i64,
    at_ms: i64,
}

/// Forwards one station's store.
pub struct Forwarder {
    pub(super) options: ForwarderOptions,
    /// Read connections on the station's store.
    pub(super) source: SqlitePool,
    /// The store's writer, to prune acknowledged entries (the daemon only).
    pruner: Option<SqlitePool>,
    /// The store's `sync_identity.uid`.
    pub(super) uid: String,
    pub(super) central: Option<Central>,
    /// The central cursor, when known to be current.
    pub(super) cursor: Option<i64>,
    /// The last cursor the central database acknowledged (kept across errors, for the
    /// backlog).
    acknowledged: i64,
    /// The central database is behind entries this store already deleted (it was restored
    /// from a backup): compare and re-send ([`Forwarder::verify`]) before the next batch.
    pub(super) needs_verify: bool,
    /// The comparisons the forwarder ran by itself (`needs_verify`) since the caller last took
    /// them ([`Forwarder::take_automatic_verifies`]): a one-shot sync prints them.
    automatic_verifies: Vec<crate::sync::verify::VerifyReport>,
    /// When an idle forwarder last looked at the central cursor.
    last_look: std::time::Instant,
    /// The last refusal recorded in the central database, so a retry does not repeat it.
    last_refusal: Option<String>,
    /// The lags of the last [`LAG_WINDOW`] forwarded entries, oldest first.
    recent_lags: std::collections::VecDeque<i64>,
    pub(super) status: Arc<Mutex<SyncStatus>>,
}

impl std::fmt::Debug for Forwarder {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Forwarder")
            .field("station", &self.options.station)
            .field("central", &redact(&self.options.url))
            .finish_non_exhaustive()
    }
}

/// One read-only connection to the store file at `path`, waiting up to 5 s on its writer.
async fn open_read_only(path: &Path) -> Result<SqlitePool, SyncError> {
    SqlitePoolOptions::new()
        .max_connections(1)
        .connect_with(
            SqliteConnectOptions::new()
                .filename(path)
                .read_only(true)
                .busy_timeout(Duration::from_secs(5)),
        )
        .await
        .map_err(SyncError::Local)
}

async fn store_uid(pool: &SqlitePool, path: &str) -> Result<String, SyncError> {
    let has: i64 = sqlx::query_scalar(
        "SELECT COUNT(*) FROM sqlite_master WHERE type = 'table' AND name = 'sync_outbox'",
    )
    .fetch_one(pool)
    .await
    .map_err(SyncError::Local)?;
    if has == 0 {
        return Err(SyncError::NoOutbox {
            path: path.to_string(),
        });
    }
    sqlx::query_scalar("SELECT uid FROM sync_identity")
        .fetch_one(pool)
        .await
        .map_err(SyncError::Local)
}

impl Forwarder {
    fn new(
        options: ForwarderOptions,
        source: SqlitePool,
        pruner: Option<SqlitePool>,
        uid: String,
    ) -> Forwarder {
        let status = SyncStatus {
            station: options.station.clone(),
            central: redact(&options.url),
            connected: false,
            backlog: 0,
            cursor: None,
            rows_forwarded: 0,
            last_forwarded_ms: None,
            last_error: None,
            last_error_ms: None,
            refused: false,
            last_verify: None,
            last_verify_ms: None,
            lag: None,
        };
        Forwarder {
            options,
            source,
            pruner,
            uid,
            central: None,
            cursor: None,
            acknowledged: 0,
            needs_verify: false,
            automatic_verifies: Vec::new(),
            last_look: std::time::Instant::now(),
            last_refusal: None,
            recent_lags: std::collections::VecDeque::with_capacity(LAG_WINDOW),
            status: Arc::new(Mutex::new(status)),
        }
    }

    /// The daemon's forwarder for its open store: reads through the store's readers, prunes
    /// through its writer.
    pub async fn for_store(
        store: &Store,
        options: ForwarderOptions,
    ) -> Result<Forwarder, SyncError> {
        let (writer, reader) = store.sync_pools();
        let uid = store_uid(reader, "(the daemon's store)").await?;
        let f = Forwarder::new(options, reader.clone(), Some(writer.clone()), uid);
        f.refresh_backlog().await;
        Ok(f)
    }

    /// A forwarder for a stopped station's store file, opened read-only.
    pub async fn for_file(path: &Path, options: ForwarderOptions) -> Result<Forwarder, SyncError> {
        if !path.exists() {
            return Err(SyncError::Local(sqlx::Error::Configuration(
                format!("no store at {}", path.display()).into(),
            )));
        }
        let pool = open_read_only(path).await?;
        let uid = store_uid(&pool, &path.display().to_string()).await?;
        let f = Forwarder::new(options, pool, None, uid);
        f.refresh_backlog().await;
        Ok(f)
    }

    /// The store's current incarnation (the last of its lineage).
    async fn incarnation(&self) -> Option<String> {
        lineage::read(&self.source)
            .await
            .ok()
            .and_then(|l| l.last().map(|i| i.id.clone()))
    }

    /// Compares the store with the central database (and re-sends what it lacks) before the
    /// next batch: `brdfd sync --verify` without `--once`.
    pub fn request_verify(&mut self) {
        self.needs_verify = true;
    }

    /// The status, shared: it changes as the forwarder runs.
    /// The comparisons this forwarder ran by itself since the last call (the central database
    /// was behind what the store had pruned), oldest first.
    pub fn take_automatic_verifies(&mut self) -> Vec<crate::sync::verify::VerifyReport> {
        std::mem::take(&mut self.automatic_verifies)
    }

    pub fn status(&self) -> Arc<Mutex<SyncStatus>> {
        self.status.clone()
    }

    /// The central database, once connected.
    pub fn central(&self) -> Option<&Central> {
        self.central.as_ref()
    }

    pub(super) fn set_status(&self, f: impl FnOnce(&mut SyncStatus)) {
        let mut s = self.status.lock().unwrap_or_else(|p| p.into_inner());
        f(&mut s);
    }

    /// Counts the entries after the last acknowledged cursor (all of them before the first
    /// contact) into the status.
    async fn refresh_backlog(&self) {
        let after = self.cursor.unwrap_or(self.acknowledged);
        if let Ok(n) =
            sqlx::query_scalar::<_, i64>("SELECT COUNT(*) FROM sync_outbox WHERE seq > $1")
                .bind(after)
                .fetch_one(&self.source)
                .await
        {
            self.set_status(|s| s.backlog = n);
        }
    }

    /// Connects (once), migrates the central schema and registers the station; reads the
    /// cursor back when it is not known to be current.
    ///
    /// On every (re)connection it also checks the store's standing: a copy of the station's
    /// store that went its own way is refused at once, before it has anything to send
    /// (src/sync/lineage.rs), and a central database that is behind entries this store
    /// already deleted (restored from a backup) is compared and caught up before the next
    /// batch ([`Forwarder::verify`]).
    pub(super) async fn ensure_ready(&mut self) -> Result<(), SyncError> {
        if self.central.is_none() {
            let central = Central::connect_and_migrate(&self.options.url).await?;
            self.central = Some(central);
            self.cursor = None;
        }
        if self.cursor.is_some() {
            return Ok(());
        }
        let central = self.central.as_ref().expect("connected above");
        // Registering again is a no-op, and brings back a station a restored central
        // database lost.
        central.register(&self.options.station, &self.uid).await?;
        let standing = central.standing(&self.options.station).await?;
        let cursor = standing.cursor;
        let (highest, lineage, deleted) = {
            let mut c = self.source.begin().await.map_err(SyncError::Local)?;
            let highest = highest_seq(&mut c).await.map_err(SyncError::Local)?;
            let lineage = lineage::read(&mut *c).await.map_err(SyncError::Local)?;
            let deleted = deleted_up_to(&mut c, highest)
                .await
                .map_err(SyncError::Local)?;
            c.commit().await.map_err(SyncError::Local)?;
            (highest, lineage, deleted)
        };
        let verdict = lineage::decide(
            &self.options.station,
            &standing,
            &self.uid,
            &lineage,
            highest,
            deleted,
        )?;
        if verdict == lineage::Verdict::CentralBehind {
            self.needs_verify = true;
        }
        // Only a store the station accepts counts the central cursor as its own.
        self.acknowledged = cursor;
        self.cursor = Some(cursor);
        Ok(())
    }

    /// Forwards one batch; `None` when the outbox holds nothing after the cursor.
    pub async fn step(&mut self) -> Result<Option<BatchReport>, SyncError> {
        let result = self.try_step().await;
        match &result {
            Ok(report) => {
                let rows = report.as_ref().map(|r| r.total_rows() as u64).unwrap_or(0);
                let cursor = self.cursor;
                let lag = match report {
                    Some(r) if !r.lags_ms.is_empty() => {
                        for &l in &r.lags_ms {
                            if self.recent_lags.len() == LAG_WINDOW {
                                self.recent_lags.pop_front();
                            }
                            self.recent_lags.push_back(l);
                        }
                        Lag::of(self.recent_lags.iter().copied())
                    }
                    _ => None,
                };
                self.set_status(|s| {
                    if lag.is_some() {
                        s.lag = lag;
                    }
                    s.connected = true;
                    s.refused = false;
                    s.cursor = cursor;
                    s.last_error = None;
                    s.last_error_ms = None;
                    if rows > 0 {
                        s.rows_forwarded += rows;
                        s.last_forwarded_ms = Some(crate::store::now_ms());
                    }
                });
            }
            Err(e) => {
                // The COMMIT may or may not have happened: read the cursor back next time.
                self.cursor = None;
                let refused = matches!(e, SyncError::Forked { .. });
                let recorded = matches!(e, SyncError::Forked { .. });
                if recorded && self.last_refusal.as_deref() != Some(&e.to_string()) {
                    if let Some(c) = &self.central {
                        let incarnation = lineage::read(&self.source)
                            .await
                            .ok()
                            .and_then(|l| l.last().map(|i| i.id.clone()))
                            .unwrap_or_default();
                        c.record_refusal(
                            &self.options.station,
                            &self.uid,
                            &incarnation,
                            &e.to_string(),
                        )
                        .await;
                    }
                    self.last_refusal = Some(e.to_string());
                }
                if !e.is_transient() {
                    // A person must act (taken id, newer schema): connect afresh next time.
                    self.central = None;
                }
                let message = e.to_string();
                self.set_status(|s| {
                    s.connected = false;
                    s.refused = refused;
                    s.last_error = Some(message);
                    s.last_error_ms = Some(crate::store::now_ms());
                });
            }
        }
        self.refresh_backlog().await;
        result
    }

    async fn try_step(&mut self) -> Result<Option<BatchReport>, SyncError> {
        self.ensure_ready().await?;
        if self.needs_verify {
            let report = self.verify().await?;
            if report.resent() > 0 || report.extra() > 0 {
                tracing::warn!(
                    station = %self.options.station,
                    "compared the store with the central database (restored from a backup?): \
                     {report}"
                );
            } else {
                tracing::info!(station = %self.options.station, "compared the store with the central database: {report}");
            }
            self.automatic_verifies.push(report);
        }
        let cursor = self.cursor.expect("ensure_ready sets it");
        let Batch {
            entries,
            rows,
            high,
            lineage,
        } = self.read_batch(cursor).await?;
        let Some(last) = entries.last() else {
            // Idle: look now and then whether the central database still has the cursor
            // where this forwarder left it (a database restored from a backup, another
            // forwarder); if not, read it back (and compare) at the next step.
            if self.last_look.elapsed() >= LOOK {
                self.last_look = std::time::Instant::now();
                let central = self.central.as_ref().expect("ensure_ready connects");
                let standing = central.standing(&self.options.station).await?;
                if standing.cursor != cursor {
                    self.cursor = None;
                } else if standing.incarnation.is_some()
                    && standing.incarnation.as_deref() == self.incarnation().await.as_deref()
                {
                    // Last seen (information only: no decision rests on it).
                    central.heartbeat(&self.options.station).await?;
                }
            }
            return Ok(None);
        };
        let new_cursor = last.seq;
        let central = self.central.as_ref().expect("ensure_ready connects");
        let mut tx = central.pool.begin().await.map_err(|e| central.error(e))?;
        // Before any row: is this store still the station's (src/sync/lineage.rs)?
        let incarnation = lock_station(
            &mut tx,
            central,
            &self.options.station,
            &self.uid,
            cursor,
            &lineage,
            high,
        )
        .await?;
        let head = lineage::chain_head(&self.uid, &lineage, high);
        let mut counts = Vec::new();
        for (table, table_rows) in &rows {
            if table_rows.is_empty() {
                continue;
            }
            upsert(&mut tx, &self.options.station, table, table_rows)
                .await
                .map_err(|e| central.error(e))?;
            counts.push((table.name, table_rows.len()));
        }
        advance_station(
            &mut tx,
            central,
            &self.options.station,
            new_cursor,
            high,
            &head,
            &incarnation,
        )
        .await?;
        tx.commit().await.map_err(|e| central.error(e))?;
        let now = crate::store::now_ms();
        self.cursor = Some(new_cursor);
        self.acknowledged = new_cursor;
        if let Some(writer) = &self.pruner {
            // Losing this delete costs nothing but space: the entries are below the cursor.
            if let Err(e) = sqlx::query("DELETE FROM sync_outbox WHERE seq <= $1")
                .bind(new_cursor)
                .execute(writer)
                .await
            {
                tracing::debug!(error = %e, "pruning the sync outbox");
            }
        }
        Ok(Some(BatchReport {
            entries: entries.len(),
            rows: counts,
            cursor: new_cursor,
            lags_ms: entries.iter().map(|e| now - e.at_ms).collect(),
        }))
    }

    /// The entries after `cursor` and the rows they name, from one snapshot of the store.
    async fn read_batch(&self, cursor: i64) -> Result<Batch, SyncError> {
        let mut tx = self.source.begin().await.map_err(SyncError::Local)?;
        let high = highest_seq(&mut tx).await.map_err(SyncError::Local)?;
        let lineage = lineage::read(&mut *tx).await.map_err(SyncError::Local)?;
        let entries: Vec<Entry> = sqlx::query(
            "SELECT seq, table_name, row_id, at_ms FROM sync_outbox
             WHERE seq > $1 ORDER BY seq LIMIT $2",
        )
        .bind(cursor)
        .bind(self.options.batch as i64)
        .fetch_all(&mut *tx)
        .await
        .map_err(SyncError::Local)?
        .into_iter()
        .map(|r| Entry {
            seq: r.get(0),
            table_name: r.get(1),
            row_id: r.get(2),
            at_ms: r.get(3),
        })
        .collect();
        let mut out = Vec::new();
        for table in &TABLES {
            let mut seen = HashSet::new();
            let ids: Vec<i64> = entries
                .iter()
                .filter(|e| {
                    tables_for(&e.table_name)
                        .iter()
                        .any(|t| t.name == table.name)
                })
                .map(|e| e.row_id)
                .filter(|id| seen.insert(*id))
                .collect();
            let rows = read_rows(&mut tx, table, &ids)
                .await
                .map_err(SyncError::Local)?;
            out.push((table, rows));
        }
        tx.commit().await.map_err(SyncError::Local)?;
        Ok(Batch {
            entries,
            rows: out,
            high,
            lineage,
        })
    }

    /// Forwards batches until the outbox is empty after the cursor; `on_batch` sees each.
    pub async fn drain(
        &mut self,
        on_batch: &mut dyn FnMut(&BatchReport),
    ) -> Result<u64, SyncError> {
        let mut rows = 0;
        while let Some(report) = self.step().await? {
            rows += report.total_rows() as u64;
            on_batch(&report);
        }
        Ok(rows)
    }

    /// Forwards for ever: a batch as soon as there is one, a look every `poll` when idle, and
    /// after an error a retry with back-off, until `stop` resolves; it never gives up by
    /// itself, whatever the error and whatever it was doing (catching up included). Errors
    /// are logged once each (a new message, not every retry) and kept in the status. While it
    /// waits, the status's backlog stays live, and when the server could not be reached, its
    /// port is probed every [`PROBE`]: forwarding resumes as soon as the server answers
    /// again, not at the end of the back-off.
    pub async fn run(
        mut self,
        stop: impl std::future::Future<Output = ()>,
        on_batch: &mut (dyn FnMut(&BatchReport) + Send),
    ) {
        tokio::pin!(stop);
        let mut backoff = MIN_BACKOFF;
        let mut last_logged: Option<String> = None;
        loop {
            let result = tokio::select! {
                _ = &mut stop => break,
                r = self.step() => r,
            };
            let (wait, unreachable) = match result {
                Ok(Some(report)) => {
                    backoff = MIN_BACKOFF;
                    if last_logged.take().is_some() {
                        tracing::info!(central = %redact(&self.options.url), "forwarding again");
                    }
                    on_batch(&report);
                    continue;
                }
                Ok(None) => {
                    backoff = MIN_BACKOFF;
                    if last_logged.take().is_some() {
                        tracing::info!(central = %redact(&self.options.url), "forwarding again");
                    }
                    (self.options.poll, false)
                }
                Err(e) => {
                    let message = e.to_string();
                    if last_logged.as_deref() != Some(message.as_str()) {
                        if matches!(e, SyncError::Forked { .. }) {
                            tracing::error!("forwarding to the central database: {message}");
                        } else {
                            tracing::warn!("forwarding to the central database: {message}");
                        }
                        last_logged = Some(message);
                    }
                    let wait = backoff;
                    backoff = (backoff * 2).min(self.options.max_backoff.max(MIN_BACKOFF));
                    (
                        wait,
                        matches!(e, SyncError::Connect { .. } | SyncError::Central { .. }),
                    )
                }
            };
            let until = tokio::time::Instant::now() + wait;
            let probe = if unreachable {
                probe_target(&self.options.url)
            } else {
                None
            };
            let mut down = false;
            loop {
                let now = tokio::time::Instant::now();
                if now >= until {
                    break;
                }
                let tick = (until - now).min(PROBE);
                tokio::select! {
                    _ = &mut stop => {
                        self.close().await;
                        return;
                    }
                    _ = tokio::time::sleep(tick) => {}
                }
                if wait > PROBE {
                    self.refresh_backlog().await;
                }
                if let Some((host, port)) = &probe {
                    let up = matches!(
                        tokio::time::timeout(
                            PROBE,
                            tokio::net::TcpStream::connect((host.as_str(), *port))
                        )
                        .await,
                        Ok(Ok(_))
                    );
                    if !up {
                        down = true;
                    } else if down {
                        // The server is back: retry now, and quickly again if it is still
                        // starting up.
                        backoff = MIN_BACKOFF;
                        break;
                    }
                }
            }
        }
        self.close().await;
    }

    async fn close(&self) {
        if let Some(c) = &self.central {
            c.close().await;
        }
    }
}

/// How often an idle forwarder looks at the central cursor.
const LOOK: Duration = Duration::from_secs(1);

/// The first wait after an error.
const MIN_BACKOFF: Duration = Duration::from_millis(500);

/// How often a forwarder waiting after a failed connection looks whether the server is back.
const PROBE: Duration = Duration::from_millis(250);

/// The TCP host and port of a central database URL (none for a Unix socket).
fn probe_target(url: &str) -> Option<(String, u16)> {
    use std::str::FromStr;
    let o = sqlx::postgres::PgConnectOptions::from_str(url).ok()?;
    let host = o.get_host().to_string();
    if host.starts_with('/') {
        return None;
    }
    Some((host, o.get_port()))
}

/// What `brdfd doctor` says of forwarding the store at `path` as `station`: the central
/// database answers, and the station's standing there (registered by this store, the store's
/// lineage accepted, how many entries wait). Changes nothing on either side: no migration, no
/// registration, the store opened read-only.
pub async fn diagnose(path: &Path, url: &str, station: &str) -> Result<String, SyncError> {
    let central = Central::connect(url).await?;
    let result = diagnose_on(&central, path, station).await;
    central.close().await;
    result
}

async fn diagnose_on(central: &Central, path: &Path, station: &str) -> Result<String, SyncError> {
    let has_chain: bool = sqlx::query_scalar(
        "SELECT to_regclass('stations') IS NOT NULL
            AND EXISTS (SELECT 1 FROM information_schema.columns
                        WHERE table_name = 'stations' AND column_name = 'head')",
    )
    .fetch_one(&central.pool)
    .await
    .map_err(|e| central.error(e))?;
    let row = if has_chain {
        sqlx::query(
            "SELECT store_uid, cursor, horizon, head, incarnation,
                    to_char(registered_at AT TIME ZONE 'UTC', 'YYYY-MM-DD HH24:MI:SS \"UTC\"'),
                    COALESCE(host, '?')
             FROM stations WHERE station = $1",
        )
        .bind(station)
        .fetch_optional(&central.pool)
        .await
        .map_err(|e| central.error(e))?
    } else {
        None
    };
    if !path.exists() {
        return Ok(format!(
            "{} answers; no store at {} yet",
            central.url,
            path.display()
        ));
    }
    let source = open_read_only(path).await?;
    let uid = store_uid(&source, &path.display().to_string()).await?;
    let mut c = source.begin().await.map_err(SyncError::Local)?;
    let highest = highest_seq(&mut c).await.map_err(SyncError::Local)?;
    let lineage = lineage::read(&mut *c).await.map_err(SyncError::Local)?;
    let deleted = deleted_up_to(&mut c, highest)
        .await
        .map_err(SyncError::Local)?;
    c.commit().await.map_err(SyncError::Local)?;
    let Some(row) = row else {
        let waiting: i64 = sqlx::query_scalar("SELECT COUNT(*) FROM sync_outbox")
            .fetch_one(&source)
            .await
            .map_err(SyncError::Local)?;
        source.close().await;
        return Ok(format!(
            "{} answers; station \"{station}\" is not registered yet (it is on first \
             contact); {waiting} entries to forward",
            central.url
        ));
    };
    let holder: String = row.get(0);
    let standing = lineage::Standing {
        cursor: row.get(1),
        horizon: row.get(2),
        head: row.get(3),
        incarnation: row.get(4),
    };
    let cursor = standing.cursor;
    if holder != uid {
        source.close().await;
        return Err(SyncError::StationTaken {
            station: station.to_string(),
            registered: row.get(5),
            host: row.get(6),
        });
    }
    let verdict = lineage::decide(station, &standing, &uid, &lineage, highest, deleted);
    let waiting: i64 = sqlx::query_scalar("SELECT COUNT(*) FROM sync_outbox WHERE seq > $1")
        .bind(cursor)
        .fetch_one(&source)
        .await
        .map_err(SyncError::Local)?;
    source.close().await;
    let behind = match verdict? {
        lineage::Verdict::Continue => "",
        lineage::Verdict::CentralBehind => {
            "; the central database is behind what this store already pruned (restored from \
             a backup?): the next sync compares and sends again from the store's tables"
        }
    };
    Ok(format!(
        "{} answers; station \"{station}\" is this store's, forwarded up to entry {cursor} of \
         {highest}, {waiting} entries waiting{behind}",
        central.url
    ))
}

/// One batch as read from one snapshot of the store.
struct Batch {
    entries: Vec<Entry>,
    rows: Vec<(&'static Table, Vec<Vec<Value>>)>,
    /// The highest outbox entry of the snapshot: the rows are as of this entry.
    high: i64,
    lineage: Vec<lineage::Incarnation>,
}

/// The highest outbox number the store ever gave out (pruned entries included).
pub(super) async fn highest_seq(c: &mut sqlx::SqliteConnection) -> Result<i64, sqlx::Error> {
    let from_sequence: Option<i64> =
        sqlx::query_scalar("SELECT seq FROM sqlite_sequence WHERE name = 'sync_outbox'")
            .fetch_optional(&mut *c)
            .await?;
    let from_table: Option<i64> = sqlx::query_scalar("SELECT MAX(seq) FROM sync_outbox")
        .fetch_one(&mut *c)
        .await?;
    Ok(from_sequence.unwrap_or(0).max(from_table.unwrap_or(0)))
}

/// The outbox entries the store deleted as acknowledged reach this far (`highest` when its
/// outbox is empty).
pub(super) async fn deleted_up_to(
    c: &mut sqlx::SqliteConnection,
    highest: i64,
) -> Result<i64, sqlx::Error> {
    let lowest: Option<i64> = sqlx::query_scalar("SELECT MIN(seq) FROM sync_outbox")
        .fetch_one(&mut *c)
        .await?;
    Ok(lowest.map_or(highest, |l| l - 1))
}

/// The rows of `table` whose `selected_by` column is one of `ids`, decoded.
pub(super) async fn read_rows(
    c: &mut sqlx::SqliteConnection,
    table: &Table,
    ids: &[i64],
) -> Result<Vec<Vec<Value>>, sqlx::Error> {
    let mut rows = Vec::new();
    // 500 placeholders per statement: well inside every SQLite's limit.
    for chunk in ids.chunks(500) {
        let mut q = QueryBuilder::<sqlx::Sqlite>::new("SELECT ");
        let names: Vec<&str> = table.columns.iter().map(|(n, _)| *n).collect();
        q.push(names.join(", "));
        q.push(format!(
            " FROM {} WHERE {} IN (",
            table.name, table.selected_by
        ));
        let mut list = q.separated(", ");
        for id in chunk {
            list.push_bind(*id);
        }
        q.push(")");
        for row in q.build().fetch_all(&mut *c).await? {
            rows.push(decode_row(table, &row)?);
        }
    }
    Ok(rows)
}

/// Locks the station's row for the transaction `tx` and checks, before any row is written,
/// that this store may forward for it: the same store, the cursor where this forwarder left
/// it, and the identity rule ([`lineage::decide`]). Returns the incarnation to record.
pub(super) async fn lock_station(
    tx: &mut sqlx::PgConnection,
    central: &Central,
    station: &str,
    uid: &str,
    expected_cursor: i64,
    lineage: &[lineage::Incarnation],
    high: i64,
) -> Result<String, SyncError> {
    let row = sqlx::query(
        "SELECT store_uid, cursor, horizon, head, incarnation,
                to_char(registered_at AT TIME ZONE 'UTC', 'YYYY-MM-DD HH24:MI:SS \"UTC\"'),
                COALESCE(host, '?')
         FROM stations WHERE station = $1 FOR UPDATE",
    )
    .bind(station)
    .fetch_optional(&mut *tx)
    .await
    .map_err(|e| central.error(e))?;
    let Some(row) = row else {
        // The central database lost the station (restored from an older backup): register
        // again on the next attempt.
        return Err(central.error(format_args!(
            "station \"{station}\" is no longer registered (the database was restored?); \
             registering again"
        )));
    };
    let holder: String = row.get(0);
    let standing = lineage::Standing {
        cursor: row.get(1),
        horizon: row.get(2),
        head: row.get(3),
        incarnation: row.get(4),
    };
    if holder != uid {
        return Err(SyncError::StationTaken {
            station: station.to_string(),
            registered: row.get(5),
            host: row.get(6),
        });
    }
    if standing.cursor != expected_cursor {
        return Err(SyncError::CursorMoved {
            station: station.to_string(),
            expected: expected_cursor,
        });
    }
    // The cursor is where this forwarder left it, so whether the central database is behind
    // the store's pruning was decided when the cursor was read: only acceptance matters here.
    lineage::decide(station, &standing, uid, lineage, high, 0)?;
    Ok(lineage
        .last()
        .map(|i| i.id.clone())
        .unwrap_or_else(|| uid.to_string()))
}

/// Moves the station's cursor, horizon (`high`, the snapshot the rows were read from) and
/// chain head there, and records its incarnation, in `tx`.
pub(super) async fn advance_station(
    tx: &mut sqlx::PgConnection,
    central: &Central,
    station: &str,
    cursor: i64,
    high: i64,
    head: &str,
    incarnation: &str,
) -> Result<(), SyncError> {
    // `high` is at least the old horizon: the identity rule refuses a store that does not
    // reach it.
    sqlx::query(
        "UPDATE stations SET cursor = $1, horizon = $2, head = $3, incarnation = $4,
                last_synced_at = now(), heartbeat_at = now()
         WHERE station = $5",
    )
    .bind(cursor)
    .bind(high)
    .bind(head)
    .bind(incarnation)
    .bind(station)
    .execute(&mut *tx)
    .await
    .map_err(|e| central.error(e))?;
    record_incarnation(tx, station, incarnation)
        .await
        .map_err(|e| central.error(e))
}

/// Records that `incarnation` forwarded for `station` (first and last seen), in `tx`.
pub(super) async fn record_incarnation(
    tx: &mut sqlx::PgConnection,
    station: &str,
    incarnation: &str,
) -> Result<(), sqlx::Error> {
    sqlx::query(
        "INSERT INTO station_incarnations (station, incarnation) VALUES ($1, $2)
         ON CONFLICT (station, incarnation) DO UPDATE SET last_seen = now()",
    )
    .bind(station)
    .bind(incarnation)
    .execute(tx)
    .await?;
    Ok(())
}

pub(super) fn decode_row(
    table: &Table,
    row: &sqlx::sqlite::SqliteRow,
) -> Result<Vec<Value>, sqlx::Error> {
    table
        .columns
        .iter()
        .enumerate()
        .map(|(i, (_, kind))| {
            // Unchecked: SQLite's storage class follows the value, not the column (a REAL
            // column may hold an integer); the value is converted as SQLite converts it.
            Ok(match kind {
                Kind::Int => Value::Int(row.try_get_unchecked(i)?),
                Kind::Text => Value::Text(row.try_get_unchecked(i)?),
                Kind::Blob => Value::Blob(row.try_get_unchecked(i)?),
                Kind::Real => Value::Real(row.try_get_unchecked(i)?),
            })
        })
        .collect()
}

/// PostgreSQL takes at most 65,535 bind parameters per statement.
const MAX_PARAMS: usize = 60_000;

pub(super) async fn upsert(
    tx: &mut sqlx::PgConnection,
    station: &str,
    table: &Table,
    rows: &[Vec<Value>],
) -> Result<(), sqlx::Error> {
    let per_row = table.columns.len() + 1;
    let names: Vec<&str> = table.columns.iter().map(|(n, _)| *n).collect();
    let updates: Vec<String> = table
        .columns
        .iter()
        .filter(|(n, _)| !table.key.contains(n))
        .map(|(n, _)| format!("{n} = EXCLUDED.{n}"))
        .collect();
    for chunk in rows.chunks(MAX_PARAMS / per_row) {
        let mut q = QueryBuilder::<sqlx::Postgres>::new(format!(
            "INSERT INTO {} (station, {}) ",
            table.name,
            names.join(", ")
        ));
        q.push_values(chunk, |mut b, row| {
            b.push_bind(station.to_string());
            for v in row {
                match v {
                    Value::Int(x) => b.push_bind(*x),
                    Value::Text(x) => b.push_bind(x.clone()),
                    Value::Blob(x) => b.push_bind(x.clone()),
                    Value::Real(x) => b.push_bind(*x),
                };
            }
        });
        q.push(format!(
            " ON CONFLICT (station, {}) DO UPDATE SET {}",
            table.key.join(", "),
            updates.join(", ")
        ));
        q.build().execute(&mut *tx).await?;
    }
    Ok(())
}

/// One line for a failure, for the CLI.
pub fn describe(e: &SyncError) -> String {
    one_line(e)
}

#[cfg(test)]
mod tests {
    use super::Lag;

    #[test]
    fn the_lag_summary_is_type_7_over_the_entries() {
        assert_eq!(Lag::of(Vec::new()), None);
        let lag = Lag::of((1..=100).rev()).unwrap();
        assert_eq!(lag.entries, 100);
        assert!((lag.p50_ms - 50.5).abs() < 1e-12, "{lag:?}");
        assert!((lag.p99_ms - 99.01).abs() < 1e-9, "{lag:?}");
        assert_eq!(lag.max_ms, 100.0);
        // A clock step backwards never makes a negative lag.
        assert_eq!(Lag::of([-5]).unwrap().max_ms, 0.0);
    }
}
