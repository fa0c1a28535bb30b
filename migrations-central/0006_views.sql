-- Central step 6: views for scientists — the station's decoding views (station migration
-- 0013) in PostgreSQL, a tidy table of fit results, the fitted kd per band, and a lab-wide
-- identity of samples, so that a query can pool the scans of every station (README "The
-- central database with SQL").
--
-- * `f64le_at(bytes, i)`: the i-th little-endian IEEE-754 f64 of a BYTEA, exactly (sign,
--   exponent and mantissa from the bytes; the mantissa times a power of two is exact in
--   float8). NaN and infinities (the stations refuse them) read as NULL.
-- * Every view keeps `station` and the station's own ids, so a row can be traced back to the
--   station's store (`brdfd show --db`, the station's views).
-- * Times are `timestamptz` (the stations store ms since the Unix epoch, UTC).
-- * A scan is `simulated` when either instrument was simulated (a replayed recording).
-- * Sample names are the stations' own: two stations may call different tiles "tile-3".
--   `lab_samples` is the lab's list of physical samples and `sample_identities` says, station
--   by station, which station sample is which lab sample. The lab fills both (they are not
--   forwarded, and no station writes them); `fit_results.lab_sample` is NULL until a station's
--   sample is assigned.

CREATE FUNCTION f64le_at(b BYTEA, i INTEGER) RETURNS DOUBLE PRECISION
LANGUAGE sql IMMUTABLE STRICT PARALLEL SAFE AS $$
    SELECT CASE
        WHEN x.e = 2047 THEN NULL
        WHEN x.e = 0 THEN x.s * x.m::float8 * power(2::float8, -1074)
        ELSE x.s * (x.m + 4503599627370496)::float8 * power(2::float8, x.e - 1075)
    END
    FROM (SELECT
        CASE WHEN get_byte(b, 8 * i + 7) >= 128 THEN -1::float8 ELSE 1::float8 END AS s,
        ((get_byte(b, 8 * i + 7) & 127) << 4) | (get_byte(b, 8 * i + 6) >> 4) AS e,
        ((get_byte(b, 8 * i + 6) & 15)::bigint << 48)
            | (get_byte(b, 8 * i + 5)::bigint << 40) | (get_byte(b, 8 * i + 4)::bigint << 32)
            | (get_byte(b, 8 * i + 3)::bigint << 24) | (get_byte(b, 8 * i + 2)::bigint << 16)
            | (get_byte(b, 8 * i + 1)::bigint << 8) | get_byte(b, 8 * i)::bigint AS m
    ) x
$$;

-- Milliseconds since the Unix epoch (UTC) as a timestamptz.
CREATE FUNCTION ms_time(ms BIGINT) RETURNS TIMESTAMPTZ
LANGUAGE sql IMMUTABLE STRICT PARALLEL SAFE AS $$
    SELECT to_timestamp(ms / 1000.0)
$$;

-- One row per value of a sample reading: as the station's view, with `station` in front.
CREATE VIEW reading_values AS
SELECT r.station, r.id AS reading_id, r.scan_id, r.device, r.geometry, b.band,
    CASE WHEN length(r.values_f64le) = 8 THEN NULL ELSE 400 + 10 * b.band END AS nm,
    f64le_at(r.values_f64le, b.band) AS value
FROM readings r
CROSS JOIN LATERAL generate_series(0, length(r.values_f64le) / 8 - 1) AS b(band);

-- The same for the reference tile's readings.
CREATE VIEW reference_reading_values AS
SELECT r.station, r.id AS reading_id, r.reference_id, r.device, r.geometry, b.band,
    CASE WHEN length(r.values_f64le) = 8 THEN NULL ELSE 400 + 10 * b.band END AS nm,
    f64le_at(r.values_f64le, b.band) AS value
FROM reference_readings r
CROSS JOIN LATERAL generate_series(0, length(r.values_f64le) / 8 - 1) AS b(band);

-- The measured BRDF (sr^-1) of each processed scan: geometry_index 0-13 in SCIENCE.md §2
-- table order, band, nm, value.
CREATE VIEW processed_values AS
SELECT p.station, p.id AS processed_id, p.scan_id, p.specular, g.i AS geometry_index, b.band,
    400 + 10 * b.band AS nm, f64le_at(p.brdf_f64le, 31 * g.i + b.band) AS value
FROM processed p
CROSS JOIN generate_series(0, 13) AS g(i)
CROSS JOIN generate_series(0, 30) AS b(band);

-- The lab's physical samples, and which station sample is which.
CREATE TABLE lab_samples (
    lab_sample  TEXT PRIMARY KEY CHECK (length(lab_sample) > 0),
    description TEXT
);
CREATE TABLE sample_identities (
    station    TEXT   NOT NULL,
    sample_id  BIGINT NOT NULL,
    lab_sample TEXT   NOT NULL REFERENCES lab_samples (lab_sample),
    PRIMARY KEY (station, sample_id),
    FOREIGN KEY (station, sample_id) REFERENCES samples (station, id)
);

-- One row per finished fit: where and when the scan was measured, with what, and what the
-- fit found (the model parameters, SCIENCE.md §4, and the ΔE00 summaries, §7).
CREATE VIEW fit_results AS
SELECT f.station, f.scan_id, f.id AS fit_run_id, si.lab_sample, sa.name AS sample,
    ms_time(COALESCE(s.finished_at_ms, s.started_at_ms, s.requested_at_ms)) AS measured_at,
    (COALESCE(s.ma_t12_simulated, 0) = 1 OR COALESCE(s.sra_simulated, 0) = 1) AS simulated,
    s.source, s.ma_t12_model, s.ma_t12_serial, s.sra_model, s.sra_serial,
    f.method, f.cost_function, f.sra, f.cost,
    (f.params_json::jsonb ->> 'ks')::float8 AS ks,
    (f.params_json::jsonb ->> 'alpha')::float8 AS alpha,
    (f.params_json::jsonb ->> 'ior')::float8 AS mu,
    e.mean AS de00_mean, e.median AS de00_median, e.max AS de00_max,
    e.diffuse_mean AS de00_diffuse_mean, e.diffuse_median AS de00_diffuse_median,
    e.diffuse_max AS de00_diffuse_max, e.specular_mean AS de00_specular_mean,
    e.specular_median AS de00_specular_median, e.specular_max AS de00_specular_max,
    e.observer, e.weighting,
    ms_time(f.finished_at_ms) AS fitted_at
FROM fit_runs f
JOIN scans s ON s.station = f.station AND s.id = f.scan_id
JOIN samples sa ON sa.station = s.station AND sa.id = s.sample_id
LEFT JOIN sample_identities si ON si.station = sa.station AND si.sample_id = sa.id
LEFT JOIN evaluation_summaries e ON e.station = f.station AND e.fit_run_id = f.id
WHERE f.status = 'done';

-- The fitted diffuse term kd (sr^-1) per band of each finished fit.
CREATE VIEW kd_values AS
SELECT f.station, f.id AS fit_run_id, f.scan_id, f.cost_function, b.band, 400 + 10 * b.band AS nm,
    (f.params_json::jsonb -> 'kd' ->> b.band)::float8 AS kd
FROM fit_runs f
CROSS JOIN generate_series(0, 30) AS b(band)
WHERE f.status = 'done';
