-- Step 8: fit runs, one per (processed scan, cost function, method, settings, seed) asked for.
--
-- Life cycle, enforced by the store's verbs (src/store/fits.rs):
--   queued → running → done | failed | cancelled   (queued → failed | cancelled too)
-- `settings_json` is every optimiser setting as serialised by serde, so a fit can be re-run bit
-- for bit; `seed` is TEXT because a u64 seed does not fit a signed 64-bit INTEGER.
-- Results, set by finish_fit: `cost`, `params_json` (kd[31], ks, alpha, ior),
-- `best_cost_per_generation_json` (array of f64), `evaluations` (cost evaluations),
-- `generations`, `wall_ms` (wall time, ms). DOUBLE PRECISION is REAL (8-byte IEEE) in SQLite.
CREATE TABLE fit_runs (
    id                            INTEGER PRIMARY KEY,
    scan_id                       BIGINT  NOT NULL REFERENCES scans (id) ON DELETE CASCADE,
    processed_id                  BIGINT  NOT NULL REFERENCES processed (id) ON DELETE CASCADE,
    method                        TEXT    NOT NULL,
    cost_function                 TEXT    NOT NULL,
    settings_json                 TEXT    NOT NULL,
    seed                          TEXT    NOT NULL,
    status                        TEXT    NOT NULL
                                  CHECK (status IN ('queued', 'running', 'done', 'failed', 'cancelled')),
    error                         TEXT,
    cost                          DOUBLE PRECISION,
    params_json                   TEXT,
    best_cost_per_generation_json TEXT,
    evaluations                   BIGINT,
    generations                   BIGINT,
    wall_ms                       DOUBLE PRECISION,
    queued_at_ms                  BIGINT  NOT NULL,
    started_at_ms                 BIGINT,
    finished_at_ms                BIGINT,
    CHECK (status <> 'failed' OR error IS NOT NULL),
    CHECK (status <> 'done' OR (cost IS NOT NULL AND params_json IS NOT NULL
                                AND best_cost_per_generation_json IS NOT NULL
                                AND evaluations IS NOT NULL AND generations IS NOT NULL
                                AND wall_ms IS NOT NULL))
);

CREATE INDEX fit_runs_by_scan ON fit_runs (scan_id);
CREATE INDEX fit_runs_by_status ON fit_runs (status);
