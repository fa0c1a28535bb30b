//! `brdfd validate` on goniometric files the test writes itself from known BRDFs: brdfd's own
//! model (the validation recovers it: prediction ΔE00 ≈ 0) and a form it cannot represent (a
//! second, narrow lobe and a retro-reflective term: prediction and oracle clearly above 0), in
//! both formats; the readers, the interpolation, the prediction figures and the JSON contract.

use brdfd::cost::CostFunction;
use brdfd::geometry::{GEOMETRIES, GeometrySet, Vec3};
use brdfd::gonio::astm::{AstmFile, Point};
use brdfd::gonio::rgl::{self, WriteOptions};
use brdfd::gonio::validate::{Options, Report, Variant, validate_with};
use brdfd::gonio::{Channels, Measurement};
use brdfd::model::{EXTRA, FresnelCosine, ModelKind, Params, evaluate_at};
use brdfd::reach::Verdict;
use brdfd::spectral::{BANDS, wavelengths_nm};
use brdfd::sra_reading::SraWeight;

mod common;

fn truth() -> Params {
    Params {
        kd: std::array::from_fn(|b| 0.02 + 0.1 * (-((b as f64 - 8.0) / 6.0).powi(2)).exp()),
        ks: 0.3,
        alpha: 0.15,
        ior: 1.5,
        extra: [0.0; EXTRA],
    }
}

fn own_model(wi: Vec3, wo: Vec3) -> Vec<f64> {
    evaluate_at(&truth(), ModelKind::Paper, FresnelCosine::Incidence, wi, wo).to_vec()
}

/// The model plus what it cannot represent: a second lobe of width 0.04 and a retro-reflective
/// term peaking where the view is the light.
fn out_of_reach(wi: Vec3, wo: Vec3) -> Vec<f64> {
    let second = Params {
        ks: 0.4,
        alpha: 0.04,
        kd: [0.0; BANDS],
        ..truth()
    };
    let lobe = evaluate_at(&second, ModelKind::Paper, FresnelCosine::Incidence, wi, wo)[0];
    let retro = 0.08
        * (wi[0] * wo[0] + wi[1] * wo[1] + wi[2] * wo[2])
            .max(0.0)
            .powi(16);
    own_model(wi, wo).iter().map(|v| v + lobe + retro).collect()
}

fn deg(d: f64) -> f64 {
    d.to_radians()
}

/// An ASTM file of `f` over θi 10–70°, θs 0–80°, φs 0–180°, plus the 14 instrument geometries.
fn astm(name: &str, f: &dyn Fn(Vec3, Vec3) -> Vec<f64>) -> AstmFile {
    let mut points = Vec::new();
    let mut push = |angles: [f64; 4]| {
        let p = Point {
            angles,
            values: vec![],
        };
        let (wi, wo) = p.directions();
        points.push(Point {
            values: f(wi, wo),
            ..p
        });
    };
    for ti in [10.0, 30.0, 50.0, 70.0] {
        for ts in (0..=8).map(|k| 10.0 * k as f64) {
            for ps in [0.0, 45.0, 90.0, 135.0, 180.0] {
                push([deg(ti), 0.0, deg(ts), deg(ps)]);
            }
        }
    }
    for g in &GEOMETRIES {
        push([
            deg(g.theta_i_deg),
            0.0,
            deg(g.theta_r_deg),
            deg(g.phi_r_deg),
        ]);
    }
    let w = wavelengths_nm().iter().map(|&n| f64::from(n)).collect();
    AstmFile::new(name.into(), "test".into(), Channels::Spectral(w), points)
}

fn cf2(model: ModelKind, fresnel: FresnelCosine) -> Variant {
    Variant {
        cost: CostFunction::Cf2,
        model,
        fresnel,
        geometries: GeometrySet::ALL,
        sra_weight: SraWeight::Paper,
    }
}

fn run(m: &Measurement) -> Report {
    let opts = Options {
        oracle_forms: &[(ModelKind::Paper, FresnelCosine::Incidence)],
        ..Options::default()
    };
    validate_with(m, &opts, &[cf2(ModelKind::Paper, FresnelCosine::Incidence)]).unwrap()
}

/// The oracle of a form is never worse than a prediction of that form, nor than Lambert.
fn assert_oracle_is_a_limit(r: &Report) {
    for o in &r.oracles {
        for f in r
            .fits
            .iter()
            .filter(|f| f.model == o.model && f.fresnel == o.fresnel)
        {
            assert!(
                o.prediction.mean <= f.prediction.mean,
                "oracle {:?} {:?} {} above the {} {} fit's {}",
                o.model,
                o.fresnel,
                o.prediction.mean,
                f.cost.name(),
                f.readings,
                f.prediction.mean
            );
        }
        assert!(o.prediction.mean <= r.lambert.prediction.mean);
    }
}

#[test]
fn astm_of_brdfd_model_is_recovered_and_a_second_lobe_is_not() {
    let file = astm("own model", &own_model);
    let m = Measurement::parse(file.write().as_bytes()).unwrap();
    assert_eq!(m.format(), "astm-e1392");
    let r = run(&m);
    eprintln!("own-model ASTM validation: {:.0} ms", r.wall_ms);
    // The readings are the file's values at the instrument geometries.
    let g = brdfd::geometry::by_name("45as45").unwrap();
    let want = own_model(g.light(), g.view());
    for (a, b) in r.readings["45as45"].raw.iter().zip(&want) {
        assert!((a - b).abs() < 1e-8, "{a} vs {b}");
    }
    // The fit with the paper's Fresnel, the form the file was made with (not the default of
    // measured scans, which is the exact Fresnel).
    let fit = &r.fits[0];
    assert!(!fit.default);
    assert!(
        fit.fit_delta_e00_mean < 0.05,
        "fit {}",
        fit.fit_delta_e00_mean
    );
    assert!(
        fit.prediction.mean < 0.05,
        "prediction {:?}",
        fit.prediction
    );
    // The oracle is the model's limit: on the model's own BRDF, about 0.
    assert!(
        r.oracle.prediction.mean < 0.05,
        "oracle {:?}",
        r.oracle.prediction
    );
    assert_oracle_is_a_limit(&r);
    assert!(
        r.lambert.prediction.mean > 1.0,
        "lambert {:?}",
        r.lambert.prediction
    );
    assert_eq!(r.directions, file.points.len());
    let loo = &r.interpolation.as_ref().unwrap().leave_one_out;
    assert!(loo.mean > 0.0 && loo.mean.is_finite());

    let hard = astm("two lobes", &out_of_reach);
    let h = run(&Measurement::parse(hard.write().as_bytes()).unwrap());
    assert_oracle_is_a_limit(&h);
    let p = &h.fits[0].prediction;
    assert!(p.mean > 1.0, "out of reach predicted {p:?}");
    assert!(
        h.oracle.prediction.mean > 0.5,
        "oracle {:?}",
        h.oracle.prediction
    );
    // Near the mirror direction is where the second lobe lives.
    assert!(p.near_specular_mean.unwrap() > p.rest_mean.unwrap());
}

/// Eight wavelengths, interpolated onto the grid: a small file, quick to write and read.
fn rgl_file(name: &str, f: &dyn Fn(Vec3, Vec3) -> Vec<f64>) -> Vec<u8> {
    let w: Vec<f64> = (0..8).map(|k| 400.0 + 300.0 * k as f64 / 7.0).collect();
    let at = w.clone();
    let g = move |wi: Vec3, wo: Vec3| {
        let v = f(wi, wo);
        at.iter()
            .map(|nm| v[((nm - 400.0) / 10.0).round() as usize])
            .collect()
    };
    let opts = WriteOptions {
        theta_i_count: 8,
        warp_resolution: 32,
        value_resolution: 32,
        ..WriteOptions::default()
    };
    rgl::write(name, &Channels::Spectral(w), &g, &opts)
}

#[test]
fn rgl_of_brdfd_model_is_recovered_and_a_second_lobe_is_not() {
    let m = Measurement::parse(&rgl_file("own model", &own_model)).unwrap();
    assert_eq!((m.format(), m.material()), ("rgl-bsdf", "own model"));
    let r = run(&m);
    eprintln!("own-model RGL validation: {:.0} ms", r.wall_ms);
    assert!(r.interpolation.is_none());
    assert_eq!(r.directions, 16 * 16 * 13);
    // Not 0: the format interpolates between its nodes, and the spectrum between 8 bands.
    assert!(
        r.fits[0].prediction.mean < 0.5,
        "{:?}",
        r.fits[0].prediction
    );
    let h = run(&Measurement::parse(&rgl_file("two lobes", &out_of_reach)).unwrap());
    assert!(
        h.fits[0].prediction.mean > 1.0,
        "{:?}",
        h.fits[0].prediction
    );
    assert!(h.oracle.prediction.mean > 0.5, "{:?}", h.oracle.prediction);
    assert_oracle_is_a_limit(&r);
    assert_oracle_is_a_limit(&h);
    // The JSON form of a report: the contract's keys (the command prints exactly this).
    let doc = serde_json::to_value(&r).unwrap();
    assert_eq!(doc["format"], "rgl-bsdf");
    assert_eq!(
        doc["readings"]["sra-20"]["raw"].as_array().unwrap().len(),
        8
    );
    assert!(doc["fits"][0]["prediction"]["p95"].is_number());
    assert!(doc["oracle"]["mean"].is_number() && doc["lambert"]["mean"].is_number());
    assert!(doc["oracle"]["start"].is_string());
    assert!(doc["fits"][0]["reach"]["verdict"].is_string());
    assert!(doc["reach"]["expected_delta_e00"].is_array());
}

/// On a file of a form the model cannot represent, the oracle of every form stays at or below
/// every prediction of its form: cf2 and m2, 14 readings and the MA-T12's 12, both Fresnel
/// factors, and Lambert.
#[test]
fn the_oracle_is_never_worse_than_a_prediction_of_its_form() {
    let m = Measurement::parse(astm("two lobes", &out_of_reach).write().as_bytes()).unwrap();
    const FORMS: [(ModelKind, FresnelCosine); 2] = [
        (ModelKind::Paper, FresnelCosine::Incidence),
        (ModelKind::Paper, FresnelCosine::Exact),
    ];
    let mut variants = Vec::new();
    for cost in [CostFunction::Cf2, CostFunction::M2] {
        for (model, fresnel) in FORMS {
            for geometries in [GeometrySet::ALL, GeometrySet::MA_T12] {
                variants.push(Variant {
                    cost,
                    model,
                    fresnel,
                    geometries,
                    sra_weight: SraWeight::Paper,
                });
            }
        }
    }
    let opts = Options {
        oracle_forms: &FORMS,
        ..Options::default()
    };
    let r = validate_with(&m, &opts, &variants).unwrap();
    assert_eq!(r.oracles.len(), 2);
    assert_oracle_is_a_limit(&r);
    // And it is a polish, not a pick: below its own start.
    for o in &r.oracles {
        eprintln!(
            "oracle {:?}: {:.3} from {} ({:.3}), {} evaluations",
            o.fresnel, o.prediction.mean, o.start, o.start_mean, o.evaluations
        );
        assert!(o.prediction.mean < o.start_mean, "{o:?}");
    }
}

/// A clear coat over the diffuse spectrum `kd`: a sharp lobe and a haze lobe `(ks, α)` of a
/// coat of index 1.5, what glossy paints are.
fn coat(kd: &[f64], sharp: (f64, f64), haze: (f64, f64), wi: Vec3, wo: Vec3) -> Vec<f64> {
    let lobe = |(ks, alpha): (f64, f64)| {
        let p = Params {
            kd: [0.0; BANDS],
            ks,
            alpha,
            ior: 1.5,
            extra: [0.0; EXTRA],
        };
        evaluate_at(&p, ModelKind::Paper, FresnelCosine::Exact, wi, wo)[0]
    };
    let spec = lobe(sharp) + lobe(haze);
    kd.iter().map(|k| k + spec).collect()
}

/// A clear coat over a coloured base.
fn glossy_coat(wi: Vec3, wo: Vec3) -> Vec<f64> {
    coat(&truth().kd, (3.0, 0.02), (0.3, 0.2), wi, wo)
}

/// A matt material: the model's diffuse term and a broad, weak lobe.
fn matt(wi: Vec3, wo: Vec3) -> Vec<f64> {
    let p = Params {
        ks: 0.05,
        alpha: 0.6,
        ..truth()
    };
    evaluate_at(&p, ModelKind::Paper, FresnelCosine::Exact, wi, wo).to_vec()
}

/// The reach verdict of a scan's fit: a matt material is in reach, a glossy two-lobe coat is
/// not, and the coat's prediction misses where the verdict says, near the mirror direction.
#[test]
fn reach_tells_a_matt_material_from_a_glossy_coat() {
    let exact = [cf2(ModelKind::Paper, FresnelCosine::Exact)];
    let opts = Options {
        oracle_forms: &[(ModelKind::Paper, FresnelCosine::Exact)],
        ..Options::default()
    };
    let verdict = |f: &dyn Fn(Vec3, Vec3) -> Vec<f64>, name: &str| {
        let m = Measurement::Astm(AstmFile::sampled(name, "test", f));
        validate_with(&m, &opts, &exact).unwrap()
    };
    let m = verdict(&matt, "matt");
    let reach = m.reach.as_ref().unwrap();
    assert_eq!(reach.verdict, Verdict::InReach, "{reach:?}");
    let matt_near = m.fits[0].prediction.near_specular_mean.unwrap();
    let g = verdict(&glossy_coat, "glossy coat");
    let reach = g.reach.as_ref().unwrap();
    assert_eq!(reach.verdict, Verdict::OutOfReach, "{reach:?}");
    assert!(reach.evidence.peak_geometry.starts_with("sra-"));
    // Where the verdict says the error is: near the mirror direction, beyond the matt one's.
    let near = g.fits[0].prediction.near_specular_mean.unwrap();
    assert!(
        near > matt_near && near > g.fits[0].prediction.rest_mean.unwrap(),
        "glossy near-specular {near}, matt {matt_near}, {:?}",
        g.fits[0].prediction
    );
}

/// A clear coat whose mirror peak is far sharper than its haze, over an orange base: the SRA
/// reads it hundreds of times above the diffuse level.
fn sharp_coat(wi: Vec3, wo: Vec3) -> Vec<f64> {
    let orange: [f64; BANDS] = std::array::from_fn(|b| match b {
        0..=9 => 0.05,
        10..=19 => 0.1,
        _ => 0.3,
    });
    coat(&orange, (1.0, 0.004), (0.8, 0.35), wi, wo)
}

/// Under cf1 with the paper's Fresnel, a lobe that cannot follow SRA readings hundreds above
/// the diffuse level drags the diffuse colour after them when every geometry weighs by cos θi
/// alone; weighed at the MA-T12 readings' level (`balanced`), the same fit keeps it.
#[test]
fn balanced_sra_weights_keep_cf1_from_losing_the_diffuse_colour() {
    let m = Measurement::Astm(AstmFile::sampled("sharp coat", "test", &sharp_coat));
    let exact_cf1 = |fresnel, sra_weight| Variant {
        cost: CostFunction::Cf1,
        model: ModelKind::Paper,
        fresnel,
        geometries: GeometrySet::ALL,
        sra_weight,
    };
    let opts = Options {
        oracle_forms: &[(ModelKind::Paper, FresnelCosine::Exact)],
        ..Options::default()
    };
    let r = validate_with(
        &m,
        &opts,
        &[
            exact_cf1(FresnelCosine::Incidence, SraWeight::Paper),
            exact_cf1(FresnelCosine::Incidence, SraWeight::Balanced),
        ],
    )
    .unwrap();
    let sra = r.readings["sra-60"].reading[0];
    let diffuse = r.readings["45as45"].reading.iter().sum::<f64>() / BANDS as f64;
    assert!(sra > 100.0 * diffuse, "SRA {sra}, diffuse {diffuse}");
    let (paper, balanced) = (&r.fits[0], &r.fits[1]);
    assert_eq!(
        (paper.sra_weight, balanced.sra_weight),
        (SraWeight::Paper, SraWeight::Balanced)
    );
    assert!(
        paper.fit_delta_e00_mean > 10.0,
        "the paper's weights lose the diffuse colour: fit ΔE00 {}",
        paper.fit_delta_e00_mean
    );
    assert!(
        balanced.fit_delta_e00_mean < 2.0 && balanced.prediction.mean < 3.0,
        "balanced: fit ΔE00 {}, prediction {}",
        balanced.fit_delta_e00_mean,
        balanced.prediction.mean
    );
}

/// The command refuses a malformed file with the line and field named, before any fit.
#[test]
fn validate_names_the_bad_field() {
    let dir = tempfile::tempdir().unwrap();
    let mut text = astm("own model", &own_model).write();
    text = text.replacen("NUM_POINTS 194", "NUM_POINTS 195", 1);
    let path = dir.path().join("short.astm");
    std::fs::write(&path, text).unwrap();
    let out = common::run_brdfd(&["validate", "--json", path.to_str().unwrap()], None);
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("NUM_POINTS") && err.contains("short.astm"),
        "{err}"
    );
}

/// `brdfd validate --json --figures DIR` on a generated ASTM file: the JSON line carries the
/// contract's keys, and both figures are drawn as SVG, one dot per predicted direction on the
/// hemisphere, both naming the fit they draw.
#[test]
fn validate_prints_the_json_contract_and_draws_its_figures() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("own.astm");
    std::fs::write(&path, astm("own model", &own_model).write()).unwrap();
    let figures = dir.path().join("figures");
    let out = common::run_brdfd(
        &[
            "validate",
            "--cost",
            "cf2",
            "--json",
            "--intervals",
            "--figures",
            figures.to_str().unwrap(),
            path.to_str().unwrap(),
        ],
        None,
    );
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let doc: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(doc["material"], "own model");
    assert_eq!(doc["format"], "astm-e1392");
    assert!(
        doc["rgb_upsampling"].is_null(),
        "a spectral file needs none"
    );
    assert_eq!(doc["readings"].as_object().unwrap().len(), 14);
    assert!(doc["readings"]["45as45"]["raw"].as_array().unwrap().len() > 1);
    let fits = doc["fits"].as_array().unwrap();
    assert!(!fits.is_empty());
    for f in fits {
        assert_eq!(f["cost"], "cf2");
        for key in ["model", "fresnel", "default", "fit_delta_e00_mean"] {
            assert!(!f[key].is_null(), "fit lacks {key}: {f}");
        }
        for key in ["mean", "median", "p95", "near_specular_mean"] {
            assert!(
                f["prediction"][key].is_number(),
                "prediction lacks {key}: {f}"
            );
        }
    }
    assert_eq!(fits.iter().filter(|f| f["default"] == true).count(), 1);
    // The default fit's prediction interval, held against every direction; only its.
    for f in fits {
        let c = &f["interval_coverage"];
        if f["default"] != true {
            assert!(c.is_null(), "{f}");
            continue;
        }
        for key in ["l", "a", "b", "all", "near_specular_l"] {
            let x = c[key].as_f64().unwrap_or_else(|| panic!("no {key} in {c}"));
            assert!((0.0..=1.0).contains(&x), "{key} {x}");
        }
        assert!(c["all"].as_f64() <= c["l"].as_f64(), "{c}");
        let widths = c["half_width"].as_array().unwrap();
        assert_eq!(widths.len(), 3);
        assert!(widths.iter().all(|w| w.as_f64().unwrap() > 0.0), "{c}");
        assert!(c["held_out_mean"].as_f64().unwrap() > 0.0, "{c}");
    }
    assert!(doc["oracle"]["mean"].is_number() && doc["lambert"]["mean"].is_number());
    assert!(doc["interpolation"]["leave_one_out"]["mean"].is_number());
    assert!(doc["reach"]["verdict"].is_string());
    assert!(
        doc.get("directions_of_default").is_none(),
        "the figures' data stays out"
    );
    let directions = doc["directions"].as_u64().unwrap() as usize;
    let hemisphere = std::fs::read_to_string(figures.join("own-model-hemisphere.svg")).unwrap();
    let svg = roxmltree::Document::parse(&hemisphere).unwrap();
    let dots = svg
        .descendants()
        .filter(|n| n.has_tag_name("circle"))
        .count();
    // The file's grid (θi 10–70°, 45 directions each) and the instrument geometries' own
    // incidences: six panels, spread over them from the first to the last; each direction of
    // a panel a dot.
    let panels: Vec<&str> = hemisphere
        .match_indices("θi = ")
        .map(|(i, _)| hemisphere[i..].split(':').next().unwrap())
        .collect();
    assert_eq!(panels.len(), 6, "{panels:?}");
    assert!(
        panels.contains(&"θi = 10°") && panels.contains(&"θi = 70°"),
        "{panels:?}"
    );
    assert!(
        dots >= 3 * 45 && dots < directions,
        "{dots} of {directions}"
    );
    let in_plane = std::fs::read_to_string(figures.join("own-model-in-plane.svg")).unwrap();
    let svg = roxmltree::Document::parse(&in_plane).unwrap();
    assert!(
        svg.descendants().any(|n| n.has_tag_name("polyline")),
        "{in_plane}"
    );
    // One curve per incidence, up to four, the last measured among them.
    let curves = in_plane.matches("θi = ").count();
    assert!(
        (2..=4).contains(&curves) && in_plane.contains("θi = 70°"),
        "{in_plane}"
    );

    assert!(in_plane.contains("predicted by the cf2 fit"), "{in_plane}");
}
