//! Store verbs of the watch folder (`[ingest] watch`, `src/service/ingest.rs`): the scans of one
//! dropped file and the record of its content hash, written in one transaction, so that a file
//! is either imported whole and known as imported, or not at all (`migrations/0012_ingest.sql`).

use super::ids::ScanId;
use super::scans::ImportedScan;
use super::{Store, StoreError, now_ms};

/// A file the watch folder imported.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct IngestedFile {
    pub id: i64,
    /// SHA-256 of the content, 64 lower-case hex digits.
    pub sha256: String,
    pub file_name: String,
    pub partner_name: Option<String>,
    pub imported_at_ms: i64,
    /// Whether its scans have been processed and their fits queued.
    pub fits_queued: bool,
    /// Its scans, in the file's order.
    pub scans: Vec<ScanId>,
}

/// What [`Store::import_file`] did.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum FileImport {
    /// The scans were stored with the file's hash.
    Imported(IngestedFile),
    /// A file with the same content was imported before; nothing was written.
    AlreadyImported(IngestedFile),
}

impl Store {
    /// Imports the scans of one file and records its content hash, in one transaction; when
    /// the hash is already recorded nothing is written and the earlier import is returned.
    /// Every scan is checked before anything is written.
    pub async fn import_file(
        &self,
        sha256: &str,
        file_name: &str,
        partner_name: Option<&str>,
        scans: &[ImportedScan<'_>],
    ) -> Result<FileImport, StoreError> {
        if sha256.len() != 64 || !sha256.bytes().all(|b| b.is_ascii_hexdigit()) {
            return Err(StoreError::Empty {
                field: "content hash (64 hex digits)",
            });
        }
        if scans.is_empty() {
            return Err(StoreError::Empty {
                field: "scans of the file",
            });
        }
        for s in scans {
            s.check()?;
        }
        let mut tx = self.writer.begin().await?;
        // Inside the write transaction: no other writer can record the same hash meanwhile.
        if let Some(done) = ingested_by_hash(&mut tx, sha256).await? {
            return Ok(FileImport::AlreadyImported(done));
        }
        let now = now_ms();
        let mut ids = Vec::with_capacity(scans.len());
        for s in scans {
            ids.push(s.insert(&mut tx, now).await?.1);
        }
        let id: i64 = sqlx::query_scalar(
            "INSERT INTO ingested_files (sha256, file_name, partner_name, imported_at_ms)
             VALUES ($1, $2, $3, $4) RETURNING id",
        )
        .bind(sha256)
        .bind(file_name)
        .bind(partner_name)
        .bind(now)
        .fetch_one(&mut *tx)
        .await?;
        for (position, scan) in ids.iter().enumerate() {
            sqlx::query(
                "INSERT INTO ingested_scans (ingested_file_id, position, scan_id)
                 VALUES ($1, $2, $3)",
            )
            .bind(id)
            .bind(position as i64)
            .bind(scan.0)
            .execute(&mut *tx)
            .await?;
        }
        tx.commit().await?;
        Ok(FileImport::Imported(IngestedFile {
            id,
            sha256: sha256.to_string(),
            file_name: file_name.to_string(),
            partner_name: partner_name.map(str::to_string),
            imported_at_ms: now,
            fits_queued: false,
            scans: ids,
        }))
    }

    /// The file imported with this content hash, if any.
    pub async fn ingested_file(&self, sha256: &str) -> Result<Option<IngestedFile>, StoreError> {
        let mut conn = self.reader.acquire().await?;
        ingested_by_hash(&mut conn, sha256).await
    }

    /// Every file imported, oldest first.
    pub async fn ingested_files(&self) -> Result<Vec<IngestedFile>, StoreError> {
        let mut conn = self.reader.acquire().await?;
        let hashes: Vec<String> =
            sqlx::query_scalar("SELECT sha256 FROM ingested_files ORDER BY id")
                .fetch_all(&mut *conn)
                .await?;
        let mut out = Vec::with_capacity(hashes.len());
        for h in hashes {
            out.extend(ingested_by_hash(&mut conn, &h).await?);
        }
        Ok(out)
    }

    /// Imported files whose scans still wait to be processed and fitted (a daemon stopped
    /// between the import and queueing its fits), oldest first.
    pub async fn ingested_awaiting_fits(&self) -> Result<Vec<IngestedFile>, StoreError> {
        let all = self.ingested_files().await?;
        Ok(all.into_iter().filter(|f| !f.fits_queued).collect())
    }

    /// Records that the scans of imported file `id` have been processed and their fits queued.
    pub async fn mark_ingest_fits_queued(&self, id: i64) -> Result<(), StoreError> {
        sqlx::query("UPDATE ingested_files SET fits_queued = 1 WHERE id = $1")
            .bind(id)
            .execute(&self.writer)
            .await?;
        Ok(())
    }
}

async fn ingested_by_hash(
    conn: &mut sqlx::SqliteConnection,
    sha256: &str,
) -> Result<Option<IngestedFile>, StoreError> {
    let row: Option<(i64, String, String, Option<String>, i64, i64)> = sqlx::query_as(
        "SELECT id, sha256, file_name, partner_name, imported_at_ms, fits_queued
         FROM ingested_files WHERE sha256 = $1",
    )
    .bind(sha256)
    .fetch_optional(&mut *conn)
    .await?;
    let Some((id, sha256, file_name, partner_name, imported_at_ms, fits_queued)) = row else {
        return Ok(None);
    };
    let scans: Vec<i64> = sqlx::query_scalar(
        "SELECT scan_id FROM ingested_scans WHERE ingested_file_id = $1 ORDER BY position",
    )
    .bind(id)
    .fetch_all(&mut *conn)
    .await?;
    Ok(Some(IngestedFile {
        id,
        sha256,
        file_name,
        partner_name,
        imported_at_ms,
        fits_queued: fits_queued != 0,
        scans: scans.into_iter().map(ScanId).collect(),
    }))
}
