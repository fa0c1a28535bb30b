//! Regenerates the committed synthetic recordings in `mock-devices/recordings/`:
//!
//! ```text
//! cargo run -p brdfd-mock-devices --example make_recordings
//! ```
//!
//! The values are not made up here: they are the eight synthetic example scans of the root
//! crate's `tests/data/` (made by `brdfd synth` from ColorChecker spectra and matt specular
//! lobes, see `tests/data/README.md`), so the recordings and those scans tell one story.
//! - The N9 reference session carries the noise-free reference readings of those scans:
//!   MA-T12 `gain_g · 0.767` in every band, SRA `gain_g · 0.245` (the same in all eight).
//! - Each sample session carries the readings of `<slug>.noisy.scan.json` (1 % noise).
//! - Each `<name>.truth.json` holds the readings used and, for samples, the model parameters of
//!   `<slug>.truth.json`.
//!
//! Output is deterministic: running it again on the same scans rewrites identical files
//! (`tests/recordings.rs` checks the committed files against the generator).

use std::path::{Path, PathBuf};

use mock_devices::generate::{GenerateOptions, Readings, SessionPair};
use mock_devices::{generate_reference_session, generate_sample_session};
use serde_json::{Value, json};

const MA_T12: [&str; 12] = drivers::protocol::MAT12_GEOMETRIES;
const SRA: [&str; 2] = drivers::protocol::SRA_GEOMETRIES;

/// The sample scans, in the order of `mock_devices::recordings::all()`.
const SLUGS: [&str; 8] = [
    "t-freesia-pink",
    "t-prairie-green",
    "t-manzana-green",
    "t-mandarin-orange",
    "t-lavender-blue",
    "t-saffron-yellow",
    "t-sky-blue",
    "t-pebble-grey",
];

fn read_json(path: &Path) -> Value {
    let text = std::fs::read_to_string(path)
        .unwrap_or_else(|e| panic!("cannot read {}: {e}", path.display()));
    serde_json::from_str(&text).unwrap_or_else(|e| panic!("{} is not JSON: {e}", path.display()))
}

/// `{"ma_t12": {...12 names}, "sra": {...2 names}}` of a scan file → [`Readings`].
fn readings(v: &Value, what: &str) -> Readings {
    let number = |x: &Value, field: &str| -> f64 {
        x.as_f64()
            .unwrap_or_else(|| panic!("{what}: {field} is not a number"))
    };
    Readings {
        ma_t12: std::array::from_fn(|g| {
            let values = v["ma_t12"][MA_T12[g]]
                .as_array()
                .unwrap_or_else(|| panic!("{what}: ma_t12.{} missing", MA_T12[g]));
            assert_eq!(values.len(), 31, "{what}: ma_t12.{} length", MA_T12[g]);
            std::array::from_fn(|b| number(&values[b], MA_T12[g]))
        }),
        sra: std::array::from_fn(|g| number(&v["sra"][SRA[g]], SRA[g])),
    }
}

fn readings_json(r: &Readings) -> Value {
    json!({
        "ma_t12": MA_T12.iter().zip(&r.ma_t12).map(|(g, s)| (g.to_string(), json!(s.to_vec())))
            .collect::<serde_json::Map<_, _>>(),
        "sra": SRA.iter().zip(&r.sra).map(|(g, v)| (g.to_string(), json!(v)))
            .collect::<serde_json::Map<_, _>>(),
    })
}

fn write(dir: &Path, name: &str, pair: &SessionPair, truth: &Value) {
    let files = [
        (format!("{name}.ma_t12.session"), pair.ma_t12.to_text()),
        (format!("{name}.sra.session"), pair.sra.to_text()),
        (
            format!("{name}.truth.json"),
            serde_json::to_string_pretty(truth).expect("JSON") + "\n",
        ),
    ];
    for (file, text) in files {
        let path = dir.join(&file);
        std::fs::write(&path, text)
            .unwrap_or_else(|e| panic!("cannot write {}: {e}", path.display()));
        println!("wrote recordings/{file}");
    }
}

fn main() {
    let crate_dir = PathBuf::from(env!("CARGO_MANIFEST_DIR"));
    let data = crate_dir.join("../tests/data");
    let out = crate_dir.join("recordings");
    std::fs::create_dir_all(&out).expect("create recordings/");

    // The reference: identical in all eight noise-free scans; checked, not assumed.
    let reference_json =
        read_json(&data.join(format!("{}.scan.json", SLUGS[0])))["reference"].clone();
    for slug in SLUGS {
        let other = read_json(&data.join(format!("{slug}.scan.json")))["reference"].clone();
        assert_eq!(
            other, reference_json,
            "{slug}: reference differs from the others"
        );
    }
    let reference = readings(&reference_json, "reference");
    let name = "synthetic-n9";
    let options = GenerateOptions {
        notes: vec![format!("ground truth {name}.truth.json")],
        ..GenerateOptions::default()
    };
    let pair = generate_reference_session(&reference, &options).expect("reference session");
    let truth = json!({
        "synthetic": true,
        "object": "Munsell N9 reference tile",
        "how": "MA-T12: gain_g * 0.767 in every band (Munsell value 9, Y = 76.7 %, ASTM D1535); \
                SRA: gain_g * 0.245; fixed per-geometry device gains in 0.9-1.1 \
                (brdfd synth DEFAULT_GAINS); no noise",
        "source": "reference of tests/data/*.scan.json (noise-free), made by `brdfd synth`",
        "readings": readings_json(&reference),
    });
    write(&out, name, &pair, &truth);

    for slug in SLUGS {
        let scan = read_json(&data.join(format!("{slug}.noisy.scan.json")));
        let model = read_json(&data.join(format!("{slug}.truth.json")));
        let sample = scan["sample"]
            .as_str()
            .expect("scan has a sample name")
            .to_string();
        let values = readings(&scan["readings"], slug);
        let name = format!("synthetic-{slug}");
        let options = GenerateOptions {
            notes: vec![format!("ground truth {name}.truth.json")],
            ..GenerateOptions::default()
        };
        let pair = generate_sample_session(&sample, &values, &options).expect("sample session");
        let truth = json!({
            "synthetic": true,
            "sample": sample,
            "how": "readings of a synthetic matt sample: kd from a ColorChecker patch \
                    (BabelColor average, D. Pascale 2012), synthetic ks, alpha, ior; \
                    MA-T12 gain_g * 0.767 * pi * f(lambda; g), SRA gain_g * 0.245 * pi * \
                    mean_lambda f(lambda; g); multiplicative N(1, 0.01) noise",
            "source": format!("readings of tests/data/{slug}.noisy.scan.json, model of \
                               tests/data/{slug}.truth.json, made by `brdfd synth`"),
            "reference": "synthetic-n9",
            "readings": readings_json(&values),
            "model": model,
        });
        write(&out, &name, &pair, &truth);
    }
}
