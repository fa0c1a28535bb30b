//! The daemon in-process when things go wrong: an instrument unplugged mid-scan, damaged replies
//! and garbage on the wire, a fit that panics, a reference too old to fit against, a fit
//! cancelled, a scan aborted. Each leaves the store consistent (readings stored with the reply
//! frames as received) and the daemon ready for the next scan.

// `serial()` is held for a whole test on purpose: each test has its own runtime, so holding
// it across awaits cannot deadlock, and it keeps the daemon tests from competing for cores.
#![allow(clippy::await_holding_lock)]

mod common;

use std::ops::ControlFlow;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

use brdfd::cost::CostFunction;
use brdfd::fit::FitScanError;
use brdfd::geometry::Device;
use brdfd::optimise::{FitError, Progress};
use brdfd::service::{
    Devices, FitFn, RefitRequest, ServiceError, ServiceOptions, ServiceSettings, default_fit_fn,
};
use brdfd::store::{FitStatus, ScanState};
use drivers::protocol::Request;
use drivers::session::Fault;
use drivers::{Instrument, TransportError};
use mock_devices::{ReplayOptions, Script, SimMat12, SimSra};

use common::*;

/// An MA-T12 script: the N9 reference, then two samples; the frame number of the reply to
/// the `k`-th FETCH (1-based) of the first sample.
fn three_objects() -> (Script, Script, usize, [&'static str; 2]) {
    let recs = mock_devices::recordings::all();
    let objects = [&recs[0], &recs[1], &recs[2]];
    let ma = Script::from_sessions(
        objects
            .iter()
            .map(|r| r.session(Instrument::MaT12).unwrap()),
    )
    .unwrap();
    let sra =
        Script::from_sessions(objects.iter().map(|r| r.session(Instrument::Sra).unwrap())).unwrap();
    let fifth_fetch_reply = ma
        .exchanges()
        .iter()
        .filter(|e| e.session == 1 && matches!(e.parsed, Some(Request::Fetch { .. })))
        .nth(4)
        .expect("a fifth FETCH")
        .replies[0]
        .index;
    (
        ma,
        sra,
        fifth_fetch_reply,
        [recs[1].sample.unwrap(), recs[2].sample.unwrap()],
    )
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn an_unplugged_instrument_fails_the_scan_keeping_its_readings_and_the_next_scan_succeeds() {
    let _serial = serial();
    bounded(async {
        let (ma, sra, after, [first, second]) = three_objects();
        // The link drops once the 5th FETCH reply of the first sample has gone by.
        let ma = ma.with_fault(Fault::Disconnect { after }).unwrap();
        let options = ReplayOptions::lenient().accelerated();
        let sim_m = SimMat12::new(ma, options.clone()).unwrap();
        let sim_s = SimSra::new(sra, options).unwrap();
        // The USB cable: while it is out, every connection attempt finds no device.
        let plugged = Arc::new(AtomicBool::new(true));
        let cable = plugged.clone();
        let usb = sim_m.clone();
        let ma_t12 = drivers::spawn_mat12(
            move || {
                if cable.load(Ordering::SeqCst) {
                    usb.connect()
                } else {
                    Err(TransportError::UsbNotFound {
                        vendor_id: drivers::mat12::usb::XRITE_VENDOR_ID,
                        product_id: None,
                        detail: None,
                    })
                }
            },
            fast_driver_config(),
        );
        let sra = drivers::spawn_sra(sim_s.factory(), fast_driver_config());
        let d = start(
            Devices::new(ma_t12, sra),
            settings(),
            ServiceOptions::default(),
        )
        .await;
        let service = &d.service;
        measure_reference(service).await;

        // The cable comes out (the open connection lives on until the fault drops it).
        plugged.store(false, Ordering::SeqCst);
        let failed = scan_and_settle(service, first).await;
        let detail = d.store.scan_detail(failed).await.unwrap();
        assert_eq!(detail.scan.state, ScanState::Failed);
        let reason = detail.scan.reason.clone().unwrap();
        assert!(reason.contains("MA-T12"), "{reason}");
        assert!(reason.contains("link lost"), "{reason}");
        // The sixth MA-T12 geometry was being fetched when the link dropped.
        let sixth = brdfd::geometry::GEOMETRIES[5].name;
        assert!(
            reason.contains(sixth),
            "names the geometry in progress: {reason}"
        );
        let ma_readings = detail
            .readings
            .iter()
            .filter(|r| r.device() == Device::MaT12)
            .count();
        let sra_readings = detail.readings.len() - ma_readings;
        assert_eq!(
            ma_readings, 5,
            "the five readings fetched before the link dropped"
        );
        assert_eq!(sra_readings, 2, "the SRA finished its part");
        // What was stored before the link dropped is what the instruments sent.
        let frames = recorded_fetch_replies(&mock_devices::recordings::all()[1]);
        for r in &detail.readings {
            assert_eq!(
                r.raw_frame, frames[r.geometry.name],
                "{}: the recorded reply",
                r.geometry.name
            );
        }
        assert!(d.store.fits_for_scan(failed).await.unwrap().is_empty());

        // Plugged back in: the next scan reconnects and completes with the next recording.
        plugged.store(true, Ordering::SeqCst);
        let ok = scan_and_settle(service, second).await;
        let detail = complete_scan(&d.store, ok).await;
        assert_eq!(detail.readings.len(), 14);
        let fits = d.store.fits_for_scan(ok).await.unwrap();
        assert_eq!(fits.len(), 3);
        assert!(fits.iter().all(|f| f.status == FitStatus::Done));
        assert!(
            sim_m.report().connections >= 2,
            "the instrument was reconnected"
        );
        assert_eq!(d.store.integrity_check().await.unwrap(), ["ok"]);
        service.shutdown().await;
    })
    .await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn damaged_replies_and_garbage_leave_only_the_frames_received_whole_in_the_store() {
    let _serial = serial();
    bounded(async {
        let (ma, sra, fifth_fetch_reply, [first, _]) = three_objects();
        // MA-T12: the first sample's fifth reading arrives damaged twice (a payload byte
        // flipped: bad CRC, refetched), after garbage that looks like a header with an
        // impossible length (dropped without a refetch).
        let ma = ma
            .with_fault(Fault::Corrupt {
                frame: fifth_fetch_reply,
                offset: 100,
                xor: 0x10,
                times: 2,
            })
            .unwrap()
            .with_fault(Fault::Garbage {
                frame: fifth_fetch_reply,
                bytes: vec![0x4D, 0x54, 0xFF, 0xFF, 0xFF],
            })
            .unwrap();
        // SRA: noise holding reply starts and line ends before the first sample's first reading.
        let sra_first_reply = sra
            .exchanges()
            .iter()
            .find(|e| e.session == 1 && matches!(e.parsed, Some(Request::Fetch { .. })))
            .expect("a FETCH")
            .replies[0]
            .index;
        let sra = sra
            .with_fault(Fault::Garbage {
                frame: sra_first_reply,
                bytes: b"!\r\n!$\x00\r\n".to_vec(),
            })
            .unwrap();
        let devices = Devices::simulated(ma, sra, &strict_fast(), [None, None]).unwrap();
        let d = start(devices, settings(), ServiceOptions::default()).await;
        let service = &d.service;
        measure_reference(service).await;
        let scan = scan_and_settle(service, first).await;
        let detail = complete_scan(&d.store, scan).await;
        // Every stored frame is the recorded reply, byte for byte: neither a damaged copy nor
        // the garbage before it.
        let frames = recorded_fetch_replies(&mock_devices::recordings::all()[1]);
        assert_eq!(detail.readings.len(), 14);
        for r in &detail.readings {
            assert_eq!(
                r.raw_frame, frames[r.geometry.name],
                "{}: the recorded reply",
                r.geometry.name
            );
        }
        for (instrument, report) in service.devices().replay_reports() {
            assert!(report.mismatches.is_empty(), "{instrument}: {report:?}");
            let fired = report.faults_fired.join("; ");
            let want: &[&str] = match instrument {
                Instrument::MaT12 => &["(1 of 2)", "(2 of 2)", "garbage before frame"],
                Instrument::Sra => &["garbage before frame"],
            };
            for w in want {
                assert!(fired.contains(w), "{instrument}: {w} not in {fired}");
            }
        }
        service.shutdown().await;
    })
    .await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_fit_that_panics_is_recorded_as_failed_and_the_daemon_goes_on() {
    let _serial = serial();
    bounded(async {
        // A test-only fit computation: the first m2 fit panics, everything else is real.
        let armed = Arc::new(AtomicBool::new(true));
        let trigger = armed.clone();
        let real = default_fit_fn();
        let fit_fn: FitFn = Arc::new(move |job, observer| {
            if job.request.settings.cost == CostFunction::M2
                && trigger.swap(false, Ordering::SeqCst)
            {
                panic!("injected test panic inside the m2 fit");
            }
            real(job, observer)
        });
        let devices = simulated(&strict_fast());
        let d = start(
            devices,
            settings(),
            ServiceOptions {
                fit_fn: Some(fit_fn),
            },
        )
        .await;
        let service = &d.service;
        measure_reference(service).await;
        let samples = mock_devices::recordings::samples();
        let first = scan_and_settle(service, samples[0].sample.unwrap()).await;
        let fits = d.store.fits_for_scan(first).await.unwrap();
        assert_eq!(fits.len(), 3);
        for f in &fits {
            if f.cost_function == CostFunction::M2 {
                assert_eq!(f.status, FitStatus::Failed);
                let error = f.error.as_deref().unwrap();
                assert!(error.contains("panicked"), "{error}");
                assert!(error.contains("injected test panic"), "{error}");
                assert!(f.result.is_none());
            } else {
                assert_eq!(f.status, FitStatus::Done, "{:?}", f.error);
            }
        }
        // The daemon goes on: the next scan's three fits all finish, and a refit of the m2
        // fit of the first scan works.
        let second = scan_and_settle(service, samples[1].sample.unwrap()).await;
        let fits = d.store.fits_for_scan(second).await.unwrap();
        assert!(fits.iter().all(|f| f.status == FitStatus::Done), "{fits:?}");
        let refit = service
            .refit(
                first,
                &RefitRequest {
                    cost_functions: vec![CostFunction::M2],
                    ..RefitRequest::default()
                },
            )
            .await
            .unwrap();
        assert!(service.wait_settled(first, STEP_TIMEOUT).await.unwrap());
        assert_eq!(
            d.store.fit_detail(refit[0]).await.unwrap().run.status,
            FitStatus::Done
        );
        service.shutdown().await;
    })
    .await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_scan_against_a_stale_reference_is_flagged_not_fitted_until_allowed() {
    let _serial = serial();
    bounded(async {
        let devices = simulated(&strict_fast());
        let settings = ServiceSettings {
            reference_max_age: Duration::from_millis(20),
            ..settings()
        };
        let d = start(devices, settings, ServiceOptions::default()).await;
        let service = &d.service;
        let mut events = service.subscribe();
        measure_reference(service).await;
        // Wait for the daemon to call the reference stale (20 ms after it), not for a guess.
        while !service.status().await.unwrap().reference.unwrap().stale {
            tokio::task::yield_now().await;
        }
        let sample = mock_devices::recordings::samples()[0].sample.unwrap();
        let scan = scan_and_settle(service, sample).await;
        let detail = d.store.scan_detail(scan).await.unwrap();
        assert_eq!(
            detail.scan.state,
            ScanState::Complete,
            "the readings are good"
        );
        assert!(
            d.store.fits_for_scan(scan).await.unwrap().is_empty(),
            "not fitted"
        );
        let mut flagged = false;
        while let Ok(ev) = events.try_recv() {
            if let brdfd::service::Event::ReferenceStale {
                scan: s, age_hours, ..
            } = ev
            {
                flagged = s == scan && age_hours > 0.0;
            }
        }
        assert!(flagged, "a reference_stale event for the scan");
        let e = service
            .refit(scan, &RefitRequest::default())
            .await
            .unwrap_err();
        assert!(matches!(e, ServiceError::StaleReference { .. }), "{e}");
        assert!(e.to_string().contains("--allow-stale-reference"), "{e}");
        let fits = service
            .refit(
                scan,
                &RefitRequest {
                    allow_stale_reference: true,
                    ..RefitRequest::default()
                },
            )
            .await
            .unwrap();
        assert_eq!(fits.len(), 3);
        assert!(service.wait_settled(scan, STEP_TIMEOUT).await.unwrap());
        service.shutdown().await;
    })
    .await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_running_fit_can_be_cancelled_and_a_scan_aborted_keeping_its_readings() {
    let _serial = serial();
    bounded(async {
        // A fit computation that runs until told to stop, reporting every 2 ms; it says when it
        // has started, so the cancel below provably hits a running fit.
        let (started_tx, started_rx) = std::sync::mpsc::channel::<()>();
        let started_tx = std::sync::Mutex::new(started_tx);
        let endless: FitFn = Arc::new(move |job, observer| {
            let _ = started_tx.lock().unwrap().send(());
            let mut generation = 0;
            loop {
                generation += 1;
                let p = Progress {
                    generation,
                    generations_total: u32::MAX,
                    best_cost: 1.0,
                    evaluations: u64::from(generation),
                };
                if let ControlFlow::Break(()) = observer(&p) {
                    return Err(FitScanError::Fit {
                        sample: job.sample.clone(),
                        cost: job.request.settings.cost,
                        source: FitError::Cancelled,
                    });
                }
                std::thread::sleep(Duration::from_millis(2));
            }
        });
        // Recorded timing, ten times faster: a scan takes about a quarter of a second.
        let devices = simulated(&ReplayOptions::lenient().speed(10.0));
        let settings = ServiceSettings {
            cost_functions: vec![CostFunction::Cf2],
            max_concurrent_fits: 1,
            ..settings()
        };
        let d = start(
            devices,
            settings,
            ServiceOptions {
                fit_fn: Some(endless),
            },
        )
        .await;
        let service = &d.service;
        measure_reference(service).await;
        let scan = service.request_scan("T.Endless").await.unwrap();
        assert!(service.wait_idle(STEP_TIMEOUT).await);
        let fit = d.store.fits_for_scan(scan).await.unwrap()[0].id;
        // Wait until it runs (the computation said so), check the store agrees, cancel it.
        tokio::task::spawn_blocking(move || started_rx.recv_timeout(STEP_TIMEOUT).unwrap())
            .await
            .unwrap();
        assert_eq!(
            d.store.fit_detail(fit).await.unwrap().run.status,
            FitStatus::Running
        );
        service.cancel_fit(fit).await.unwrap();
        assert!(service.wait_settled(scan, STEP_TIMEOUT).await.unwrap());
        assert_eq!(
            d.store.fit_detail(fit).await.unwrap().run.status,
            FitStatus::Cancelled
        );
        let e = service.cancel_fit(fit).await.unwrap_err();
        assert!(e.to_string().contains("cancelled"), "{e}");

        // Abort a scan once some readings are in.
        let mut events = service.subscribe();
        let aborted = service.request_scan("T.Aborted").await.unwrap();
        loop {
            if let brdfd::service::Event::ScanReading { scan, .. } = events.recv().await.unwrap()
                && scan == aborted
            {
                break;
            }
        }
        service.abort().unwrap();
        assert!(service.wait_idle(STEP_TIMEOUT).await);
        let detail = d.store.scan_detail(aborted).await.unwrap();
        assert_eq!(detail.scan.state, ScanState::Aborted);
        assert_eq!(
            detail.scan.reason.as_deref(),
            Some("aborted by the operator")
        );
        assert!(!detail.readings.is_empty() && detail.readings.len() < 14);
        assert!(matches!(service.abort(), Err(ServiceError::Idle)));
        service.shutdown().await;
    })
    .await;
}
