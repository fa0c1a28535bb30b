//! A store's lineage and the identity rule: which store may forward for a station, decided by
//! what the store and the central database hold, never by when they last spoke (station
//! migration `0017_sync_lineage.sql`, central steps 0005 and 0010).
//!
//! A copied file (`cp` of a checkpointed store, `VACUUM INTO`, `sqlite3 .backup`) carries the
//! same store id and the same outbox as its original, so at the moment of the copy the two are
//! the same history, and either may go on. They differ by what they write next: every opening
//! of a store for writing appends a new random incarnation to `sync_lineage`, with the highest
//! outbox entry the store held then (`born_after`). Every outbox entry after that is written by
//! that incarnation, in that file only. So the history of a store up to outbox entry `n` is
//! named by the incarnations that began before `n`, in order, and [`chain_head`] hashes them
//! into a chain: link 0 is SHA-256 over the store id, and each incarnation's link is SHA-256
//! over the link before it, its id and its `born_after`; the head at `n` is the last link of an
//! incarnation with `born_after < n`. Two stores with the same head at `n` hold the same
//! entries up to `n`; once one of them writes under a new incarnation, its head at any later
//! entry differs from the other's for good.
//!
//! The central database keeps, per station, how far the station's rows reach (`horizon`: the
//! highest outbox entry of the snapshots they were read from, at least the cursor) and the
//! chain head there (`stations.head`), with the incarnation that sent them (information).
//! [`decide`] is the one rule, applied by every forwarder (the daemon's, `brdfd sync`, `brdfd
//! sync --once`, `--verify`) inside the transaction that would write, before any row, and by
//! `brdfd doctor`:
//! - the store reaches the horizon and its head there is the central head: it holds everything
//!   the station sent, so it is the station's store, at any pace (a restart, a second run of
//!   `brdfd sync --once` in the same second, an exact copy that has not diverged). If the
//!   central cursor is behind what the store has already deleted from its outbox (the central
//!   database restored from an older dump), the store compares and sends again from its
//!   tables ([`Verdict::CentralBehind`]);
//! - the store's head at the horizon differs: the station went on as another copy of this
//!   store after this one was copied (or this one went its own way): refused
//!   ([`SyncError::Forked`]), with the two ways out, `--adopt NEW_ID` and `--retire-old
//!   ARCHIVE_ID`; nothing of it is written;
//! - the store does not reach the horizon: an older copy (a restored backup): refused the same
//!   way;
//! - no head yet: first contact, or a station last forwarded by a brdfd before the chain. Then
//!   the incarnation the central database recorded must be in this store's lineage, with the
//!   store's next incarnation beginning at or after the horizon ([`check_incarnation`]); the
//!   next batch records the head, so an upgraded station goes on from its cursor without a
//!   full resend.
//!
//! Which of two copies that both go on keeps the station is told by the files too (station
//! migration 0021, [`crate::store::lineage`]): an incarnation that began in another file than
//! the incarnation before it, while that one was never closed, is marked [`Incarnation::copied`]
//! — a copy of a running store, whose original may be going on — and once it has written
//! entries the station's history does not hold it is refused: the copy, never the original,
//! whichever order they are synced in. Of two copies of a store that was closed cleanly (a
//! bench moved to a new PC), the first to forward after the split keeps the station and the
//! other is refused from then on. A store that crashed and was then moved to another file looks
//! like a live copy and is refused as one; `--retire-old` gives it the station back.

use sha2::{Digest, Sha256};
use sqlx::{Row, SqlitePool};

use super::SyncError;
use super::tables::TABLES;

/// One incarnation of a store.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Incarnation {
    pub id: String,
    /// The highest outbox entry the store held when this incarnation began.
    pub born_after: i64,
    /// It began in a copy of the store taken while the incarnation before it was open
    /// (station migration 0021): the original may be going on.
    pub copied: bool,
}

/// What the central database holds of a station.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Standing {
    /// The last outbox entry forwarded.
    pub cursor: i64,
    /// The highest outbox entry whose effects may be in the central rows (at least `cursor`).
    pub horizon: i64,
    /// The chain head of the station's store at `horizon` ([`chain_head`]); `None` before the
    /// first batch of a brdfd with the chain.
    pub head: Option<String>,
    /// The last incarnation that forwarded, if any did since lineage existed.
    pub incarnation: Option<String>,
}

/// What a store accepted for its station does next.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Verdict {
    /// Forward the outbox after the central cursor.
    Continue,
    /// The central cursor is behind entries this store already deleted (the database was
    /// restored from an older dump): compare and send again from the tables first.
    CentralBehind,
}

/// Begins a new incarnation of a store; the store records it when it opens for writing.
pub use crate::store::begin_incarnation;

/// The store's incarnations, oldest first (the last is the one writing now).
pub async fn read<'e, E>(executor: E) -> Result<Vec<Incarnation>, sqlx::Error>
where
    E: sqlx::Executor<'e, Database = sqlx::Sqlite>,
{
    // A store not yet opened by a brdfd with step 21 (forwarded read-only by `brdfd sync`)
    // has no `copied` column: none of its incarnations is known as a copy.
    let rows = sqlx::query("SELECT * FROM sync_lineage ORDER BY seq")
        .fetch_all(executor)
        .await?;
    rows.iter()
        .map(|r| {
            Ok(Incarnation {
                id: r.try_get("incarnation")?,
                born_after: r.try_get("born_after")?,
                copied: r.try_get::<Option<i64>, _>("copied").ok().flatten() == Some(1),
            })
        })
        .collect()
}

/// The chain head (hex SHA-256) of the store `uid` with `lineage` at outbox entry `at`: the
/// history of the entries up to `at`, named by the incarnations that wrote them (module doc).
pub fn chain_head(uid: &str, lineage: &[Incarnation], at: i64) -> String {
    let mut link: [u8; 32] = Sha256::new()
        .chain_update(b"brdfd store\0")
        .chain_update(uid.as_bytes())
        .finalize()
        .into();
    for i in lineage.iter().filter(|i| i.born_after < at) {
        link = Sha256::new()
            .chain_update(link)
            .chain_update(i.id.as_bytes())
            .chain_update(i.born_after.to_be_bytes())
            .finalize()
            .into();
    }
    hex::encode(link)
}

/// The identity rule (module doc): whether the store `uid` with `lineage`, whose snapshot
/// reaches outbox entry `high` and whose outbox was pruned up to `deleted_up_to`, may forward
/// as `station`, which the central database holds as `standing`.
pub fn decide(
    station: &str,
    standing: &Standing,
    uid: &str,
    lineage: &[Incarnation],
    high: i64,
    deleted_up_to: i64,
) -> Result<Verdict, SyncError> {
    let forked = |detail: String| SyncError::Forked {
        station: station.to_string(),
        detail,
    };
    let horizon = standing.horizon.max(standing.cursor);
    if high < horizon {
        return Err(forked(format!(
            "this store reaches outbox entry {high}, but the station forwarded up to entry \
             {horizon}: it is an older copy of the station's store"
        )));
    }
    match &standing.head {
        Some(head) => {
            let mine = chain_head(uid, lineage, horizon);
            if &mine != head {
                return Err(forked(format!(
                    "the station's history up to outbox entry {horizon} (chain head {}) is not \
                     this store's ({}): another copy of this store forwarded under this id \
                     since this one was copied, or this one went its own way",
                    &head[..head.len().min(12)],
                    &mine[..12]
                )));
            }
        }
        None => check_incarnation(station, standing, lineage, high)?,
    }
    // A copy taken of the store while it was open does not take the station over by itself:
    // its original may be going on. Covered already: an incarnation the station's history
    // holds (born before the horizon), or one at or before the incarnation central recorded
    // (after `--retire-old`).
    let recorded = standing
        .incarnation
        .as_deref()
        .and_then(|id| lineage.iter().position(|i| i.id == id));
    for (at, i) in lineage.iter().enumerate() {
        let covered = i.born_after < horizon || recorded.is_some_and(|r| at <= r);
        if i.copied && !covered && high > i.born_after && standing.cursor > 0 {
            return Err(forked(format!(
                "this store is a copy of the station's store taken at outbox entry {} while \
                 that store was open (it was never closed before the copy), and it wrote on \
                 its own since: the original may be going on",
                i.born_after
            )));
        }
    }
    Ok(if standing.cursor < deleted_up_to {
        Verdict::CentralBehind
    } else {
        Verdict::Continue
    })
}

/// The rule for a station whose central row has no chain head yet (first contact, or last
/// forwarded by a brdfd before the chain): the incarnation that forwarded last must be this
/// store's, or an earlier one of it whose successor began at or after the horizon.
pub fn check_incarnation(
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
            copied: false,
        }
    }

    fn copy_of(id: &str, born_after: i64) -> Incarnation {
        Incarnation {
            copied: true,
            ..inc(id, born_after)
        }
    }

    #[test]
    fn a_copy_of_an_open_store_does_not_take_the_station_over_even_first() {
        // The original (b, still open) forwarded up to 25; a live copy taken at 25 began d
        // there and wrote, and forwards before the original does: refused.
        let orig = [inc("a", 0), inc("b", 10)];
        let copy = [inc("a", 0), inc("b", 10), copy_of("d", 25)];
        let s = sent(&orig, 25);
        let e = decide("s", &s, "u", &copy, 30, 0).unwrap_err();
        assert!(
            e.to_string()
                .contains("copy of the station's store taken at outbox entry 25"),
            "{e}"
        );
        // Not written since the copy: the same history, nothing to send, accepted.
        decide("s", &s, "u", &copy, 25, 0).unwrap();
        // The original goes on.
        decide("s", &s, "u", &orig, 40, 0).unwrap();
        // After `--retire-old` (no head, the copy's later incarnation recorded) it is the station.
        let retired = Standing {
            cursor: 0,
            horizon: 0,
            head: None,
            incarnation: Some("e".into()),
        };
        let mut copy_on = copy.to_vec();
        copy_on.push(inc("e", 30));
        decide("s", &retired, "u", &copy_on, 30, 0).unwrap();
        // First contact: nothing to take over.
        decide("s", &standing(None, 0), "u", &copy, 30, 0).unwrap();
    }

    fn standing(head: Option<&str>, horizon: i64) -> Standing {
        Standing {
            cursor: horizon,
            horizon,
            head: None,
            incarnation: head.map(str::to_string),
        }
    }

    /// What the central database holds after `lineage` of store "u" forwarded up to `at`.
    fn sent(lineage: &[Incarnation], at: i64) -> Standing {
        Standing {
            cursor: at,
            horizon: at,
            head: Some(chain_head("u", lineage, at)),
            incarnation: lineage.last().map(|i| i.id.clone()),
        }
    }

    #[test]
    fn the_chain_head_names_the_writers_up_to_an_entry() {
        let l = [inc("a", 0), inc("b", 10), inc("c", 40)];
        // Entries 1..=10 were written by a alone, 11..=40 by a then b.
        assert_eq!(chain_head("u", &l, 10), chain_head("u", &l[..1], 10));
        assert_eq!(chain_head("u", &l, 40), chain_head("u", &l[..2], 99));
        assert_ne!(chain_head("u", &l, 40), chain_head("u", &l, 41));
        assert_ne!(
            chain_head("u", &l, 41),
            chain_head("u", &[inc("a", 0), inc("b", 10), inc("d", 40)], 41)
        );
        // Another store's chain differs from the start; an incarnation at another entry too.
        assert_ne!(chain_head("u", &l, 5), chain_head("v", &l, 5));
        assert_ne!(
            chain_head("u", &l, 40),
            chain_head("u", &[inc("a", 0), inc("b", 11)], 40)
        );
        assert_eq!(chain_head("u", &l, 5).len(), 64);
    }

    #[test]
    fn the_same_store_is_accepted_at_any_pace() {
        // Forwarded up to 40 by b; reopened (c, at 40 or later: a `brdfd demo`, a restart) and
        // forwarded again at once: no clock is read.
        let before = [inc("a", 0), inc("b", 10)];
        let now = [inc("a", 0), inc("b", 10), inc("c", 40)];
        let s = sent(&before, 40);
        assert_eq!(
            decide("s", &s, "u", &now, 52, 0).unwrap(),
            Verdict::Continue
        );
        assert_eq!(
            decide("s", &s, "u", &before, 40, 40).unwrap(),
            Verdict::Continue
        );
        // Reopened before everything was sent: still the same history up to 40.
        let early = [inc("a", 0), inc("b", 10), inc("c", 45)];
        decide("s", &s, "u", &early, 60, 0).unwrap();
    }

    #[test]
    fn a_copy_that_went_its_own_way_is_refused_and_the_original_is_not() {
        // Copied at 25 (both hold a, b); the original reopened as c and the copy as d, both
        // at 25. The original forwarded up to 40 first.
        let orig = [inc("a", 0), inc("b", 10), inc("c", 25)];
        let copy = [inc("a", 0), inc("b", 10), inc("d", 25)];
        let s = sent(&orig, 40);
        let e = decide("s", &s, "u", &copy, 60, 0).unwrap_err();
        assert!(matches!(e, SyncError::Forked { .. }), "{e}");
        let text = e.to_string();
        assert!(text.contains("entry 40"), "{text}");
        assert!(
            text.contains("--adopt NEW_ID") && text.contains("--retire-old"),
            "{text}"
        );
        // The copy holding fewer entries than the station sent: an older copy, refused too.
        let e = decide("s", &s, "u", &copy, 30, 0).unwrap_err();
        assert!(e.to_string().contains("older copy"), "{e}");
        // The original goes on, whatever the copy did in between.
        decide("s", &s, "u", &orig, 70, 40).unwrap();
        // Before the original forwarded past the copy point, both are the same history.
        let s = sent(&orig[..2], 25);
        decide("s", &s, "u", &copy, 30, 0).unwrap();
        decide("s", &s, "u", &orig, 30, 0).unwrap();
    }

    #[test]
    fn a_central_database_behind_the_store_is_caught_up_from_the_tables() {
        // The store forwarded up to 90 and deleted its outbox up to there; the central
        // database was restored to a dump taken at 40.
        let l = [inc("a", 0), inc("b", 10), inc("c", 60)];
        let s = sent(&l, 40);
        assert_eq!(
            decide("s", &s, "u", &l, 90, 90).unwrap(),
            Verdict::CentralBehind
        );
        assert_eq!(decide("s", &s, "u", &l, 90, 30).unwrap(), Verdict::Continue);
    }

    #[test]
    fn without_a_head_the_incarnation_rule_decides() {
        let l = [inc("a", 0), inc("b", 10), inc("c", 40)];
        decide("s", &standing(Some("b"), 40), "u", &l, 52, 0).unwrap();
        decide("s", &standing(None, 0), "u", &l, 52, 0).unwrap();
        let e = decide("s", &standing(Some("x"), 40), "u", &l, 52, 0).unwrap_err();
        assert!(e.to_string().contains("never had"), "{e}");
    }

    #[test]
    fn the_same_incarnation_going_on_is_accepted() {
        let l = [inc("a", 0), inc("b", 10)];
        check_incarnation("s", &standing(Some("b"), 40), &l, 45).unwrap();
        check_incarnation("s", &standing(None, 40), &l, 45).unwrap();
    }

    #[test]
    fn a_restart_after_everything_sent_is_accepted() {
        // b forwarded up to 40, then the store was reopened at 40 (or later) as c.
        let l = [inc("a", 0), inc("b", 10), inc("c", 40)];
        check_incarnation("s", &standing(Some("b"), 40), &l, 52).unwrap();
    }

    #[test]
    fn a_copy_taken_before_the_station_went_on_is_refused() {
        // Copied at 25; the original (b) forwarded up to 40 since.
        let l = [inc("a", 0), inc("b", 10), inc("c", 25)];
        let e = check_incarnation("s", &standing(Some("b"), 40), &l, 60).unwrap_err();
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
        let e = check_incarnation("s", &standing(Some("d"), 40), &l, 60).unwrap_err();
        assert!(e.to_string().contains("never had"), "{e}");
    }

    #[test]
    fn an_older_copy_of_the_same_incarnation_is_refused() {
        let l = [inc("a", 0), inc("b", 10)];
        let e = check_incarnation("s", &standing(Some("b"), 40), &l, 30).unwrap_err();
        assert!(e.to_string().contains("older copy"), "{e}");
    }
}
