//! The store's lineage record: each opening for writing appends a new incarnation to
//! `sync_lineage` (station migrations `0017_sync_lineage.sql`, `0021_sync_lineage_file.sql`)
//! with the file it was opened in, and a clean close marks it closed. What the incarnations
//! mean for forwarding, and the rule that tells a copy of a store from the store, are the
//! sync's (`src/sync/lineage.rs`).

use std::path::Path;

use sqlx::SqlitePool;

/// The identity of the file at `path` (device and inode), `None` where it cannot be read.
pub fn file_id(path: &Path) -> Option<String> {
    #[cfg(unix)]
    {
        use std::os::unix::fs::MetadataExt;
        let m = std::fs::metadata(path).ok()?;
        Some(format!("{}:{}", m.dev(), m.ino()))
    }
    #[cfg(not(unix))]
    {
        let _ = path;
        None
    }
}

/// Begins a new incarnation of the store behind `writer`, opened in the file `file_id`
/// (called by `Store::open` after its migrations, before anything is written). It is marked
/// `copied` when the incarnation before it wrote another file and was never closed: this
/// file is a copy of a store taken while it was open.
pub async fn begin_incarnation(
    writer: &SqlitePool,
    file_id: Option<&str>,
) -> Result<(), sqlx::Error> {
    sqlx::query(
        "INSERT INTO sync_lineage (incarnation, born_after, started_at_ms, file_id, copied)
         VALUES (lower(hex(randomblob(16))),
                 MAX(COALESCE((SELECT seq FROM sqlite_sequence WHERE name = 'sync_outbox'), 0),
                     COALESCE((SELECT MAX(seq) FROM sync_outbox), 0)),
                 CAST((julianday('now') - 2440587.5) * 86400000.0 AS INTEGER),
                 $1,
                 COALESCE((SELECT file_id IS NOT NULL AND $1 IS NOT NULL AND file_id <> $1
                                  AND closed_at_ms IS NULL
                           FROM sync_lineage ORDER BY seq DESC LIMIT 1), 0))",
    )
    .bind(file_id)
    .execute(writer)
    .await?;
    Ok(())
}

/// Marks the incarnation writing now as closed cleanly (`Store::close`): a copy of the file
/// taken from now on is a store moved, not a copy of a running one.
pub async fn end_incarnation(writer: &SqlitePool) -> Result<(), sqlx::Error> {
    sqlx::query(
        "UPDATE sync_lineage
         SET closed_at_ms = CAST((julianday('now') - 2440587.5) * 86400000.0 AS INTEGER)
         WHERE seq = (SELECT MAX(seq) FROM sync_lineage)",
    )
    .execute(writer)
    .await?;
    Ok(())
}
