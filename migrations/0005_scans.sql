-- Step 5: scans of a sample against the reference set in force when it was requested.
--
-- Life cycle, enforced by the store's verbs (src/store/scans.rs):
--   requested → measuring → complete | failed | aborted   (requested → failed | aborted too)
-- A scan becomes complete only from measuring and only holding all 14 readings. `reason` says
-- why a scan failed (required then) or was aborted. A failed scan keeps its readings.
CREATE TABLE scans (
    id              INTEGER PRIMARY KEY,
    sample_id       BIGINT  NOT NULL REFERENCES samples (id),
    reference_id    BIGINT  NOT NULL REFERENCES reference_sets (id),
    state           TEXT    NOT NULL
                    CHECK (state IN ('requested', 'measuring', 'complete', 'failed', 'aborted')),
    reason          TEXT,
    requested_at_ms BIGINT  NOT NULL,
    started_at_ms   BIGINT,
    finished_at_ms  BIGINT,
    CHECK (state <> 'failed' OR reason IS NOT NULL),
    CHECK (state IN ('requested', 'measuring') OR finished_at_ms IS NOT NULL)
);

CREATE INDEX scans_by_state ON scans (state);
CREATE INDEX scans_by_sample ON scans (sample_id);
