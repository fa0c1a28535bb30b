-- Step 30: each done fit's leave-one-geometry-out cross-validation (SCIENCE.md §12.5).
--
-- `fit_runs.crossval_json`: the `CrossValidation` of the fit's own configuration ({"cost",
-- "model", "fresnel", "fitted_mean", "held_out_mean", "held_out": [{"geometry", "delta_e00",
-- "measured_lab": [L, a, b], "predicted_lab": [L, a, b]}, …]}): each MA-T12 geometry the scan
-- measured held out in turn, the rest fitted, the held-out reading predicted.
-- `fit_runs.held_out_mean`: its mean held-out ΔE00, a column of its own so that queries and
-- central's views can show it beside the fit's ΔE00 without reading the JSON. The daemon stores
-- the fit first and these when the cross-validation ends, so NULL means "not (yet) computed" or
-- `[fit] crossval = false`.
ALTER TABLE fit_runs ADD COLUMN crossval_json TEXT;
ALTER TABLE fit_runs ADD COLUMN held_out_mean REAL;
