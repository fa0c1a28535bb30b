//! The figures the reach verdict is calibrated on (`brdfd::reach::CALIBRATION`, SCIENCE.md
//! §12.7): for each measured goniometric file named on the command line and for generated
//! glossy materials of a form the model cannot represent (a coloured base under a clear coat:
//! a sharp lobe and a haze lobe), the evidence a scan of the material would give (specular
//! excess, the fit's ΔE00 at the MA-T12 geometries, the held-out ΔE00 of `brdfd crossval`) beside
//! what the handheld estimate really does over the hemisphere (`brdfd validate`: prediction
//! ΔE00 mean under cf2 with either Fresnel factor, and the oracle), and the verdict brdfd gives.
//!
//! Run: `cargo run --release --example reach_calibration -- [FILE…]` (ASTM E1392 or RGL
//! `.bsdf` files; the generated materials are always added).

use brdfd::cost::CostFunction;
use brdfd::crossval::crossval_measured;
use brdfd::fit::FitRequest;
use brdfd::geometry::{GeometrySet, Vec3};
use brdfd::gonio::Measurement;
use brdfd::gonio::astm::AstmFile;
use brdfd::gonio::validate::{Options, Variant, readings, validate_with};
use brdfd::model::{EXTRA, FresnelCosine, ModelKind, Params, evaluate_at};
use brdfd::optimise::Settings;
use brdfd::spectral::BANDS;

/// A coloured base under a clear coat: the base's diffuse spectrum plus two GGX lobes of the
/// coat with exact Fresnel (μ = 1.5), a sharp one `(ks, α)` and a haze one.
fn coat(base: [f64; 3], sharp: (f64, f64), haze: (f64, f64)) -> impl Fn(Vec3, Vec3) -> Vec<f64> {
    let kd: [f64; BANDS] = std::array::from_fn(|b| match b {
        0..=9 => base[2],
        10..=19 => base[1],
        _ => base[0],
    });
    let lobe = move |(ks, alpha): (f64, f64)| Params {
        kd: [0.0; BANDS],
        ks,
        alpha,
        ior: 1.5,
        extra: [0.0; EXTRA],
    };
    move |wi, wo| {
        let s = |p: Params| evaluate_at(&p, ModelKind::Paper, FresnelCosine::Exact, wi, wo)[0];
        let spec = s(lobe(sharp)) + s(lobe(haze));
        kd.iter().map(|k| k + spec).collect()
    }
}

/// A metallic lacquer: a dark base, a coloured flake lobe `(ks, α)` tinted by `tint` (the
/// model's lobe is grey) and a sharp clear-coat lobe.
fn metallic(
    tint: [f64; 3],
    flakes: (f64, f64),
    coat: (f64, f64),
) -> impl Fn(Vec3, Vec3) -> Vec<f64> {
    let t: [f64; BANDS] = std::array::from_fn(|b| match b {
        0..=9 => tint[2],
        10..=19 => tint[1],
        _ => tint[0],
    });
    let lobe = move |(ks, alpha): (f64, f64)| Params {
        kd: [0.0; BANDS],
        ks,
        alpha,
        ior: 1.5,
        extra: [0.0; EXTRA],
    };
    move |wi, wo| {
        let s = |p: Params| evaluate_at(&p, ModelKind::Paper, FresnelCosine::Exact, wi, wo)[0];
        let (f, c) = (s(lobe(flakes)), s(lobe(coat)));
        t.iter().map(|k| 0.01 * k + f * k + c).collect()
    }
}

/// A generated material: name, colour (r, g, b) and two lobes `(ks, α)`.
type Generated = (&'static str, [f64; 3], (f64, f64), (f64, f64));

fn main() {
    let mut materials: Vec<(String, Measurement)> = Vec::new();
    for path in std::env::args().skip(1) {
        let bytes = std::fs::read(&path).unwrap_or_else(|e| panic!("{path}: {e}"));
        let m = Measurement::parse(&bytes).unwrap_or_else(|e| panic!("{path}: {e}"));
        let name = std::path::Path::new(&path)
            .file_name()
            .map_or(path.clone(), |n| n.to_string_lossy().into_owned());
        materials.push((name, m));
    }
    let generated: [Generated; 4] = [
        (
            "generated satin",
            [0.12, 0.05, 0.03],
            (0.6, 0.08),
            (0.4, 0.3),
        ),
        (
            "generated gloss coat",
            [0.03, 0.06, 0.12],
            (2.0, 0.03),
            (0.3, 0.2),
        ),
        (
            "generated high-gloss coat",
            [0.10, 0.10, 0.10],
            (4.0, 0.01),
            (0.2, 0.15),
        ),
        (
            "generated black gloss",
            [0.01, 0.01, 0.01],
            (3.0, 0.02),
            (0.2, 0.2),
        ),
    ];
    for (name, base, sharp, haze) in generated {
        let f = coat(base, sharp, haze);
        materials.push((
            name.to_string(),
            Measurement::Astm(AstmFile::sampled(name, "generated", &f)),
        ));
    }
    let metallics: [Generated; 2] = [
        (
            "generated blue metallic",
            [0.1, 0.3, 0.9],
            (0.8, 0.25),
            (2.0, 0.02),
        ),
        (
            "generated red metallic",
            [0.9, 0.15, 0.1],
            (1.5, 0.15),
            (3.0, 0.01),
        ),
    ];
    for (name, tint, flakes, coat) in metallics {
        let f = metallic(tint, flakes, coat);
        materials.push((
            name.to_string(),
            Measurement::Astm(AstmFile::sampled(name, "generated", &f)),
        ));
    }
    let variants: Vec<Variant> = [FresnelCosine::Incidence, FresnelCosine::Exact]
        .into_iter()
        .map(|fresnel| Variant {
            cost: CostFunction::Cf2,
            model: ModelKind::Paper,
            fresnel,
            geometries: GeometrySet::ALL,
            sra_weight: brdfd::sra_reading::SraWeight::Paper,
        })
        .collect();
    let opts = Options {
        oracle_forms: &[(ModelKind::Paper, FresnelCosine::Exact)],
        ..Options::default()
    };
    println!(
        "| material | peak | specular excess | fit ΔE00 (exact) | held-out ΔE00 (exact) | prediction incidence | prediction exact (near-specular) | oracle exact | verdict (exact) | expected (near-specular) |"
    );
    println!("|---|---|---|---|---|---|---|---|---|---|");
    for (name, m) in &materials {
        let r = validate_with(m, &opts, &variants).expect("validation");
        let exact = r
            .fits
            .iter()
            .find(|f| f.fresnel == FresnelCosine::Exact)
            .expect("an exact fit");
        let incidence = r
            .fits
            .iter()
            .find(|f| f.fresnel == FresnelCosine::Incidence)
            .expect("an incidence fit");
        let (measured, _) = readings(m, opts.sra);
        let request = FitRequest {
            settings: Settings {
                cost: CostFunction::Cf2,
                fresnel: FresnelCosine::Exact,
                sra: opts.sra,
                ..Settings::default()
            },
            colorimetry: opts.colorimetry,
            ..FitRequest::default()
        };
        let cv = crossval_measured(name, "goniometric measurement", &measured, &request)
            .expect("cross-validation");
        let reach = exact.reach.as_ref().expect("a 45as45 reading");
        let e = &reach.evidence;
        // The verdict with the held-out ΔE00 as a scan's cross-validation would give it.
        let with_held = brdfd::reach::assess(&brdfd::reach::Evidence {
            held_out_delta_e00: Some(cv.held_out_mean),
            ..e.clone()
        });
        let [a, b] = with_held.expected_delta_e00;
        let [na, nb] = with_held.expected_near_specular_delta_e00;
        let expected = format!("{a:.1}–{b:.1} ({na:.1}–{nb:.1})");
        println!(
            "| {name} | {} | {:.2} | {:.2} | {:.2} | {:.2} | {:.2} ({:.2}) | {:.2} | {} | {expected} |",
            e.peak_geometry,
            e.specular_excess,
            e.fit_delta_e00,
            cv.held_out_mean,
            incidence.prediction.mean,
            exact.prediction.mean,
            exact.prediction.near_specular_mean.unwrap_or(f64::NAN),
            r.oracle.prediction.mean,
            with_held.verdict,
        );
    }
}
