-- Step 10: provenance. Every reference set and scan says which instruments measured it and how
-- its readings came in, so a replayed or simulated scan can never pass for a real one.
--
-- Per instrument (`ma_t12_*`, `sra_*`): the model, serial and firmware the device reported when
-- it connected (its IDENTIFY reply), and `*_simulated`: 1 when the transport was a simulated
-- instrument (a replayed session file), 0 when it was a real USB or serial device, NULL when not
-- known. Rows written before this step get 'unknown' and NULL: nobody recorded it then.
--
-- `source` says how the readings entered the store: 'measured' (the daemon's own instruments),
-- 'imported' (a brdfd.scan/1 file or an instrument-software export), 'replay' (brdfd replay of
-- session files) or 'unknown' (older rows). `source_detail` holds the file name or the session
-- for imports and replays.
--
-- The identity is copied onto the row instead of pointing at `instruments`: a simulated device
-- replays a recording and reports the serial of the instrument that was recorded, so the serial
-- alone cannot say whether this scan was measured by it.
ALTER TABLE reference_sets ADD COLUMN ma_t12_model     TEXT NOT NULL DEFAULT 'unknown';
ALTER TABLE reference_sets ADD COLUMN ma_t12_serial    TEXT NOT NULL DEFAULT 'unknown';
ALTER TABLE reference_sets ADD COLUMN ma_t12_firmware  TEXT NOT NULL DEFAULT 'unknown';
ALTER TABLE reference_sets ADD COLUMN ma_t12_simulated INTEGER CHECK (ma_t12_simulated IN (0, 1));
ALTER TABLE reference_sets ADD COLUMN sra_model        TEXT NOT NULL DEFAULT 'unknown';
ALTER TABLE reference_sets ADD COLUMN sra_serial       TEXT NOT NULL DEFAULT 'unknown';
ALTER TABLE reference_sets ADD COLUMN sra_firmware     TEXT NOT NULL DEFAULT 'unknown';
ALTER TABLE reference_sets ADD COLUMN sra_simulated    INTEGER CHECK (sra_simulated IN (0, 1));
ALTER TABLE reference_sets ADD COLUMN source           TEXT NOT NULL DEFAULT 'unknown'
    CHECK (source IN ('measured', 'imported', 'replay', 'unknown'));
ALTER TABLE reference_sets ADD COLUMN source_detail    TEXT;

ALTER TABLE scans ADD COLUMN ma_t12_model     TEXT NOT NULL DEFAULT 'unknown';
ALTER TABLE scans ADD COLUMN ma_t12_serial    TEXT NOT NULL DEFAULT 'unknown';
ALTER TABLE scans ADD COLUMN ma_t12_firmware  TEXT NOT NULL DEFAULT 'unknown';
ALTER TABLE scans ADD COLUMN ma_t12_simulated INTEGER CHECK (ma_t12_simulated IN (0, 1));
ALTER TABLE scans ADD COLUMN sra_model        TEXT NOT NULL DEFAULT 'unknown';
ALTER TABLE scans ADD COLUMN sra_serial       TEXT NOT NULL DEFAULT 'unknown';
ALTER TABLE scans ADD COLUMN sra_firmware     TEXT NOT NULL DEFAULT 'unknown';
ALTER TABLE scans ADD COLUMN sra_simulated    INTEGER CHECK (sra_simulated IN (0, 1));
ALTER TABLE scans ADD COLUMN source           TEXT NOT NULL DEFAULT 'unknown'
    CHECK (source IN ('measured', 'imported', 'replay', 'unknown'));
ALTER TABLE scans ADD COLUMN source_detail    TEXT;
