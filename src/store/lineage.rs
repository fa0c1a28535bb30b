//! The store's lineage record: each opening for writing appends a new incarnation to
//! `sync_lineage` (station migration `0017_sync_lineage.sql`). What the incarnations mean for
//! forwarding, and the check that tells a copy of a store from the store, are the sync's
//! (`src/sync/lineage.rs`).

use sqlx::SqlitePool;

/// Begins a new incarnation of the store behind `writer` (called by `Store::open` after its
/// migrations, before anything is written).
pub async fn begin_incarnation(writer: &SqlitePool) -> Result<(), sqlx::Error> {
    sqlx::query(
        "INSERT INTO sync_lineage (incarnation, born_after, started_at_ms)
         VALUES (lower(hex(randomblob(16))),
                 MAX(COALESCE((SELECT seq FROM sqlite_sequence WHERE name = 'sync_outbox'), 0),
                     COALESCE((SELECT MAX(seq) FROM sync_outbox), 0)),
                 CAST((julianday('now') - 2440587.5) * 86400000.0 AS INTEGER))",
    )
    .execute(writer)
    .await?;
    Ok(())
}
