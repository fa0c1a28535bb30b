-- Step 12: the watch folder's record of what it imported ([ingest] watch, src/service/ingest.rs).
--
-- One row per file (or MA-T12 export + SRA CSV pair) imported from the watch folder, keyed by
-- the SHA-256 of its content, written in the same transaction as the scans it holds: a file
-- whose hash is here has been imported, whole, and is never imported again (the same bytes
-- dropped a second time, under any name, are refused); a file whose hash is not here left no
-- row behind, so importing it again after a crash cannot duplicate anything.
--
-- * `sha256` is 64 lower-case hex digits: of the file's bytes, or for a pair of the export's
--   bytes and the SRA CSV's bytes (each length-prefixed, so no two pairs hash alike by moving
--   bytes from one file to the other).
-- * `file_name` and `partner_name` are the names the files had in the watch folder.
-- * `fits_queued` is 0 until the scans have been processed and their fits queued (after the
--   commit): a daemon stopped in between queues them at its next start.
-- * `ingested_scans` lists the scans of each file, in the file's order.
--
-- Both tables stay on the station (src/sync/tables.rs, LOCAL_TABLES): the scans themselves,
-- with their provenance "imported from FILE", are what the central database receives.
CREATE TABLE ingested_files (
    id             INTEGER PRIMARY KEY,
    sha256         TEXT    NOT NULL UNIQUE CHECK (length(sha256) = 64),
    file_name      TEXT    NOT NULL,
    partner_name   TEXT,
    imported_at_ms BIGINT  NOT NULL,
    fits_queued    INTEGER NOT NULL DEFAULT 0 CHECK (fits_queued IN (0, 1))
);

CREATE TABLE ingested_scans (
    ingested_file_id INTEGER NOT NULL REFERENCES ingested_files (id),
    position         INTEGER NOT NULL CHECK (position >= 0),
    scan_id          INTEGER NOT NULL UNIQUE REFERENCES scans (id),
    PRIMARY KEY (ingested_file_id, position)
);
