//! Each driver task (`drivers::spawn_mat12`, `drivers::spawn_sra`) against its simulated
//! instrument through the real transport path — the `UsbBulk` trait for the MA-T12, a real
//! pseudo-terminal pair for the SRA — replaying the committed recordings, with every reading
//! compared bit for bit with the recording. Also: recorded and scaled timing, strict and
//! lenient matching, the tty's raw mode, and the wall time of replaying everything.

mod common;

use std::io::{Read, Write};
use std::time::{Duration, Instant};

use common::{Rig, TEST_TIMEOUT, assert_bit_eq, fast_config, pty_lock, scan, within};
use drivers::protocol::{ErrorCode, Reading, RequestKind};
use drivers::session::Fault;
use drivers::{DriverConfig, DriverError, Instrument};
use mock_devices::pty::termios_is_raw;
use mock_devices::{Mode, ReplayOptions, Script, SimMat12, SimSra, recordings};

const BOTH: [Instrument; 2] = [Instrument::MaT12, Instrument::Sra];

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn every_recording_replays_bit_for_bit_through_both_drivers() {
    for recording in recordings::all() {
        for instrument in BOTH {
            let script = recording.script(instrument).unwrap();
            let want = script.readings();
            let (got, report, _) = scan(
                script,
                ReplayOptions::strict().accelerated(),
                DriverConfig::default(),
            )
            .await;
            let what = format!("{} on the {instrument}", recording.name);
            let got = got.unwrap_or_else(|e| panic!("{what}: {e}"));
            assert_bit_eq(&got, &want, &what);
            assert!(report.mismatches.is_empty(), "{what}: {report:?}");
            assert_eq!(
                report.remaining, 0,
                "{what}: the whole recording was replayed"
            );
            assert_eq!(report.connections, 1, "{what}");
        }
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn recorded_timing_is_kept_and_a_speed_factor_scales_it() {
    // SRA at recorded timing: the session lasts 1.7 s (a 1.5 s measurement and 9600-baud lines).
    let recording = recordings::reference();
    let script = recording.script(Instrument::Sra).unwrap();
    // The device's share of the recorded time from MEASURE-ALL on: each reply's delay after its
    // request. (brdfd's own gaps and request wire times are the driver's, not replayed.)
    // The session's closing ABORT exchange (`$AB*…`, drivers/PROTOCOL.md) is not part of the
    // measurement.
    let recorded_ms: u64 = script.exchanges()[1..]
        .iter()
        .filter(|e| {
            !e.request
                .as_ref()
                .is_some_and(|r| r.bytes.starts_with(b"$AB*"))
        })
        .map(|e| e.replies[0].t_ms - e.request.as_ref().unwrap().t_ms)
        .sum();
    let want = script.readings();
    let rig = Rig::new(script, ReplayOptions::strict(), DriverConfig::default());
    // Introduced with IDENTIFY already (or about to be); time MEASURE-ALL and the FETCHes.
    within(rig.handle.identify()).await.unwrap();
    let start = Instant::now();
    let got = within(rig.handle.measure_all()).await.unwrap();
    let took = start.elapsed();
    assert_bit_eq(&got, &want, "N9 on the SRA at recorded timing");
    println!(
        "SRA N9 at recorded timing: {took:?} (device delays in the recording: {recorded_ms} ms)"
    );
    assert!(
        recorded_ms > 1500,
        "the recording holds a 1.5 s measurement"
    );
    // Recorded delays are whole milliseconds; the replay waits each of them.
    assert!(
        took >= Duration::from_millis(recorded_ms),
        "{took:?} < {recorded_ms} ms"
    );
    // No upper bound: how much longer it takes depends on the machine's load. The delays the
    // engine computes are checked exactly, without a clock, in `engine.rs`'s unit tests.
    rig.finish().await;

    // MA-T12 eight times faster: the 2.4 s measurement takes 0.3 s.
    let script = recording.script(Instrument::MaT12).unwrap();
    let want = script.readings();
    let rig = Rig::new(
        script,
        ReplayOptions::strict().speed(8.0),
        DriverConfig::default(),
    );
    let start = Instant::now();
    let got = within(rig.handle.measure_all()).await.unwrap();
    let took = start.elapsed();
    println!("MA-T12 N9 at 8x: {took:?}");
    assert_bit_eq(&got, &want, "N9 on the MA-T12 at 8x");
    // A lower bound only (the scaled delays are waited); the scaling itself is checked
    // without a clock in `engine.rs`'s unit tests.
    assert!(took >= Duration::from_millis(2400 / 8), "{took:?}");
    rig.finish().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn strict_mode_refuses_a_request_out_of_order_and_reports_it() {
    for instrument in BOTH {
        let script = recordings::reference().script(instrument).unwrap();
        let last = *instrument.geometries().last().unwrap();
        let rig = Rig::new(script, ReplayOptions::strict().accelerated(), fast_config());
        let err = within(rig.handle.measure_one(last)).await.unwrap_err();
        assert_eq!(
            err,
            DriverError::Refused {
                instrument,
                request: RequestKind::MeasureOne,
                geometry: Some(last),
                code: ErrorCode::UnknownRequest
            }
        );
        let msg = err.to_string();
        assert!(
            msg.contains(last) && msg.contains("UNKNOWN-REQUEST"),
            "{msg}"
        );
        let report = rig.finish().await;
        assert_eq!(report.mismatches.len(), 1, "{report:?}");
        let m = report.mismatches[0].to_string();
        assert!(m.starts_with("expected frame 2, MEASURE-ALL"), "{m}");
        assert!(m.contains(&format!("received MEASURE-ONE {last}")), "{m}");
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn lenient_mode_answers_repeated_scans_and_refuses_what_was_never_recorded() {
    for instrument in BOTH {
        let recording = recordings::by_name("T.Prairie green").unwrap();
        let script = recording.script(instrument).unwrap();
        let want = script.readings();
        let options = ReplayOptions {
            mode: Mode::Lenient,
            ..ReplayOptions::default().accelerated()
        };
        let rig = Rig::new(script, options, fast_config());
        for round in 0..3 {
            let got = within(rig.handle.measure_all())
                .await
                .unwrap_or_else(|e| panic!("{instrument} round {round}: {e}"));
            assert_bit_eq(&got, &want, &format!("{instrument} round {round}"));
        }
        let err = within(rig.handle.status()).await.unwrap_err();
        assert!(
            matches!(
                err,
                DriverError::Refused {
                    code: ErrorCode::UnknownRequest,
                    ..
                }
            ),
            "{err}"
        );
        let report = rig.finish().await;
        assert_eq!(report.mismatches.len(), 1, "{report:?}");
        assert!(report.mismatches[0].received.starts_with("STATUS"));
    }
}

#[test]
fn the_pty_is_raw_and_carries_every_byte_value_unchanged() {
    let _pty = pty_lock();
    // All 256 byte values from the instrument (a garbage fault before IDENTITY), and from the
    // host (in descending order, so that no request forms and the device drops them all).
    let all: Vec<u8> = (0..=255).collect();
    let script = recordings::reference()
        .script(Instrument::Sra)
        .unwrap()
        .with_fault(Fault::Garbage {
            frame: 1,
            bytes: all.clone(),
        })
        .unwrap();
    let sim = SimSra::new(script, ReplayOptions::strict().accelerated()).unwrap();
    let mut port = sim.connect().unwrap();
    assert!(termios_is_raw(&port).unwrap(), "the driver's end is raw");

    let down: Vec<u8> = (0..=255).rev().collect();
    port.write_all(&down).unwrap();
    port.write_all(b"$ID*298E\r\n").unwrap();
    let identity = &sim.script().exchanges()[0].replies[0].bytes.clone();
    let mut want = all.clone();
    want.extend_from_slice(identity);
    let mut got = Vec::new();
    let deadline = Instant::now() + Duration::from_secs(5);
    let mut buf = [0u8; 512];
    serialport::SerialPort::set_timeout(&mut port, Duration::from_millis(50)).unwrap();
    while got.len() < want.len() && Instant::now() < deadline {
        if let Ok(n) = port.read(&mut buf) {
            got.extend_from_slice(&buf[..n]);
        }
    }
    assert_eq!(got, want, "device to host");
    let report = sim.report();
    let dropped: String = report
        .dropped
        .iter()
        .map(|d| d.split(' ').next().unwrap())
        .collect();
    assert_eq!(dropped, drivers::session::to_hex(&down), "host to device");
    assert_eq!(report.requests, 1);
}

// The std lock only serialises pty tests, each on its own runtime; blocking while another
// test holds it is the point.
#[allow(clippy::await_holding_lock)]
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_sra_port_opened_by_name_like_a_real_one_replays_too() {
    let _pty = pty_lock();
    let script = recordings::by_name("T.Sky blue")
        .unwrap()
        .script(Instrument::Sra)
        .unwrap();
    let want = script.readings();
    let sim = SimSra::new(script, ReplayOptions::strict().accelerated()).unwrap();
    let factory_sim = sim.clone();
    let handle = drivers::spawn_sra(move || factory_sim.connect_by_name(), fast_config());
    let got = within(handle.measure_all()).await.unwrap();
    assert_bit_eq(&got, &want, "T.Sky blue via open_serial");
    handle.shutdown().await;
    assert!(sim.report().mismatches.is_empty());
}

/// The N9 reference and the eight samples, each instrument's nine sessions back to back on one
/// connection, both drivers at once, accelerated: the demo's workload. Prints the wall time;
/// `cargo bench -p brdfd-mock-devices --bench replay` measures it in a release build.
// The std lock only serialises pty tests, each on its own runtime; blocking while another
// test holds it is the point.
#[allow(clippy::await_holding_lock)]
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn replaying_all_recordings_through_both_drivers_is_fast() {
    let _pty = pty_lock();
    let mat12 = recordings::playlist(Instrument::MaT12).unwrap();
    let sra = recordings::playlist(Instrument::Sra).unwrap();
    let want: [Vec<Vec<Reading>>; 2] = [&mat12, &sra].map(|s| {
        (0..s.session_count())
            .map(|n| s.session_readings(n))
            .collect()
    });
    let options = ReplayOptions::strict().accelerated();
    let mat12 = SimMat12::new(mat12, options.clone()).unwrap();
    let sra = SimSra::new(sra, options).unwrap();

    let start = Instant::now();
    let a = drivers::spawn_mat12(mat12.factory(), DriverConfig::default());
    let b = drivers::spawn_sra(sra.factory(), DriverConfig::default());
    let run = |h: drivers::DriverHandle| async move {
        let mut scans = Vec::new();
        for _ in 0..recordings::all().len() {
            scans.push(h.measure_all().await.expect("scan"));
        }
        h.shutdown().await;
        scans
    };
    let (got_a, got_b) = tokio::time::timeout(TEST_TIMEOUT, async { tokio::join!(run(a), run(b)) })
        .await
        .expect("replay hung");
    let took = start.elapsed();
    println!(
        "replayed N9 + 8 samples through both drivers (accelerated, strict, debug build): \
         {:.1} ms wall",
        took.as_secs_f64() * 1e3
    );
    for (got, want, what) in [(got_a, &want[0], "MA-T12"), (got_b, &want[1], "SRA")] {
        assert_eq!(got.len(), 9);
        for (k, (g, w)) in got.iter().zip(want).enumerate() {
            assert_bit_eq(g, w, &format!("{what} session {k}"));
        }
    }
    assert!(mat12.report().mismatches.is_empty());
    assert!(sra.report().mismatches.is_empty());
    assert_eq!((mat12.report().remaining, sra.report().remaining), (0, 0));
    // No wall-clock bound here (it would depend on the machine's load); the speed is measured
    // by `cargo bench -p brdfd-mock-devices --bench replay`.
}

#[test]
fn a_script_for_the_other_instrument_is_refused_with_advice() {
    let sra = recordings::reference().script(Instrument::Sra).unwrap();
    let err = SimMat12::new(sra, ReplayOptions::strict()).unwrap_err();
    assert!(
        err.to_string()
            .contains("use the other simulated instrument"),
        "{err}"
    );
    let mixed = Script::from_sessions([
        recordings::reference().session(Instrument::MaT12).unwrap(),
        recordings::reference().session(Instrument::Sra).unwrap(),
    ]);
    assert!(mixed.is_err());
}
