//! The daemon in-process on simulated instruments replaying the committed recordings
//! (strict, accelerated): a reference, a scan and three fits land in the store with every row,
//! each value checked against the recording it came from and against the standalone fit
//! pipeline, each reading's raw frame byte for byte the recorded reply to its FETCH (also when
//! the instrument writes digits brdfd's codec would not); export and import round-trip; the
//! imported reference never takes over.

// `serial()` is held for a whole test on purpose: each test has its own runtime, so holding
// it across awaits cannot deadlock, and it keeps the daemon tests from competing for cores.
#![allow(clippy::await_holding_lock)]

mod common;

use brdfd::cost::CostFunction;
use brdfd::fit::{FitRequest, fit_scan};
use brdfd::geometry::{Device, GEOMETRIES};
use brdfd::optimise::{Method, Settings};
use brdfd::processing::{self, ProcessingOptions, SpecularStrategy};
use brdfd::service::{Event, RefitRequest};
use brdfd::store::{FitStatus, ReadingValues, ReferenceStatus};
use drivers::protocol::{Codec, Response};
use drivers::sra::codec::SraCodec;
use drivers::{Instrument, ReadingValue};

use common::*;

/// The readings a recording holds for one object, by geometry name.
fn recorded(
    r: &mock_devices::recordings::Recording,
) -> std::collections::HashMap<&'static str, Vec<f64>> {
    let mut out = std::collections::HashMap::new();
    for instrument in [Instrument::MaT12, Instrument::Sra] {
        for reading in r.script(instrument).unwrap().readings() {
            let values = match reading.value {
                ReadingValue::Reflectance(s) => s.to_vec(),
                ReadingValue::Intensity(v) => vec![v],
            };
            out.insert(reading.geometry, values);
        }
    }
    out
}

/// Checks one stored reading: its values are the recording's, bit for bit, and its raw frame
/// is, byte for byte, the reply frame the recording holds for that geometry's FETCH (the
/// session file's `<` line): the bytes as received, not a re-encoding.
fn check_reading(
    r: &brdfd::store::Reading,
    truth: &std::collections::HashMap<&'static str, Vec<f64>>,
    frames: &std::collections::HashMap<&'static str, Vec<u8>>,
) {
    let name = r.geometry.name;
    assert!(
        bit_eq(r.values.as_slice(), &truth[name]),
        "{name}: stored values differ from the recording"
    );
    assert_eq!(
        drivers::session::to_hex(&r.raw_frame),
        drivers::session::to_hex(&frames[name]),
        "{name}: the stored raw frame is the recorded reply to its FETCH"
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_reference_a_scan_and_three_fits_land_in_the_store_with_every_row() {
    let _serial = serial();
    bounded(async {
        let d = start_builtin(strict_fast()).await;
        let service = &d.service;
        let mut events = service.subscribe();

        // Reference: 14 readings, the N9 recording's values, raw frames.
        let reference = measure_reference(service).await;
        let rd = d.store.reference_detail(reference).await.unwrap();
        assert_eq!(rd.reference.status, ReferenceStatus::Complete);
        assert_eq!(rd.reference.name, "Munsell N9");
        assert_eq!(rd.readings.len(), 14);
        let n9 = mock_devices::recordings::reference();
        let (n9_values, n9_frames) = (recorded(n9), recorded_fetch_replies(n9));
        for r in &rd.readings {
            check_reading(r, &n9_values, &n9_frames);
        }
        assert_eq!(
            service.reference_in_force().await.unwrap().unwrap().id,
            reference
        );

        // Scan: 14 readings from the first sample's recording.
        let first = &mock_devices::recordings::samples()[0];
        let sample = first.sample.unwrap();
        let scan = scan_and_settle(service, sample).await;
        let detail = complete_scan(&d.store, scan).await;
        assert_eq!(detail.scan.sample, sample);
        assert_eq!(detail.scan.reference_id, reference);
        assert_eq!(detail.readings.len(), 14);
        assert!(detail.scan.started_at_ms.is_some() && detail.scan.finished_at_ms.is_some());
        let (truth, frames) = (recorded(first), recorded_fetch_replies(first));
        for (r, g) in detail.readings.iter().zip(GEOMETRIES.iter()) {
            assert_eq!(r.geometry.name, g.name, "readings in table order");
            check_reading(r, &truth, &frames);
        }

        // The processed BRDF is processing of the exported scan, bit for bit.
        let exported = service.export_scan(scan).await.unwrap();
        let processed = d.store.processed_for_scan(scan).await.unwrap();
        assert_eq!(processed.len(), 1);
        assert_eq!(processed[0].specular, SpecularStrategy::Ratio);
        let want = processing::process(&exported, &ProcessingOptions::default()).unwrap();
        for (a, b) in processed[0].brdf.values.iter().zip(&want.values) {
            assert!(bit_eq(a, b), "processed BRDF");
        }

        // Three fits, done, each equal to the standalone pipeline with the same settings.
        let fits = d.store.fits_for_scan(scan).await.unwrap();
        assert_eq!(fits.len(), 3);
        let costs: Vec<CostFunction> = fits.iter().map(|f| f.cost_function).collect();
        assert_eq!(costs, CostFunction::ALL);
        for f in &fits {
            assert_eq!(f.status, FitStatus::Done, "fit {}: {:?}", f.id, f.error);
            assert_eq!(f.method, "separable");
            assert_eq!(f.seed, 1);
            assert_eq!(f.processed, processed[0].id);
            let settings: Settings = serde_json::from_value(f.settings.clone()).unwrap();
            assert_eq!(settings.cost, f.cost_function);
            assert_eq!(settings.method, Method::Separable);
            let result = f.result.as_ref().expect("result stored");
            assert!(!result.best_cost_per_generation.is_empty());
            assert!(result.evaluations > 0 && result.generations > 0);
            assert!(f.started_at_ms.is_some() && f.finished_at_ms.is_some());

            let standalone = fit_scan(
                &exported,
                &FitRequest {
                    processing: ProcessingOptions::default(),
                    settings,
                    ..FitRequest::default()
                },
            )
            .unwrap();
            let params: brdfd::model::Params =
                serde_json::from_value(result.params.clone()).unwrap();
            assert!(bit_eq(&params.kd, &standalone.outcome.params.kd), "kd");
            assert_eq!(params.ks.to_bits(), standalone.outcome.params.ks.to_bits());
            assert_eq!(result.cost.to_bits(), standalone.outcome.cost.to_bits());
            assert_eq!(
                result.best_cost_per_generation,
                standalone.outcome.best_cost_per_generation
            );

            let detail = d.store.fit_detail(f.id).await.unwrap();
            let e = detail.evaluation.expect("evaluation stored");
            assert!(bit_eq(&e.per_geometry, &standalone.evaluation.per_geometry));
            // The store sums the sorted values for its summaries: equal to rounding.
            let close = |a: f64, b: f64| (a - b).abs() <= 1e-12 * b.abs().max(1.0);
            assert!(close(e.all.mean, standalone.evaluation.all.mean));
            assert!(close(e.diffuse.mean, standalone.evaluation.diffuse.mean));
            assert!(close(
                e.specular.unwrap().mean,
                standalone.evaluation.specular.unwrap().mean
            ));
        }

        // Both instruments are recorded with the identities they gave.
        let instruments = d.store.instruments().await.unwrap();
        let serials: Vec<&str> = instruments.iter().map(|i| i.serial.as_str()).collect();
        assert!(serials.contains(&"SIM-MAT12-0001"), "{serials:?}");
        assert!(serials.contains(&"SIM-SRA-0001"), "{serials:?}");

        // Every subscriber saw the whole story, in order.
        let mut seen = Vec::new();
        while let Ok(ev) = events.try_recv() {
            seen.push(ev);
        }
        let readings = seen
            .iter()
            .filter(|e| matches!(e, Event::ScanReading { scan: s, .. } if *s == scan))
            .count();
        assert_eq!(readings, 14);
        let pos = |pred: &dyn Fn(&Event) -> bool| seen.iter().position(pred);
        let complete = pos(&|e| matches!(e, Event::ScanComplete { scan: s } if *s == scan));
        let last_reading = seen
            .iter()
            .rposition(|e| matches!(e, Event::ScanReading { scan: s, .. } if *s == scan));
        assert!(last_reading < complete, "readings before completion");
        let done = seen
            .iter()
            .filter(|e| matches!(e, Event::FitDone { scan: s, .. } if *s == scan))
            .count();
        assert_eq!(done, 3);

        // Strict replay: every request matched the recording.
        for (instrument, report) in service.devices().replay_reports() {
            assert!(
                report.mismatches.is_empty(),
                "{instrument}: {:?}",
                report.mismatches
            );
        }
        assert_eq!(d.store.integrity_check().await.unwrap(), ["ok"]);
        assert!(service.shutdown().await);
    })
    .await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn export_then_import_gives_the_same_scan_and_fits_and_keeps_the_reference_in_force() {
    let _serial = serial();
    bounded(async {
        let d = start_builtin(strict_fast()).await;
        let service = &d.service;
        let reference = measure_reference(service).await;
        let sample = mock_devices::recordings::samples()[0].sample.unwrap();
        let scan = scan_and_settle(service, sample).await;
        let exported = service.export_scan(scan).await.unwrap();
        // The file says its readings are a replayed recording, and which.
        let origin = exported
            .origin
            .as_ref()
            .expect("an exported scan says where it came from");
        let source = origin.source.as_deref().unwrap_or_default();
        assert!(source.starts_with("simulated — replayed from"), "{source}");
        assert!(
            origin.ma_t12.as_ref().is_some_and(|i| i.simulated),
            "{origin:?}"
        );
        assert!(
            origin.sra.as_ref().is_some_and(|i| i.simulated),
            "{origin:?}"
        );
        assert!(origin.measured_at.is_some());
        // Through the file format, as `brdfd export` / `brdfd import` do.
        let text = exported.to_json_pretty().unwrap();
        let file = brdfd::scan::Scan::from_json(text.as_bytes()).unwrap();
        assert_eq!(file, exported);

        let (imported, fits) = service.import_scan(&file).await.unwrap();
        assert_eq!(fits.len(), 3);
        assert!(service.wait_settled(imported, STEP_TIMEOUT).await.unwrap());
        assert_eq!(service.export_scan(imported).await.unwrap(), exported);
        let a = d.store.fits_for_scan(scan).await.unwrap();
        let b = d.store.fits_for_scan(imported).await.unwrap();
        for (x, y) in a.iter().zip(&b) {
            assert_eq!(y.status, FitStatus::Done);
            assert_eq!(
                x.result.as_ref().unwrap().cost,
                y.result.as_ref().unwrap().cost
            );
        }
        // Imported readings carry no device traffic.
        let detail = d.store.scan_detail(imported).await.unwrap();
        assert!(detail.readings.iter().all(|r| r.raw_frame.is_empty()));
        assert!(detail.reference.reference.name.ends_with(" (imported)"));
        // New scans still use the measured reference.
        assert_eq!(
            service.reference_in_force().await.unwrap().unwrap().id,
            reference
        );

        // A refit with another seed and one cost function.
        let refits = service
            .refit(
                scan,
                &RefitRequest {
                    cost_functions: vec![CostFunction::Cf1],
                    seed: Some(7),
                    ..RefitRequest::default()
                },
            )
            .await
            .unwrap();
        assert_eq!(refits.len(), 1);
        assert!(service.wait_settled(scan, STEP_TIMEOUT).await.unwrap());
        let run = d.store.fit_detail(refits[0]).await.unwrap().run;
        assert_eq!((run.status, run.seed), (FitStatus::Done, 7));

        // An incomplete scan file is refused naming the field.
        let mut bad = text.clone();
        bad = bad.replacen("\"sra-60\"", "\"sra-61\"", 1);
        let e = brdfd::scan::Scan::from_json(bad.as_bytes()).unwrap_err();
        assert!(e.to_string().contains("sra-61"), "{e}");

        // A reading value of a stored scan survives the round trip through ReadingValues.
        assert!(matches!(
            detail.readings[12].values,
            ReadingValues::Intensity(_)
        ));
        service.shutdown().await;
    })
    .await;
}

/// Rewrites each SRA reading line of `session` with a trailing zero on its value (`0.25` →
/// `0.250`, `2.5e-7` → `2.50e-7`): the same reading, in digits brdfd's codec never writes.
/// Returns the new lines by geometry.
fn widen_sra_readings(
    session: &mut drivers::session::Session,
) -> std::collections::HashMap<&'static str, Vec<u8>> {
    let widen = |m: &str| {
        if m.contains('.') {
            format!("{m}0")
        } else {
            format!("{m}.0")
        }
    };
    let wanted = fetch_replies(session);
    let mut out = std::collections::HashMap::new();
    for frame in &mut session.frames {
        let Some((&geometry, _)) = wanted.iter().find(|(_, b)| **b == frame.bytes) else {
            continue;
        };
        let text = std::str::from_utf8(&frame.bytes).unwrap();
        // `!RD,<code>,<value>*XXXX\r\n`
        let body = &text[1..text.len() - 7];
        let (head, value) = body.rsplit_once(',').unwrap();
        let value = match value.split_once('e') {
            Some((m, e)) => format!("{}e{e}", widen(m)),
            None => widen(value),
        };
        frame.bytes = drivers::sra::codec::line(b'!', &format!("{head},{value}"));
        out.insert(geometry, frame.bytes.clone());
    }
    assert_eq!(out.len(), 2, "both SRA readings rewritten");
    out
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_stored_frame_is_the_one_received_even_in_digits_brdfd_would_not_write() {
    let _serial = serial();
    bounded(async {
        let n9 = mock_devices::recordings::reference();
        let mut sra = n9.session(Instrument::Sra).unwrap();
        let sent = widen_sra_readings(&mut sra);
        let devices = brdfd::service::Devices::simulated(
            n9.script(Instrument::MaT12).unwrap(),
            mock_devices::Script::new(sra).unwrap(),
            &strict_fast(),
            [None, None],
        )
        .unwrap();
        let d = start(
            devices,
            settings(),
            brdfd::service::ServiceOptions::default(),
        )
        .await;
        let reference = measure_reference(&d.service).await;
        let rd = d.store.reference_detail(reference).await.unwrap();
        let truth = recorded(n9);
        let mut frames = recorded_fetch_replies(n9);
        frames.extend(sent.clone());
        for r in &rd.readings {
            check_reading(r, &truth, &frames);
        }
        // The codec would have written those readings differently: a re-encoding could not
        // have produced the stored frames.
        for r in rd.readings.iter().filter(|r| r.device() == Device::Sra) {
            let ReadingValues::Intensity(v) = r.values else {
                panic!("{}: not an intensity", r.geometry.name)
            };
            let canonical = SraCodec::encode_response(&Response::Fetched(drivers::Reading {
                geometry: r.geometry.name,
                value: ReadingValue::Intensity(v),
            }))
            .unwrap();
            assert_ne!(canonical, r.raw_frame, "{}", r.geometry.name);
            assert_eq!(r.raw_frame, sent[r.geometry.name]);
        }
        assert!(d.service.shutdown().await);
    })
    .await;
}
