//! Store verbs of imports by file: the scans of one file and the record of its content hash,
//! written in one transaction, so that a file is either imported whole and known as imported,
//! or not at all.
//!
//! Every door records each imported scan's file (`scan_imports`, `migrations/0031_scan_imports.sql`):
//! the SHA-256 of the bytes, the file name, when; [`Store::import_scans`] (`brdfd import`,
//! `POST /scans/import`) and [`Store::import_file`] (the watch folder) look the hash up inside
//! their write transaction, so the same bytes through any door give their scans once unless
//! asked again ([`PriorImport`]). An instrument export's SHA-256 is also in its scans'
//! provenance (`…; sha256 HEX; …`), and in that of a scan file converted from it (`brdfd
//! import-format`, among its origin notes): the lookup takes both ways, so an export and its
//! conversion are one measurement, whichever comes second. The watch folder also keeps its own record of each dropped
//! file (`ingested_files`, `migrations/0012_ingest.sql`), which its crash recovery and the
//! queueing of its fits read.

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
    /// The watch folder imported a file with the same content before; nothing was written.
    AlreadyImported(IngestedFile),
    /// The same content came in through another door before (`brdfd import`,
    /// `POST /scans/import`); nothing was written.
    ImportedElsewhere(PriorImport),
}

/// The file an import's scans come from: its content hash and its name.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ImportFile<'a> {
    /// SHA-256 of the bytes received, 64 lower-case hex digits.
    pub sha256: &'a str,
    /// The file's name (no directory), when the door knows it.
    pub file_name: Option<&'a str>,
}

/// An earlier import of the same content, as every door answers a repeat.
#[derive(Debug, Clone, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct PriorImport {
    /// SHA-256 of the content, 64 lower-case hex digits.
    pub sha256: String,
    /// Every scan imported from it, oldest first (more than one file's worth when it was
    /// imported again on purpose).
    pub scans: Vec<ScanId>,
    /// The name of the file of the first import, when known.
    pub file_name: Option<String>,
    /// When the first import was made, ms since the epoch.
    pub imported_at_ms: i64,
}

/// What [`Store::import_scans`] did.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum ScansImport {
    /// The scans were stored (with their file, when one was given), in the order given.
    Imported(Vec<ScanId>),
    /// The same content was imported before and `again` was not asked; nothing was written.
    AlreadyImported(PriorImport),
}

fn check_sha256(sha256: &str) -> Result<(), StoreError> {
    if sha256.len() != 64 || !sha256.bytes().all(|b| b.is_ascii_hexdigit()) {
        return Err(StoreError::Empty {
            field: "content hash (64 hex digits)",
        });
    }
    Ok(())
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
        check_sha256(sha256)?;
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
        if let Some(prior) = prior_by_hash(&mut tx, sha256).await? {
            return Ok(FileImport::ImportedElsewhere(prior));
        }
        if let Some(prior) = prior_of_sources(&mut tx, scans, sha256).await? {
            return Ok(FileImport::ImportedElsewhere(prior));
        }
        let now = now_ms();
        let shown = match partner_name {
            Some(p) => format!("{file_name} and {p}"),
            None => file_name.to_string(),
        };
        let file = ImportFile {
            sha256,
            file_name: Some(&shown),
        };
        let mut ids = Vec::with_capacity(scans.len());
        for s in scans {
            let id = s.insert(&mut tx, now).await?.1;
            record_import(&mut tx, id, &file, now).await?;
            ids.push(id);
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

    /// Imports the scans of one file in one transaction, each processed like
    /// [`Store::import`]. With `file`, each scan records it, and unless `again` a file whose
    /// hash is recorded already (through any door) writes nothing and gives the earlier
    /// import; without, the scans are stored as they are (a demo's, a test's). Every scan is
    /// checked before anything is written.
    pub async fn import_scans(
        &self,
        file: Option<&ImportFile<'_>>,
        scans: &[ImportedScan<'_>],
        again: bool,
    ) -> Result<ScansImport, StoreError> {
        if let Some(f) = file {
            check_sha256(f.sha256)?;
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
        if let Some(f) = file
            && !again
        {
            if let Some(prior) = prior_by_hash(&mut tx, f.sha256).await? {
                return Ok(ScansImport::AlreadyImported(prior));
            }
            if let Some(prior) = prior_of_sources(&mut tx, scans, f.sha256).await? {
                return Ok(ScansImport::AlreadyImported(prior));
            }
        }
        let now = now_ms();
        let mut ids = Vec::with_capacity(scans.len());
        for s in scans {
            let id = s.insert(&mut tx, now).await?.1;
            if let Some(f) = file {
                record_import(&mut tx, id, f, now).await?;
            }
            ids.push(id);
        }
        tx.commit().await?;
        Ok(ScansImport::Imported(ids))
    }

    /// The imports of the content with this hash through any door, if any.
    pub async fn prior_import(&self, sha256: &str) -> Result<Option<PriorImport>, StoreError> {
        let mut conn = self.reader.acquire().await?;
        prior_by_hash(&mut conn, sha256).await
    }

    /// The file a scan was imported from, if it was imported from one whose hash is known.
    pub async fn scan_import(&self, scan: ScanId) -> Result<Option<PriorImport>, StoreError> {
        let row: Option<(String, Option<String>, i64)> = sqlx::query_as(
            "SELECT sha256, file_name, imported_at_ms FROM scan_imports WHERE scan_id = $1",
        )
        .bind(scan.0)
        .fetch_optional(&self.reader)
        .await?;
        Ok(row.map(|(sha256, file_name, imported_at_ms)| PriorImport {
            sha256,
            scans: vec![scan],
            file_name,
            imported_at_ms,
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

/// Records that scan `id` was imported from `file` at `now`.
async fn record_import(
    tx: &mut sqlx::SqliteConnection,
    id: ScanId,
    file: &ImportFile<'_>,
    now: i64,
) -> Result<(), StoreError> {
    sqlx::query(
        "INSERT INTO scan_imports (scan_id, sha256, file_name, imported_at_ms)
         VALUES ($1, $2, $3, $4)",
    )
    .bind(id.0)
    .bind(file.sha256.to_ascii_lowercase())
    .bind(file.file_name)
    .bind(now)
    .execute(&mut *tx)
    .await?;
    Ok(())
}

/// Every import of the content with this hash: its scans, and the first one's file and time.
/// The SHA-256 of the instrument export a scan's provenance names (`…; sha256 HEX; …`, what an
/// X-Rite export's import, and a scan file converted from one by `brdfd import-format`, record
/// of the export), if it names one.
fn source_sha256(detail: &str) -> Option<&str> {
    let at = detail.find("sha256 ")? + "sha256 ".len();
    let hex = detail.get(at..at + 64)?;
    hex.bytes().all(|b| b.is_ascii_hexdigit()).then_some(hex)
}

/// An earlier import of the instrument export one of `scans` was converted from (its
/// provenance names the export's hash): the same measurement, through another file. The
/// file's own hash `looked_up` (an export's import names itself) is not looked up again.
async fn prior_of_sources(
    conn: &mut sqlx::SqliteConnection,
    scans: &[ImportedScan<'_>],
    looked_up: &str,
) -> Result<Option<PriorImport>, StoreError> {
    let mut hashes: Vec<&str> = scans
        .iter()
        .filter_map(|s| {
            s.provenance
                .source_detail
                .as_deref()
                .and_then(source_sha256)
        })
        .filter(|h| !h.eq_ignore_ascii_case(looked_up))
        .collect();
    // The scans of one export name the same hash: one lookup each.
    hashes.sort_unstable();
    hashes.dedup();
    for hash in hashes {
        if let Some(prior) = prior_by_hash(conn, hash).await? {
            return Ok(Some(prior));
        }
    }
    Ok(None)
}

/// The imports of the content with this hash: the scans imported from a file with these bytes,
/// and the imported scans whose provenance names it as the export they came from (a scan
/// file converted from the export, or the export itself when a conversion was imported first).
async fn prior_by_hash(
    conn: &mut sqlx::SqliteConnection,
    sha256: &str,
) -> Result<Option<PriorImport>, StoreError> {
    let sha256 = sha256.to_ascii_lowercase();
    let rows: Vec<(i64, Option<String>, i64)> = sqlx::query_as(
        "SELECT s.id, i.file_name, COALESCE(i.imported_at_ms, s.requested_at_ms) AS at_ms
         FROM scans s LEFT JOIN scan_imports i ON i.scan_id = s.id
         WHERE i.sha256 = $1
            OR (s.source = 'imported' AND instr(s.source_detail, 'sha256 ' || $1) > 0)
         ORDER BY at_ms, s.id",
    )
    .bind(&sha256)
    .fetch_all(&mut *conn)
    .await?;
    let Some((_, file_name, imported_at_ms)) = rows.first().cloned() else {
        return Ok(None);
    };
    Ok(Some(PriorImport {
        sha256,
        scans: rows.into_iter().map(|(id, _, _)| ScanId(id)).collect(),
        file_name,
        imported_at_ms,
    }))
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::Device;
    use crate::store::{NewReading, Provenance, ReadingValues, Source};

    #[test]
    fn the_export_hash_a_provenance_names_is_read_whole_or_not_at_all() {
        let hex = "ab".repeat(32);
        let detail = format!("X-Rite QC export PAR_1.xlsx; job J; sha256 {hex}; standard S");
        assert_eq!(source_sha256(&detail), Some(hex.as_str()));
        assert_eq!(source_sha256(&format!("sha256 {hex}")), Some(hex.as_str()));
        // Too short, or not hex: no hash.
        assert_eq!(source_sha256(&format!("sha256 {}", &hex[..63])), None);
        assert_eq!(source_sha256(&format!("sha256 {}zz", &hex[..62])), None);
        assert_eq!(source_sha256("brdfd.scan/1 file a.scan.json"), None);
    }

    fn readings() -> Vec<NewReading<'static>> {
        crate::geometry::ma_t12()
            .iter()
            .map(|g| NewReading {
                device: Device::MaT12,
                geometry: g,
                values: ReadingValues::Spectrum(std::array::from_fn(|b| {
                    0.2 + 0.01 * g.index as f64 + 0.001 * b as f64
                })),
                raw_frame: &[],
            })
            .collect()
    }

    fn scan<'a>(provenance: &'a Provenance, readings: &'a [NewReading<'a>]) -> ImportedScan<'a> {
        ImportedScan {
            sample_name: "PAR_PW_RO_NG_1",
            reference_name: "instrument calibration",
            provenance,
            reference_readings: None,
            readings,
            taken_at_ms: Some(1_723_000_000_000),
            textures: &[],
        }
    }

    async fn count(store: &Store) -> i64 {
        sqlx::query_scalar("SELECT count(*) FROM scans")
            .fetch_one(&store.reader)
            .await
            .unwrap()
    }

    #[tokio::test]
    async fn the_same_content_through_any_door_is_imported_once_unless_again() {
        let store = Store::open_in_memory().await.unwrap();
        let provenance = Provenance {
            source: Source::Imported,
            ..Provenance::unknown()
        };
        let r = readings();
        let two = [scan(&provenance, &r), scan(&provenance, &r)];
        let hash = "ab".repeat(32);
        let file = ImportFile {
            sha256: &hash,
            file_name: Some("PAR_PW_RO_NG_1.xlsx"),
        };
        let ScansImport::Imported(first) =
            store.import_scans(Some(&file), &two, false).await.unwrap()
        else {
            panic!("not imported")
        };
        assert_eq!(first.len(), 2);
        // Again, under another name (the hash in capitals): the first import, nothing written.
        let upper = hash.to_ascii_uppercase();
        let renamed = ImportFile {
            sha256: &upper,
            file_name: Some("copy.xlsx"),
        };
        let again = store
            .import_scans(Some(&renamed), &two, false)
            .await
            .unwrap();
        let ScansImport::AlreadyImported(prior) = again else {
            panic!("{again:?}")
        };
        assert_eq!(prior.scans, first);
        assert_eq!(prior.file_name.as_deref(), Some("PAR_PW_RO_NG_1.xlsx"));
        assert_eq!(prior.sha256, hash);
        assert_eq!(count(&store).await, 2);
        // The watch folder sees it too, under any name.
        let dropped = store
            .import_file(&hash, "dropped.xlsx", None, &two)
            .await
            .unwrap();
        assert!(
            matches!(&dropped, FileImport::ImportedElsewhere(p) if p.scans == first),
            "{dropped:?}"
        );
        assert_eq!(count(&store).await, 2);
        // Asked again: two more scans, and the earlier imports then name all four.
        let ScansImport::Imported(forced) =
            store.import_scans(Some(&file), &two, true).await.unwrap()
        else {
            panic!("not imported again")
        };
        assert_eq!(count(&store).await, 4);
        let prior = store.prior_import(&hash).await.unwrap().unwrap();
        assert_eq!(prior.scans, [first.clone(), forced].concat());
        assert_eq!(
            store
                .scan_import(first[1])
                .await
                .unwrap()
                .unwrap()
                .file_name,
            Some("PAR_PW_RO_NG_1.xlsx".to_string())
        );
        // Without a file, nothing is recorded or looked up (a demo's scans).
        let ScansImport::Imported(plain) = store.import_scans(None, &two, false).await.unwrap()
        else {
            panic!("not imported")
        };
        assert_eq!(store.scan_import(plain[0]).await.unwrap(), None);
    }

    #[tokio::test]
    async fn a_file_dropped_first_is_known_to_the_other_doors() {
        let store = Store::open_in_memory().await.unwrap();
        let provenance = Provenance::unknown();
        let r = readings();
        let one = [scan(&provenance, &r)];
        let hash = "cd".repeat(32);
        let FileImport::Imported(dropped) = store
            .import_file(&hash, "a.cgats", Some("a.sra.csv"), &one)
            .await
            .unwrap()
        else {
            panic!("not imported")
        };
        let file = ImportFile {
            sha256: &hash,
            file_name: Some("upload"),
        };
        let again = store.import_scans(Some(&file), &one, false).await.unwrap();
        let ScansImport::AlreadyImported(prior) = again else {
            panic!("{again:?}")
        };
        assert_eq!(prior.scans, dropped.scans);
        assert_eq!(prior.file_name.as_deref(), Some("a.cgats and a.sra.csv"));
    }

    /// The backfill of `migrations/0031_scan_imports.sql`, run again over rows as they were
    /// before it: the watch folder's imports from `ingested_files`, `.xlsx` uploads from the
    /// SHA-256 their provenance records, other uploads left out.
    #[tokio::test]
    async fn existing_imports_are_backfilled_where_their_hash_is_known() {
        let store = Store::open_in_memory().await.unwrap();
        let r = readings();
        let sha = "0123456789abcdef".repeat(4);
        let uploaded = Provenance {
            source: Source::Imported,
            source_detail: Some(format!(
                "uploaded X-Rite QC .xlsx export; X-Rite QC export the uploaded .xlsx; job J; \
                 sha256 {sha}; standard S"
            )),
            ..Provenance::unknown()
        };
        let scan_file = Provenance {
            source: Source::Imported,
            source_detail: Some("brdfd.scan/1 file".into()),
            ..Provenance::unknown()
        };
        let (_, xlsx) = store.import(&scan(&uploaded, &r)).await.unwrap();
        let (_, plain) = store.import(&scan(&scan_file, &r)).await.unwrap();
        let watch_hash = "ef".repeat(32);
        let FileImport::Imported(dropped) = store
            .import_file(&watch_hash, "d.xlsx", None, &[scan(&scan_file, &r)])
            .await
            .unwrap()
        else {
            panic!("not imported")
        };
        sqlx::query("DELETE FROM scan_imports")
            .execute(&store.writer)
            .await
            .unwrap();
        let migration = include_str!("../../migrations/0031_scan_imports.sql");
        let backfill = &migration[migration.find("INSERT INTO scan_imports").unwrap()..];
        sqlx::raw_sql(backfill)
            .execute(&store.writer)
            .await
            .unwrap();
        let row = store.scan_import(xlsx).await.unwrap().unwrap();
        assert_eq!((row.sha256.as_str(), row.file_name), (sha.as_str(), None));
        assert_eq!(store.scan_import(plain).await.unwrap(), None);
        let row = store.scan_import(dropped.scans[0]).await.unwrap().unwrap();
        assert_eq!(row.sha256, watch_hash);
        assert_eq!(row.file_name.as_deref(), Some("d.xlsx"));
    }
}
