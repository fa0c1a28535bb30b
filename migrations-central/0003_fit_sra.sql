-- Central step 3: what station migration 0015 added — the SRA reading model of each fit
-- (`fit_runs.sra`, 'flat' or 'luminance'; SCIENCE.md §5.1). Rows forwarded before this step get
-- the station default, the paper's flat model.
ALTER TABLE fit_runs ADD COLUMN sra TEXT NOT NULL DEFAULT 'flat';
