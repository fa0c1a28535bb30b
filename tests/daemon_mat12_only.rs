//! A lab with only an MA-T12: the daemon with the SRA turned off (`[devices.sra] transport =
//! "off"`) measures references and scans on the 12 MA-T12 geometries of the simulated MA-T12,
//! fits them without specular readings, with bootstrap intervals, and refuses a scan with SRA
//! readings against such a reference once the SRA is back. In process (the service) and as a
//! `brdfd serve` child (the configuration, the banner and `status`).

// `serial()` is held for a whole test on purpose: each test has its own runtime, so holding
// it across awaits cannot deadlock, and it keeps the daemon tests from competing for cores.
#![allow(clippy::await_holding_lock)]

mod common;

use std::time::{Duration, Instant};

use brdfd::geometry::{Device, MA_T12_COUNT};
use brdfd::service::devices::Devices;
use brdfd::service::{ServiceError, ServiceOptions};
use brdfd::store::{FitStatus, StoreError};
use drivers::Instrument;
use mock_devices::ReplayOptions;

use common::*;

fn lenient_fast() -> ReplayOptions {
    ReplayOptions::lenient().accelerated()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn with_the_sra_off_a_reference_and_a_scan_have_12_readings_and_fit_with_intervals() {
    let _serial = serial();
    bounded(async {
        let devices = Devices::simulated_mat12_only(playlist(Instrument::MaT12), &lenient_fast())
            .expect("simulated MA-T12");
        let d = start(devices, settings(), ServiceOptions::default()).await;
        let service = &d.service;
        let status = service.status().await.unwrap();
        let sra = status.devices.iter().find(|s| s.device == "sra").unwrap();
        assert_eq!(sra.state, "off", "{sra:?}");

        let reference = measure_reference(service).await;
        let r = d.store.reference_detail(reference).await.unwrap();
        assert_eq!(r.readings.len(), MA_T12_COUNT);
        assert!(!r.reference.specular_readings);
        assert!(
            r.readings
                .iter()
                .all(|x| x.geometry.device == Device::MaT12)
        );

        let scan = scan_and_settle(service, "T.Sky blue").await;
        let detail = complete_scan(&d.store, scan).await;
        assert!(!detail.scan.specular_readings);
        assert_eq!(detail.readings.len(), MA_T12_COUNT);

        let fits = d.store.fits_for_scan(scan).await.unwrap();
        assert_eq!(fits.len(), 3, "one fit per cost function");
        let deadline = Instant::now() + Duration::from_secs(120);
        for fit in &fits {
            assert_eq!(
                fit.status,
                FitStatus::Done,
                "fit {}: {:?}",
                fit.id,
                fit.error
            );
            // The intervals come after the fit, from the bootstrap.
            let detail = loop {
                let detail = d.store.fit_detail(fit.id).await.unwrap();
                if detail.uncertainty.is_some() || Instant::now() > deadline {
                    break detail;
                }
                tokio::time::sleep(Duration::from_millis(50)).await;
            };
            let e = detail.evaluation.expect("a done fit is evaluated");
            assert!(e.specular.is_none(), "no specular readings: {e:?}");
            assert!(e.per_geometry[..MA_T12_COUNT].iter().all(|v| v.is_finite()));
            assert!(e.per_geometry[MA_T12_COUNT..].iter().all(|v| v.is_nan()));
            let u = detail
                .uncertainty
                .unwrap_or_else(|| panic!("fit {}: no bootstrap intervals", fit.id));
            assert!(u.resamples > 0 && u.kd.len() == 31);
            assert!(u.delta_e00_specular_mean.is_none());
            for (name, i) in [("ks", &u.ks), ("alpha", &u.alpha), ("ior", &u.ior)] {
                assert!(
                    i[0].is_finite() && i[1].is_finite() && i[0] <= i[1],
                    "fit {} {name}: {i:?}",
                    fit.id
                );
            }
        }
        let store = d.store.clone();
        service.shutdown().await;
        drop(store);

        // The SRA is back: the same store, both instruments. The reference in force has no SRA
        // readings, so a scan (which now has them) is refused with the fix.
        let devices = simulated(&lenient_fast());
        let store = brdfd::store::Store::open(&d.db).await.unwrap();
        let again = brdfd::service::Service::start(
            store.clone(),
            devices,
            settings(),
            ServiceOptions::default(),
        )
        .await
        .unwrap();
        match again.request_scan("T.Sky blue").await {
            Err(ServiceError::Store(StoreError::ReferenceWithoutSpecular { reference: r })) => {
                assert_eq!(r, reference)
            }
            other => panic!("expected a refusal naming the reference, got {other:?}"),
        }
        // A new reference with the SRA makes scanning possible again.
        let full = measure_reference(&again).await;
        assert!(
            store
                .reference_detail(full)
                .await
                .unwrap()
                .reference
                .specular_readings
        );
        let scan = again
            .request_scan("T.Sky blue")
            .await
            .expect("scan accepted");
        assert!(again.wait_settled(scan, STEP_TIMEOUT).await.unwrap());
        let detail = complete_scan(&store, scan).await;
        assert!(detail.scan.specular_readings);
        assert_eq!(detail.readings.len(), 14);
        again.shutdown().await;
    })
    .await;
}

/// The store refuses what an MA-T12-only measurement cannot hold: an SRA reading, and
/// completion before the 12 MA-T12 readings are in (the error counts 12, not 14).
#[tokio::test]
async fn the_store_keeps_an_ma_t12_only_scan_to_its_12_geometries() {
    let dir = tempfile::tempdir().unwrap();
    let store = brdfd::store::Store::open(&dir.path().join("s.db"))
        .await
        .unwrap();
    let reference = store
        .begin_reference_of("Munsell N9", None, false)
        .await
        .unwrap();
    let values = |g: &brdfd::geometry::Geometry| match g.device {
        Device::MaT12 => brdfd::store::ReadingValues::Spectrum([0.8; 31]),
        Device::Sra => brdfd::store::ReadingValues::Intensity(0.5),
    };
    let geometries = brdfd::geometry::GEOMETRIES;
    let sra = &geometries[MA_T12_COUNT];
    let e = store
        .add_reference_reading(reference, Device::Sra, sra, &values(sra), b"")
        .await
        .unwrap_err();
    assert!(matches!(e, StoreError::GeometryNotMeasured { .. }), "{e}");
    for g in &geometries[..MA_T12_COUNT - 1] {
        store
            .add_reference_reading(reference, g.device, g, &values(g), b"")
            .await
            .unwrap();
    }
    let e = store.complete_reference(reference).await.unwrap_err();
    assert!(
        e.to_string().contains("holds 11 of 12 readings")
            && e.to_string().contains(geometries[MA_T12_COUNT - 1].name),
        "{e}"
    );
    let last = &geometries[MA_T12_COUNT - 1];
    store
        .add_reference_reading(reference, last.device, last, &values(last), b"")
        .await
        .unwrap();
    store.complete_reference(reference).await.unwrap();
    let e = store.request_scan("a", reference).await.unwrap_err();
    assert!(
        matches!(e, StoreError::ReferenceWithoutSpecular { .. }),
        "{e}"
    );
    let scan = store.request_scan_of("a", reference, false).await.unwrap();
    store.start_measuring(scan).await.unwrap();
    let e = store
        .add_reading(scan, Device::Sra, sra, &values(sra), b"")
        .await
        .unwrap_err();
    assert!(matches!(e, StoreError::GeometryNotMeasured { .. }), "{e}");
    for g in &geometries[..MA_T12_COUNT] {
        store
            .add_reading(scan, g.device, g, &values(g), b"")
            .await
            .unwrap();
    }
    store.complete_scan(scan).await.unwrap();
    let s = store.scan_detail(scan).await.unwrap();
    assert!(!s.scan.specular_readings);
    assert_eq!(s.to_scan().unwrap().readings.sra, None);
}

/// `brdfd serve` with `[devices.sra] transport = "off"` says so loudly at start, `status`
/// shows the SRA off, and the CLI's `status`, `reference` and `show` speak of the MA-T12 and
/// 12 geometries only.
#[test]
fn serve_with_the_sra_off_says_so_and_status_shows_it() {
    let _serial = serial();
    let dir = tempfile::tempdir().unwrap();
    let config = dir.path().join("brdfd.toml");
    std::fs::write(
        &config,
        format!(
            "[store]\npath = \"{}\"\n\n[api]\nlisten = \"127.0.0.1:0\"\n\n[log]\nlevel = \"warn\"\n\n\
             [devices.ma_t12]\ntransport = \"simulated\"\n\n[devices.sra]\ntransport = \"off\"\n",
            dir.path().join("brdfd.db").display()
        ),
    )
    .unwrap();
    // As `spawn_serve` starts it, with stderr kept in a file to read the banner.
    let log = dir.path().join("stderr.txt");
    let mut child = std::process::Command::new(env!("CARGO_BIN_EXE_brdfd"))
        .args(["serve", "--config"])
        .arg(&config)
        .env_remove("BRDFD_TOKEN")
        .env_remove("BRDFD_CONFIG")
        .stdout(std::process::Stdio::piped())
        .stderr(std::fs::File::create(&log).unwrap())
        .spawn()
        .expect("brdfd serve starts");
    let mut line = String::new();
    std::io::BufRead::read_line(
        &mut std::io::BufReader::new(child.stdout.take().unwrap()),
        &mut line,
    )
    .unwrap();
    let addr: std::net::SocketAddr = line
        .split("http://")
        .nth(1)
        .and_then(|rest| rest.split_whitespace().next())
        .and_then(|a| a.parse().ok())
        .unwrap_or_else(|| panic!("no address in {line:?}"));
    let client = client_of_serve(addr, dir.path());
    let status = client.get("/status").expect("status");
    let sra = status["devices"]
        .as_array()
        .unwrap()
        .iter()
        .find(|d| d["device"] == "sra")
        .expect("the SRA is listed")
        .clone();
    assert_eq!(sra["state"], "off", "{sra}");
    // The banners follow the listening line; the API may answer before they are written.
    wait_until("the SRA-off banner on stderr", || {
        std::fs::read_to_string(&log).is_ok_and(|e| e.contains("SRA TURNED OFF"))
    });
    // The CLI speaks of 12 geometries and an SRA that is off, never of "both instruments", an
    // "SRA false" or an SRA reading model that played no part in the fits.
    let addr_s = addr.to_string();
    let token = dir.path().join("brdfd.token");
    let token_s = token.to_str().unwrap();
    let cli = |args: &[&str]| {
        let mut all = args.to_vec();
        all.extend(["--addr", &addr_s, "--token-file", token_s]);
        let out = run_brdfd(&all, None);
        let text = String::from_utf8_lossy(&out.stdout).into_owned();
        assert!(
            out.status.success(),
            "brdfd {args:?}: {text}{}",
            String::from_utf8_lossy(&out.stderr)
        );
        text
    };
    let status = cli(&["status"]);
    assert!(status.contains("SRA off"), "{status}");
    assert!(!status.contains("SRA false"), "{status}");
    let reference = cli(&["reference"]);
    assert!(reference.contains("on the MA-T12 (SRA off"), "{reference}");
    assert!(!reference.contains("both instruments"), "{reference}");
    let scan = cli(&["scan", "--sample", "T.Sky blue"]);
    let id = scan
        .split_whitespace()
        .nth(1)
        .unwrap_or_else(|| panic!("no scan id in {scan}"))
        .to_string();
    let show = cli(&["show", &id]);
    assert!(show.contains("12 of 12 readings"), "{show}");
    assert!(
        show.contains("ΔE00 under D65"),
        "the fits are listed: {show}"
    );
    assert!(!show.contains("SRA reading model"), "{show}");
    let _ = child.kill();
    let _ = child.wait();
}
