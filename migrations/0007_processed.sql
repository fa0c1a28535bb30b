-- Step 7: a complete scan processed against its reference (SCIENCE.md §3): the measured BRDF in
-- sr⁻¹ at all 14 geometries × 31 bands, geometry-major in SCIENCE.md §2 table order, as
-- little-endian f64 (14 · 31 · 8 = 3472 bytes). `specular` is the SRA strategy used
-- ('ratio' or 'paper-eq9'); one row per (scan, strategy).
CREATE TABLE processed (
    id            INTEGER PRIMARY KEY,
    scan_id       BIGINT  NOT NULL REFERENCES scans (id) ON DELETE CASCADE,
    specular      TEXT    NOT NULL CHECK (length(specular) > 0),
    brdf_f64le    BLOB    NOT NULL CHECK (length(brdf_f64le) = 3472),
    created_at_ms BIGINT  NOT NULL,
    UNIQUE (scan_id, specular)
);
