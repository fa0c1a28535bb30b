-- Central step 18: which science configuration each fit was made with (SCIENCE.md §4.1), read
-- from the settings every station forwards with its fits (`fit_runs.settings_json`): the model
-- form, the lobe's Fresnel factor and the SRA reading model, and the preset they amount to
-- ('measured': exact Fresnel and luminance SRA, the default of measured scans; 'paper': the
-- paper's Schlick on cos θi and flat SRA; 'custom' otherwise). Settings stored before a choice
-- existed read as the paper's. No table changes.
CREATE VIEW fit_configuration AS
SELECT f.station, f.scan_id, f.id AS fit_run_id, f.cost_function, f.method, f.status,
    c.model, c.fresnel, f.sra,
    CASE
        WHEN c.model = 'paper' AND c.fresnel = 'exact' AND f.sra = 'luminance' THEN 'measured'
        WHEN c.model = 'paper' AND c.fresnel = 'incidence' AND f.sra = 'flat' THEN 'paper'
        ELSE 'custom'
    END AS preset
FROM fit_runs f
CROSS JOIN LATERAL (
    SELECT COALESCE(f.settings_json::jsonb ->> 'model', 'paper') AS model,
        COALESCE(f.settings_json::jsonb ->> 'fresnel', 'incidence') AS fresnel
) c;
