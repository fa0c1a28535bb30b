-- Step 15: the SRA reading model of each fit (SCIENCE.md §5.1).
--
-- `fit_runs.sra`: how the fit's cost read the two SRA readings — 'flat' (the paper's: the one
-- achromatic value spread over the 31 bands, compared band by band) or 'luminance' (the reading
-- is the luminous reflectance Y under the instrument's illuminant and observer, compared with the
-- model's Y). The whole setting, with the illuminant and observer, is in `settings_json` (key
-- `sra`, absent for the default); this column makes the model visible to SQL and to the central
-- database. Rows written before this step were fitted with the paper's model, the default.
ALTER TABLE fit_runs ADD COLUMN sra TEXT NOT NULL DEFAULT 'flat'
    CHECK (sra IN ('flat', 'luminance'));
