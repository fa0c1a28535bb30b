-- Central step 4: what station migration 0016 added — scans from an instrument's own software
-- (SCIENCE.md §3): the reference set's kind ('tile' or 'instrument-calibration'), the scan's
-- geometries ('all' or 'ma-t12': no SRA readings), and specular summaries that are NULL for a
-- fit without SRA readings. Rows forwarded before this step are tiles with all 14 geometries.
ALTER TABLE reference_sets ADD COLUMN kind TEXT NOT NULL DEFAULT 'tile';
ALTER TABLE scans ADD COLUMN geometries TEXT NOT NULL DEFAULT 'all';
ALTER TABLE evaluation_summaries ALTER COLUMN specular_mean DROP NOT NULL;
ALTER TABLE evaluation_summaries ALTER COLUMN specular_median DROP NOT NULL;
ALTER TABLE evaluation_summaries ALTER COLUMN specular_max DROP NOT NULL;
