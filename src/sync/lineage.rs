//! A store's lineage: the incarnations that wrote it, and the central check that tells a copy
//! of a store from the store (station migration `0017_sync_lineage.sql`, central step 0005).
//!
//! A copied file (`cp` of a checkpointed store, `VACUUM INTO`, `sqlite3 .backup`) carries the
//! same store id and the same outbox as its original, so the two cannot be told apart by what
//! they hold. They can by what they do next: every opening of a store for writing appends a
//! new random incarnation to `sync_lineage` together with the highest outbox entry the store
//! held then (`born_after`). The central database keeps, per station, the last incarnation
//! that forwarded (`stations.incarnation`) and the horizon of what it sent (`stations.horizon`:
//! the highest outbox entry of the snapshots its rows were read from). A batch is accepted,
//! inside the transaction that would write its rows and before any of them, only when
//! [`check`] passes:
//! - the central incarnation is this store's own (a daemon going on; a stopped store forwarded
//!   by `brdfd sync --db`), and this store has everything up to the horizon; or
//! - the central incarnation is an earlier one of this store's lineage, and this store's next
//!   incarnation began at or after the horizon: everything the station sent is in this file
//!   (a restart; a store moved to a new PC, the old one stopped first); or
//! - the station has no incarnation on record yet (first contact, or a brdfd before lineage).
//!
//! Anything else is a fork: another copy of this store forwarded past the point this one was
//! copied at, or forwarded an incarnation this store never had. The copy that comes second is
//! refused with [`SyncError::Forked`], and nothing it holds is written; the way out is
//! `brdfd sync --adopt NEW_ID` ([`adopt`]), which makes the copy a station of its own.

use sqlx::{Row, SqlitePool};

use super::SyncError;
use super::tables::TABLES;

/// One incarnation of a store.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Incarnation {
    pub id: String,
    /// The highest outbox entry the store held when this incarnation began.
    pub born_after: i64,
}

/// What the central database holds of a station's lineage.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Standing {
    /// The last incarnation that forwarded, if any did since lineage existed.
    pub incarnation: Option<String>,
    /// The highest outbox entry whose effects may be in the central rows.
    pub horizon: i64,
}

/// Begins a new incarnation of a store; the store records it when it opens for writing.
pub use crate::store::begin_incarnation;

/// The store's incarnations, oldest first (the last is the one writing now).
pub async fn read<'e, E>(executor: E) -> Result<Vec<Incarnation>, sqlx::Error>
where
    E: sqlx::Executor<'e, Database = sqlx::Sqlite>,
{
    let rows = sqlx::query("SELECT incarnation, born_after FROM sync_lineage ORDER BY seq")
        .fetch_all(executor)
        .await?;
    Ok(rows
        .iter()
        .map(|r| Incarnation {
            id: r.get(0),
            born_after: r.get(1),
        })
        .collect())
}

/// Whether a store whose lineage is `lineage` and whose snapshot reaches outbox entry `high`
/// may forward as `station`, which the central database holds as `standing`.
pub fn check(
    station: &str,
    standing: &Standing,
    lineage: &[Incarnation],
    high: i64,
) -> Result<(), SyncError> {
    let Some(head) = &standing.incarnation else {
        return Ok(());
    };
    let forked = |detail: String| SyncError::Forked {
        station: station.to_string(),
        detail,
    };
    let Some(at) = lineage.iter().position(|i| &i.id == head) else {
        return Err(forked(format!(
            "the station's rows came last from incarnation {head}, which this store never had: \
             another copy of this store forwarded under this id"
        )));
    };
    if let Some(next) = lineage.get(at + 1) {
        if next.born_after < standing.horizon {
            return Err(forked(format!(
                "this store was copied from the station at outbox entry {}, but the station \
                 forwarded up to entry {} since",
                next.born_after, standing.horizon
            )));
        }
    } else if high < standing.horizon {
        return Err(forked(format!(
            "this store reaches outbox entry {high}, but the station forwarded up to entry {}: \
             it is an older copy of the station's store",
            standing.horizon
        )));
    }
    Ok(())
}

/// Makes the store behind `writer` a station of its own: a new store id, a new lineage, and
/// every forwarded row queued again, so that forwarding under a new station id sends all of
/// it. One transaction: on failure the store is as it was. Returns the entries queued.
pub async fn adopt(writer: &SqlitePool) -> Result<u64, sqlx::Error> {
    let mut tx = writer.begin().await?;
    sqlx::query("UPDATE sync_identity SET uid = lower(hex(randomblob(16)))")
        .execute(&mut *tx)
        .await?;
    sqlx::query("DELETE FROM sync_lineage")
        .execute(&mut *tx)
        .await?;
    sqlx::query("DELETE FROM sync_outbox")
        .execute(&mut *tx)
        .await?;
    let mut queued = 0;
    for t in &TABLES {
        if t.name == "evaluations" {
            // Queued with their summary.
            continue;
        }
        let r = sqlx::query(&format!(
            "INSERT INTO sync_outbox (table_name, row_id, at_ms)
             SELECT '{name}', {by}, CAST((julianday('now') - 2440587.5) * 86400000.0 AS INTEGER)
             FROM {name} ORDER BY {by}",
            name = t.name,
            by = t.selected_by
        ))
        .execute(&mut *tx)
        .await?;
        queued += r.rows_affected();
    }
    sqlx::query(
        "INSERT INTO sync_lineage (incarnation, born_after, started_at_ms)
         VALUES (lower(hex(randomblob(16))),
                 (SELECT seq FROM sqlite_sequence WHERE name = 'sync_outbox'),
                 CAST((julianday('now') - 2440587.5) * 86400000.0 AS INTEGER))",
    )
    .execute(&mut *tx)
    .await?;
    tx.commit().await?;
    Ok(queued)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn inc(id: &str, born_after: i64) -> Incarnation {
        Incarnation {
            id: id.into(),
            born_after,
        }
    }

    fn standing(head: Option<&str>, horizon: i64) -> Standing {
        Standing {
            incarnation: head.map(str::to_string),
            horizon,
        }
    }

    #[test]
    fn the_same_incarnation_going_on_is_accepted() {
        let l = [inc("a", 0), inc("b", 10)];
        check("s", &standing(Some("b"), 40), &l, 45).unwrap();
        check("s", &standing(None, 40), &l, 45).unwrap();
    }

    #[test]
    fn a_restart_after_everything_sent_is_accepted() {
        // b forwarded up to 40, then the store was reopened at 40 (or later) as c.
        let l = [inc("a", 0), inc("b", 10), inc("c", 40)];
        check("s", &standing(Some("b"), 40), &l, 52).unwrap();
    }

    #[test]
    fn a_copy_taken_before_the_station_went_on_is_refused() {
        // Copied at 25; the original (b) forwarded up to 40 since.
        let l = [inc("a", 0), inc("b", 10), inc("c", 25)];
        let e = check("s", &standing(Some("b"), 40), &l, 60).unwrap_err();
        assert!(matches!(e, SyncError::Forked { .. }), "{e}");
        let text = e.to_string();
        assert!(
            text.contains("entry 25") && text.contains("entry 40"),
            "{text}"
        );
        assert!(text.contains("--adopt NEW_ID"), "{text}");
    }

    #[test]
    fn an_incarnation_this_store_never_had_is_a_fork() {
        // The other copy began d after b; this one began c.
        let l = [inc("a", 0), inc("b", 10), inc("c", 40)];
        let e = check("s", &standing(Some("d"), 40), &l, 60).unwrap_err();
        assert!(e.to_string().contains("never had"), "{e}");
    }

    #[test]
    fn an_older_copy_of_the_same_incarnation_is_refused() {
        let l = [inc("a", 0), inc("b", 10)];
        let e = check("s", &standing(Some("b"), 40), &l, 30).unwrap_err();
        assert!(e.to_string().contains("older copy"), "{e}");
    }
}
