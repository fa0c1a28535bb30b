-- Step 20: the colorimetry of each fit, recorded when it is queued (SCIENCE.md §7.1).
--
-- A fit runs on what was recorded with it, never on the configuration of the day it runs (a
-- fit queued again after a restart, or waiting while `[colour]` was changed): the processed
-- scan it fits (`processed_id`), every optimiser setting (`settings_json`), and now the
-- colorimetry its ΔE00 are computed with under D65: `fit_observer` ('2' or '10') and
-- `fit_weighting` ('summation' or 'astm-e308'), as `evaluation_summaries.observer` and
-- `.weighting` record it for a done fit. NULL for rows queued before this step: such a fit,
-- if it still runs, uses the configured colorimetry, as it did then.
ALTER TABLE fit_runs ADD COLUMN fit_observer TEXT CHECK (fit_observer IN ('2', '10'));
ALTER TABLE fit_runs ADD COLUMN fit_weighting TEXT
    CHECK (fit_weighting IN ('summation', 'astm-e308'));
