//! Reading the lab's central PostgreSQL database (filled by `src/sync/`) back into the store's
//! own records, so that reports and exports built from it go through exactly the code that
//! builds them from a station's SQLite store.
//!
//! The central tables mirror the station tables with `station` in front of every key
//! (`migrations-central/`), so the station's row types ([`ScanRow`], [`FitRow`], …) decode the
//! central rows unchanged: same column names, same bytes, same parsing. What differs is only
//! the SQL: every join also matches `station`, and rows are fetched in bulk (one query per
//! table for the whole selection, not one per scan), which is what keeps a 10,000-scan report
//! from waiting on 50,000 round trips.

use std::collections::HashMap;

use sqlx::postgres::PgRow;
use sqlx::{FromRow, PgPool, Row};

use super::StoreError;
use super::codec::{self, ReadingRow};
use super::fits::FitRow;
use super::ids::{ReferenceId, ScanId};
use super::records::{FitRun, Processed, Reading, ReferenceDetail, ScanDetail, provenance_columns};
use super::references::ReferenceRow;
use super::scans::{ProcessedRow, ScanRow};

/// One scan of the central database with everything a report needs.
#[derive(Debug, Clone, PartialEq)]
pub struct CentralScan {
    pub station: String,
    pub detail: ScanDetail,
    /// Its processed versions, by id.
    pub processed: Vec<Processed>,
    /// Its fit runs, oldest first.
    pub fits: Vec<FitRun>,
    /// What each fit run's detail adds (migration 0011, forwarded by central step 0002), by
    /// fit run id; the report parses it.
    pub fit_extras: HashMap<i64, FitExtrasText>,
}

/// A fit run's bootstrap intervals and evaluation colorimetry as stored (text columns).
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct FitExtrasText {
    pub uncertainty_json: Option<String>,
    /// The cross-validation (migration 0030, forwarded by central step 0017).
    pub crossval_json: Option<String>,
    pub observer: Option<String>,
    pub weighting: Option<String>,
}

/// Which scans of the central database.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct CentralSelection {
    /// One station's, or every station's.
    pub station: Option<String>,
    /// These local scan ids (of `station`), in this order; `None`: every complete scan, by
    /// station and id.
    pub scans: Option<Vec<i64>>,
}

/// The selected scans as a CTE `sel (station, id, reference_id)`; `$1` station or NULL, `$2`
/// scan ids or NULL (then complete scans only).
const SELECTED: &str = "\
    WITH sel AS (
        SELECT s.station, s.id, s.reference_id FROM scans s
        WHERE ($1::text IS NULL OR s.station = $1)
          AND CASE WHEN $2::bigint[] IS NULL THEN s.state = 'complete'
                   ELSE s.id = ANY($2) END)";

type Key = (String, i64);

async fn fetch(
    pool: &PgPool,
    sql: &str,
    station: Option<&str>,
    ids: Option<&[i64]>,
) -> Result<Vec<PgRow>, sqlx::Error> {
    sqlx::query(sql)
        .bind(station)
        .bind(ids)
        .fetch_all(pool)
        .await
}

fn key(row: &PgRow, column: &str) -> Result<Key, sqlx::Error> {
    Ok((row.try_get("station")?, row.try_get(column)?))
}

/// The readings `sql` selects from `table`, by station and the id in `key_column` (the scan
/// or reference set they belong to), each list in geometry-table order.
async fn readings_by(
    pool: &PgPool,
    sql: &str,
    station: Option<&str>,
    ids: Option<&[i64]>,
    key_column: &str,
    table: &'static str,
) -> Result<HashMap<Key, Vec<Reading>>, StoreError> {
    let mut readings: HashMap<Key, Vec<Reading>> = HashMap::new();
    for row in fetch(pool, sql, station, ids).await? {
        let k = key(&row, key_column)?;
        let reading = ReadingRow::from_row(&row)?.into_reading(table)?;
        readings.entry(k).or_default().push(reading);
    }
    for r in readings.values_mut() {
        codec::sort_readings(r);
    }
    Ok(readings)
}

/// Every selected scan with its readings, reference, processed versions and fit runs.
pub async fn load_scans(
    pool: &PgPool,
    selection: &CentralSelection,
) -> Result<Vec<CentralScan>, StoreError> {
    let station = selection.station.as_deref();
    let ids = selection.scans.as_deref();
    let provenance_s = provenance_columns("s");
    let provenance_r = provenance_columns("r");
    // Scans.
    let scan_rows = fetch(
        pool,
        &format!(
            "{SELECTED}
         SELECT s.station, s.id, s.sample_id, sa.name AS sample, s.reference_id, s.state,
                s.reason, s.requested_at_ms, s.started_at_ms, s.finished_at_ms, s.geometries,
                (SELECT COUNT(*) FROM readings r WHERE r.station = s.station AND r.scan_id = s.id)
                    AS reading_count,
                {provenance_s}
         FROM sel JOIN scans s ON s.station = sel.station AND s.id = sel.id
         JOIN samples sa ON sa.station = s.station AND sa.id = s.sample_id
         ORDER BY s.station, s.id"
        ),
        station,
        ids,
    )
    .await?;
    // Readings of the scans.
    let mut readings = readings_by(
        pool,
        &format!(
            "{SELECTED}
         SELECT r.station, r.scan_id, r.id, r.device, r.geometry, r.values_f64le, r.raw_frame,
                r.received_at_ms AS at_ms
         FROM sel JOIN readings r ON r.station = sel.station AND r.scan_id = sel.id"
        ),
        station,
        ids,
        "scan_id",
        "readings",
    )
    .await?;
    // Their reference sets and the sets' readings.
    let mut references: HashMap<Key, ReferenceDetail> = HashMap::new();
    for row in fetch(
        pool,
        &format!(
            "{SELECTED}
         SELECT r.station, r.id, r.name, r.status, r.reason, r.rho_ref, r.taken_at_ms,
                r.completed_at_ms, r.kind, r.geometries,
                (SELECT COUNT(*) FROM reference_readings rr
                 WHERE rr.station = r.station AND rr.reference_id = r.id) AS reading_count,
                {provenance_r}
         FROM reference_sets r
         WHERE (r.station, r.id) IN (SELECT station, reference_id FROM sel)"
        ),
        station,
        ids,
    )
    .await?
    {
        let k = key(&row, "id")?;
        let summary = ReferenceRow::from_row(&row)?.into_summary()?;
        references.insert(
            k,
            ReferenceDetail {
                reference: summary,
                readings: Vec::new(),
            },
        );
    }
    let reference_readings = readings_by(
        pool,
        &format!(
            "{SELECTED}
         SELECT rr.station, rr.reference_id, rr.id, rr.device, rr.geometry, rr.values_f64le,
                rr.raw_frame, rr.taken_at_ms AS at_ms
         FROM reference_readings rr
         WHERE (rr.station, rr.reference_id) IN (SELECT station, reference_id FROM sel)"
        ),
        station,
        ids,
        "reference_id",
        "reference_readings",
    )
    .await?;
    for (k, set_readings) in reference_readings {
        if let Some(r) = references.get_mut(&k) {
            r.readings = set_readings;
        }
    }
    // Processed versions.
    let mut processed: HashMap<Key, Vec<Processed>> = HashMap::new();
    for row in fetch(
        pool,
        &format!(
            "{SELECTED}
         SELECT p.station, p.id, p.scan_id, p.specular, p.brdf_f64le, p.created_at_ms,
                s.geometries
         FROM sel JOIN processed p ON p.station = sel.station AND p.scan_id = sel.id
              JOIN scans s ON s.station = p.station AND s.id = p.scan_id
         ORDER BY p.station, p.id"
        ),
        station,
        ids,
    )
    .await?
    {
        let k = key(&row, "scan_id")?;
        processed
            .entry(k)
            .or_default()
            .push(ProcessedRow::from_row(&row)?.into_processed()?);
    }
    // Fit runs.
    let mut fits: HashMap<Key, Vec<FitRun>> = HashMap::new();
    let mut extras: HashMap<Key, HashMap<i64, FitExtrasText>> = HashMap::new();
    for row in fetch(
        pool,
        &format!(
            "{SELECTED}
         SELECT f.station, f.id, f.scan_id, f.processed_id, p.specular, f.method,
                f.cost_function, f.settings_json, f.seed, f.fit_observer, f.fit_weighting,
                f.status, f.error, f.cost,
                f.params_json, f.best_cost_per_generation_json, f.evaluations, f.generations,
                f.wall_ms, f.queued_at_ms, f.started_at_ms, f.finished_at_ms,
                f.uncertainty_json, f.crossval_json, e.observer, e.weighting
         FROM sel JOIN fit_runs f ON f.station = sel.station AND f.scan_id = sel.id
         JOIN processed p ON p.station = f.station AND p.id = f.processed_id
         LEFT JOIN evaluation_summaries e ON e.station = f.station AND e.fit_run_id = f.id
         ORDER BY f.station, f.id"
        ),
        station,
        ids,
    )
    .await?
    {
        let k = key(&row, "scan_id")?;
        let run = FitRow::from_row(&row)?.into_run()?;
        extras.entry(k.clone()).or_default().insert(
            run.id.0,
            FitExtrasText {
                uncertainty_json: row.try_get("uncertainty_json")?,
                crossval_json: row.try_get("crossval_json")?,
                observer: row.try_get("observer")?,
                weighting: row.try_get("weighting")?,
            },
        );
        fits.entry(k).or_default().push(run);
    }
    let mut out = Vec::with_capacity(scan_rows.len());
    for row in &scan_rows {
        let k = key(row, "id")?;
        let summary = ScanRow::from_row(row)?.into_summary()?;
        let reference = references
            .get(&(k.0.clone(), summary.reference_id.0))
            .cloned()
            .ok_or(StoreError::NotFound {
                what: ReferenceId::WHAT,
                id: summary.reference_id.0,
            })?;
        out.push(CentralScan {
            station: k.0.clone(),
            detail: ScanDetail {
                scan: summary,
                readings: readings.remove(&k).unwrap_or_default(),
                reference,
            },
            processed: processed.remove(&k).unwrap_or_default(),
            fits: fits.remove(&k).unwrap_or_default(),
            fit_extras: extras.remove(&k).unwrap_or_default(),
        });
    }
    if let Some(ids) = ids {
        // The order asked for; an id the station does not have is an error, as in SQLite.
        let mut ordered = Vec::with_capacity(ids.len());
        for id in ids {
            let i =
                out.iter()
                    .position(|s| s.detail.scan.id.0 == *id)
                    .ok_or(StoreError::NotFound {
                        what: ScanId::WHAT,
                        id: *id,
                    })?;
            ordered.push(out[i].clone());
        }
        return Ok(ordered);
    }
    Ok(out)
}
