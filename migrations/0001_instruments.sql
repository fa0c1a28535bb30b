-- Step 1: the instruments brdfd has talked to.
--
-- One row per physical instrument, keyed by (device kind, serial number), so a replaced or
-- second instrument of the same kind gets its own row. `identity` is the device's own
-- identification string (model, firmware) as last reported; `first_seen_ms` never changes,
-- `last_seen_ms` moves on every connection.
--
-- Conventions for every table (see src/store/mod.rs):
-- * timestamps are INTEGER milliseconds since the Unix epoch, UTC (`*_ms` columns);
-- * `INTEGER PRIMARY KEY` is SQLite's auto-assigned row id; a PostgreSQL dialect of these files
--   would write `BIGINT GENERATED ALWAYS AS IDENTITY PRIMARY KEY` and BYTEA for BLOB; everything
--   else here is portable SQL.
-- * device kinds are the keys of `brdfd::geometry::Device::key()`: 'ma_t12' and 'sra'.
CREATE TABLE instruments (
    id            INTEGER PRIMARY KEY,
    device        TEXT    NOT NULL CHECK (device IN ('ma_t12', 'sra')),
    serial        TEXT    NOT NULL CHECK (length(serial) > 0),
    identity      TEXT    NOT NULL,
    first_seen_ms BIGINT  NOT NULL,
    last_seen_ms  BIGINT  NOT NULL,
    UNIQUE (device, serial)
);
