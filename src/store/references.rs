//! Store verbs for instruments and reference sets (readings of the white reference tile that
//! scans are normalised by).

use crate::geometry::{Device, Geometry};
use crate::scan::INSTRUMENT_CALIBRATION;
use crate::spectral::{Spectrum, wavelengths_nm};

use super::backend;
use super::codec::{self, ReadingRow};
use super::ids::{InstrumentId, ReadingId, ReferenceId};
use super::records::{
    Instrument, ProvenanceRow, ReadingValues, ReferenceDetail, ReferenceSummary, Source,
    provenance_columns,
};
use super::{Store, StoreError, now_ms};

#[derive(sqlx::FromRow)]
struct InstrumentRow {
    id: i64,
    device: String,
    serial: String,
    identity: String,
    first_seen_ms: i64,
    last_seen_ms: i64,
}

#[derive(sqlx::FromRow)]
pub(super) struct ReferenceRow {
    id: i64,
    name: String,
    status: String,
    reason: Option<String>,
    rho_ref: Option<Vec<u8>>,
    taken_at_ms: i64,
    completed_at_ms: Option<i64>,
    kind: String,
    geometries: String,
    reading_count: i64,
    #[sqlx(flatten)]
    provenance: ProvenanceRow,
}

/// The reference sets' summary columns.
static REFERENCE_SUMMARY: std::sync::LazyLock<String> = std::sync::LazyLock::new(|| {
    format!(
        "SELECT r.id, r.name, r.status, r.reason, r.rho_ref, r.taken_at_ms, r.completed_at_ms,
                r.kind, r.geometries,
                (SELECT COUNT(*) FROM reference_readings rr WHERE rr.reference_id = r.id)
                    AS reading_count,
                {}
         FROM reference_sets r",
        provenance_columns("r")
    )
});

impl ReferenceRow {
    pub(super) fn into_summary(self) -> Result<ReferenceSummary, StoreError> {
        let corrupt = |detail: String| StoreError::Corrupt {
            table: "reference_sets",
            id: self.id,
            detail,
        };
        let status = self.status.parse().map_err(corrupt)?;
        let rho_ref = match &self.rho_ref {
            None => None,
            Some(b) => Some(
                codec::decode_spectrum(b)
                    .ok_or_else(|| corrupt(format!("rho_ref has {} bytes", b.len())))?,
            ),
        };
        Ok(ReferenceSummary {
            id: ReferenceId(self.id),
            name: self.name,
            status,
            reason: self.reason,
            rho_ref,
            taken_at_ms: self.taken_at_ms,
            completed_at_ms: self.completed_at_ms,
            instrument_calibration: match self.kind.as_str() {
                "tile" => false,
                INSTRUMENT_CALIBRATION => true,
                other => return Err(corrupt(format!("unknown kind \"{other}\""))),
            },
            specular_readings: match self.geometries.as_str() {
                super::scans::GEOMETRIES_ALL => true,
                super::scans::GEOMETRIES_MA_T12 => false,
                other => return Err(corrupt(format!("unknown geometries \"{other}\""))),
            },
            reading_count: self.reading_count as usize,
            provenance: self
                .provenance
                .into_provenance(self.geometries != super::scans::GEOMETRIES_MA_T12)
                .map_err(corrupt)?,
        })
    }
}

impl Store {
    /// Records an instrument by its serial number, or refreshes its identity string and
    /// last-seen time if it is known. Returns its id either way.
    pub async fn add_instrument(
        &self,
        device: Device,
        serial: &str,
        identity: &str,
    ) -> Result<InstrumentId, StoreError> {
        if serial.trim().is_empty() {
            return Err(StoreError::Empty {
                field: "instrument serial number",
            });
        }
        let id: i64 = sqlx::query_scalar(backend::UPSERT_INSTRUMENT)
            .bind(device.key())
            .bind(serial)
            .bind(identity)
            .bind(now_ms())
            .fetch_one(&self.writer)
            .await?;
        Ok(InstrumentId(id))
    }

    /// Every known instrument, by id.
    pub async fn instruments(&self) -> Result<Vec<Instrument>, StoreError> {
        let rows: Vec<InstrumentRow> = sqlx::query_as(
            "SELECT id, device, serial, identity, first_seen_ms, last_seen_ms
             FROM instruments ORDER BY id",
        )
        .fetch_all(&self.reader)
        .await?;
        rows.into_iter()
            .map(|r| {
                let device =
                    codec::device_from_key(&r.device).ok_or_else(|| StoreError::Corrupt {
                        table: "instruments",
                        id: r.id,
                        detail: format!("unknown device \"{}\"", r.device),
                    })?;
                Ok(Instrument {
                    id: InstrumentId(r.id),
                    device,
                    serial: r.serial,
                    identity: r.identity,
                    first_seen_ms: r.first_seen_ms,
                    last_seen_ms: r.last_seen_ms,
                })
            })
            .collect()
    }

    /// Starts a reference set for the tile `name` (e.g. "Munsell N9"), status `measuring`, on
    /// all 14 geometries. `rho_ref` is the tile's calibrated reflectance factor, if known;
    /// every value must be positive and finite.
    pub async fn begin_reference(
        &self,
        name: &str,
        rho_ref: Option<&Spectrum>,
    ) -> Result<ReferenceId, StoreError> {
        self.begin_reference_of(name, rho_ref, true).await
    }

    /// [`Store::begin_reference`] with (`specular_readings`) or without the SRA's two readings
    /// of the tile: without them the set completes with the 12 MA-T12 readings, and normalises
    /// scans without SRA readings only.
    pub async fn begin_reference_of(
        &self,
        name: &str,
        rho_ref: Option<&Spectrum>,
        specular_readings: bool,
    ) -> Result<ReferenceId, StoreError> {
        if name.trim().is_empty() {
            return Err(StoreError::Empty {
                field: "reference name",
            });
        }
        if let Some(rho) = rho_ref {
            let owner = || format!("calibrated reflectance of reference \"{name}\"");
            let band = |i: usize| format!("the value at {} nm", wavelengths_nm()[i]);
            codec::check_finite(&owner, rho, band)?;
            if let Some(i) = rho.iter().position(|&v| v <= 0.0) {
                return Err(StoreError::NonPositiveReference {
                    owner: owner(),
                    what: band(i),
                    value: rho[i],
                });
            }
        }
        let id: i64 = sqlx::query_scalar(
            "INSERT INTO reference_sets (name, status, rho_ref, taken_at_ms, geometries)
             VALUES ($1, 'measuring', $2, $3, $4) RETURNING id",
        )
        .bind(name)
        .bind(rho_ref.map(|r| codec::encode_f64s(r)))
        .bind(now_ms())
        .bind(super::scans::geometries_key(specular_readings))
        .fetch_one(&self.writer)
        .await?;
        Ok(ReferenceId(id))
    }

    /// Stores one reading of the reference tile. The set must be `measuring`; each geometry
    /// once; every value positive and finite (the sample is divided by it).
    pub async fn add_reference_reading(
        &self,
        reference: ReferenceId,
        device: Device,
        geometry: &Geometry,
        values: &ReadingValues,
        raw_frame: &[u8],
    ) -> Result<ReadingId, StoreError> {
        self.insert_reading(reference, device, geometry, values, raw_frame)
            .await
    }

    /// Marks a reference set `complete`. It must be `measuring` and hold a reading at each of
    /// its geometries (all 14, or the 12 MA-T12 ones of a tile measured without the SRA).
    pub async fn complete_reference(&self, reference: ReferenceId) -> Result<(), StoreError> {
        self.complete_owner(reference).await
    }

    /// Marks a `measuring` reference set `failed`, keeping its readings.
    pub async fn fail_reference(
        &self,
        reference: ReferenceId,
        reason: &str,
    ) -> Result<(), StoreError> {
        if reason.trim().is_empty() {
            return Err(StoreError::Empty {
                field: "failure reason",
            });
        }
        let done = sqlx::query(
            "UPDATE reference_sets SET status = 'failed', reason = $2
             WHERE id = $1 AND status = 'measuring'",
        )
        .bind(reference.0)
        .bind(reason)
        .execute(&self.writer)
        .await?;
        self.changed(reference, done.rows_affected(), "measuring", "fail it")
            .await
    }

    /// The most recently completed reference set, the one new scans use; `None` before the
    /// first. Whether it is too old is the caller's call (`[scan] reference_max_age_hours`).
    pub async fn latest_reference(&self) -> Result<Option<ReferenceSummary>, StoreError> {
        let row: Option<ReferenceRow> = sqlx::query_as(&format!(
            "{} WHERE r.status = 'complete'
             ORDER BY r.completed_at_ms DESC, r.id DESC LIMIT 1",
            *REFERENCE_SUMMARY
        ))
        .fetch_optional(&self.reader)
        .await?;
        row.map(ReferenceRow::into_summary).transpose()
    }

    /// The most recently completed reference set that did not come with an imported scan (its
    /// provenance `source` is not `imported`): the daemon's reference in force at start, so
    /// that an import never becomes it, also across a restart.
    pub async fn latest_measured_reference(&self) -> Result<Option<ReferenceSummary>, StoreError> {
        let row: Option<ReferenceRow> = sqlx::query_as(&format!(
            "{} WHERE r.status = 'complete' AND r.source <> $1
             ORDER BY r.completed_at_ms DESC, r.id DESC LIMIT 1",
            *REFERENCE_SUMMARY
        ))
        .bind(Source::Imported.as_str())
        .fetch_optional(&self.reader)
        .await?;
        row.map(ReferenceRow::into_summary).transpose()
    }

    /// A reference set with its readings in geometry-table order.
    pub async fn reference_detail(
        &self,
        reference: ReferenceId,
    ) -> Result<ReferenceDetail, StoreError> {
        let row: Option<ReferenceRow> =
            sqlx::query_as(&format!("{} WHERE r.id = $1", *REFERENCE_SUMMARY))
                .bind(reference.0)
                .fetch_optional(&self.reader)
                .await?;
        let reference_summary = row
            .ok_or(StoreError::NotFound {
                what: ReferenceId::WHAT,
                id: reference.0,
            })?
            .into_summary()?;
        let rows: Vec<ReadingRow> = sqlx::query_as(
            "SELECT id, device, geometry, values_f64le, raw_frame, taken_at_ms AS at_ms
             FROM reference_readings WHERE reference_id = $1",
        )
        .bind(reference.0)
        .fetch_all(&self.reader)
        .await?;
        let mut readings = rows
            .into_iter()
            .map(|r| r.into_reading("reference_readings"))
            .collect::<Result<Vec<_>, _>>()?;
        codec::sort_readings(&mut readings);
        Ok(ReferenceDetail {
            reference: reference_summary,
            readings,
        })
    }
}
