//! The committed recordings are what the generator makes from the values in their
//! ground-truth files, byte for byte: the readings in each `truth.json` are the readings on the
//! wire (bit for bit, through the drivers' codecs), and nobody edited a session by hand.
//! Also checks the documented construction of the N9 reference (0.767 × a per-geometry gain in
//! 0.9–1.1, flat across the bands).

use drivers::Instrument;
use drivers::protocol::ReadingValue;
use mock_devices::generate::{GenerateOptions, REFERENCE_NAME, Readings};
use mock_devices::{Script, generate_reference_session, generate_sample_session, recordings};
use serde_json::Value;

fn readings_from(truth: &Value, what: &str) -> Readings {
    let r = &truth["readings"];
    let mat12 = drivers::protocol::MAT12_GEOMETRIES;
    let sra = drivers::protocol::SRA_GEOMETRIES;
    Readings {
        ma_t12: std::array::from_fn(|g| {
            let v = r["ma_t12"][mat12[g]]
                .as_array()
                .unwrap_or_else(|| panic!("{what}: readings.ma_t12.{} missing", mat12[g]));
            assert_eq!(v.len(), 31, "{what}: {}", mat12[g]);
            std::array::from_fn(|b| v[b].as_f64().expect("number"))
        }),
        sra: std::array::from_fn(|g| {
            r["sra"][sra[g]]
                .as_f64()
                .unwrap_or_else(|| panic!("{what}: readings.sra.{} missing", sra[g]))
        }),
    }
}

#[test]
fn committed_sessions_are_the_generator_output_for_their_ground_truth() {
    for rec in recordings::all() {
        let truth: Value = serde_json::from_str(rec.truth)
            .unwrap_or_else(|e| panic!("{}.truth.json: {e}", rec.name));
        assert_eq!(truth["synthetic"], Value::Bool(true), "{}", rec.name);
        let readings = readings_from(&truth, rec.name);
        let options = GenerateOptions {
            notes: vec![format!("ground truth {}.truth.json", rec.name)],
            ..GenerateOptions::default()
        };
        let pair = match rec.sample {
            None => generate_reference_session(&readings, &options),
            Some(sample) => {
                assert_eq!(truth["sample"].as_str(), Some(sample), "{}", rec.name);
                assert_eq!(
                    truth["model"]["sample"].as_str(),
                    Some(sample),
                    "{}",
                    rec.name
                );
                generate_sample_session(sample, &readings, &options)
            }
        }
        .unwrap();
        assert_eq!(
            pair.ma_t12.to_text(),
            rec.ma_t12,
            "{}.ma_t12.session",
            rec.name
        );
        assert_eq!(pair.sra.to_text(), rec.sra, "{}.sra.session", rec.name);

        // And, independently of the generator, the readings on the wire are the truth file's.
        let wire = Script::new(rec.session(Instrument::MaT12).unwrap())
            .unwrap()
            .readings();
        for (g, reading) in wire.iter().enumerate() {
            let ReadingValue::Reflectance(s) = reading.value else {
                panic!("MA-T12 readings are spectra")
            };
            for (b, v) in s.iter().enumerate() {
                assert_eq!(
                    v.to_bits(),
                    readings.ma_t12[g][b].to_bits(),
                    "{} {} band {b}",
                    rec.name,
                    reading.geometry
                );
            }
        }
        let wire = Script::new(rec.session(Instrument::Sra).unwrap())
            .unwrap()
            .readings();
        for (g, reading) in wire.iter().enumerate() {
            let ReadingValue::Intensity(v) = reading.value else {
                panic!("SRA readings are intensities")
            };
            assert_eq!(
                v.to_bits(),
                readings.sra[g].to_bits(),
                "{} {}",
                rec.name,
                reading.geometry
            );
        }
    }
}

#[test]
fn the_reference_is_a_flat_0_767_tile_times_a_device_gain() {
    let rec = recordings::reference();
    assert!(
        rec.ma_t12
            .contains(&format!("note reference {REFERENCE_NAME}"))
    );
    let truth: Value = serde_json::from_str(rec.truth).unwrap();
    let r = readings_from(&truth, rec.name);
    let mut gains = Vec::new();
    for spectrum in &r.ma_t12 {
        // Flat: one value in every band.
        assert!(spectrum.iter().all(|v| v == &spectrum[0]), "{spectrum:?}");
        gains.push(spectrum[0] / 0.767);
    }
    for v in r.sra {
        gains.push(v / 0.245);
    }
    assert!(gains.iter().all(|g| (0.9..=1.1).contains(g)), "{gains:?}");
    // The gains differ per geometry (a processing step that forgot the reference would show).
    assert!(gains.iter().any(|g| (g - 1.0).abs() > 0.05), "{gains:?}");
}

#[test]
fn samples_are_matt_and_dimmer_than_the_reference_off_specular() {
    // A sanity check of the values, not of the physics: a matt sample reflects less than the
    // N9 tile at the 45° detector far from the mirror direction (45as110 here), in every band.
    let n9: Value = serde_json::from_str(recordings::reference().truth).unwrap();
    let n9 = readings_from(&n9, "n9");
    for rec in recordings::samples() {
        let truth: Value = serde_json::from_str(rec.truth).unwrap();
        let r = readings_from(&truth, rec.name);
        for b in 0..31 {
            assert!(r.ma_t12[11][b] < n9.ma_t12[11][b], "{} band {b}", rec.name);
        }
    }
}
