-- Step 11: fit uncertainty and colorimetry (SCIENCE.md §7.1, §10).
--
-- `fit_runs.uncertainty_json`: the bootstrap intervals of a done fit, the `uncertainty` object of
-- the fit JSON ({"method", "resamples", "noise", "seed", "ks": [lo, hi], "alpha", "ior", "kd":
-- 31 × [lo, hi], "delta_e00_mean", "delta_e00_diffuse_mean", "delta_e00_specular_mean"}). The
-- daemon stores the fit first and the intervals when the bootstrap ends, so NULL means "not
-- (yet) computed" or `[fit] bootstrap = 0`.
--
-- `evaluation_summaries.observer`, `.weighting`: the colorimetry the ΔE00 values were computed
-- with ('2' or '10'; 'summation' or 'astm-e308'). Rows written before this step were computed
-- with the paper's, the defaults.
ALTER TABLE fit_runs ADD COLUMN uncertainty_json TEXT;
ALTER TABLE evaluation_summaries ADD COLUMN observer TEXT NOT NULL DEFAULT '2'
    CHECK (observer IN ('2', '10'));
ALTER TABLE evaluation_summaries ADD COLUMN weighting TEXT NOT NULL DEFAULT 'summation'
    CHECK (weighting IN ('summation', 'astm-e308'));
