-- Step 31: what every imported scan was imported from, whatever the door (`brdfd import` and
-- `POST /scans/import`, the watch folder), so that the same file imported again is recognised
-- and answered with the scans it gave (src/store/ingest.rs, src/service/pipeline.rs).
--
-- One row per imported scan:
-- * `sha256` is 64 lower-case hex digits, of the bytes the daemon received: the file as
--   uploaded, or as dropped into the watch folder (for an MA-T12 export dropped with its SRA
--   CSV, of the two files' bytes each length-prefixed, as `ingested_files.sha256`). The scans
--   of one file share it; a file imported again on purpose (`--again`, `again=true`) gives
--   scans with the same hash, so it is indexed, not unique.
-- * `file_name` is the file's name as the door knew it (no directory), NULL when it was not
--   sent.
-- * `imported_at_ms` is when it was imported (the scan's own times are the measurement's).
--
-- Existing imported scans are filled in where their bytes' hash is known: the watch folder's
-- imports from `ingested_files`, and X-Rite `.xlsx` uploads from the file's SHA-256 that their
-- provenance records ("…; sha256 HEX; …"), their file name unknown (NULL: the upload did not
-- carry it). The bytes of other uploads (brdfd.scan/1 files through `brdfd import` or
-- `POST /scans/import`) were not kept, so those scans have no row: an import of the same file
-- is not recognised as a repeat of them.
--
-- The table stays on the station (src/sync/tables.rs, LOCAL_TABLES), as `ingested_files`: the
-- scans themselves, with their provenance, are what the central database receives.
CREATE TABLE scan_imports (
    scan_id        INTEGER PRIMARY KEY REFERENCES scans (id),
    sha256         TEXT    NOT NULL CHECK (length(sha256) = 64),
    file_name      TEXT,
    imported_at_ms BIGINT  NOT NULL
);

CREATE INDEX scan_imports_by_sha256 ON scan_imports (sha256);

INSERT INTO scan_imports (scan_id, sha256, file_name, imported_at_ms)
SELECT i.scan_id, f.sha256,
       f.file_name || coalesce(' and ' || f.partner_name, ''),
       f.imported_at_ms
FROM ingested_scans i
JOIN ingested_files f ON f.id = i.ingested_file_id;

INSERT INTO scan_imports (scan_id, sha256, file_name, imported_at_ms)
SELECT s.id,
       substr(s.source_detail, instr(s.source_detail, '; sha256 ') + 9, 64),
       NULL,
       coalesce((SELECT min(r.received_at_ms) FROM readings r WHERE r.scan_id = s.id),
                s.requested_at_ms)
FROM scans s
WHERE s.source = 'imported'
  AND s.source_detail LIKE 'uploaded X-Rite QC .xlsx export;%'
  AND instr(s.source_detail, '; sha256 ') > 0
  AND length(substr(s.source_detail, instr(s.source_detail, '; sha256 ') + 9, 64)) = 64
  AND substr(s.source_detail, instr(s.source_detail, '; sha256 ') + 9, 64) NOT GLOB '*[^0-9a-f]*'
  AND s.id NOT IN (SELECT scan_id FROM scan_imports);
