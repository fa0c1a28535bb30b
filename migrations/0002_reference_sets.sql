-- Step 2: reference sets, one per measurement of the white reference tile (e.g. "Munsell N9").
--
-- Named `reference_sets` because REFERENCES is an SQL keyword. A set is `measuring` while its
-- 14 readings come in, then `complete` (all 14 present, checked by the store) or `failed`
-- (with a reason). Scans are normalised by a complete set.
--
-- `rho_ref` is the tile's optional calibrated reflectance factor (SCIENCE.md §3): 31 f64,
-- little-endian, 400–700 nm every 10 nm (248 bytes). NULL means ρ_ref = 1, the paper's default.
CREATE TABLE reference_sets (
    id              INTEGER PRIMARY KEY,
    name            TEXT    NOT NULL CHECK (length(name) > 0),
    status          TEXT    NOT NULL CHECK (status IN ('measuring', 'complete', 'failed')),
    reason          TEXT,
    rho_ref         BLOB    CHECK (rho_ref IS NULL OR length(rho_ref) = 248),
    taken_at_ms     BIGINT  NOT NULL,
    completed_at_ms BIGINT,
    CHECK (status <> 'failed' OR reason IS NOT NULL),
    CHECK (status <> 'complete' OR completed_at_ms IS NOT NULL)
);

CREATE INDEX reference_sets_by_status ON reference_sets (status, completed_at_ms);
