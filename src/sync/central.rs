//! The central database: connecting, bringing its schema up to date, and the stations table.
//!
//! Decisions:
//! - The schema is `migrations-central/`, embedded like the station's and applied by whoever
//!   connects first (sqlx takes an advisory lock, so stations starting together are safe).
//!   Before migrating, the highest version already applied is compared with the highest this
//!   brdfd knows: a database migrated by a newer brdfd is refused, never half-understood.
//! - A station id is claimed by the first store that registers it (its `sync_identity.uid`);
//!   another store under the same id is refused, so two benches never mix their rows; and a
//!   store registered under one id is refused under another, which would count it twice.
//! - Two connections per station at most: forwarding is one transaction at a time, and a lab's
//!   server must hold every station's pool (ARCHITECTURE.md: pooling at 100 stations).

use std::str::FromStr;
use std::time::Duration;

use sqlx::postgres::{PgConnectOptions, PgPoolOptions};
use sqlx::{PgPool, Row};

use super::lineage::Standing;
use super::{SyncError, redact};

/// The central schema, from `migrations-central/`.
pub static CENTRAL_MIGRATOR: sqlx::migrate::Migrator = sqlx::migrate!("./migrations-central");

/// How long connecting (or waiting for a pooled connection) may take before it is an error.
const CONNECT_TIMEOUT: Duration = Duration::from_secs(10);

/// A connection pool on the central database, its schema checked.
#[derive(Debug, Clone)]
pub struct Central {
    pub(crate) pool: PgPool,
    /// The URL without its password, for messages.
    pub(crate) url: String,
}

/// What the central database knows of a station.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct StationRow {
    pub station: String,
    pub cursor: i64,
}

impl Central {
    /// Connects without touching the schema (readers: `report --db postgres://…`), checking
    /// only that it is not newer than this brdfd.
    pub async fn connect(url: &str) -> Result<Central, SyncError> {
        let redacted = redact(url);
        let options = PgConnectOptions::from_str(url).map_err(|e| SyncError::BadUrl {
            url: redacted.clone(),
            message: one_line(&e),
        })?;
        let pool = PgPoolOptions::new()
            .max_connections(2)
            .acquire_timeout(CONNECT_TIMEOUT)
            .connect_with(options)
            .await
            .map_err(|e| SyncError::Connect {
                url: redacted.clone(),
                message: one_line(&e),
            })?;
        let central = Central {
            pool,
            url: redacted,
        };
        central.check_version().await?;
        Ok(central)
    }

    /// Connects and applies any central migration the database lacks.
    pub async fn connect_and_migrate(url: &str) -> Result<Central, SyncError> {
        let central = Central::connect(url).await?;
        CENTRAL_MIGRATOR
            .run(&central.pool)
            .await
            .map_err(|e| SyncError::Migrate {
                url: central.url.clone(),
                message: one_line(&e),
            })?;
        Ok(central)
    }

    /// The pool (for readers in `src/store/central.rs` and tests).
    pub fn pool(&self) -> &PgPool {
        &self.pool
    }

    /// The URL without its password.
    pub fn url(&self) -> &str {
        &self.url
    }

    pub(crate) fn error(&self, e: impl std::fmt::Display) -> SyncError {
        SyncError::Central {
            url: self.url.clone(),
            message: one_line(&e),
        }
    }

    /// Refuses a database whose schema is newer than [`CENTRAL_MIGRATOR`].
    async fn check_version(&self) -> Result<(), SyncError> {
        let known = CENTRAL_MIGRATOR
            .iter()
            .map(|m| m.version)
            .max()
            .unwrap_or(0);
        let exists: bool = sqlx::query_scalar("SELECT to_regclass('_sqlx_migrations') IS NOT NULL")
            .fetch_one(&self.pool)
            .await
            .map_err(|e| self.error(e))?;
        if !exists {
            return Ok(());
        }
        let found: Option<i64> = sqlx::query_scalar("SELECT MAX(version) FROM _sqlx_migrations")
            .fetch_one(&self.pool)
            .await
            .map_err(|e| self.error(e))?;
        match found {
            Some(found) if found > known => Err(SyncError::NewerSchema {
                url: self.url.clone(),
                found,
                known,
            }),
            _ => Ok(()),
        }
    }

    /// Registers `station` for the store `uid` (first come, first served) and returns its
    /// cursor; refuses a station id another store holds.
    pub async fn register(&self, station: &str, uid: &str) -> Result<StationRow, SyncError> {
        // An archive of a retired station's old store takes no rows (src/sync/retire.rs).
        let archived: Option<String> = sqlx::query_scalar(
            "SELECT retired_from FROM stations WHERE station = $1 AND retired_from IS NOT NULL",
        )
        .bind(station)
        .fetch_optional(&self.pool)
        .await
        .map_err(|e| self.error(e))?;
        if let Some(from) = archived {
            return Err(SyncError::Archived {
                station: station.to_string(),
                from,
            });
        }
        // One store, one id: the same store under a second id would count its scans twice.
        let other: Option<String> = sqlx::query_scalar(
            "SELECT station FROM stations WHERE store_uid = $1 AND station <> $2 LIMIT 1",
        )
        .bind(uid)
        .bind(station)
        .fetch_optional(&self.pool)
        .await
        .map_err(|e| self.error(e))?;
        if let Some(existing) = other {
            return Err(SyncError::StoreHasOtherId {
                station: station.to_string(),
                existing,
            });
        }
        sqlx::query(
            "INSERT INTO stations (station, store_uid, host, brdfd_version) VALUES ($1, $2, $3, $4)
             ON CONFLICT (station) DO NOTHING",
        )
        .bind(station)
        .bind(uid)
        .bind(super::default_station_id())
        .bind(env!("CARGO_PKG_VERSION"))
        .execute(&self.pool)
        .await
        .map_err(|e| self.error(e))?;
        let row = sqlx::query(
            "SELECT store_uid, cursor, COALESCE(host, '?') AS host,
                    to_char(registered_at AT TIME ZONE 'UTC', 'YYYY-MM-DD HH24:MI:SS \"UTC\"')
                        AS registered
             FROM stations WHERE station = $1",
        )
        .bind(station)
        .fetch_one(&self.pool)
        .await
        .map_err(|e| self.error(e))?;
        let holder: String = row.get("store_uid");
        if holder != uid {
            return Err(SyncError::StationTaken {
                station: station.to_string(),
                registered: row.get("registered"),
                host: row.get("host"),
            });
        }
        Ok(StationRow {
            station: station.to_string(),
            cursor: row.get("cursor"),
        })
    }

    /// The cursor of a registered station.
    pub async fn cursor(&self, station: &str) -> Result<i64, SyncError> {
        sqlx::query_scalar("SELECT cursor FROM stations WHERE station = $1")
            .bind(station)
            .fetch_one(&self.pool)
            .await
            .map_err(|e| self.error(e))
    }

    /// The station's standing (src/sync/lineage.rs): cursor, horizon, chain head and last
    /// incarnation.
    pub async fn standing(&self, station: &str) -> Result<Standing, SyncError> {
        let row = sqlx::query(
            "SELECT cursor, horizon, head, incarnation FROM stations WHERE station = $1",
        )
        .bind(station)
        .fetch_one(&self.pool)
        .await
        .map_err(|e| self.error(e))?;
        Ok(Standing {
            cursor: row.get(0),
            horizon: row.get(1),
            head: row.get(2),
            incarnation: row.get(3),
        })
    }

    /// The station's store was seen (an idle forwarder's look at its cursor): information for
    /// the lab's administrator and for `--retire-old`, never part of the identity rule.
    pub async fn heartbeat(&self, station: &str) -> Result<(), SyncError> {
        sqlx::query("UPDATE stations SET heartbeat_at = now() WHERE station = $1")
            .bind(station)
            .execute(&self.pool)
            .await
            .map_err(|e| self.error(e))?;
        Ok(())
    }

    /// Records that a store was refused for `station`, for the lab's administrator
    /// (`station_refusals`); best effort: the refusal itself is what matters.
    pub async fn record_refusal(&self, station: &str, uid: &str, incarnation: &str, reason: &str) {
        let r = sqlx::query(
            "INSERT INTO station_refusals (station, store_uid, incarnation, host, reason)
             VALUES ($1, $2, $3, $4, $5)",
        )
        .bind(station)
        .bind(uid)
        .bind(incarnation)
        .bind(super::default_station_id())
        .bind(reason)
        .execute(&self.pool)
        .await;
        if let Err(e) = r {
            tracing::debug!(error = %e, "recording a refusal in the central database");
        }
    }

    /// Every station id, sorted.
    pub async fn stations(&self) -> Result<Vec<String>, SyncError> {
        sqlx::query_scalar("SELECT station FROM stations ORDER BY station")
            .fetch_all(&self.pool)
            .await
            .map_err(|e| self.error(e))
    }

    pub async fn close(&self) {
        self.pool.close().await;
    }
}

/// The first line of an error's message (sqlx's are one line, a server's may not be).
pub(crate) fn one_line(e: &impl std::fmt::Display) -> String {
    let text = e.to_string();
    text.lines().next().unwrap_or("").trim().to_string()
}
