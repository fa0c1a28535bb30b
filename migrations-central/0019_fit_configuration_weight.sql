-- Central step 19: the SRA readings' weight in each fit's cost (SCIENCE.md §5.2) in
-- `fit_configuration`, and the presets read with it: 'measured' is the exact Fresnel and the
-- luminance SRA model with the SRA readings balanced under cf1 and m2 and weighed as the paper
-- under cf2; 'paper' is the paper's Schlick on cos θi, flat SRA and the paper's weights.
-- Settings stored before the weight existed read as the paper's weights. No table changes; the
-- view keeps its columns and adds `sra_weight` after them.
CREATE OR REPLACE VIEW fit_configuration AS
SELECT f.station, f.scan_id, f.id AS fit_run_id, f.cost_function, f.method, f.status,
    c.model, c.fresnel, f.sra,
    CASE
        WHEN c.model = 'paper' AND c.fresnel = 'exact' AND f.sra = 'luminance'
            AND c.sra_weight = CASE WHEN f.cost_function = 'cf2' THEN 'paper' ELSE 'balanced' END
            THEN 'measured'
        WHEN c.model = 'paper' AND c.fresnel = 'incidence' AND f.sra = 'flat'
            AND c.sra_weight = 'paper' THEN 'paper'
        ELSE 'custom'
    END AS preset,
    c.sra_weight
FROM fit_runs f
CROSS JOIN LATERAL (
    SELECT COALESCE(f.settings_json::jsonb ->> 'model', 'paper') AS model,
        COALESCE(f.settings_json::jsonb ->> 'fresnel', 'incidence') AS fresnel,
        COALESCE(f.settings_json::jsonb -> 'sra' ->> 'weight', 'paper') AS sra_weight
) c;
