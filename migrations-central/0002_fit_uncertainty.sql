-- Central step 2: what station migration 0011 added — a fit's bootstrap intervals
-- (`fit_runs.uncertainty_json`, SCIENCE.md §10) and the colorimetry each evaluation was computed
-- with (`evaluation_summaries.observer`, `weighting`: SCIENCE.md §7.1). Rows forwarded before
-- this step get the station defaults: no intervals, the paper's 2° observer and summation.
ALTER TABLE fit_runs ADD COLUMN uncertainty_json TEXT;
ALTER TABLE evaluation_summaries ADD COLUMN observer TEXT NOT NULL DEFAULT '2';
ALTER TABLE evaluation_summaries ADD COLUMN weighting TEXT NOT NULL DEFAULT 'summation';
