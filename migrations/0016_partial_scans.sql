-- Step 16: scans from an instrument's own software (SCIENCE.md §3), which may lack the N9 tile
-- and the SRA.
--
-- `reference_sets.kind`: 'tile' (a Munsell N9 measured on the instruments, the daemon's own
-- scans) or 'instrument-calibration' (no tile: the MA-T12's values are the reflectance factor
-- relative to the instrument's own calibrated white standard, R = S). An instrument-calibration
-- set has no readings. Rows written before this step are tiles.
ALTER TABLE reference_sets ADD COLUMN kind TEXT NOT NULL DEFAULT 'tile'
    CHECK (kind IN ('tile', 'instrument-calibration'));

-- `scans.geometries`: which geometries the scan measures — 'all' 14, or 'ma-t12', the 12
-- MA-T12 geometries of a scan without SRA readings. A scan is complete when it holds a reading
-- at each of them.
ALTER TABLE scans ADD COLUMN geometries TEXT NOT NULL DEFAULT 'all'
    CHECK (geometries IN ('all', 'ma-t12'));

-- `evaluation_summaries.specular_*` become NULL for a fit of a scan without SRA readings. SQLite
-- cannot drop a NOT NULL, so the table is rebuilt with every row kept, and its forwarding
-- triggers (step 14) are made again.
CREATE TABLE evaluation_summaries_partial (
    fit_run_id      BIGINT           PRIMARY KEY REFERENCES fit_runs (id) ON DELETE CASCADE,
    mean            DOUBLE PRECISION NOT NULL,
    median          DOUBLE PRECISION NOT NULL,
    max             DOUBLE PRECISION NOT NULL,
    diffuse_mean    DOUBLE PRECISION NOT NULL,
    diffuse_median  DOUBLE PRECISION NOT NULL,
    diffuse_max     DOUBLE PRECISION NOT NULL,
    specular_mean   DOUBLE PRECISION,
    specular_median DOUBLE PRECISION,
    specular_max    DOUBLE PRECISION,
    observer        TEXT NOT NULL DEFAULT '2' CHECK (observer IN ('2', '10')),
    weighting       TEXT NOT NULL DEFAULT 'summation' CHECK (weighting IN ('summation', 'astm-e308')),
    CHECK ((specular_mean IS NULL) = (specular_median IS NULL)
           AND (specular_mean IS NULL) = (specular_max IS NULL))
);
INSERT INTO evaluation_summaries_partial
    SELECT fit_run_id, mean, median, max, diffuse_mean, diffuse_median, diffuse_max,
           specular_mean, specular_median, specular_max, observer, weighting
    FROM evaluation_summaries;
DROP TABLE evaluation_summaries;
ALTER TABLE evaluation_summaries_partial RENAME TO evaluation_summaries;
CREATE TRIGGER sync_evaluation_summaries_insert AFTER INSERT ON evaluation_summaries BEGIN
    INSERT INTO sync_outbox (table_name, row_id, at_ms) VALUES ('evaluation_summaries',
        NEW.fit_run_id, CAST((julianday('now') - 2440587.5) * 86400000.0 AS INTEGER));
END;
CREATE TRIGGER sync_evaluation_summaries_update AFTER UPDATE ON evaluation_summaries BEGIN
    INSERT INTO sync_outbox (table_name, row_id, at_ms) VALUES ('evaluation_summaries',
        NEW.fit_run_id, CAST((julianday('now') - 2440587.5) * 86400000.0 AS INTEGER));
END;
