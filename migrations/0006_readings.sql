-- Step 6: a scan's readings, each inserted the moment it arrives from its device, so a scan that
-- fails half way keeps what it measured. Same encoding as reference_readings (step 3):
-- little-endian f64, 31 for MA-T12 spectra, 1 for SRA intensities; the raw reply frame as is.
CREATE TABLE readings (
    id             INTEGER PRIMARY KEY,
    scan_id        BIGINT  NOT NULL REFERENCES scans (id) ON DELETE CASCADE,
    device         TEXT    NOT NULL CHECK (device IN ('ma_t12', 'sra')),
    geometry       TEXT    NOT NULL,
    values_f64le   BLOB    NOT NULL,
    raw_frame      BLOB    NOT NULL,
    received_at_ms BIGINT  NOT NULL,
    UNIQUE (scan_id, geometry),
    CHECK ((device = 'ma_t12' AND length(values_f64le) = 248
            AND geometry IN ('15as-45', '15as-30', '15as-15', '15as15', '15as45', '15as80',
                             '45as-15', '45as15', '45as25', '45as45', '45as75', '45as110'))
        OR (device = 'sra' AND length(values_f64le) = 8
            AND geometry IN ('sra-20', 'sra-60')))
);
