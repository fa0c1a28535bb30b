//! Store verbs for scans, their readings, and processed scans.
//!
//! A scan goes requested → measuring → complete | failed | aborted. Each verb moves it with one
//! conditional UPDATE (`… WHERE state = 'measuring'`), so the rule holds even if two tasks race,
//! and only reads the row again to explain a refusal.

use crate::geometry::{Device, GEOMETRY_COUNT, Geometry, MA_T12_COUNT};
use crate::processing::{MeasuredBrdf, SpecularStrategy};
use crate::spectral::wavelengths_nm;

use super::backend::{self, Db};
use super::codec::{self, ReadingRow};
use super::guarded::{refused, state_of};
use super::ids::{ProcessedId, ReadingId, ReferenceId, SampleId, ScanId};
use super::records::{
    NewReading, Processed, Provenance, ProvenanceRow, ReadingValues, ReferenceStatus, ScanDetail,
    ScanFilter, ScanState, ScanSummary, provenance_columns,
};
use super::{Store, StoreError, now_ms};

/// `scans.geometries` of a scan with all 14 geometries.
pub(super) const GEOMETRIES_ALL: &str = "all";
/// `scans.geometries` of a scan without SRA readings: the 12 MA-T12 geometries.
pub(super) const GEOMETRIES_MA_T12: &str = "ma-t12";

/// The `scans.geometries` value of a geometry set the store keeps.
pub(super) fn geometries_key(specular_readings: bool) -> &'static str {
    if specular_readings {
        GEOMETRIES_ALL
    } else {
        GEOMETRIES_MA_T12
    }
}

/// The reason [`Store::mark_interrupted_scans_failed`] records.
pub const INTERRUPTED_REASON: &str = "daemon stopped during the scan";

#[derive(sqlx::FromRow)]
pub(super) struct ScanRow {
    id: i64,
    sample_id: i64,
    sample: String,
    reference_id: i64,
    state: String,
    reason: Option<String>,
    requested_at_ms: i64,
    started_at_ms: Option<i64>,
    finished_at_ms: Option<i64>,
    geometries: String,
    reading_count: i64,
    #[sqlx(flatten)]
    provenance: ProvenanceRow,
}

/// The scans' summary columns.
static SCAN_SUMMARY: std::sync::LazyLock<String> = std::sync::LazyLock::new(|| {
    format!(
        "SELECT s.id, s.sample_id, sa.name AS sample, s.reference_id, s.state, s.reason,
                s.requested_at_ms, s.started_at_ms, s.finished_at_ms, s.geometries,
                (SELECT COUNT(*) FROM readings r WHERE r.scan_id = s.id) AS reading_count,
                {}
         FROM scans s JOIN samples sa ON sa.id = s.sample_id",
        provenance_columns("s")
    )
});

impl ScanRow {
    pub(super) fn into_summary(self) -> Result<ScanSummary, StoreError> {
        let state = self.state.parse().map_err(|detail| StoreError::Corrupt {
            table: "scans",
            id: self.id,
            detail,
        })?;
        Ok(ScanSummary {
            id: ScanId(self.id),
            sample_id: SampleId(self.sample_id),
            sample: self.sample,
            reference_id: ReferenceId(self.reference_id),
            state,
            reason: self.reason,
            requested_at_ms: self.requested_at_ms,
            started_at_ms: self.started_at_ms,
            finished_at_ms: self.finished_at_ms,
            reading_count: self.reading_count as usize,
            specular_readings: match self.geometries.as_str() {
                GEOMETRIES_ALL => true,
                GEOMETRIES_MA_T12 => false,
                other => {
                    return Err(StoreError::Corrupt {
                        table: "scans",
                        id: self.id,
                        detail: format!("unknown geometries \"{other}\""),
                    });
                }
            },
            provenance: self
                .provenance
                .into_provenance(self.geometries != GEOMETRIES_MA_T12)
                .map_err(|detail| StoreError::Corrupt {
                    table: "scans",
                    id: self.id,
                    detail,
                })?,
        })
    }
}

#[derive(sqlx::FromRow)]
pub(super) struct ProcessedRow {
    id: i64,
    scan_id: i64,
    specular: String,
    brdf_f64le: Vec<u8>,
    created_at_ms: i64,
    /// The scan's `geometries`: which of the 14 the BRDF holds.
    geometries: String,
}

impl ProcessedRow {
    pub(super) fn into_processed(self) -> Result<Processed, StoreError> {
        let corrupt = |detail: String| StoreError::Corrupt {
            table: "processed",
            id: self.id,
            detail,
        };
        let specular = self
            .specular
            .parse()
            .map_err(|e: crate::processing::UnknownSpecularStrategy| corrupt(e.to_string()))?;
        let geometries = match self.geometries.as_str() {
            GEOMETRIES_ALL => crate::geometry::GeometrySet::ALL,
            GEOMETRIES_MA_T12 => crate::geometry::GeometrySet::MA_T12,
            other => return Err(corrupt(format!("unknown scan geometries \"{other}\""))),
        };
        let brdf = codec::decode_brdf(&self.brdf_f64le, geometries)
            .ok_or_else(|| corrupt(format!("brdf has {} bytes", self.brdf_f64le.len())))?;
        Ok(Processed {
            id: ProcessedId(self.id),
            scan: ScanId(self.scan_id),
            specular,
            brdf,
            created_at_ms: self.created_at_ms,
        })
    }
}

impl Store {
    /// Asks for a scan of the sample `sample_name` (created on first use), to be normalised by
    /// reference set `reference`, which must be complete. The scan starts `requested` and
    /// measures all 14 geometries.
    pub async fn request_scan(
        &self,
        sample_name: &str,
        reference: ReferenceId,
    ) -> Result<ScanId, StoreError> {
        self.request_scan_of(sample_name, reference, true).await
    }

    /// [`Store::request_scan`] for a scan with (`specular_readings`) or without the SRA's two
    /// readings: without them it completes with the 12 MA-T12 readings. A scan with SRA
    /// readings needs a reference set that has them too.
    pub async fn request_scan_of(
        &self,
        sample_name: &str,
        reference: ReferenceId,
        specular_readings: bool,
    ) -> Result<ScanId, StoreError> {
        if sample_name.trim().is_empty() {
            return Err(StoreError::Empty {
                field: "sample name",
            });
        }
        let mut tx = self.writer.begin().await?;
        let status = state_of(&mut *tx, reference).await?;
        if status != ReferenceStatus::Complete {
            return Err(StoreError::ReferenceState {
                reference,
                status,
                expected: "complete",
                action: "scan against it",
            });
        }
        let reference_geometries: String =
            sqlx::query_scalar("SELECT geometries FROM reference_sets WHERE id = $1")
                .bind(reference.0)
                .fetch_one(&mut *tx)
                .await?;
        if specular_readings && reference_geometries != GEOMETRIES_ALL {
            return Err(StoreError::ReferenceWithoutSpecular { reference });
        }
        let now = now_ms();
        let sample: i64 = sqlx::query_scalar(backend::UPSERT_SAMPLE)
            .bind(sample_name)
            .bind(now)
            .fetch_one(&mut *tx)
            .await?;
        let id: i64 = sqlx::query_scalar(
            "INSERT INTO scans (sample_id, reference_id, state, requested_at_ms, geometries)
             VALUES ($1, $2, 'requested', $3, $4) RETURNING id",
        )
        .bind(sample)
        .bind(reference.0)
        .bind(now)
        .bind(geometries_key(specular_readings))
        .fetch_one(&mut *tx)
        .await?;
        tx.commit().await?;
        Ok(ScanId(id))
    }

    /// requested → measuring: the devices are starting.
    pub async fn start_measuring(&self, scan: ScanId) -> Result<(), StoreError> {
        let done = sqlx::query(
            "UPDATE scans SET state = 'measuring', started_at_ms = $2
             WHERE id = $1 AND state = 'requested'",
        )
        .bind(scan.0)
        .bind(now_ms())
        .execute(&self.writer)
        .await?;
        self.changed(
            scan,
            done.rows_affected(),
            "requested",
            "start measuring it",
        )
        .await
    }

    /// Stores one reading of a `measuring` scan the moment it arrives (one commit). Each
    /// geometry once; `device` must be the geometry's; values finite.
    pub async fn add_reading(
        &self,
        scan: ScanId,
        device: Device,
        geometry: &Geometry,
        values: &ReadingValues,
        raw_frame: &[u8],
    ) -> Result<ReadingId, StoreError> {
        self.insert_reading(scan, device, geometry, values, raw_frame)
            .await
    }

    /// Stores several readings of a `measuring` scan in one transaction: all or none (imports,
    /// and the benchmark of a whole scan). Same checks as [`Store::add_reading`].
    pub async fn add_readings_tx(
        &self,
        scan: ScanId,
        readings: &[NewReading<'_>],
    ) -> Result<Vec<ReadingId>, StoreError> {
        let owner = || format!("scan {scan}");
        let mut checked = Vec::with_capacity(readings.len());
        for r in readings {
            checked.push(codec::check_reading(
                &owner, r.device, r.geometry, &r.values, false,
            )?);
        }
        let mut tx = self.writer.begin().await?;
        let state = state_of(&mut *tx, scan).await?;
        if state != ScanState::Measuring {
            return Err(StoreError::ScanState {
                scan,
                state,
                expected: "measuring",
                action: "add readings to it",
            });
        }
        let now = now_ms();
        let mut ids = Vec::with_capacity(readings.len());
        for (r, geometry) in readings.iter().zip(checked) {
            let inserted: Result<i64, sqlx::Error> = sqlx::query_scalar(
                "INSERT INTO readings
                     (scan_id, device, geometry, values_f64le, raw_frame, received_at_ms)
                 VALUES ($1, $2, $3, $4, $5, $6) RETURNING id",
            )
            .bind(scan.0)
            .bind(r.device.key())
            .bind(geometry.name)
            .bind(codec::encode_f64s(r.values.as_slice()))
            .bind(r.raw_frame)
            .bind(now)
            .fetch_one(&mut *tx)
            .await;
            match inserted {
                Ok(id) => ids.push(ReadingId(id)),
                // Dropping `tx` rolls back the readings inserted so far.
                Err(e) if backend::is_unique_violation(&e) => {
                    return Err(StoreError::DuplicateReading {
                        owner: owner(),
                        geometry: geometry.name,
                    });
                }
                Err(e) => return Err(e.into()),
            }
        }
        tx.commit().await?;
        Ok(ids)
    }

    /// Stores an imported scan in one transaction: its reference readings as a complete
    /// reference set named `reference_name`, the sample (created on first use), and the scan,
    /// complete, with its 14 readings and `provenance` on both. All or nothing: a failure
    /// anywhere leaves no reference set, scan or reading behind. Same checks as
    /// [`Store::add_reference_reading`] and [`Store::add_reading`]; both sets must hold each of
    /// the 14 geometries once.
    pub async fn import_scan(
        &self,
        sample_name: &str,
        reference_name: &str,
        provenance: &Provenance,
        reference_readings: &[NewReading<'_>],
        readings: &[NewReading<'_>],
    ) -> Result<(ReferenceId, ScanId), StoreError> {
        let import = ImportedScan {
            sample_name,
            reference_name,
            provenance,
            reference_readings: Some(reference_readings),
            readings,
            taken_at_ms: None,
            textures: &[],
        };
        import.check()?;
        let mut tx = self.writer.begin().await?;
        let ids = import.insert(&mut tx, now_ms()).await?;
        tx.commit().await?;
        Ok(ids)
    }

    /// [`Store::import_scan`] for any [`ImportedScan`]: a tile or the instrument's own
    /// calibration, with or without SRA readings. All or nothing.
    pub async fn import(
        &self,
        import: &ImportedScan<'_>,
    ) -> Result<(ReferenceId, ScanId), StoreError> {
        import.check()?;
        let mut tx = self.writer.begin().await?;
        let ids = import.insert(&mut tx, now_ms()).await?;
        tx.commit().await?;
        Ok(ids)
    }

    /// measuring → complete. Refused unless the scan is `measuring` and holds a reading at each
    /// of its geometries (all 14, or the 12 MA-T12 ones of a scan without SRA readings).
    pub async fn complete_scan(&self, scan: ScanId) -> Result<(), StoreError> {
        self.complete_owner(scan).await
    }

    /// requested | measuring → failed, with the reason (e.g. "MA-T12 timed out at 45as25").
    /// The readings already stored are kept.
    pub async fn fail_scan(&self, scan: ScanId, reason: &str) -> Result<(), StoreError> {
        self.end_unfinished(scan, "failed", reason, "failure reason", "fail it")
            .await
    }

    /// requested | measuring → aborted (the operator stopped it). Readings are kept.
    pub async fn abort_scan(&self, scan: ScanId) -> Result<(), StoreError> {
        self.abort_scan_because(scan, "aborted by the operator")
            .await
    }

    /// requested | measuring → aborted, with the reason (e.g. "the daemon was shut down
    /// during the measurement"). Readings are kept.
    pub async fn abort_scan_because(&self, scan: ScanId, reason: &str) -> Result<(), StoreError> {
        self.end_unfinished(scan, "aborted", reason, "abort reason", "abort it")
            .await
    }

    /// requested | measuring → `state` (`failed` or `aborted`) with `reason`, which must not
    /// be blank (it is the `field`); `action` names the change if the scan is in no such state.
    async fn end_unfinished(
        &self,
        scan: ScanId,
        state: &str,
        reason: &str,
        field: &'static str,
        action: &'static str,
    ) -> Result<(), StoreError> {
        if reason.trim().is_empty() {
            return Err(StoreError::Empty { field });
        }
        let done = sqlx::query(
            "UPDATE scans SET state = $4, reason = $2, finished_at_ms = $3
             WHERE id = $1 AND state IN ('requested', 'measuring')",
        )
        .bind(scan.0)
        .bind(reason)
        .bind(now_ms())
        .bind(state)
        .execute(&self.writer)
        .await?;
        self.changed(scan, done.rows_affected(), "requested or measuring", action)
            .await
    }

    /// At start-up: every scan a crash left `requested` or `measuring` becomes `failed` with
    /// the reason [`INTERRUPTED_REASON`], keeping its readings. Returns their ids, oldest first.
    pub async fn mark_interrupted_scans_failed(&self) -> Result<Vec<ScanId>, StoreError> {
        let mut ids: Vec<i64> = sqlx::query_scalar(
            "UPDATE scans SET state = 'failed', reason = $1, finished_at_ms = $2
             WHERE state IN ('requested', 'measuring')
             RETURNING id",
        )
        .bind(INTERRUPTED_REASON)
        .bind(now_ms())
        .fetch_all(&self.writer)
        .await?;
        ids.sort_unstable();
        Ok(ids.into_iter().map(ScanId).collect())
    }

    /// A scan, its readings and its reference set with that set's readings, readings in
    /// geometry-table order.
    pub async fn scan_detail(&self, scan: ScanId) -> Result<ScanDetail, StoreError> {
        let row: Option<ScanRow> = sqlx::query_as(&format!("{} WHERE s.id = $1", *SCAN_SUMMARY))
            .bind(scan.0)
            .fetch_optional(&self.reader)
            .await?;
        let summary = row
            .ok_or(StoreError::NotFound {
                what: ScanId::WHAT,
                id: scan.0,
            })?
            .into_summary()?;
        let rows: Vec<ReadingRow> = sqlx::query_as(
            "SELECT id, device, geometry, values_f64le, raw_frame, received_at_ms AS at_ms
             FROM readings WHERE scan_id = $1",
        )
        .bind(scan.0)
        .fetch_all(&self.reader)
        .await?;
        let mut readings = rows
            .into_iter()
            .map(|r| r.into_reading("readings"))
            .collect::<Result<Vec<_>, _>>()?;
        codec::sort_readings(&mut readings);
        let reference = self.reference_detail(summary.reference_id).await?;
        Ok(ScanDetail {
            scan: summary,
            readings,
            reference,
        })
    }

    /// Scans matching `filter`, newest first.
    pub async fn list_scans(&self, filter: &ScanFilter) -> Result<Vec<ScanSummary>, StoreError> {
        // QueryBuilder writes each backend's placeholder, so the optional clauses stay portable.
        let mut q = sqlx::QueryBuilder::<Db>::new(SCAN_SUMMARY.as_str());
        q.push(" WHERE 1 = 1");
        if let Some(state) = filter.state {
            q.push(" AND s.state = ").push_bind(state.as_str());
        }
        if let Some(sample) = &filter.sample {
            q.push(" AND sa.name = ").push_bind(sample.clone());
        }
        if let Some(before) = filter.before {
            q.push(" AND s.id < ").push_bind(before.0);
        }
        q.push(" ORDER BY s.id DESC LIMIT ")
            .push_bind(i64::from(filter.limit));
        let rows: Vec<ScanRow> = q.build_query_as().fetch_all(&self.reader).await?;
        rows.into_iter().map(ScanRow::into_summary).collect()
    }

    /// Stores the measured BRDF (sr⁻¹) of a `complete` scan under one specular strategy; once
    /// per (scan, strategy). Values must be finite.
    pub async fn add_processed(
        &self,
        scan: ScanId,
        specular: SpecularStrategy,
        brdf: &MeasuredBrdf,
    ) -> Result<ProcessedId, StoreError> {
        for (g, spectrum) in brdf.values.iter().enumerate() {
            let geometry = &crate::geometry::GEOMETRIES[g];
            codec::check_finite(
                &|| format!("processed scan {scan} at {}", geometry.name),
                spectrum,
                |i| format!("the BRDF at {} nm", wavelengths_nm()[i]),
            )?;
        }
        let inserted: Result<Option<i64>, sqlx::Error> = sqlx::query_scalar(
            "INSERT INTO processed (scan_id, specular, brdf_f64le, created_at_ms)
             SELECT $1, $2, $3, $4
             WHERE EXISTS (SELECT 1 FROM scans WHERE id = $1 AND state = 'complete')
             RETURNING id",
        )
        .bind(scan.0)
        .bind(specular.name())
        .bind(codec::encode_brdf(brdf))
        .bind(now_ms())
        .fetch_optional(&self.writer)
        .await;
        match inserted {
            Ok(Some(id)) => Ok(ProcessedId(id)),
            Ok(None) => {
                Err(refused(&self.writer, scan, "complete", "store its processed BRDF").await)
            }
            Err(e) if backend::is_unique_violation(&e) => {
                Err(StoreError::AlreadyProcessed { scan, specular })
            }
            Err(e) => Err(e.into()),
        }
    }

    /// A processed scan by id (the fit worker's input).
    pub async fn processed(&self, id: ProcessedId) -> Result<Processed, StoreError> {
        let row: Option<ProcessedRow> = sqlx::query_as(
            "SELECT p.id, p.scan_id, p.specular, p.brdf_f64le, p.created_at_ms, s.geometries
             FROM processed p JOIN scans s ON s.id = p.scan_id WHERE p.id = $1",
        )
        .bind(id.0)
        .fetch_optional(&self.reader)
        .await?;
        row.ok_or(StoreError::NotFound {
            what: ProcessedId::WHAT,
            id: id.0,
        })?
        .into_processed()
    }

    /// Every processed version of a scan, by id.
    pub async fn processed_for_scan(&self, scan: ScanId) -> Result<Vec<Processed>, StoreError> {
        let rows: Vec<ProcessedRow> = sqlx::query_as(
            "SELECT p.id, p.scan_id, p.specular, p.brdf_f64le, p.created_at_ms, s.geometries
             FROM processed p JOIN scans s ON s.id = p.scan_id
             WHERE p.scan_id = $1 ORDER BY p.id",
        )
        .bind(scan.0)
        .fetch_all(&self.reader)
        .await?;
        rows.into_iter().map(ProcessedRow::into_processed).collect()
    }
}

/// One scan to import, as [`Store::import_scan`] takes it; the watch folder imports several
/// of these in one transaction (`ingest.rs`).
#[derive(Debug, Clone, Copy)]
pub struct ImportedScan<'a> {
    pub sample_name: &'a str,
    pub reference_name: &'a str,
    pub provenance: &'a Provenance,
    /// The tile's readings; `None` for a scan normalised by the instrument's own white
    /// calibration (an instrument-software export without an N9 reading): its reference set
    /// is of kind `instrument-calibration` and holds no readings.
    pub reference_readings: Option<&'a [NewReading<'a>]>,
    /// All 14 geometries, or the 12 MA-T12 ones of a scan without SRA readings.
    pub readings: &'a [NewReading<'a>],
    /// When the instrument took the readings, ms since the epoch, if the file says so (else the
    /// import time is recorded).
    pub taken_at_ms: Option<i64>,
    /// The instrument camera's images of the measurement, kept with the scan (each PNG once).
    pub textures: &'a [super::NewTexture<'a>],
}

/// The number of SRA readings in a set.
fn sra_count(set: &[NewReading<'_>]) -> usize {
    set.iter().filter(|r| r.device == Device::Sra).count()
}

impl ImportedScan<'_> {
    /// Whether the scan has SRA readings (then all 14 geometries are required).
    pub(super) fn specular_readings(&self) -> bool {
        sra_count(self.readings) > 0
    }

    /// The checks of [`Store::add_reference_reading`] and [`Store::add_reading`], before any
    /// write: non-empty names, each geometry of the scan once (all 14, or the 12 MA-T12 ones
    /// without SRA readings), and a tile that has every geometry the scan has.
    pub(super) fn check(&self) -> Result<(), StoreError> {
        for (field, name) in [
            ("sample name", self.sample_name),
            ("reference name", self.reference_name),
        ] {
            if name.trim().is_empty() {
                return Err(StoreError::Empty { field });
            }
        }
        super::textures::check_textures(self.textures)?;
        self.checked().map(|_| ())
    }

    fn checked(&self) -> Result<Vec<(bool, &NewReading<'_>, &'static Geometry)>, StoreError> {
        let reference_owner = || format!("imported reference \"{}\"", self.reference_name);
        let scan_owner = || format!("imported scan of \"{}\"", self.sample_name);
        let reference_readings = self.reference_readings.unwrap_or(&[]);
        let mut checked = Vec::with_capacity(reference_readings.len() + self.readings.len());
        let scan_has_sra = self.specular_readings();
        let mut sets: Vec<(&[NewReading<'_>], &dyn Fn() -> String, bool)> =
            vec![(self.readings, &scan_owner, false)];
        if let Some(set) = self.reference_readings {
            sets.insert(0, (set, &reference_owner, true));
        }
        for (set, owner, is_reference) in sets {
            let mut present = Vec::with_capacity(set.len());
            for r in set {
                let g = codec::check_reading(owner, r.device, r.geometry, &r.values, is_reference)?;
                if present.contains(&g.name) {
                    return Err(StoreError::DuplicateReading {
                        owner: owner(),
                        geometry: g.name,
                    });
                }
                present.push(g.name);
                checked.push((is_reference, r, g));
            }
            // A set is whole with its SRA readings or without any; a tile needs them when the
            // scan has them.
            let has_sra = sra_count(set) > 0 || (is_reference && scan_has_sra);
            let want = if has_sra {
                GEOMETRY_COUNT
            } else {
                MA_T12_COUNT
            };
            if present.len() != want {
                let mut present: Vec<String> = present.iter().map(|g| g.to_string()).collect();
                if !has_sra {
                    present.extend(crate::geometry::sra().iter().map(|g| g.name.to_string()));
                }
                let missing = codec::missing_geometries(&present);
                let have = set.len();
                return Err(if is_reference {
                    StoreError::ReferenceIncomplete {
                        reference: ReferenceId(0),
                        have,
                        want,
                        missing,
                    }
                } else {
                    StoreError::ScanIncomplete {
                        scan: ScanId(0),
                        have,
                        want,
                        missing,
                    }
                });
            }
        }
        Ok(checked)
    }

    /// Writes the reference set, the sample (created on first use) and the complete scan with
    /// their readings and provenance inside `tx`; [`ImportedScan::check`] must have passed.
    pub(super) async fn insert(
        &self,
        tx: &mut sqlx::Transaction<'_, Db>,
        now: i64,
    ) -> Result<(ReferenceId, ScanId), StoreError> {
        let checked = self.checked()?;
        let (kind, reference_geometries) = match self.reference_readings {
            Some(set) => ("tile", geometries_key(sra_count(set) > 0)),
            // No readings: the instrument's calibration covers every geometry the scan has.
            None => (crate::scan::INSTRUMENT_CALIBRATION, GEOMETRIES_ALL),
        };
        let taken = self.taken_at_ms.unwrap_or(now);
        let reference: i64 = sqlx::query_scalar(
            "INSERT INTO reference_sets
                 (name, status, taken_at_ms, completed_at_ms, kind, geometries)
             VALUES ($1, 'complete', $2, $2, $3, $4) RETURNING id",
        )
        .bind(self.reference_name)
        .bind(taken)
        .bind(kind)
        .bind(reference_geometries)
        .fetch_one(&mut **tx)
        .await?;
        super::write_provenance(
            &mut **tx,
            "reference_sets",
            ReferenceId::WHAT,
            reference,
            self.provenance,
        )
        .await?;
        let sample: i64 = sqlx::query_scalar(backend::UPSERT_SAMPLE)
            .bind(self.sample_name)
            .bind(now)
            .fetch_one(&mut **tx)
            .await?;
        let scan: i64 = sqlx::query_scalar(
            "INSERT INTO scans (sample_id, reference_id, state, requested_at_ms, started_at_ms,
                                finished_at_ms, geometries)
             VALUES ($1, $2, 'complete', $3, $3, $3, $4) RETURNING id",
        )
        .bind(sample)
        .bind(reference)
        .bind(taken)
        .bind(geometries_key(self.specular_readings()))
        .fetch_one(&mut **tx)
        .await?;
        super::write_provenance(&mut **tx, "scans", ScanId::WHAT, scan, self.provenance).await?;
        for (is_reference, r, g) in checked {
            let sql = if is_reference {
                "INSERT INTO reference_readings
                     (reference_id, device, geometry, values_f64le, raw_frame, taken_at_ms)
                 VALUES ($1, $2, $3, $4, $5, $6)"
            } else {
                "INSERT INTO readings
                     (scan_id, device, geometry, values_f64le, raw_frame, received_at_ms)
                 VALUES ($1, $2, $3, $4, $5, $6)"
            };
            sqlx::query(sql)
                .bind(if is_reference { reference } else { scan })
                .bind(r.device.key())
                .bind(g.name)
                .bind(codec::encode_f64s(r.values.as_slice()))
                .bind(r.raw_frame)
                .bind(now)
                .execute(&mut **tx)
                .await?;
        }
        super::textures::insert_textures(tx, scan, self.textures).await?;
        Ok((ReferenceId(reference), ScanId(scan)))
    }
}
