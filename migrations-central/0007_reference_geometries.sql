-- Central step 7: what station migration 0018 added — which geometries a reference set
-- measures: 'all' 14, or 'ma-t12', a tile measured by a station whose SRA is turned off (or
-- imported with MA-T12-only scans). Rows forwarded before this step are 'all', except tiles
-- without SRA readings, as on the station.
ALTER TABLE reference_sets ADD COLUMN geometries TEXT NOT NULL DEFAULT 'all';
UPDATE reference_sets r SET geometries = 'ma-t12'
    WHERE r.kind = 'tile'
      AND EXISTS (SELECT 1 FROM reference_readings rr
                  WHERE rr.station = r.station AND rr.reference_id = r.id)
      AND NOT EXISTS (SELECT 1 FROM reference_readings rr
                      WHERE rr.station = r.station AND rr.reference_id = r.id
                        AND rr.device = 'sra');
