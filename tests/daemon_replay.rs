//! The `brdfd` binary's in-process daemon commands: `demo` (the README's main command, run
//! twice on the same directory), `replay` of the embedded recordings and of session files,
//! and `record` → `replay` round trips (a recording replays strictly).

mod common;

use std::path::Path;
use std::process::Output;

use brdfd::store::{FitStatus, ScanFilter, ScanState, Store};

use common::*;

fn brdfd(args: &[&str], cwd: &Path) -> Output {
    run_brdfd(args, Some(cwd))
}

fn text(o: &Output) -> (String, String) {
    (
        String::from_utf8_lossy(&o.stdout).into_owned(),
        String::from_utf8_lossy(&o.stderr).into_owned(),
    )
}

#[test]
fn demo_replays_the_recordings_into_a_local_store_and_runs_twice() {
    let _serial = serial();
    let dir = tempfile::tempdir().unwrap();
    let first = brdfd(&["demo"], dir.path());
    let (out, err) = text(&first);
    assert!(first.status.success(), "{err}");
    // One row per sample and cost function, with diffuse and specular ΔE00.
    let rows: Vec<&str> = out
        .lines()
        .filter(|l| {
            l.starts_with("T.")
                && (l.contains(" cf1 ") || l.contains(" cf2 ") || l.contains(" m2 "))
        })
        .collect();
    assert_eq!(rows.len(), 24, "{out}");
    assert!(out.contains("diffuse") && out.contains("specular"));
    // Which configuration it ran under, and what its specular ΔE00 means.
    assert!(
        out.contains("preset: paper (the paper's configuration: Schlick's Fresnel on cos θi"),
        "{out}"
    );
    assert!(
        out.contains("specular: ΔE00 at sra-20 and sra-60 against the grey spectrum"),
        "{out}"
    );
    assert!(out.contains("database: brdfd-demo/brdfd.db (new"), "{out}");
    assert!(out.contains("outputs: brdfd-demo/report.txt"), "{out}");
    assert!(out.contains("timing:") && out.contains("store") && out.contains("fitting"));
    let report = std::fs::read_to_string(dir.path().join("brdfd-demo/report.txt")).unwrap();
    assert_eq!(report, out, "the report file is what was printed");
    let scans = std::fs::read_dir(dir.path().join("brdfd-demo/scans"))
        .unwrap()
        .count();
    assert_eq!(scans, 8);

    // Twice: the database is reused and the second run's scans are added.
    let second = brdfd(&["demo"], dir.path());
    let (out2, err2) = text(&second);
    assert!(second.status.success(), "{err2}");
    assert!(
        out2.contains("(reused: this run's scans were added"),
        "{out2}"
    );
    // Same recordings, same seed: the same ΔE00 table (scan ids differ).
    let table = |o: &str| -> Vec<String> {
        o.lines()
            .filter(|l| l.starts_with("T."))
            .map(|l| {
                let mut cols: Vec<&str> = l.split_whitespace().collect();
                cols.retain(|c| c.parse::<i64>().is_err()); // drop the scan id
                cols.truncate(cols.len() - 1); // and the wall time
                cols.join(" ")
            })
            .collect()
    };
    assert_eq!(table(&out), table(&out2));

    // --json: the fits as one object (in another directory; report.txt is still written).
    let other = tempfile::tempdir().unwrap();
    let third = brdfd(&["demo", "--json"], other.path());
    let (out3, err3) = text(&third);
    assert!(third.status.success(), "{err3}");
    let v: serde_json::Value = serde_json::from_str(&out3).unwrap();
    assert_eq!(v["fits"].as_array().unwrap().len(), 24, "{v}");
    assert_eq!(v["database_reused"], false, "{v}");
    assert!(other.path().join("brdfd-demo/report.txt").exists());
    let fit = &v["fits"][0];
    assert!(fit["sample"].as_str().unwrap().starts_with("T."), "{fit}");
    assert!(
        fit["evaluation"]["all"]["mean"].as_f64().unwrap() > 0.0,
        "{fit}"
    );

    block_on(async {
        let store = Store::open(dir.path().join("brdfd-demo/brdfd.db"))
            .await
            .unwrap();
        assert_eq!(store.integrity_check().await.unwrap(), ["ok"]);
        let all = store
            .list_scans(&ScanFilter {
                limit: 100,
                ..ScanFilter::default()
            })
            .await
            .unwrap();
        assert_eq!(all.len(), 16);
        assert!(
            all.iter()
                .all(|s| s.state == ScanState::Complete && s.reading_count == 14)
        );
        for s in &all {
            let fits = store.fits_for_scan(s.id).await.unwrap();
            assert_eq!(fits.len(), 3);
            assert!(fits.iter().all(|f| f.status == FitStatus::Done));
        }
        store.close().await;
    });
}

/// `brdfd demo --bootstrap N` waits for every fit's bootstrap, so the report on its database
/// has an interval for each fit and Fig. 8 its error bars; the plain demo says how to get them.
#[test]
fn demo_with_a_bootstrap_gives_every_fit_its_intervals_for_the_report() {
    let _serial = serial();
    let dir = tempfile::tempdir().unwrap();
    let plain = brdfd(&["demo", "--dir", "plain"], dir.path());
    let (out, err) = text(&plain);
    assert!(plain.status.success(), "{err}");
    assert!(
        out.contains("intervals: none (no bootstrap); `brdfd demo --bootstrap 200`"),
        "{out}"
    );

    let run = brdfd(&["demo", "--bootstrap", "3", "--dir", "boot"], dir.path());
    let (out, err) = text(&run);
    assert!(run.status.success(), "{err}");
    assert!(
        out.contains("intervals: every fit bootstrapped with 3 resamples"),
        "{out}"
    );
    block_on(async {
        let store = Store::open(dir.path().join("boot/brdfd.db")).await.unwrap();
        let all = store.list_scans(&ScanFilter::default()).await.unwrap();
        assert_eq!(all.len(), 8);
        for s in &all {
            for f in store.fits_for_scan(s.id).await.unwrap() {
                let d = store.fit_detail(f.id).await.unwrap();
                let u = d
                    .uncertainty
                    .unwrap_or_else(|| panic!("scan {} fit {}: no intervals", s.id, f.id));
                assert_eq!(u.resamples, 3);
            }
        }
        store.close().await;
    });
    let report = brdfd(
        &[
            "report",
            "--all",
            "--db",
            "boot/brdfd.db",
            "--out",
            "report",
            "--max-sample-figures",
            "1",
        ],
        dir.path(),
    );
    assert!(report.status.success(), "{}", text(&report).1);
    let md = std::fs::read_to_string(dir.path().join("report/summary.md")).unwrap();
    assert!(!md.contains("no bootstrap intervals"), "{md}");
    assert!(!md.contains("(no interval)"), "{md}");
    assert!(!md.contains("no error bars"), "{md}");
}

#[test]
fn record_then_replay_strictly_through_the_whole_daemon() {
    let _serial = serial();
    let dir = tempfile::tempdir().unwrap();
    let out_dir = dir.path().join("sessions");
    let o = out_dir.display().to_string();
    // On the default (simulated) instruments: the reference, then a sample.
    let r = brdfd(&["record", "--out", &o], dir.path());
    assert!(r.status.success(), "{}", text(&r).1);
    let s = brdfd(
        &["record", "--sample", "T.Recorded", "--out", &o],
        dir.path(),
    );
    assert!(s.status.success(), "{}", text(&s).1);
    assert!(
        text(&s)
            .0
            .contains("recorded 12 MA-T12 and 2 SRA readings of T.Recorded")
    );
    // --json: the same as an object naming the session files (into another directory).
    let j = brdfd(
        &[
            "record",
            "--sample",
            "T.Json",
            "--out",
            &dir.path().join("json-sessions").display().to_string(),
            "--json",
        ],
        dir.path(),
    );
    assert!(j.status.success(), "{}", text(&j).1);
    let v: serde_json::Value = serde_json::from_str(&text(&j).0).unwrap();
    assert_eq!(v["ma_t12_readings"], 12, "{v}");
    assert_eq!(v["sra_readings"], 2, "{v}");
    for f in v["sessions"].as_array().unwrap() {
        assert!(std::path::Path::new(f.as_str().unwrap()).exists(), "{f}");
    }
    let files = [
        out_dir.join("reference.ma_t12.session"),
        out_dir.join("reference.sra.session"),
        out_dir.join("t-recorded.ma_t12.session"),
        out_dir.join("t-recorded.sra.session"),
    ];
    for f in &files {
        let session = drivers::session::Session::parse(&std::fs::read_to_string(f).unwrap())
            .unwrap_or_else(|e| panic!("{}: {e}", f.display()));
        // IDENTIFY, MEASURE-ALL and a FETCH per geometry, both ways.
        let n = session.instrument.geometries().len();
        assert_eq!(session.frames.len(), 2 * (2 + n), "{}", f.display());
    }
    let db = dir.path().join("replayed.db");
    let args: Vec<String> = files
        .iter()
        .map(|f| f.display().to_string())
        .chain(["--db".to_string(), db.display().to_string()])
        .collect();
    let args: Vec<&str> = std::iter::once("replay")
        .chain(args.iter().map(String::as_str))
        .collect();
    let replay = brdfd(&args, dir.path());
    let (out, err) = text(&replay);
    assert!(replay.status.success(), "{out}\n{err}");
    assert!(out.contains("scan 1 \"T.Recorded\": complete"), "{out}");
    assert_eq!(out.matches(": mean ΔE00").count(), 3, "{out}");
    assert!(out.contains("(strict, accelerated)"), "{out}");
    // --json: the same outcome as one object (into a fresh in-memory store).
    let json_args: Vec<String> = files
        .iter()
        .map(|f| f.display().to_string())
        .chain(["--json".to_string()])
        .collect();
    let json_args: Vec<&str> = std::iter::once("replay")
        .chain(json_args.iter().map(String::as_str))
        .collect();
    let replay = brdfd(&json_args, dir.path());
    let (out, err) = text(&replay);
    assert!(replay.status.success(), "{out}\n{err}");
    let v: serde_json::Value = serde_json::from_str(&out).unwrap();
    assert_eq!(v["scans"][0]["sample"], "T.Recorded", "{v}");
    assert_eq!(v["scans"][0]["state"], "complete", "{v}");
    assert_eq!(v["scans"][0]["fits"].as_array().unwrap().len(), 3, "{v}");
    assert!(
        v["scans"][0]["fits"][0]["delta_e00_mean"].as_f64().unwrap() >= 0.0,
        "{v}"
    );
    assert_eq!(v["mode"], "strict", "{v}");

    // Sessions given out of pairs are refused with what to do.
    let bad = brdfd(&["replay", &files[0].display().to_string()], dir.path());
    assert_eq!(bad.status.code(), Some(1));
    assert!(
        text(&bad)
            .1
            .contains("1 MA-T12 session(s) but 0 SRA session(s)")
    );
}

#[test]
fn replay_of_the_embedded_recordings_is_strict_and_clean() {
    let _serial = serial();
    let dir = tempfile::tempdir().unwrap();
    let o = brdfd(&["replay", "builtin"], dir.path());
    let (out, err) = text(&o);
    assert!(o.status.success(), "{out}\n{err}");
    assert_eq!(
        out.lines().filter(|l| l.ends_with(": complete")).count(),
        8,
        "{out}"
    );
    assert!(
        out.contains("1 reference(s), 8 scan(s) replayed (strict, accelerated)"),
        "{out}"
    );
    assert!(out.contains("store: in memory"), "{out}");
}

/// The committed N9 and T.Freesia pink sessions copied into `dir`, the sample's SRA session
/// with its two FETCH exchanges swapped (timestamps kept): the driver asks for sra-20 first,
/// the recording has sra-60 first. Returns the four paths in replay order.
fn sessions_with_swapped_fetches(dir: &Path) -> Vec<String> {
    let rec = Path::new(env!("CARGO_MANIFEST_DIR")).join("mock-devices/recordings");
    let mut out = Vec::new();
    for (name, swap) in [
        ("synthetic-n9.ma_t12.session", false),
        ("synthetic-n9.sra.session", false),
        ("synthetic-t-freesia-pink.ma_t12.session", false),
        ("synthetic-t-freesia-pink.sra.session", true),
    ] {
        let text = std::fs::read_to_string(rec.join(name)).unwrap();
        let text = if swap {
            let mut lines: Vec<String> = text.lines().map(str::to_owned).collect();
            let at = |what: &str| lines.iter().position(|l| l.ends_with(what)).unwrap();
            let (f20, f60) = (at("# FETCH sra-20"), at("# FETCH sra-60"));
            // Each FETCH is followed by its READING.
            assert_eq!(f60, f20 + 2, "{lines:?}");
            assert!(lines[f20 + 1].contains("# READING sra-20"), "{lines:?}");
            assert!(lines[f60 + 1].contains("# READING sra-60"), "{lines:?}");
            // Keep each line's timestamp, swap what follows it.
            let body = |l: &str| l.split_once(' ').unwrap().1.to_owned();
            let stamp = |l: &str| l.split_once(' ').unwrap().0.to_owned();
            let (b20, b20r) = (body(&lines[f20]), body(&lines[f20 + 1]));
            let (b60, b60r) = (body(&lines[f60]), body(&lines[f60 + 1]));
            lines[f20] = format!("{} {b60}", stamp(&lines[f20]));
            lines[f20 + 1] = format!("{} {b60r}", stamp(&lines[f20 + 1]));
            lines[f60] = format!("{} {b20}", stamp(&lines[f60]));
            lines[f60 + 1] = format!("{} {b20r}", stamp(&lines[f60 + 1]));
            lines.join("\n") + "\n"
        } else {
            text
        };
        let path = dir.join(name);
        std::fs::write(&path, text).unwrap();
        out.push(path.display().to_string());
    }
    out
}

#[test]
fn replay_from_the_cli_fails_on_a_mismatch_unless_lenient_and_keeps_recorded_timing() {
    let _serial = serial();
    let dir = tempfile::tempdir().unwrap();
    let files = sessions_with_swapped_fetches(dir.path());
    let mut args: Vec<&str> = vec!["replay"];
    args.extend(files.iter().map(String::as_str));

    // Strict (the default): the run fails, naming the request that did not match.
    let strict = brdfd(&args, dir.path());
    let (out, err) = text(&strict);
    assert_eq!(strict.status.code(), Some(1), "{out}\n{err}");
    assert!(
        err.contains("(SRA): request did not match the recording: expected frame 14, FETCH sra-60"),
        "{out}\n{err}"
    );
    assert!(err.contains("received FETCH sra-20"), "{err}");
    assert!(out.contains("scan 1 \"T.Freesia pink\": failed"), "{out}");

    // Lenient: the same requests are matched by kind and geometry; the scan completes and
    // is fitted.
    let mut lenient = args.clone();
    lenient.push("--lenient");
    let o = brdfd(&lenient, dir.path());
    let (out, err) = text(&o);
    assert!(o.status.success(), "{out}\n{err}");
    assert!(out.contains("scan 1 \"T.Freesia pink\": complete"), "{out}");
    assert_eq!(out.matches(": mean ΔE00").count(), 3, "{out}");
    assert!(
        out.contains("1 reference(s), 1 scan(s) replayed (lenient, accelerated)"),
        "{out}"
    );

    // Realtime: the recorded pace. A lower bound only (a replay cannot be faster than its
    // recording), so a busy machine cannot fail it: the N9 and the sample each take at least
    // their MA-T12 session's last timestamp (2,451 ms for N9).
    let mut realtime = lenient.clone();
    realtime.push("--realtime");
    let started = std::time::Instant::now();
    let o = brdfd(&realtime, dir.path());
    let (out, err) = text(&o);
    assert!(o.status.success(), "{out}\n{err}");
    assert!(out.contains("(lenient, recorded timing)"), "{out}");
    assert!(
        started.elapsed() >= std::time::Duration::from_millis(2 * 2_000),
        "{:?}",
        started.elapsed()
    );
}
