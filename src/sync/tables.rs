//! Which tables and columns leave a station, and how each is keyed in the central database.
//!
//! One list, read by both ends: the forwarder selects these columns from the station's SQLite
//! store and upserts them, in this order, into the central table of the same name
//! (`migrations-central/`), which adds `station` in front of the key. A column added to a
//! station table by a later migration is not forwarded until it is listed here and a central
//! migration adds it; `every_station_column_is_forwarded` (below) fails until then, so it
//! cannot be forgotten.

/// How a column's value is read from SQLite and bound into PostgreSQL.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Kind {
    /// INTEGER / BIGINT (also 0/1 flags).
    Int,
    /// TEXT.
    Text,
    /// BLOB / BYTEA.
    Blob,
    /// REAL / DOUBLE PRECISION.
    Real,
}

/// A forwarded table.
#[derive(Debug)]
pub struct Table {
    pub name: &'static str,
    /// The row's key within its station (the central key is `station` + these).
    pub key: &'static [&'static str],
    /// The column the outbox's `row_id` names: `id`, or `fit_run_id` for a fit's evaluation.
    pub selected_by: &'static str,
    /// Every forwarded column, key included, in the order they are selected and bound.
    pub columns: &'static [(&'static str, Kind)],
}

use Kind::{Blob, Int, Real, Text};

const PROVENANCE: [(&str, Kind); 10] = [
    ("ma_t12_model", Text),
    ("ma_t12_serial", Text),
    ("ma_t12_firmware", Text),
    ("ma_t12_simulated", Int),
    ("sra_model", Text),
    ("sra_serial", Text),
    ("sra_firmware", Text),
    ("sra_simulated", Int),
    ("source", Text),
    ("source_detail", Text),
];

macro_rules! with_provenance {
    ($($c:expr),* $(,)?) => {
        &[$($c,)* PROVENANCE[0], PROVENANCE[1], PROVENANCE[2], PROVENANCE[3], PROVENANCE[4],
          PROVENANCE[5], PROVENANCE[6], PROVENANCE[7], PROVENANCE[8], PROVENANCE[9]]
    };
}

/// Every forwarded table, parents before children (the order a batch is upserted in).
pub static TABLES: [Table; 10] = [
    Table {
        name: "instruments",
        key: &["id"],
        selected_by: "id",
        columns: &[
            ("id", Int),
            ("device", Text),
            ("serial", Text),
            ("identity", Text),
            ("first_seen_ms", Int),
            ("last_seen_ms", Int),
        ],
    },
    Table {
        name: "samples",
        key: &["id"],
        selected_by: "id",
        columns: &[("id", Int), ("name", Text), ("created_at_ms", Int)],
    },
    Table {
        name: "reference_sets",
        key: &["id"],
        selected_by: "id",
        columns: with_provenance![
            ("id", Int),
            ("name", Text),
            ("status", Text),
            ("reason", Text),
            ("rho_ref", Blob),
            ("taken_at_ms", Int),
            ("completed_at_ms", Int),
            // A tile, or the instrument's own calibration (no readings).
            ("kind", Text),
            // All 14 geometries, or the 12 MA-T12 ones (a tile measured without the SRA).
            ("geometries", Text),
        ],
    },
    Table {
        name: "reference_readings",
        key: &["id"],
        selected_by: "id",
        columns: &[
            ("id", Int),
            ("reference_id", Int),
            ("device", Text),
            ("geometry", Text),
            ("values_f64le", Blob),
            ("raw_frame", Blob),
            ("taken_at_ms", Int),
        ],
    },
    Table {
        name: "scans",
        key: &["id"],
        selected_by: "id",
        columns: with_provenance![
            ("id", Int),
            ("sample_id", Int),
            ("reference_id", Int),
            ("state", Text),
            ("reason", Text),
            ("requested_at_ms", Int),
            ("started_at_ms", Int),
            ("finished_at_ms", Int),
            // All 14 geometries, or the 12 MA-T12 ones (no SRA readings).
            ("geometries", Text),
        ],
    },
    Table {
        name: "readings",
        key: &["id"],
        selected_by: "id",
        columns: &[
            ("id", Int),
            ("scan_id", Int),
            ("device", Text),
            ("geometry", Text),
            ("values_f64le", Blob),
            ("raw_frame", Blob),
            ("received_at_ms", Int),
        ],
    },
    Table {
        name: "processed",
        key: &["id"],
        selected_by: "id",
        columns: &[
            ("id", Int),
            ("scan_id", Int),
            ("specular", Text),
            ("brdf_f64le", Blob),
            ("created_at_ms", Int),
        ],
    },
    Table {
        name: "fit_runs",
        key: &["id"],
        selected_by: "id",
        columns: &[
            ("id", Int),
            ("scan_id", Int),
            ("processed_id", Int),
            ("method", Text),
            ("cost_function", Text),
            ("settings_json", Text),
            ("seed", Text),
            ("status", Text),
            ("error", Text),
            ("cost", Real),
            ("params_json", Text),
            ("best_cost_per_generation_json", Text),
            ("evaluations", Int),
            ("generations", Int),
            ("wall_ms", Real),
            ("queued_at_ms", Int),
            ("started_at_ms", Int),
            ("finished_at_ms", Int),
            // Migration 0011 (central 0002): the bootstrap intervals.
            ("uncertainty_json", Text),
            // Migration 0015 (central 0003): the SRA reading model.
            ("sra", Text),
            // Migration 0020 (central 0009): the colorimetry the fit was queued with.
            ("fit_observer", Text),
            ("fit_weighting", Text),
            // Migration 0030 (central 0017): the leave-one-geometry-out cross-validation.
            ("crossval_json", Text),
            ("held_out_mean", Real),
        ],
    },
    Table {
        name: "evaluation_summaries",
        key: &["fit_run_id"],
        selected_by: "fit_run_id",
        columns: &[
            ("fit_run_id", Int),
            ("mean", Real),
            ("median", Real),
            ("max", Real),
            ("diffuse_mean", Real),
            ("diffuse_median", Real),
            ("diffuse_max", Real),
            ("specular_mean", Real),
            ("specular_median", Real),
            ("specular_max", Real),
            // Migration 0011 (central 0002): the colorimetry of the evaluation.
            ("observer", Text),
            ("weighting", Text),
        ],
    },
    Table {
        name: "evaluations",
        key: &["fit_run_id", "geometry"],
        selected_by: "fit_run_id",
        columns: &[("fit_run_id", Int), ("geometry", Text), ("delta_e00", Real)],
    },
];

/// The tables an outbox entry of `table_name` stands for: itself, and for a fit's evaluation
/// summary the 14 per-geometry values with it. Empty for a name this brdfd does not forward.
pub fn tables_for(table_name: &str) -> Vec<&'static Table> {
    match table_name {
        "evaluation_summaries" => vec![table("evaluation_summaries"), table("evaluations")],
        name => TABLES.iter().filter(|t| t.name == name).collect(),
    }
}

/// The table called `name` (a constant of this module).
pub fn table(name: &str) -> &'static Table {
    TABLES
        .iter()
        .find(|t| t.name == name)
        .unwrap_or_else(|| panic!("no forwarded table {name}"))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::store::Store;
    use sqlx::Row;

    /// Columns of station tables that stay on the station: none today.
    const LOCAL_ONLY: &[(&str, &str)] = &[];

    /// Station tables that are not forwarded at all: the outbox itself, and the watch
    /// folder's record of imported files (its scans are forwarded like any other).
    const LOCAL_TABLES: &[&str] = &[
        "sync_outbox",
        "sync_identity",
        "sync_lineage",
        "ingested_files",
        "ingested_scans",
        // Each imported scan's file (content hash, name), by which every door recognises a
        // repeat; the scans' provenance goes with them.
        "scan_imports",
        // The instrument camera's texture images of imported scans stay on the station; the
        // central database has the scans' readings, fits and evaluations.
        "texture_images",
        "scan_textures",
        // Constants of the SQL views of migration 0013, the same on every station.
        "view_bands",
        "view_pow2",
    ];

    #[tokio::test]
    async fn every_station_table_is_forwarded_or_local() {
        let store = Store::open_in_memory().await.unwrap();
        let pool = store.sync_pools().0.clone();
        let names: Vec<String> = sqlx::query_scalar(
            "SELECT name FROM sqlite_master WHERE type = 'table'
               AND name NOT LIKE 'sqlite_%' AND name NOT LIKE '_sqlx_%'",
        )
        .fetch_all(&pool)
        .await
        .unwrap();
        for n in &names {
            assert!(
                TABLES.iter().any(|t| t.name == n) || LOCAL_TABLES.contains(&n.as_str()),
                "station table {n} is neither forwarded (src/sync/tables.rs and a central \
                 migration) nor listed in LOCAL_TABLES"
            );
        }
    }

    #[tokio::test]
    async fn every_station_column_is_forwarded() {
        let store = Store::open_in_memory().await.unwrap();
        let pool = store.sync_pools().0.clone();
        for t in &TABLES {
            let rows = sqlx::query(&format!("PRAGMA table_info({})", t.name))
                .fetch_all(&pool)
                .await
                .unwrap();
            let station: Vec<String> = rows.iter().map(|r| r.get::<String, _>("name")).collect();
            for c in &station {
                assert!(
                    t.columns.iter().any(|(n, _)| n == c)
                        || LOCAL_ONLY.contains(&(t.name, c.as_str())),
                    "{}.{c} is neither forwarded (src/sync/tables.rs and a central migration) \
                     nor listed as local-only",
                    t.name
                );
            }
            for (n, _) in t.columns {
                assert!(
                    station.contains(&n.to_string()),
                    "{}.{n} is not a station column",
                    t.name
                );
            }
        }
    }

    #[test]
    fn outbox_names_map_to_tables() {
        assert_eq!(tables_for("scans")[0].name, "scans");
        assert_eq!(tables_for("evaluation_summaries").len(), 2);
        assert!(tables_for("sync_outbox").is_empty());
    }
}
