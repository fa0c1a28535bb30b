//! The RGL tensor-file reader (`brdfd::gonio::rgl`) against Mitsuba 3's `measured` plugin: a
//! `.bsdf` written by brdfd's own writer, RGB and spectral, evaluated by both at 1,200 random
//! direction pairs, agreeing to 1e-4 relative. Mitsuba runs from the virtual environment
//! `.ci/run` makes (`target/tools/mitsuba-venv`, or the Python named by
//! `BRDFD_MITSUBA_PYTHON`); the test fails, not skips, when it is missing.
//!
//! `BRDFD_GONIO_BSDF` may name further RGB `.bsdf` files (colon-separated) to hold to Mitsuba
//! the same way, e.g. measured ones that cannot be part of the repository.

use std::io::Write as _;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};

use brdfd::geometry::Vec3;
use brdfd::gonio::rgl::{RglBsdf, WriteOptions, write};
use brdfd::gonio::{Channels, direction};
use rand::{Rng, SeedableRng};
use serde_json::{Value, json};

fn python() -> PathBuf {
    let p = std::env::var_os("BRDFD_MITSUBA_PYTHON").map_or_else(
        || PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("target/tools/mitsuba-venv/bin/python"),
        PathBuf::from,
    );
    assert!(
        p.exists(),
        "Mitsuba 3 is needed for this test: run `bash .ci/run` (it makes target/tools/mitsuba-venv \
         with `pip install mitsuba`), or set BRDFD_MITSUBA_PYTHON to a Python that imports mitsuba; \
         looked for {}",
        p.display()
    );
    p
}

/// Evaluates `file` in Mitsuba at `pairs` (wi, wo); RGB, or at `wavelengths` (4 at a time).
/// Mitsuba's `eval` is f·cos θo; the script divides the cosine out.
const SCRIPT: &str = r#"
import json, sys
import mitsuba as mi
req = json.load(sys.stdin)
mi.set_variant(req["variant"])
bsdf = mi.load_dict({"type": "measured", "filename": req["file"]})
ctx = mi.BSDFContext()
out = []
for p in req["pairs"]:
    si = mi.SurfaceInteraction3f()
    si.wi = mi.Vector3f(p[0], p[1], p[2])
    wo = mi.Vector3f(p[3], p[4], p[5])
    vals = []
    if req["variant"] == "scalar_rgb":
        v = bsdf.eval(ctx, si, wo)
        vals = [v[0], v[1], v[2]]
    else:
        w = req["wavelengths"]
        for k in range(0, len(w), 4):
            si.wavelengths = type(si.wavelengths)(*w[k:k + 4])
            v = bsdf.eval(ctx, si, wo)
            vals += [v[0], v[1], v[2], v[3]]
    out.append([x / p[5] for x in vals])
print(json.dumps(out))
"#;

fn mitsuba_eval(
    file: &Path,
    variant: &str,
    wavelengths: &[f64],
    pairs: &[(Vec3, Vec3)],
) -> Vec<Vec<f64>> {
    let req = json!({
        "variant": variant,
        "file": file,
        "wavelengths": wavelengths,
        "pairs": pairs.iter().map(|(a, b)| [a[0], a[1], a[2], b[0], b[1], b[2]]).collect::<Vec<_>>(),
    });
    let mut child = Command::new(python())
        .args(["-c", SCRIPT])
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("start the Mitsuba Python");
    child
        .stdin
        .take()
        .unwrap()
        .write_all(req.to_string().as_bytes())
        .unwrap();
    let out = child.wait_with_output().unwrap();
    assert!(
        out.status.success(),
        "Mitsuba failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v: Value = serde_json::from_slice(&out.stdout).unwrap();
    v.as_array()
        .unwrap()
        .iter()
        .map(|r| {
            r.as_array()
                .unwrap()
                .iter()
                .map(|x| x.as_f64().unwrap())
                .collect()
        })
        .collect()
}

/// Random pairs above the horizon, θ up to 80°: incidences off the file's grid too.
fn pairs(n: usize, seed: u64) -> Vec<(Vec3, Vec3)> {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    (0..n)
        .map(|_| {
            let mut d = || {
                let t: f64 = rng.random_range(0.0..80f64.to_radians());
                let p: f64 = rng.random_range(-std::f64::consts::PI..std::f64::consts::PI);
                direction(t, p)
            };
            (d(), d())
        })
        .collect()
}

/// Worst relative difference, values below `floor` compared absolutely against it.
fn check(ours: &RglBsdf, theirs: &[Vec<f64>], pairs: &[(Vec3, Vec3)], channels: &[usize]) -> f64 {
    let mut worst: f64 = 0.0;
    let mut bad = 0;
    for ((wi, wo), m) in pairs.iter().zip(theirs) {
        let b = ours.eval(*wi, *wo);
        for (k, &c) in channels.iter().enumerate() {
            let scale = m[k].abs().max(1e-3);
            let d = (b[c] - m[k]).abs() / scale;
            if d > 1e-4 {
                bad += 1;
                if bad <= 5 {
                    eprintln!(
                        "wi {wi:?} wo {wo:?} channel {c}: brdfd {} mitsuba {}",
                        b[c], m[k]
                    );
                }
            }
            worst = worst.max(d);
        }
    }
    if bad > 0 {
        eprintln!("{bad} values differ by more than 1e-4 relative");
    }
    worst
}

/// A BRDF with structure in every direction: a coloured diffuse term, a GGX-like lobe about
/// the mirror direction and a retro-reflective bump.
fn brdf(n: usize) -> impl Fn(Vec3, Vec3) -> Vec<f64> {
    move |wi: Vec3, wo: Vec3| {
        let h = {
            let s = [wi[0] + wo[0], wi[1] + wo[1], wi[2] + wo[2]];
            let l = (s[0] * s[0] + s[1] * s[1] + s[2] * s[2]).sqrt();
            s[2] / l
        };
        let lobe = 0.4 * (-(1.0 - h * h) / (h * h) / 0.08).exp() / (h.powi(4) + 0.01);
        let retro = 0.05
            * (wi[0] * wo[0] + wi[1] * wo[1] + wi[2] * wo[2])
                .max(0.0)
                .powi(8);
        (0..n)
            .map(|c| 0.05 + 0.2 * c as f64 / n as f64 + lobe + retro)
            .collect()
    }
}

#[test]
fn rgl_reader_matches_mitsuba_measured_plugin() {
    let dir = tempfile::tempdir().unwrap();
    let opts = WriteOptions::default();
    let pairs = pairs(1200, 7);

    let rgb = dir.path().join("rgb.bsdf");
    std::fs::write(&rgb, write("rgb test", &Channels::Rgb, &brdf(3), &opts)).unwrap();
    let ours = RglBsdf::parse(&std::fs::read(&rgb).unwrap()).unwrap();
    let theirs = mitsuba_eval(&rgb, "scalar_rgb", &[], &pairs);
    let worst = check(&ours, &theirs, &pairs, &[0, 1, 2]);
    assert!(worst < 1e-4, "RGB: worst relative difference {worst:e}");

    let wavelengths: Vec<f64> = (0..8).map(|k| 400.0 + 40.0 * k as f64).collect();
    let spectral = dir.path().join("spectral.bsdf");
    let channels = Channels::Spectral(wavelengths.clone());
    std::fs::write(
        &spectral,
        write("spectral test", &channels, &brdf(8), &opts),
    )
    .unwrap();
    let ours = RglBsdf::parse(&std::fs::read(&spectral).unwrap()).unwrap();
    let theirs = mitsuba_eval(&spectral, "scalar_spectral", &wavelengths, &pairs);
    let worst = check(&ours, &theirs, &pairs, &(0..8).collect::<Vec<_>>());
    assert!(
        worst < 1e-4,
        "spectral: worst relative difference {worst:e}"
    );

    for extra in std::env::var("BRDFD_GONIO_BSDF")
        .unwrap_or_default()
        .split(':')
        .filter(|s| !s.is_empty())
    {
        let path = Path::new(extra);
        let ours = RglBsdf::parse(&std::fs::read(path).unwrap()).unwrap();
        let theirs = mitsuba_eval(path, "scalar_rgb", &[], &pairs);
        let worst = check(&ours, &theirs, &pairs, &[0, 1, 2]);
        eprintln!(
            "{}: worst relative difference {worst:e} over {} pairs",
            path.display(),
            pairs.len()
        );
        assert!(
            worst < 1e-4,
            "{}: worst relative difference {worst:e}",
            path.display()
        );
    }
}
