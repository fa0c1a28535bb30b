//! The shape every state-guarded verb of the store shares. A verb changes a row only in the
//! states it allows, in one statement (`UPDATE … WHERE id = $1 AND state IN (…)`, or an
//! `INSERT … SELECT … WHERE EXISTS` for a reading); when that touches nothing, the row's
//! current state is read back to say why ("scan 12 is complete, expected measuring, to add a
//! reading to it"). [`Guarded`] names, per kind of row, where its state lives and which error
//! says so; [`ReadingOwner`] adds, for scans and reference sets, where their readings live.

use crate::geometry::{Device, GEOMETRY_COUNT, Geometry};

use super::backend::{self, Db};
use super::codec;
use super::ids::{FitRunId, ReadingId, ReferenceId, ScanId};
use super::records::{FitStatus, ReadingValues, ReferenceStatus, ScanState};
use super::{Store, StoreError, now_ms};

/// A row with a life-cycle column: a scan (`state`), a reference set or a fit run (`status`).
pub(super) trait Guarded: Copy + std::fmt::Display {
    /// The row's table.
    const TABLE: &'static str;
    /// Its life-cycle column.
    const COLUMN: &'static str;
    /// What the id names, for `NotFound`.
    const WHAT: &'static str;
    /// The parsed life-cycle column.
    type State: std::str::FromStr<Err = String> + PartialEq;

    /// The row's primary key.
    fn key(self) -> i64;

    /// The error of a verb that found the row in `state` rather than in `expected`.
    fn wrong_state(
        self,
        state: Self::State,
        expected: &'static str,
        action: &'static str,
    ) -> StoreError;
}

impl Guarded for ScanId {
    const TABLE: &'static str = "scans";
    const COLUMN: &'static str = "state";
    const WHAT: &'static str = ScanId::WHAT;
    type State = ScanState;

    fn key(self) -> i64 {
        self.0
    }

    fn wrong_state(
        self,
        state: ScanState,
        expected: &'static str,
        action: &'static str,
    ) -> StoreError {
        StoreError::ScanState {
            scan: self,
            state,
            expected,
            action,
        }
    }
}

impl Guarded for ReferenceId {
    const TABLE: &'static str = "reference_sets";
    const COLUMN: &'static str = "status";
    const WHAT: &'static str = ReferenceId::WHAT;
    type State = ReferenceStatus;

    fn key(self) -> i64 {
        self.0
    }

    fn wrong_state(
        self,
        status: ReferenceStatus,
        expected: &'static str,
        action: &'static str,
    ) -> StoreError {
        StoreError::ReferenceState {
            reference: self,
            status,
            expected,
            action,
        }
    }
}

impl Guarded for FitRunId {
    const TABLE: &'static str = "fit_runs";
    const COLUMN: &'static str = "status";
    const WHAT: &'static str = FitRunId::WHAT;
    type State = FitStatus;

    fn key(self) -> i64 {
        self.0
    }

    fn wrong_state(
        self,
        status: FitStatus,
        expected: &'static str,
        action: &'static str,
    ) -> StoreError {
        StoreError::FitState {
            fit: self,
            status,
            expected,
            action,
        }
    }
}

/// The life-cycle state of row `id`, or `NotFound`.
pub(super) async fn state_of<'e, E, I>(ex: E, id: I) -> Result<I::State, StoreError>
where
    E: sqlx::Executor<'e, Database = Db>,
    I: Guarded,
{
    super::lifecycle(ex, I::TABLE, I::COLUMN, I::WHAT, id.key()).await
}

/// The error of a guarded verb on `id` that changed nothing: the row's state, read through
/// `ex`, was not `expected`. A failure to read the state is returned instead.
pub(super) async fn refused<'e, E, I>(
    ex: E,
    id: I,
    expected: &'static str,
    action: &'static str,
) -> StoreError
where
    E: sqlx::Executor<'e, Database = Db>,
    I: Guarded,
{
    match state_of(ex, id).await {
        Ok(state) => id.wrong_state(state, expected, action),
        Err(e) => e,
    }
}

/// A row that owns readings: a scan or a reference set, both `measuring` while they take them.
pub(super) trait ReadingOwner: Guarded {
    /// The table of its readings.
    const READINGS: &'static str;
    /// The column of a reading that names its owner.
    const OWNER_COLUMN: &'static str;
    /// The column of a reading that holds when it arrived.
    const AT_COLUMN: &'static str;
    /// The owner's column set when it completes.
    const COMPLETED_AT_COLUMN: &'static str;
    /// Whether every reading value must be positive (a reference: samples are divided by it).
    const POSITIVE: bool;
    /// The state in which it takes readings.
    const MEASURING: Self::State;

    /// The error of completing an owner that holds only `have` of its `want` readings.
    fn incomplete(self, have: usize, want: usize, missing: String) -> StoreError;
}

impl ReadingOwner for ScanId {
    const READINGS: &'static str = "readings";
    const OWNER_COLUMN: &'static str = "scan_id";
    const AT_COLUMN: &'static str = "received_at_ms";
    const COMPLETED_AT_COLUMN: &'static str = "finished_at_ms";
    const POSITIVE: bool = false;
    const MEASURING: ScanState = ScanState::Measuring;

    fn incomplete(self, have: usize, want: usize, missing: String) -> StoreError {
        StoreError::ScanIncomplete {
            scan: self,
            have,
            want,
            missing,
        }
    }
}

impl ReadingOwner for ReferenceId {
    const READINGS: &'static str = "reference_readings";
    const OWNER_COLUMN: &'static str = "reference_id";
    const AT_COLUMN: &'static str = "taken_at_ms";
    const COMPLETED_AT_COLUMN: &'static str = "completed_at_ms";
    const POSITIVE: bool = true;
    const MEASURING: ReferenceStatus = ReferenceStatus::Measuring;

    fn incomplete(self, have: usize, want: usize, missing: String) -> StoreError {
        StoreError::ReferenceIncomplete {
            reference: self,
            have,
            want,
            missing,
        }
    }
}

impl Store {
    /// `Ok` when a guarded verb on `id` changed its one row (`rows` = 1), else why not.
    pub(super) async fn changed<I: Guarded>(
        &self,
        id: I,
        rows: u64,
        expected: &'static str,
        action: &'static str,
    ) -> Result<(), StoreError> {
        if rows == 1 {
            return Ok(());
        }
        Err(refused(&self.writer, id, expected, action).await)
    }

    /// Stores one reading of `owner`, which must be `measuring`, in one commit: each geometry
    /// once, `device` the geometry's, values finite (and positive for a reference).
    pub(super) async fn insert_reading<O: ReadingOwner>(
        &self,
        owner: O,
        device: Device,
        geometry: &Geometry,
        values: &ReadingValues,
        raw_frame: &[u8],
    ) -> Result<ReadingId, StoreError> {
        let name = || format!("{} {owner}", O::WHAT);
        let geometry = codec::check_reading(&name, device, geometry, values, O::POSITIVE)?;
        // The state test and the insert are one statement, so a verb of another task (a fail,
        // an abort) cannot slip in between and the owner cannot gain a reading afterwards. An
        // owner that measures the MA-T12 geometries only takes no SRA reading.
        let sql = format!(
            "INSERT INTO {readings}
                 ({owner_column}, device, geometry, values_f64le, raw_frame, {at})
             SELECT $1, $2, $3, $4, $5, $6
             WHERE EXISTS (SELECT 1 FROM {table} WHERE id = $1 AND {column} = 'measuring'
                           AND (geometries = 'all' OR $2 = 'ma_t12'))
             RETURNING id",
            readings = O::READINGS,
            owner_column = O::OWNER_COLUMN,
            at = O::AT_COLUMN,
            table = O::TABLE,
            column = O::COLUMN,
        );
        let inserted: Result<Option<i64>, sqlx::Error> = sqlx::query_scalar(&sql)
            .bind(owner.key())
            .bind(device.key())
            .bind(geometry.name)
            .bind(codec::encode_f64s(values.as_slice()))
            .bind(raw_frame)
            .bind(now_ms())
            .fetch_optional(&self.writer)
            .await;
        match inserted {
            Ok(Some(id)) => Ok(ReadingId(id)),
            Ok(None) if device == Device::Sra && !self.measures_sra(owner).await? => {
                Err(StoreError::GeometryNotMeasured {
                    owner: name(),
                    geometry: geometry.name,
                })
            }
            Ok(None) => Err(refused(&self.writer, owner, "measuring", "add a reading to it").await),
            Err(e) if backend::is_unique_violation(&e) => Err(StoreError::DuplicateReading {
                owner: name(),
                geometry: geometry.name,
            }),
            Err(e) => Err(e.into()),
        }
    }

    /// Whether `owner` measures the SRA geometries (its `geometries` is `all`).
    async fn measures_sra<O: ReadingOwner>(&self, owner: O) -> Result<bool, StoreError> {
        let geometries: Option<String> = sqlx::query_scalar(&format!(
            "SELECT geometries FROM {} WHERE id = $1",
            O::TABLE
        ))
        .bind(owner.key())
        .fetch_optional(&self.writer)
        .await?;
        Ok(geometries.is_none_or(|g| g == super::scans::GEOMETRIES_ALL))
    }

    /// measuring → complete for `owner`; refused unless it is `measuring` and holds a reading
    /// at each of its geometries — all 14, or the 12 MA-T12 ones when its `geometries` says so
    /// (the error then lists the missing geometries).
    pub(super) async fn complete_owner<O: ReadingOwner>(&self, owner: O) -> Result<(), StoreError> {
        // The CHECKs of the readings tables pin each row to a distinct one of the 14
        // geometries, and an MA-T12-only owner takes no SRA reading, so a count of 14 (12)
        // means every geometry is present.
        let sql = format!(
            "UPDATE {table} SET {column} = 'complete', {completed} = $2
             WHERE id = $1 AND {column} = 'measuring'
               AND (SELECT COUNT(*) FROM {readings} WHERE {owner_column} = $1)
                   = CASE geometries WHEN 'all' THEN $3 ELSE $4 END",
            table = O::TABLE,
            column = O::COLUMN,
            completed = O::COMPLETED_AT_COLUMN,
            readings = O::READINGS,
            owner_column = O::OWNER_COLUMN,
        );
        let done = sqlx::query(&sql)
            .bind(owner.key())
            .bind(now_ms())
            .bind(GEOMETRY_COUNT as i64)
            .bind(crate::geometry::MA_T12_COUNT as i64)
            .execute(&self.writer)
            .await?;
        if done.rows_affected() == 1 {
            return Ok(());
        }
        let state = state_of(&self.writer, owner).await?;
        if state != O::MEASURING {
            return Err(owner.wrong_state(state, "measuring", "complete it"));
        }
        let present: Vec<String> = sqlx::query_scalar(&format!(
            "SELECT geometry FROM {} WHERE {} = $1",
            O::READINGS,
            O::OWNER_COLUMN
        ))
        .bind(owner.key())
        .fetch_all(&self.writer)
        .await?;
        let have = present.len();
        let mut covered = present;
        let want = if self.measures_sra(owner).await? {
            GEOMETRY_COUNT
        } else {
            covered.extend(crate::geometry::sra().iter().map(|g| g.name.to_string()));
            crate::geometry::MA_T12_COUNT
        };
        Err(owner.incomplete(have, want, codec::missing_geometries(&covered)))
    }
}
