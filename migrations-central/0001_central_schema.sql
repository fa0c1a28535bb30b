-- Central step 1: the lab's central PostgreSQL database, which every station's store is
-- forwarded to (src/sync/, ARCHITECTURE.md "Several stations, one lab").
--
-- Each table mirrors the station table of the same name (migrations/0001–0010), column for
-- column, with the station's id in front: a row is keyed by (station, id), where `id` is its
-- row id in the station's store, and every reference to another row stays within the station
-- (the foreign keys include `station`). Column names are the stations' own, so the store's
-- row decoding (src/store/central.rs) reads both alike.
--
-- Dialect: BIGINT for SQLite's INTEGER, BYTEA for BLOB (the same little-endian f64 bytes),
-- DOUBLE PRECISION as in SQLite. The CHECKs of the stations are not repeated: the rows were
-- checked when the station wrote them, and a central CHECK that a newer station's row failed
-- would stop that station's forwarding.
--
-- Foreign keys are DEFERRABLE INITIALLY DEFERRED: a forwarder sends a batch in commit order,
-- but the rows of one batch are checked at its COMMIT, together with the station's cursor.

-- One row per station: who claimed the id (the store's `sync_identity.uid`) and how far its
-- outbox has been applied (`cursor` = the last `sync_outbox.seq` committed here). The cursor
-- moves in the same transaction as the rows, so a crash on either side loses or doubles nothing.
CREATE TABLE stations (
    station        TEXT        PRIMARY KEY CHECK (length(station) > 0),
    store_uid      TEXT        NOT NULL,
    cursor         BIGINT      NOT NULL DEFAULT 0,
    host           TEXT,
    brdfd_version  TEXT,
    registered_at  TIMESTAMPTZ NOT NULL DEFAULT now(),
    last_synced_at TIMESTAMPTZ
);

CREATE TABLE instruments (
    station       TEXT   NOT NULL REFERENCES stations (station),
    id            BIGINT NOT NULL,
    device        TEXT   NOT NULL,
    serial        TEXT   NOT NULL,
    identity      TEXT   NOT NULL,
    first_seen_ms BIGINT NOT NULL,
    last_seen_ms  BIGINT NOT NULL,
    PRIMARY KEY (station, id)
);

CREATE TABLE samples (
    station       TEXT   NOT NULL REFERENCES stations (station),
    id            BIGINT NOT NULL,
    name          TEXT   NOT NULL,
    created_at_ms BIGINT NOT NULL,
    PRIMARY KEY (station, id)
);

CREATE TABLE reference_sets (
    station          TEXT   NOT NULL REFERENCES stations (station),
    id               BIGINT NOT NULL,
    name             TEXT   NOT NULL,
    status           TEXT   NOT NULL,
    reason           TEXT,
    rho_ref          BYTEA,
    taken_at_ms      BIGINT NOT NULL,
    completed_at_ms  BIGINT,
    ma_t12_model     TEXT   NOT NULL,
    ma_t12_serial    TEXT   NOT NULL,
    ma_t12_firmware  TEXT   NOT NULL,
    ma_t12_simulated BIGINT,
    sra_model        TEXT   NOT NULL,
    sra_serial       TEXT   NOT NULL,
    sra_firmware     TEXT   NOT NULL,
    sra_simulated    BIGINT,
    source           TEXT   NOT NULL,
    source_detail    TEXT,
    PRIMARY KEY (station, id)
);

CREATE TABLE reference_readings (
    station      TEXT   NOT NULL,
    id           BIGINT NOT NULL,
    reference_id BIGINT NOT NULL,
    device       TEXT   NOT NULL,
    geometry     TEXT   NOT NULL,
    values_f64le BYTEA  NOT NULL,
    raw_frame    BYTEA  NOT NULL,
    taken_at_ms  BIGINT NOT NULL,
    PRIMARY KEY (station, id),
    FOREIGN KEY (station, reference_id) REFERENCES reference_sets (station, id)
        DEFERRABLE INITIALLY DEFERRED
);
CREATE INDEX reference_readings_by_reference ON reference_readings (station, reference_id);

CREATE TABLE scans (
    station          TEXT   NOT NULL REFERENCES stations (station),
    id               BIGINT NOT NULL,
    sample_id        BIGINT NOT NULL,
    reference_id     BIGINT NOT NULL,
    state            TEXT   NOT NULL,
    reason           TEXT,
    requested_at_ms  BIGINT NOT NULL,
    started_at_ms    BIGINT,
    finished_at_ms   BIGINT,
    ma_t12_model     TEXT   NOT NULL,
    ma_t12_serial    TEXT   NOT NULL,
    ma_t12_firmware  TEXT   NOT NULL,
    ma_t12_simulated BIGINT,
    sra_model        TEXT   NOT NULL,
    sra_serial       TEXT   NOT NULL,
    sra_firmware     TEXT   NOT NULL,
    sra_simulated    BIGINT,
    source           TEXT   NOT NULL,
    source_detail    TEXT,
    PRIMARY KEY (station, id),
    FOREIGN KEY (station, sample_id) REFERENCES samples (station, id)
        DEFERRABLE INITIALLY DEFERRED,
    FOREIGN KEY (station, reference_id) REFERENCES reference_sets (station, id)
        DEFERRABLE INITIALLY DEFERRED
);
CREATE INDEX scans_by_state ON scans (state, station, id);

CREATE TABLE readings (
    station        TEXT   NOT NULL,
    id             BIGINT NOT NULL,
    scan_id        BIGINT NOT NULL,
    device         TEXT   NOT NULL,
    geometry       TEXT   NOT NULL,
    values_f64le   BYTEA  NOT NULL,
    raw_frame      BYTEA  NOT NULL,
    received_at_ms BIGINT NOT NULL,
    PRIMARY KEY (station, id),
    FOREIGN KEY (station, scan_id) REFERENCES scans (station, id)
        DEFERRABLE INITIALLY DEFERRED
);
CREATE INDEX readings_by_scan ON readings (station, scan_id);

CREATE TABLE processed (
    station       TEXT   NOT NULL,
    id            BIGINT NOT NULL,
    scan_id       BIGINT NOT NULL,
    specular      TEXT   NOT NULL,
    brdf_f64le    BYTEA  NOT NULL,
    created_at_ms BIGINT NOT NULL,
    PRIMARY KEY (station, id),
    FOREIGN KEY (station, scan_id) REFERENCES scans (station, id)
        DEFERRABLE INITIALLY DEFERRED
);
CREATE INDEX processed_by_scan ON processed (station, scan_id);

CREATE TABLE fit_runs (
    station                       TEXT             NOT NULL,
    id                            BIGINT           NOT NULL,
    scan_id                       BIGINT           NOT NULL,
    processed_id                  BIGINT           NOT NULL,
    method                        TEXT             NOT NULL,
    cost_function                 TEXT             NOT NULL,
    settings_json                 TEXT             NOT NULL,
    seed                          TEXT             NOT NULL,
    status                        TEXT             NOT NULL,
    error                         TEXT,
    cost                          DOUBLE PRECISION,
    params_json                   TEXT,
    best_cost_per_generation_json TEXT,
    evaluations                   BIGINT,
    generations                   BIGINT,
    wall_ms                       DOUBLE PRECISION,
    queued_at_ms                  BIGINT           NOT NULL,
    started_at_ms                 BIGINT,
    finished_at_ms                BIGINT,
    PRIMARY KEY (station, id),
    FOREIGN KEY (station, scan_id) REFERENCES scans (station, id)
        DEFERRABLE INITIALLY DEFERRED,
    FOREIGN KEY (station, processed_id) REFERENCES processed (station, id)
        DEFERRABLE INITIALLY DEFERRED
);
CREATE INDEX fit_runs_by_scan ON fit_runs (station, scan_id);

CREATE TABLE evaluations (
    station    TEXT             NOT NULL,
    fit_run_id BIGINT           NOT NULL,
    geometry   TEXT             NOT NULL,
    delta_e00  DOUBLE PRECISION NOT NULL,
    PRIMARY KEY (station, fit_run_id, geometry),
    FOREIGN KEY (station, fit_run_id) REFERENCES fit_runs (station, id)
        DEFERRABLE INITIALLY DEFERRED
);

CREATE TABLE evaluation_summaries (
    station         TEXT             NOT NULL,
    fit_run_id      BIGINT           NOT NULL,
    mean            DOUBLE PRECISION NOT NULL,
    median          DOUBLE PRECISION NOT NULL,
    max             DOUBLE PRECISION NOT NULL,
    diffuse_mean    DOUBLE PRECISION NOT NULL,
    diffuse_median  DOUBLE PRECISION NOT NULL,
    diffuse_max     DOUBLE PRECISION NOT NULL,
    specular_mean   DOUBLE PRECISION NOT NULL,
    specular_median DOUBLE PRECISION NOT NULL,
    specular_max    DOUBLE PRECISION NOT NULL,
    PRIMARY KEY (station, fit_run_id),
    FOREIGN KEY (station, fit_run_id) REFERENCES fit_runs (station, id)
        DEFERRABLE INITIALLY DEFERRED
);
