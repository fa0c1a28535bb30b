-- Central step 9: what station migration 0020 added — the colorimetry each fit was queued with
-- (`fit_runs.fit_observer` '2' or '10', `fit_weighting` 'summation' or 'astm-e308'; SCIENCE.md
-- §7.1). NULL for rows queued on the station before that step.
ALTER TABLE fit_runs ADD COLUMN fit_observer TEXT;
ALTER TABLE fit_runs ADD COLUMN fit_weighting TEXT;
