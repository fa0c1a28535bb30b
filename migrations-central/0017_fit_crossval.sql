-- Central step 17: what station migration 0030 added — each done fit's leave-one-geometry-out
-- cross-validation (`fit_runs.crossval_json`) and its mean held-out ΔE00 (`held_out_mean`):
-- how far to trust the fit's estimate at angles it was not fitted to (SCIENCE.md §12.5). NULL
-- for fits forwarded before the station computed it.
ALTER TABLE fit_runs ADD COLUMN crossval_json TEXT;
ALTER TABLE fit_runs ADD COLUMN held_out_mean DOUBLE PRECISION;

-- One row per done fit with a cross-validation: its ΔE00 at the MA-T12 geometries it was
-- fitted to beside the mean ΔE00 of each of them predicted with it held out.
CREATE VIEW fit_held_out AS
SELECT f.station, f.scan_id, f.id AS fit_run_id, sa.name AS sample, f.cost_function,
    e.diffuse_mean AS de00_diffuse_mean, f.held_out_mean AS de00_held_out_mean,
    ms_time(f.finished_at_ms) AS fitted_at
FROM fit_runs f
JOIN scans s ON s.station = f.station AND s.id = f.scan_id
JOIN samples sa ON sa.station = s.station AND sa.id = s.sample_id
LEFT JOIN evaluation_summaries e ON e.station = f.station AND e.fit_run_id = f.id
WHERE f.status = 'done' AND f.held_out_mean IS NOT NULL;
