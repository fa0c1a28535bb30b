//! Every fault of PROTOCOL.md §5, injected by the simulated instruments, ends in its documented
//! outcome when the real driver task meets it through the real transport path (the USB bulk
//! trait, the pty for the SRA): a resend or reconnection that succeeds with the recorded
//! readings bit for bit, or a clean error naming the instrument and the geometry. Every scan
//! runs under a timeout (no hang) and a panic anywhere would fail the test.
//!
//! Frame numbers in the committed recordings: 0 IDENTIFY, 1 IDENTITY, 2 MEASURE-ALL,
//! 3 MEASURED, then FETCH of geometry k at 4 + 2k and its READING at 5 + 2k.

mod common;

use common::{assert_bit_eq, fast_config, scan};
use drivers::protocol::RequestKind;
use drivers::session::{Fault, Session};
use drivers::{DriverError, Event, Instrument};
use mock_devices::{ReplayOptions, Script, recordings};

const BOTH: [Instrument; 2] = [Instrument::MaT12, Instrument::Sra];

/// Geometry index used for the faults: the first, so that on both instruments another FETCH
/// follows it (a dropped link is only noticed by the next request).
const K: usize = 0;
const FETCH_K: usize = 4 + 2 * K;
const READING_K: usize = 5 + 2 * K;

fn script(instrument: Instrument, faults: &[Fault]) -> Script {
    let mut s = recordings::by_name("T.Freesia pink")
        .unwrap()
        .script(instrument)
        .unwrap();
    for f in faults {
        s.add_fault(f.clone()).unwrap();
    }
    s
}

/// Scan with `faults` on each instrument; the scan must succeed with the recorded readings.
/// Returns the reports and events for further checks.
async fn must_recover(faults: &[Fault]) -> Vec<(mock_devices::ReplayReport, Vec<Event>)> {
    let mut out = Vec::new();
    for instrument in BOTH {
        let s = script(instrument, faults);
        let want = s.readings();
        let (got, report, events) =
            scan(s, ReplayOptions::strict().accelerated(), fast_config()).await;
        let what = format!("{instrument} with {faults:?}");
        let got = got.unwrap_or_else(|e| panic!("{what}: expected recovery, got: {e}"));
        assert_bit_eq(&got, &want, &what);
        assert!(report.mismatches.is_empty(), "{what}: {report:?}");
        assert!(!report.faults_fired.is_empty(), "{what}: the fault fired");
        out.push((report, events));
    }
    out
}

/// Scan with `faults` (and options) on each instrument; the scan must fail with an error that
/// names the instrument and the geometry in progress.
async fn must_fail_naming_geometry(faults: &[Fault], options: ReplayOptions) -> Vec<DriverError> {
    let mut out = Vec::new();
    for instrument in BOTH {
        let geometry = instrument.geometries()[K];
        let (got, report, _) =
            scan(script(instrument, faults), options.clone(), fast_config()).await;
        let what = format!("{instrument} with {faults:?} {options:?}");
        let err = got.expect_err(&what);
        let msg = err.to_string();
        assert!(msg.starts_with(&instrument.to_string()), "{what}: {msg}");
        assert!(
            msg.contains(&format!("FETCH at geometry {geometry}")),
            "{what}: {msg}"
        );
        assert!(!report.faults_fired.is_empty(), "{what}: the fault fired");
        out.push(err);
    }
    out
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_corrupted_reading_is_refetched() {
    let corrupt = |times| Fault::Corrupt {
        frame: READING_K,
        offset: 9,
        xor: 0x40,
        times,
    };
    for (report, _) in must_recover(&[corrupt(3)]).await {
        assert_eq!(report.faults_fired.len(), 3, "{report:?}");
        // IDENTIFY, MEASURE-ALL, 12 or 2 FETCHes, and 3 resends of FETCH k.
        assert_eq!(report.served, report.requests);
        assert_eq!(report.requests as usize, 2 + report_geometries(&report) + 3);
    }
    let errors =
        must_fail_naming_geometry(&[corrupt(4)], ReplayOptions::strict().accelerated()).await;
    for e in errors {
        assert!(
            matches!(
                e,
                DriverError::NoValidReply {
                    request: RequestKind::Fetch,
                    sends: 4,
                    ..
                }
            ),
            "{e}"
        );
        assert!(e.to_string().contains("checksum"), "{e}");
    }
}

/// Number of FETCHes in a full scan, from the requests of a clean report (helper for counts).
fn report_geometries(report: &mock_devices::ReplayReport) -> usize {
    // 2 on the SRA, 12 on the MA-T12: tell them apart by the size of the scan.
    if report.requests > 10 { 12 } else { 2 }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_missing_reply_times_out_and_is_requested_again() {
    let no_reply = |times| Fault::NoReply {
        frame: READING_K,
        times,
    };
    for (report, _) in must_recover(&[no_reply(2)]).await {
        assert_eq!(
            report.faults_fired,
            vec![
                format!("no-reply frame {READING_K} (time 1)"),
                format!("no-reply frame {READING_K} (time 2)")
            ]
        );
    }
    for e in must_fail_naming_geometry(&[no_reply(4)], ReplayOptions::strict().accelerated()).await
    {
        let msg = e.to_string();
        assert!(msg.contains("no reply within 500 ms"), "{msg}");
        assert!(msg.contains("after 4 sends"), "{msg}");
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn garbage_before_a_reply_is_dropped_without_a_resend() {
    // Binary noise with no frame start of either codec (a trailing lone `M` included) and no
    // line end: the decoder skips it and uses the reading that follows.
    let garbage = Fault::Garbage {
        frame: READING_K,
        bytes: vec![0x00, 0xff, 0x13, 0x11, 0x03, 0x7f, 0x0d, 0x4d],
    };
    for (report, _) in must_recover(&[garbage]).await {
        assert_eq!(report.faults_fired.len(), 1);
        // No resend: each request was sent once.
        assert_eq!(report.requests as usize, 2 + report_geometries(&report));
    }
    // Garbage that looks like the start of a broken frame (an MA-T12 header with an impossible
    // length; an SRA reply line too short to hold its checksum) is garbage too (PROTOCOL.md §4):
    // no resend, and the scan ends with the recorded readings.
    let broken = Fault::Garbage {
        frame: READING_K,
        bytes: vec![
            0x4d, 0x54, 0xff, 0xff, 0xff, 0x21, 0x24, 0x00, 0x0d, 0x0a, 0x4d,
        ],
    };
    for (report, _) in must_recover(&[broken]).await {
        assert_eq!(report.faults_fired.len(), 1);
        assert_eq!(report.requests as usize, 2 + report_geometries(&report));
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn slow_replies_succeed_under_the_timeout_and_fail_cleanly_beyond_it() {
    // Every device frame 100 ms late, under the 500 ms reply timeout.
    let under = Fault::Slow {
        delay_ms: 100,
        frame: None,
    };
    for (report, _) in must_recover(&[under]).await {
        assert_eq!(report.requests as usize, 2 + report_geometries(&report));
    }
    // One reading 2.2 s late: beyond the four 500 ms waits of its four sends.
    let beyond = Fault::Slow {
        delay_ms: 2200,
        frame: Some(READING_K),
    };
    for e in must_fail_naming_geometry(&[beyond], ReplayOptions::strict().accelerated()).await {
        assert!(
            matches!(e, DriverError::NoValidReply { sends: 4, .. }),
            "{e}"
        );
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_dropped_link_is_reconnected_and_the_scan_continues() {
    // Dropped just after the reading of geometry k was sent, and just after the FETCH of
    // geometry k arrived (the request is lost with the link).
    for after in [READING_K, FETCH_K] {
        for (report, events) in must_recover(&[Fault::Disconnect { after }]).await {
            assert_eq!(report.connections, 2, "{report:?}");
            let disconnected = events
                .iter()
                .position(|e| matches!(e, Event::Disconnected { .. }))
                .expect("a Disconnected event");
            let reconnecting = events
                .iter()
                .position(|e| matches!(e, Event::Reconnecting { attempt: 1, .. }))
                .expect("a Reconnecting event");
            let connected = events
                .iter()
                .rposition(|e| matches!(e, Event::Connected { .. }))
                .expect("a Connected event");
            assert!(
                disconnected < reconnecting && reconnecting < connected,
                "{events:?}"
            );
        }
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn an_unplugged_instrument_fails_the_scan_naming_the_geometry() {
    let options = ReplayOptions {
        unplug_after: Some(FETCH_K),
        ..ReplayOptions::strict().accelerated()
    };
    let errors = must_fail_naming_geometry(&[], options).await;
    for e in &errors {
        let DriverError::Disconnected { attempts, last, .. } = e else {
            panic!("expected a disconnect error, got {e}");
        };
        assert_eq!(*attempts, 3, "{e}");
        assert!(
            last.contains("not found on USB") || last.contains("cannot open serial port"),
            "{e}"
        );
        assert!(e.to_string().contains("check the cable and power"), "{e}");
    }
}

/// The same faults, given as `fault` directives in the session file instead of in code.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn faults_in_the_session_file_are_applied() {
    for instrument in BOTH {
        let text = recordings::by_name("T.Freesia pink")
            .unwrap()
            .text(instrument);
        // Fault lines go in the header, before the first frame line.
        let first_frame = text
            .lines()
            .position(|l| l.starts_with(|c: char| c.is_ascii_digit()))
            .unwrap();
        let split = text.lines().take(first_frame).map(|l| l.len() + 1).sum();
        let (header, frames) = text.split_at(split);
        // Frames that exist in each recording: the SRA's has 8 (2 geometries).
        let (no_reply, disconnect) = match instrument {
            Instrument::MaT12 => (9, 11),
            Instrument::Sra => (5, 6),
        };
        let with_faults = format!(
            "{header}fault corrupt frame={READING_K} offset=7 times=2\n\
             fault garbage frame=3 bytes=00ff4d54\n\
             fault no-reply frame={no_reply}\n\
             fault disconnect after={disconnect}\n\
             fault slow delay_ms=20 frame=5\n{frames}"
        );
        let session = Session::parse(&with_faults).unwrap();
        assert_eq!(session.faults.len(), 5);
        let s = Script::new(session).unwrap();
        let want = s.readings();
        let (got, report, _) = scan(s, ReplayOptions::strict().accelerated(), fast_config()).await;
        let got = got.unwrap_or_else(|e| panic!("{instrument}: {e}"));
        assert_bit_eq(&got, &want, &format!("{instrument} with file faults"));
        let fired = report.faults_fired.join("; ");
        for want in [
            format!("corrupt frame {READING_K} byte 7 (1 of 2)"),
            format!("corrupt frame {READING_K} byte 7 (2 of 2)"),
            "garbage before frame 3".to_string(),
            format!("no-reply frame {no_reply} (time 1)"),
            format!("disconnect after frame {disconnect}"),
        ] {
            assert!(fired.contains(&want), "{instrument}: {want} not in {fired}");
        }
        assert_eq!(report.connections, 2, "{instrument}");
    }
}
