-- Step 13: views that decode the stored spectra for people and tools that read the store with
-- SQL (`sqlite3`, pandas, R). Readings and BRDFs are stored as little-endian IEEE-754 f64 BLOBs
-- (`values_f64le`, `brdf_f64le`), which SQL cannot read by itself; these views turn them into one
-- row per value, exactly (bit for bit: the integer mantissa times a power of two, both exact in
-- f64), without any extension. README "Reading the store with SQL" has examples.
--
-- * `view_bands`: band index 0–30 → wavelength, 400–700 nm in 10 nm steps (SCIENCE.md §1).
-- * `view_pow2`: 2^e for e = −1074 … 1023, every power of two an f64 can hold, built by
--   doubling and halving (exact).
-- * Each view decodes one 8-byte group with `hex()`: byte k of the little-endian number is the
--   hex pair at characters 2k+1, 2k+2; sign = top bit of byte 7, exponent = the next 11 bits,
--   mantissa = the low 52 bits. NaN and infinities (exponent 2047; the store refuses them) read
--   as NULL.
-- * An SRA reading holds one value (its achromatic intensity): band 0, `nm` NULL.

CREATE TABLE view_bands (
    band INTEGER PRIMARY KEY,
    nm   INTEGER NOT NULL
);
WITH RECURSIVE b(i) AS (SELECT 0 UNION ALL SELECT i + 1 FROM b WHERE i < 30)
INSERT INTO view_bands (band, nm) SELECT i, 400 + 10 * i FROM b;

CREATE TABLE view_pow2 (
    e INTEGER PRIMARY KEY,
    v REAL    NOT NULL
);
WITH RECURSIVE up(e, v) AS (SELECT 0, 1.0 UNION ALL SELECT e + 1, v * 2.0 FROM up WHERE e < 1023)
INSERT INTO view_pow2 (e, v) SELECT e, v FROM up;
WITH RECURSIVE down(e, v) AS (SELECT -1, 0.5 UNION ALL SELECT e - 1, v / 2.0 FROM down WHERE e > -1074)
INSERT INTO view_pow2 (e, v) SELECT e, v FROM down;

-- One row per value of a sample reading: scan, geometry, band and nm (NULL for the SRA), value (MA-T12: reflectance factor, 0-1; SRA: the device's intensity).
CREATE VIEW reading_values AS
WITH raw AS (
    SELECT r.id AS reading_id, r.scan_id, r.device, r.geometry, b.band,
        CASE WHEN length(r.values_f64le) = 8 THEN NULL ELSE b.nm END AS nm,
        hex(substr(r.values_f64le, 8 * b.band + 1, 8)) AS h
    FROM readings r JOIN view_bands b ON b.band < length(r.values_f64le) / 8
), parts AS (
    SELECT reading_id, scan_id, device, geometry, band, nm,
        (CASE WHEN (instr('0123456789ABCDEF', substr(h, 15, 1)) - 1) >= 8 THEN -1.0 ELSE 1.0 END) AS sign,
        ((((instr('0123456789ABCDEF', substr(h, 15, 1)) - 1) % 8) * 16 + (instr('0123456789ABCDEF', substr(h, 16, 1)) - 1)) * 16 + (instr('0123456789ABCDEF', substr(h, 13, 1)) - 1)) AS exponent,
        ((instr('0123456789ABCDEF', substr(h, 14, 1)) - 1) * 281474976710656
            + ((instr('0123456789ABCDEF', substr(h, 11, 1)) - 1) * 16 + (instr('0123456789ABCDEF', substr(h, 12, 1)) - 1)) * 1099511627776
            + ((instr('0123456789ABCDEF', substr(h, 9, 1)) - 1) * 16 + (instr('0123456789ABCDEF', substr(h, 10, 1)) - 1)) * 4294967296
            + ((instr('0123456789ABCDEF', substr(h, 7, 1)) - 1) * 16 + (instr('0123456789ABCDEF', substr(h, 8, 1)) - 1)) * 16777216
            + ((instr('0123456789ABCDEF', substr(h, 5, 1)) - 1) * 16 + (instr('0123456789ABCDEF', substr(h, 6, 1)) - 1)) * 65536
            + ((instr('0123456789ABCDEF', substr(h, 3, 1)) - 1) * 16 + (instr('0123456789ABCDEF', substr(h, 4, 1)) - 1)) * 256
            + ((instr('0123456789ABCDEF', substr(h, 1, 1)) - 1) * 16 + (instr('0123456789ABCDEF', substr(h, 2, 1)) - 1)) * 1) AS mantissa
    FROM raw
)
SELECT parts.reading_id, parts.scan_id, parts.device, parts.geometry, parts.band, parts.nm,
    CASE
        WHEN parts.exponent = 2047 THEN NULL
        WHEN parts.exponent = 0 THEN parts.sign * parts.mantissa * p.v
        ELSE parts.sign * (parts.mantissa + 4503599627370496) * p.v
    END AS value
FROM parts JOIN view_pow2 p
  ON p.e = CASE WHEN parts.exponent = 0 THEN -1074 ELSE parts.exponent - 1075 END;

-- The same for the reference tile's readings.
CREATE VIEW reference_reading_values AS
WITH raw AS (
    SELECT r.id AS reading_id, r.reference_id, r.device, r.geometry, b.band,
        CASE WHEN length(r.values_f64le) = 8 THEN NULL ELSE b.nm END AS nm,
        hex(substr(r.values_f64le, 8 * b.band + 1, 8)) AS h
    FROM reference_readings r JOIN view_bands b ON b.band < length(r.values_f64le) / 8
), parts AS (
    SELECT reading_id, reference_id, device, geometry, band, nm,
        (CASE WHEN (instr('0123456789ABCDEF', substr(h, 15, 1)) - 1) >= 8 THEN -1.0 ELSE 1.0 END) AS sign,
        ((((instr('0123456789ABCDEF', substr(h, 15, 1)) - 1) % 8) * 16 + (instr('0123456789ABCDEF', substr(h, 16, 1)) - 1)) * 16 + (instr('0123456789ABCDEF', substr(h, 13, 1)) - 1)) AS exponent,
        ((instr('0123456789ABCDEF', substr(h, 14, 1)) - 1) * 281474976710656
            + ((instr('0123456789ABCDEF', substr(h, 11, 1)) - 1) * 16 + (instr('0123456789ABCDEF', substr(h, 12, 1)) - 1)) * 1099511627776
            + ((instr('0123456789ABCDEF', substr(h, 9, 1)) - 1) * 16 + (instr('0123456789ABCDEF', substr(h, 10, 1)) - 1)) * 4294967296
            + ((instr('0123456789ABCDEF', substr(h, 7, 1)) - 1) * 16 + (instr('0123456789ABCDEF', substr(h, 8, 1)) - 1)) * 16777216
            + ((instr('0123456789ABCDEF', substr(h, 5, 1)) - 1) * 16 + (instr('0123456789ABCDEF', substr(h, 6, 1)) - 1)) * 65536
            + ((instr('0123456789ABCDEF', substr(h, 3, 1)) - 1) * 16 + (instr('0123456789ABCDEF', substr(h, 4, 1)) - 1)) * 256
            + ((instr('0123456789ABCDEF', substr(h, 1, 1)) - 1) * 16 + (instr('0123456789ABCDEF', substr(h, 2, 1)) - 1)) * 1) AS mantissa
    FROM raw
)
SELECT parts.reading_id, parts.reference_id, parts.device, parts.geometry, parts.band, parts.nm,
    CASE
        WHEN parts.exponent = 2047 THEN NULL
        WHEN parts.exponent = 0 THEN parts.sign * parts.mantissa * p.v
        ELSE parts.sign * (parts.mantissa + 4503599627370496) * p.v
    END AS value
FROM parts JOIN view_pow2 p
  ON p.e = CASE WHEN parts.exponent = 0 THEN -1074 ELSE parts.exponent - 1075 END;

-- The measured BRDF (sr^-1) of each processed scan: geometry_index 0-13 in SCIENCE.md §2 table order, band, nm, value.
CREATE VIEW processed_values AS
WITH raw AS (
    SELECT p.id AS processed_id, p.scan_id, p.specular, g.i AS geometry_index, b.band, b.nm,
        hex(substr(p.brdf_f64le, 8 * (31 * g.i + b.band) + 1, 8)) AS h
    FROM processed p
    JOIN (SELECT band AS i FROM view_bands WHERE band < 14) g
    JOIN view_bands b
), parts AS (
    SELECT processed_id, scan_id, specular, geometry_index, band, nm,
        (CASE WHEN (instr('0123456789ABCDEF', substr(h, 15, 1)) - 1) >= 8 THEN -1.0 ELSE 1.0 END) AS sign,
        ((((instr('0123456789ABCDEF', substr(h, 15, 1)) - 1) % 8) * 16 + (instr('0123456789ABCDEF', substr(h, 16, 1)) - 1)) * 16 + (instr('0123456789ABCDEF', substr(h, 13, 1)) - 1)) AS exponent,
        ((instr('0123456789ABCDEF', substr(h, 14, 1)) - 1) * 281474976710656
            + ((instr('0123456789ABCDEF', substr(h, 11, 1)) - 1) * 16 + (instr('0123456789ABCDEF', substr(h, 12, 1)) - 1)) * 1099511627776
            + ((instr('0123456789ABCDEF', substr(h, 9, 1)) - 1) * 16 + (instr('0123456789ABCDEF', substr(h, 10, 1)) - 1)) * 4294967296
            + ((instr('0123456789ABCDEF', substr(h, 7, 1)) - 1) * 16 + (instr('0123456789ABCDEF', substr(h, 8, 1)) - 1)) * 16777216
            + ((instr('0123456789ABCDEF', substr(h, 5, 1)) - 1) * 16 + (instr('0123456789ABCDEF', substr(h, 6, 1)) - 1)) * 65536
            + ((instr('0123456789ABCDEF', substr(h, 3, 1)) - 1) * 16 + (instr('0123456789ABCDEF', substr(h, 4, 1)) - 1)) * 256
            + ((instr('0123456789ABCDEF', substr(h, 1, 1)) - 1) * 16 + (instr('0123456789ABCDEF', substr(h, 2, 1)) - 1)) * 1) AS mantissa
    FROM raw
)
SELECT parts.processed_id, parts.scan_id, parts.specular, parts.geometry_index, parts.band, parts.nm,
    CASE
        WHEN parts.exponent = 2047 THEN NULL
        WHEN parts.exponent = 0 THEN parts.sign * parts.mantissa * p.v
        ELSE parts.sign * (parts.mantissa + 4503599627370496) * p.v
    END AS value
FROM parts JOIN view_pow2 p
  ON p.e = CASE WHEN parts.exponent = 0 THEN -1074 ELSE parts.exponent - 1075 END;
