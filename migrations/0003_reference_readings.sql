-- Step 3: the readings of a reference set, one per geometry.
--
-- `geometry` is the device's geometry name (SCIENCE.md §2, e.g. '15as-45', 'sra-20').
-- `values_f64le` holds the reading as little-endian f64: 31 of them (248 bytes) for an MA-T12
-- reflectance-factor spectrum, 1 (8 bytes) for an SRA 1D-BRDF intensity. A BLOB round-trips
-- every f64 bit for bit, which text would not guarantee across drivers.
-- `raw_frame` is the device's reply frame exactly as received, kept for audit and replay.
-- The CHECK pins each device to its own geometries and value length, so "14 rows" means
-- "all 14 geometries" (the names are SCIENCE.md §2's, as in src/geometry.rs).
CREATE TABLE reference_readings (
    id           INTEGER PRIMARY KEY,
    reference_id BIGINT  NOT NULL REFERENCES reference_sets (id) ON DELETE CASCADE,
    device       TEXT    NOT NULL CHECK (device IN ('ma_t12', 'sra')),
    geometry     TEXT    NOT NULL,
    values_f64le BLOB    NOT NULL,
    raw_frame    BLOB    NOT NULL,
    taken_at_ms  BIGINT  NOT NULL,
    UNIQUE (reference_id, geometry),
    CHECK ((device = 'ma_t12' AND length(values_f64le) = 248
            AND geometry IN ('15as-45', '15as-30', '15as-15', '15as15', '15as45', '15as80',
                             '45as-15', '45as15', '45as25', '45as45', '45as75', '45as110'))
        OR (device = 'sra' AND length(values_f64le) = 8
            AND geometry IN ('sra-20', 'sra-60')))
);
