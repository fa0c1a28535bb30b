-- Step 9: the colour evaluation of a finished fit (SCIENCE.md §7): ΔE00 between measured and
-- estimated colour at each of the 14 geometries, and its summary (mean, median, maximum over
-- all 14, over the 12 diffuse MA-T12 geometries and over the 2 specular SRA ones). The store
-- computes the summary from the 14 values it writes, so the two can never disagree.
CREATE TABLE evaluations (
    fit_run_id BIGINT           NOT NULL REFERENCES fit_runs (id) ON DELETE CASCADE,
    geometry   TEXT             NOT NULL,
    delta_e00  DOUBLE PRECISION NOT NULL,
    PRIMARY KEY (fit_run_id, geometry)
);

CREATE TABLE evaluation_summaries (
    fit_run_id      BIGINT           PRIMARY KEY REFERENCES fit_runs (id) ON DELETE CASCADE,
    mean            DOUBLE PRECISION NOT NULL,
    median          DOUBLE PRECISION NOT NULL,
    max             DOUBLE PRECISION NOT NULL,
    diffuse_mean    DOUBLE PRECISION NOT NULL,
    diffuse_median  DOUBLE PRECISION NOT NULL,
    diffuse_max     DOUBLE PRECISION NOT NULL,
    specular_mean   DOUBLE PRECISION NOT NULL,
    specular_median DOUBLE PRECISION NOT NULL,
    specular_max    DOUBLE PRECISION NOT NULL
);
