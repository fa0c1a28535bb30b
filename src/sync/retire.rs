//! Retiring a station's old store, so that a copy of it can take the station id over
//! (`brdfd sync --db FILE --retire-old ARCHIVE_ID`; central step `0008_station_retirement.sql`).
//!
//! A bench moved to a new PC is a copy of its store. When the old PC went on forwarding after
//! the copy was taken, the copy is refused for the station ([`super::lineage`]): the central
//! rows are the old store's, and the copy's rows under the same keys would mix with them.
//! There are two ways out: `--adopt NEW_ID` makes the copy a station of its own, and
//! [`retire`] keeps the station id for the copy. Retiring, in one central transaction:
//! 1. refuses an archive id already in use, and a station that is itself an archive;
//! 2. moves every central row of the station, the lab's sample identities and its
//!    incarnations to `ARCHIVE_ID`, a station row of its own marked `retired_from` — nothing
//!    is deleted, and the archive stays queryable like any station;
//! 3. starts the station afresh for this store: its store id, cursor 0, and this store's
//!    incarnation as the station's, so the old store (which never had that incarnation) is
//!    refused if it is ever started again.
//!
//! Nothing here reads a clock to decide: when the old store was last seen forwarding is
//! reported ([`Retired::last_seen_seconds`]) as information only. An old store that still
//! runs is refused from its next forward on, because its incarnation is no longer the
//! station's; the retirement takes the station row `FOR UPDATE`, so a forward in flight
//! either commits before it (and its rows move to the archive) or is refused after it.
//!
//! The copy then sends everything it holds (its comparison with the central database finds
//! all of it missing), and the central database ends with the copy under the station id and
//! the old store's rows under the archive id.

use sqlx::Row;

use super::SyncError;
use super::central::Central;
use super::tables::TABLES;

/// What [`retire`] moved.
#[derive(Debug, Clone, PartialEq)]
pub struct Retired {
    /// Central rows moved to the archive, per table (tables with none left out).
    pub rows: Vec<(&'static str, u64)>,
    /// The old store's host, as it registered.
    pub host: String,
    /// Seconds since the old store last forwarded (its heartbeat), if it ever did: told to
    /// the operator, never used to decide.
    pub last_seen_seconds: Option<f64>,
}

impl Retired {
    pub fn total_rows(&self) -> u64 {
        self.rows.iter().map(|(_, n)| n).sum()
    }
}

/// Retires what the central database holds for `station` to `archive` and gives the station
/// to the store `uid`, whose incarnation forwarding now is `incarnation`. One transaction: on
/// any failure the central database is as it was.
pub async fn retire(
    central: &Central,
    station: &str,
    archive: &str,
    uid: &str,
    incarnation: &str,
) -> Result<Retired, SyncError> {
    let refused = |why: String| SyncError::Retire {
        station: station.to_string(),
        why,
    };
    if archive == station {
        return Err(refused(
            "the archive id must differ from the station id".into(),
        ));
    }
    let err = |e: sqlx::Error| central.error(e);
    let mut tx = central.pool.begin().await.map_err(err)?;
    let row = sqlx::query(
        "SELECT COALESCE(host, '?'), EXTRACT(EPOCH FROM now() - heartbeat_at)::float8,
                retired_from
         FROM stations WHERE station = $1 FOR UPDATE",
    )
    .bind(station)
    .fetch_optional(&mut *tx)
    .await
    .map_err(err)?;
    let Some(row) = row else {
        return Err(refused(
            "the central database has no such station: nothing to retire (forward this store \
             as it is)"
                .into(),
        ));
    };
    let host: String = row.get(0);
    let silent: Option<f64> = row.get(1);
    let retired_from: Option<String> = row.get(2);
    if let Some(from) = retired_from {
        return Err(refused(format!(
            "it is itself the archive of station \"{from}\""
        )));
    }
    let taken: bool =
        sqlx::query_scalar("SELECT EXISTS (SELECT 1 FROM stations WHERE station = $1)")
            .bind(archive)
            .fetch_one(&mut *tx)
            .await
            .map_err(err)?;
    if taken {
        return Err(refused(format!(
            "station id \"{archive}\" is already in use; choose another archive id"
        )));
    }
    // The archive's station row: the old one as it was. Its store id is marked so that no
    // store registers as both (a store holds one station id).
    sqlx::query(
        "INSERT INTO stations (station, store_uid, cursor, host, brdfd_version, registered_at,
                               last_synced_at, incarnation, horizon, head, heartbeat_at,
                               retired_from, retired_at)
         SELECT $2, 'retired:' || store_uid, cursor, host, brdfd_version, registered_at,
                last_synced_at, incarnation, horizon, head, NULL, station, now()
         FROM stations WHERE station = $1",
    )
    .bind(station)
    .bind(archive)
    .execute(&mut *tx)
    .await
    .map_err(err)?;
    // The lab's sample identities point at samples with an immediate foreign key: set them
    // aside while the samples move, then put them back on the archive's samples.
    let identities: Vec<(i64, String)> = sqlx::query_as(
        "DELETE FROM sample_identities WHERE station = $1 RETURNING sample_id, lab_sample",
    )
    .bind(station)
    .fetch_all(&mut *tx)
    .await
    .map_err(err)?;
    let mut rows = Vec::new();
    // The rows' own foreign keys (station, id) are deferred to the commit, when all of them
    // have moved.
    for t in &TABLES {
        let r = sqlx::query(&format!(
            "UPDATE {} SET station = $2 WHERE station = $1",
            t.name
        ))
        .bind(station)
        .bind(archive)
        .execute(&mut *tx)
        .await
        .map_err(err)?;
        if r.rows_affected() > 0 {
            rows.push((t.name, r.rows_affected()));
        }
    }
    for (sample_id, lab_sample) in &identities {
        sqlx::query(
            "INSERT INTO sample_identities (station, sample_id, lab_sample) VALUES ($1, $2, $3)",
        )
        .bind(archive)
        .bind(sample_id)
        .bind(lab_sample)
        .execute(&mut *tx)
        .await
        .map_err(err)?;
    }
    sqlx::query("UPDATE station_incarnations SET station = $2 WHERE station = $1")
        .bind(station)
        .bind(archive)
        .execute(&mut *tx)
        .await
        .map_err(err)?;
    // The station afresh, for this store and this incarnation.
    sqlx::query(
        "UPDATE stations SET store_uid = $2, cursor = 0, horizon = 0, head = NULL,
                incarnation = $3,
                heartbeat_at = NULL, last_synced_at = NULL, registered_at = now(), host = $4,
                brdfd_version = $5
         WHERE station = $1",
    )
    .bind(station)
    .bind(uid)
    .bind(incarnation)
    .bind(super::default_station_id())
    .bind(env!("CARGO_PKG_VERSION"))
    .execute(&mut *tx)
    .await
    .map_err(err)?;
    super::forward::record_incarnation(&mut tx, station, incarnation)
        .await
        .map_err(err)?;
    tx.commit().await.map_err(err)?;
    Ok(Retired {
        rows,
        host,
        last_seen_seconds: silent,
    })
}
