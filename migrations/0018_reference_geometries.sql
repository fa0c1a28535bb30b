-- Step 18: which geometries a reference set measures, as `scans.geometries` says it for a scan
-- (step 16): 'all' 14, or 'ma-t12', the 12 MA-T12 geometries of a tile measured by a daemon
-- whose SRA is turned off (`[devices.sra] transport = "off"`). A reference set is complete when
-- it holds a reading at each of them; a scan with SRA readings needs a reference that has them.
--
-- Rows written before this step: a tile without SRA readings (imported with MA-T12-only scans)
-- is 'ma-t12'; every other set, including the instrument-calibration sets, which hold no
-- readings, stays 'all'.
ALTER TABLE reference_sets ADD COLUMN geometries TEXT NOT NULL DEFAULT 'all'
    CHECK (geometries IN ('all', 'ma-t12'));
UPDATE reference_sets SET geometries = 'ma-t12'
    WHERE kind = 'tile'
      AND EXISTS (SELECT 1 FROM reference_readings rr WHERE rr.reference_id = reference_sets.id)
      AND NOT EXISTS (SELECT 1 FROM reference_readings rr
                      WHERE rr.reference_id = reference_sets.id AND rr.device = 'sra');
