//! The attack suite: a live `brdfd serve` child on loopback (simulated instruments, a store in
//! a temporary directory), and one test per way a web page, a second process or a stray path
//! could misuse it. Each asserts the refusal **and** that nothing changed: no reference started,
//! no scan imported, the store's rows as they were, the first daemon's scan completed.
//!
//! Requests are written by hand over a raw `TcpStream` where a client library would normalise
//! them (a forged `Host`, a half-sent header), so the bytes are exactly an attacker's.

// `serial()` is held across each whole test on purpose.
#![allow(clippy::await_holding_lock)]

mod common;

use std::io::{Read, Write};
use std::net::{SocketAddr, TcpStream};
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use brdfd::client::Client;
use serde_json::{Value, json};

use common::*;

/// Writes a configuration with simulated instruments, quick connection bounds and `extra`
/// appended to `[api]`.
fn config(dir: &Path, api_extra: &str) -> PathBuf {
    write_simulated_config(
        dir,
        &format!("header_timeout_ms = 500\nidle_timeout_ms = 20000\n{api_extra}"),
        "",
    )
}

/// A new connection to `addr` whose reads give up after [`STEP_TIMEOUT`].
fn connect(addr: SocketAddr) -> TcpStream {
    let s = TcpStream::connect(addr).unwrap();
    s.set_read_timeout(Some(STEP_TIMEOUT)).unwrap();
    s
}

/// Sends one raw request on a new connection and reads the answer until the server closes
/// it (or [`STEP_TIMEOUT`] passes).
fn answer(addr: SocketAddr, request: &str) -> String {
    let mut s = connect(addr);
    s.write_all(request.as_bytes()).unwrap();
    let mut out = String::new();
    let _ = s.read_to_string(&mut out);
    out
}

/// The status code on a raw answer's status line, if it has one.
fn status_of(answer: &str) -> Option<u16> {
    answer
        .split_whitespace()
        .nth(1)
        .and_then(|c| c.parse().ok())
}

/// One raw HTTP/1.1 request; returns the status code and the body.
fn raw(addr: SocketAddr, request: &str) -> (u16, String) {
    let out = answer(addr, request);
    let status = status_of(&out).unwrap_or_else(|| panic!("no status line in {out:?}"));
    let body = out.split("\r\n\r\n").nth(1).unwrap_or("").to_string();
    (status, body)
}

/// A request as a browser on another site would send it (no token unless given).
fn request(method: &str, path: &str, headers: &[(&str, &str)], body: &str) -> String {
    let mut r = format!(
        "{method} {path} HTTP/1.1\r\nconnection: close\r\ncontent-length: {}\r\n",
        body.len()
    );
    for (k, v) in headers {
        r.push_str(&format!("{k}: {v}\r\n"));
    }
    r.push_str("\r\n");
    r.push_str(body);
    r
}

/// [`raw`] of a [`request`] whose `Host` is `addr` itself (sent first, as a browser on the
/// daemon's own page would), then `headers`.
fn ask(
    addr: SocketAddr,
    method: &str,
    path: &str,
    headers: &[(&str, &str)],
    body: &str,
) -> (u16, String) {
    let host = addr.to_string();
    let mut all = vec![("host", host.as_str())];
    all.extend_from_slice(headers);
    raw(addr, &request(method, path, &all, body))
}

/// Reads `s` until what it has read contains `marker`, failing with `closed` if the server
/// closes it first; returns what was read.
fn read_until(s: &mut TcpStream, marker: &str, closed: &str) -> String {
    let mut seen = Vec::new();
    let mut buf = [0u8; 1024];
    while !String::from_utf8_lossy(&seen).contains(marker) {
        let n = s.read(&mut buf).unwrap();
        assert!(n > 0, "{closed}");
        seen.extend_from_slice(&buf[..n]);
    }
    String::from_utf8_lossy(&seen).into_owned()
}

/// Row counts of the tables an attack could change, read through the read-only store.
fn counts(dir: &Path) -> Vec<(String, i64)> {
    block_on(async {
        let store = brdfd::store::Store::open_read_only(dir.join("brdfd.db"))
            .await
            .expect("read-only open beside the daemon");
        let mut out = Vec::new();
        for table in ["reference_sets", "scans", "readings", "fit_runs"] {
            out.push((table.to_string(), store.count_rows(table).await.unwrap()));
        }
        store.close().await;
        out
    })
}

fn idle(client: &Client) -> bool {
    client.get("/status").unwrap()["busy"].is_null()
}

/// A daemon on [`config`]`(dir, api_extra)` in a new temporary directory: the directory, the
/// configuration file and the daemon (bound in this order, the daemon is dropped first).
fn serve_fresh(api_extra: &str) -> (tempfile::TempDir, PathBuf, ServeChild) {
    let dir = tempfile::tempdir().unwrap();
    let cfg = config(dir.path(), api_extra);
    let d = spawn_serve(&cfg, &[]);
    (dir, cfg, d)
}

/// Runs `brdfd serve --config CFG EXTRA_ARGS…`, checks that it fails, and returns its stderr.
fn serve_refused(cfg: &Path, extra_args: &[&str]) -> String {
    let mut args = vec!["serve", "--config", cfg.to_str().unwrap()];
    args.extend_from_slice(extra_args);
    let out = run_brdfd(&args, None);
    assert_ne!(out.status.code(), Some(0));
    String::from_utf8_lossy(&out.stderr).into_owned()
}

/// Measures the reference, waits for it, and starts a scan of T.Sky blue; returns its id.
fn reference_and_scan(d: &ServeChild) -> i64 {
    d.client.post("/reference", None).unwrap();
    wait_until("the reference", || idle(&d.client));
    d.client
        .post("/scans", Some(&json!({"sample": "T.Sky blue"})))
        .unwrap()["scan"]
        .as_i64()
        .unwrap()
}

#[test]
fn a_web_page_cannot_measure_abort_cancel_or_import() {
    let _serial = serial();
    let (_dir, _, d) = serve_fresh("");
    let host = d.addr.to_string();
    let bearer = format!("Bearer {}", d.token);
    let before = counts(&d.dir);
    let scan_file = std::fs::read_to_string(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/tests/data/t-sky-blue.scan.json"
    ))
    .unwrap();
    let evil = ("origin", "https://evil.example");
    // What a page can send: no token, a foreign Origin, form or text bodies.
    let attempts: Vec<(String, u16)> = vec![
        (
            request("POST", "/reference", &[("host", &host), evil], ""),
            403,
        ),
        (
            request(
                "POST",
                "/reference",
                &[
                    ("host", &host),
                    ("content-type", "application/x-www-form-urlencoded"),
                ],
                "",
            ),
            401,
        ),
        (
            request(
                "POST",
                "/abort",
                &[("host", &host), ("content-type", "text/plain")],
                "",
            ),
            401,
        ),
        (
            request("POST", "/fits/1/cancel", &[("host", &host), evil], ""),
            403,
        ),
        (
            request(
                "POST",
                "/scans/import",
                &[("host", &host), evil, ("content-type", "text/plain")],
                &scan_file,
            ),
            403,
        ),
        (
            request(
                "POST",
                "/scans/import",
                &[("host", &host), ("content-type", "text/plain")],
                &scan_file,
            ),
            401,
        ),
        // Even with the token, a foreign origin or a non-JSON body is refused.
        (
            request(
                "POST",
                "/reference",
                &[
                    ("host", &host),
                    evil,
                    ("authorization", &bearer),
                    ("content-type", "application/json"),
                ],
                "",
            ),
            403,
        ),
        (
            request(
                "POST",
                "/scans/import",
                &[
                    ("host", &host),
                    ("authorization", &bearer),
                    ("content-type", "text/plain"),
                ],
                &scan_file,
            ),
            415,
        ),
        (
            request(
                "POST",
                "/reference",
                &[
                    ("host", &host),
                    ("sec-fetch-site", "cross-site"),
                    ("authorization", &bearer),
                    ("content-type", "application/json"),
                ],
                "",
            ),
            403,
        ),
        // DNS rebinding: the page's own host name in Host.
        (
            request(
                "GET",
                "/scans",
                &[("host", "attacker.example"), ("authorization", &bearer)],
                "",
            ),
            421,
        ),
        (
            request(
                "POST",
                "/reference",
                &[
                    ("host", &format!("attacker.example:{}", d.addr.port())),
                    ("authorization", &bearer),
                    ("content-type", "application/json"),
                ],
                "",
            ),
            421,
        ),
        (
            request("GET", "/scans", &[("host", "attacker.example")], ""),
            421,
        ),
    ];
    for (req, want) in &attempts {
        let (status, body) = raw(d.addr, req);
        assert_eq!(status, *want, "{req}\n→ {status} {body}");
        let v: Value =
            serde_json::from_str(&body).unwrap_or_else(|_| panic!("JSON refusal: {body}"));
        assert!(!v["error"].as_str().unwrap().is_empty());
    }
    // The 401 says which file the token is in, but not where on the machine.
    let (_, body) = ask(d.addr, "GET", "/scans", &[], "");
    assert!(body.contains("brdfd.token"), "{body}");
    assert!(!body.contains(&*d.dir.to_string_lossy()), "{body}");
    // Nothing started, nothing imported.
    let status = d.client.get("/status").unwrap();
    assert!(
        status["busy"].is_null() && status["reference"].is_null(),
        "{status}"
    );
    assert_eq!(counts(&d.dir), before);
    // Monitoring needs no token; the operator's client works.
    let (status, _) = ask(d.addr, "GET", "/healthz", &[], "");
    assert_eq!(status, 200);
    assert!(
        d.client
            .get("/scans")
            .unwrap()
            .as_array()
            .unwrap()
            .is_empty()
    );
    // The token file is the daemon's alone.
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        let mode = std::fs::metadata(d.dir.join("brdfd.token"))
            .unwrap()
            .permissions()
            .mode();
        assert_eq!(mode & 0o077, 0, "token file mode {mode:o}");
    }
}

#[test]
fn listening_beyond_loopback_needs_allow_remote_on_the_command_line_too() {
    let _serial = serial();
    let dir = tempfile::tempdir().unwrap();
    let stderr = serve_refused(&config(dir.path(), ""), &["--listen", "0.0.0.0:0"]);
    assert!(
        stderr.contains("--listen 0.0.0.0:0") && stderr.contains("allow_remote"),
        "{stderr}"
    );
    assert!(
        !dir.path().join("brdfd.db").exists(),
        "refused before the store is touched"
    );
}

#[test]
fn a_second_daemon_on_the_same_store_is_refused_and_the_first_scan_completes() {
    let _serial = serial();
    let (dir, cfg, d) = serve_fresh("");
    let scan = reference_and_scan(&d);
    // While it measures, a second daemon on the same store is refused at once.
    let stderr = serve_refused(&cfg, &["--listen", "127.0.0.1:0"]);
    assert!(stderr.contains("in use by another brdfd"), "{stderr}");
    assert!(
        stderr.contains(&format!("pid {}", d.child.id())),
        "{stderr}"
    );
    assert!(stderr.contains(&d.addr.to_string()), "{stderr}");
    // The first daemon's scan is untouched and completes.
    wait_until("the scan", || idle(&d.client));
    let v = d.client.get(&format!("/scans/{scan}")).unwrap();
    assert_eq!(v["scan"]["state"], "complete", "{v}");
    // Provenance: simulated instruments, said so on the scan.
    let p = &v["scan"]["provenance"];
    assert_eq!(p["ma_t12"]["simulated"], true, "{p}");
    assert_eq!(p["sra"]["simulated"], true, "{p}");
    assert_eq!(p["source"], "measured");
    assert_ne!(p["ma_t12"]["serial"], "unknown", "{p}");
    // A read-only report works beside the running daemon.
    let out = run_brdfd(
        &[
            "report",
            "--all",
            "--db",
            dir.path().join("brdfd.db").to_str().unwrap(),
            "--out",
            dir.path().join("rep").to_str().unwrap(),
        ],
        None,
    );
    assert_eq!(
        out.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
}

#[test]
fn a_refit_naming_one_cost_function_two_thousand_times_queues_it_once() {
    let _serial = serial();
    let (_dir, _, d) = serve_fresh("");
    let scan = reference_and_scan(&d);
    wait_until("the scan", || idle(&d.client));
    let before = counts(&d.dir);
    let names: Vec<&str> = ["cf1", "cf2"].iter().cycle().take(2000).copied().collect();
    let v = d
        .client
        .post(
            &format!("/scans/{scan}/refit"),
            Some(&json!({"cost_functions": names})),
        )
        .unwrap();
    assert_eq!(v["fits"].as_array().unwrap().len(), 2, "{v}");
    let after = counts(&d.dir);
    let fit_runs = |c: &[(String, i64)]| c.iter().find(|(t, _)| t == "fit_runs").unwrap().1;
    assert_eq!(fit_runs(&after), fit_runs(&before) + 2);
    // An unknown cost function and an over-long page are refused.
    let e = d
        .client
        .post(
            &format!("/scans/{scan}/refit"),
            Some(&json!({"cost_functions": ["cf9"]})),
        )
        .unwrap_err();
    assert!(e.to_string().contains("cf9"), "{e}");
    let e = d.client.get("/scans?limit=100000").unwrap_err();
    assert!(e.to_string().contains("before=ID"), "{e}");
    // Names with control characters never reach the store (or a terminal).
    let e = d
        .client
        .post("/scans", Some(&json!({"sample": "T.\u{1b}[2Jevil"})))
        .unwrap_err();
    assert!(e.to_string().contains("control character"), "{e}");
    let e = d
        .client
        .post("/scans", Some(&json!({"sample": "x".repeat(201)})))
        .unwrap_err();
    assert!(e.to_string().contains("at most 200"), "{e}");
}

#[test]
fn half_sent_headers_are_closed_and_connections_and_streams_are_capped() {
    let _serial = serial();
    let (_dir, _, d) = serve_fresh("max_connections = 12\nmax_event_subscribers = 2");
    // Slowloris: half a header on each of 10 connections; the server closes them after the
    // header timeout (500 ms here), and not before it.
    let opened = Instant::now();
    let mut slow: Vec<TcpStream> = (0..10)
        .map(|_| {
            let mut s = TcpStream::connect(d.addr).unwrap();
            s.write_all(b"GET /status HTTP/1.1\r\nhost: 127.0.0.1\r\nx-half: ")
                .unwrap();
            s.set_read_timeout(Some(STEP_TIMEOUT)).unwrap();
            s
        })
        .collect();
    for s in &mut slow {
        let mut buf = [0u8; 512];
        // The server's answer (408 or a plain close) ends the connection: read returns, it
        // does not hang until STEP_TIMEOUT.
        let started = Instant::now();
        loop {
            match s.read(&mut buf) {
                Ok(0) | Err(_) => break,
                Ok(_) => continue,
            }
        }
        assert!(
            started.elapsed() < STEP_TIMEOUT,
            "a half-sent header was kept open"
        );
    }
    // At the configured timeout: not before 500 ms, and not much after.
    let took = opened.elapsed();
    assert!(
        took >= Duration::from_millis(450) && took < Duration::from_secs(3),
        "half-sent headers closed after {took:?}, header_timeout_ms = 500"
    );
    // Connection cap, 12 here. Twelve connections idle after a request: the 13th is served,
    // and the one that has waited longest is closed to make room.
    let host = d.addr.to_string();
    let mut held: Vec<TcpStream> = (0..12)
        .map(|_| {
            let mut s = connect(d.addr);
            let keep_alive = request("GET", "/healthz", &[("host", &host)], "")
                .replace("connection: close", "connection: keep-alive");
            s.write_all(keep_alive.as_bytes()).unwrap();
            read_until(
                &mut s,
                "{\"ok\":true}",
                "the connection closed before its answer",
            );
            s
        })
        .collect();
    let (status, body) = ask(d.addr, "GET", "/healthz", &[], "");
    assert_eq!(status, 200, "{body}");
    let mut buf = [0u8; 64];
    assert!(
        matches!(held[0].read(&mut buf), Ok(0) | Err(_)),
        "the longest-waiting connection was closed"
    );
    drop(held);
    // Twelve connections each with a request in flight (a body promised, not sent): the
    // 13th is answered 503, as no connection can be closed without losing a request. Each
    // asks for `100 Continue`, which comes once the handler reads the body: the request is
    // then provably in flight before the next connection is made.
    let bearer = format!("Bearer {}", d.token);
    let busy: Vec<TcpStream> = (0..12)
        .map(|_| {
            let mut s = connect(d.addr);
            s.write_all(
                format!(
                    "POST /scans/import HTTP/1.1\r\nhost: {host}\r\nauthorization: {bearer}\r\n\
                     content-type: application/json\r\ncontent-length: 1000\r\n\
                     expect: 100-continue\r\n\r\n"
                )
                .as_bytes(),
            )
            .unwrap();
            let mut buf = [0u8; 256];
            let n = s.read(&mut buf).unwrap();
            let head = String::from_utf8_lossy(&buf[..n]);
            assert!(head.starts_with("HTTP/1.1 100"), "{head}");
            s
        })
        .collect();
    let (status, body) = ask(d.addr, "GET", "/healthz", &[], "");
    assert_eq!(status, 503, "{body}");
    assert!(body.contains("max_connections"), "{body}");
    drop(busy);
    wait_until("the cap to free", || {
        ask(d.addr, "GET", "/healthz", &[], "").0 == 200
    });
    // Event streams: two at once, the third is refused.
    let a = d.client.events().unwrap();
    let b = d.client.events().unwrap();
    let e = d.client.events().unwrap_err();
    assert!(e.to_string().contains("max_event_subscribers"), "{e}");
    drop((a, b));
    wait_until("a stream slot", || d.client.events().is_ok());
}

#[test]
fn a_recording_named_like_the_store_is_refused_and_old_recordings_are_kept() {
    let _serial = serial();
    let dir = tempfile::tempdir().unwrap();
    let cfg = config(dir.path(), "");
    let text = std::fs::read_to_string(&cfg).unwrap().replace(
        "[devices.ma_t12]\n",
        &format!(
            "[devices.ma_t12]\nrecord = \"{}\"\n",
            dir.path().join("brdfd.db").display()
        ),
    );
    std::fs::write(&cfg, text).unwrap();
    std::fs::write(dir.path().join("brdfd.db"), b"precious").unwrap();
    let stderr = serve_refused(&cfg, &[]);
    assert!(stderr.contains("same file as [store] path"), "{stderr}");
    assert_eq!(
        std::fs::read(dir.path().join("brdfd.db")).unwrap(),
        b"precious"
    );

    // A recording from an earlier run is moved aside, not truncated.
    let rec = dir.path().join("ma_t12.session");
    std::fs::write(&rec, b"an earlier recording").unwrap();
    let cfg2 = config(dir.path(), "");
    let text = std::fs::read_to_string(&cfg2)
        .unwrap()
        .replace("brdfd.db", "other.db")
        .replace(
            "[devices.ma_t12]\n",
            &format!("[devices.ma_t12]\nrecord = \"{}\"\n", rec.display()),
        );
    std::fs::write(&cfg2, text).unwrap();
    let d = spawn_serve(&cfg2, &[]);
    drop(d);
    let kept: Vec<_> = std::fs::read_dir(dir.path())
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| {
            let n = p.file_name().unwrap().to_string_lossy().into_owned();
            n.starts_with("ma_t12.") && n.ends_with(".session") && n != "ma_t12.session"
        })
        .collect();
    assert_eq!(kept.len(), 1, "{kept:?}");
    assert_eq!(std::fs::read(&kept[0]).unwrap(), b"an earlier recording");
}

/// The store's file, byte for byte.
fn store_bytes(dir: &Path) -> Vec<u8> {
    std::fs::read(dir.join("brdfd.db")).unwrap()
}

/// A daemon with a store that has a reference and a scan in it, checkpointed into the main
/// file, so that overwriting the file would destroy them.
fn serve_with_a_scan(dir: &Path, sections: &str) -> ServeChild {
    write_simulated_config(
        dir,
        "header_timeout_ms = 500\nidle_timeout_ms = 20000\n",
        sections,
    );
    let d = spawn_serve(&dir.join("brdfd.toml"), &[]);
    reference_and_scan(&d);
    wait_until("the scan", || idle(&d.client));
    d
}

#[test]
fn a_link_in_the_watch_folder_never_redirects_a_note_a_move_or_a_read() {
    let _serial = serial();
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let inbox = dir.join("inbox");
    std::fs::create_dir(&inbox).unwrap();
    let d = serve_with_a_scan(
        dir,
        &format!(
            "[fit]\ncost_functions = [\"cf2\"]\nbootstrap = 0\n\n[ingest]\nwatch = \"{}\"\n\
             settle_ms = 50\npoll_ms = 20\npair_wait_ms = 0\nmax_file_mib = 1\n\n",
            inbox.display()
        ),
    );
    let ingest = |d: &ServeChild| d.client.get("/status").unwrap()["ingest"].clone();
    wait_until("the fits", || {
        let s = d.client.get("/status").unwrap();
        s["fits_queued"] == 0 && s["fits_running"] == 0 && s["bootstraps_pending"] == 0
    });
    let before = counts(dir);
    let db = dir.join("brdfd.db");
    let db_before = store_bytes(dir);
    // 1. The note of a bad file, planted as a link to the store.
    std::os::unix::fs::symlink(&db, inbox.join("failed/k.scan.json.error.txt")).unwrap();
    std::fs::write(inbox.join("k.scan.json"), b"{ not a scan").unwrap();
    wait_until("the bad file rejected", || ingest(&d)["rejected"] == 1);
    assert!(
        std::fs::symlink_metadata(inbox.join("failed/k.scan.json.error.txt"))
            .unwrap()
            .file_type()
            .is_symlink()
    );
    let note = std::fs::read_to_string(inbox.join("failed/k-2.scan.json.error.txt")).unwrap();
    assert!(note.contains("k.scan.json was not imported"), "{note}");
    assert!(inbox.join("failed/k-2.scan.json").exists());
    // 2. A link to a scan file outside the folder: moved to failed/ unread, not imported.
    let outside = dir.join("outside.scan.json");
    std::fs::copy(
        concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/tests/data/t-sky-blue.scan.json"
        ),
        &outside,
    )
    .unwrap();
    std::os::unix::fs::symlink(&outside, inbox.join("l.scan.json")).unwrap();
    // 3. A hard link to the store named like an export, and a file over max_file_mib.
    std::fs::hard_link(&db, inbox.join("h.cxf")).unwrap();
    std::fs::write(inbox.join("big.scan.json"), vec![b' '; 2 << 20]).unwrap();
    wait_until("the three rejected", || ingest(&d)["rejected"] == 4);
    let note = std::fs::read_to_string(inbox.join("failed/l.scan.json.error.txt")).unwrap();
    assert!(note.contains("symbolic link"), "{note}");
    let note = std::fs::read_to_string(inbox.join("failed/h.cxf.error.txt")).unwrap();
    assert!(note.contains("hard link"), "{note}");
    let note = std::fs::read_to_string(inbox.join("failed/big.scan.json.error.txt")).unwrap();
    assert!(
        note.contains(
            "big.scan.json: the whole file: 2097152 bytes is beyond the import limit \"file \
             size\" of 1048576 bytes"
        ) && note.contains("ingest.max_file_mib"),
        "{note}"
    );
    assert!(outside.exists());
    // 4. done/ swapped for a link while running: nothing is moved through it.
    let elsewhere = dir.join("elsewhere");
    std::fs::create_dir(&elsewhere).unwrap();
    std::fs::rename(inbox.join("done"), dir.join("done-moved")).unwrap();
    std::os::unix::fs::symlink(&elsewhere, inbox.join("done")).unwrap();
    std::fs::copy(&outside, inbox.join("good.scan.json")).unwrap();
    wait_until("the swap noticed", || {
        ingest(&d)["last_error"]
            .as_str()
            .is_some_and(|e| e.contains("was replaced"))
    });
    assert!(inbox.join("good.scan.json").exists(), "not taken");
    assert_eq!(std::fs::read_dir(&elsewhere).unwrap().count(), 0);
    // The store: the same rows, the same bytes, and it answers.
    assert_eq!(counts(dir), before);
    assert_eq!(store_bytes(dir), db_before, "the store's file changed");
    assert!(d.client.get("/scans").unwrap().as_array().unwrap().len() == 1);
}

#[test]
fn report_and_export_never_write_through_a_link_or_onto_the_store() {
    let _serial = serial();
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    // The paper's SRA model and 20 resamples: its fits and bootstraps settle in seconds in a
    // debug build (cf2's 200 full-search refits under the luminance default take minutes
    // there); what is written is the same files either way.
    let d = serve_with_a_scan(dir, "[fit]\nsra = \"flat\"\nbootstrap = 20\n\n");
    wait_until("the fits", || {
        let s = d.client.get("/status").unwrap();
        s["fits_queued"] == 0 && s["fits_running"] == 0 && s["bootstraps_pending"] == 0
    });
    drop(d);
    let db = dir.join("brdfd.db");
    let db_s = db.to_str().unwrap();
    let before = store_bytes(dir);
    let refused = |args: &[&str], says: &str| {
        let out = run_brdfd(args, None);
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_ne!(out.status.code(), Some(0), "{args:?} succeeded");
        assert!(stderr.contains(says), "{args:?}: {stderr}");
    };
    // report --out DIR with DIR/index.html a link to the store.
    let out = dir.join("rep");
    std::fs::create_dir(&out).unwrap();
    std::os::unix::fs::symlink(&db, out.join("index.html")).unwrap();
    let out_s = out.to_str().unwrap();
    refused(
        &["report", "--all", "--db", db_s, "--out", out_s],
        "symbolic link",
    );
    refused(
        &["report", "--all", "--db", db_s, "--out", out_s, "--force"],
        "symbolic link",
    );
    // --out that is itself a link to a folder.
    let real = dir.join("real");
    std::fs::create_dir(&real).unwrap();
    std::os::unix::fs::symlink(&real, dir.join("linked")).unwrap();
    let linked = dir.join("linked");
    refused(
        &[
            "report",
            "--all",
            "--db",
            db_s,
            "--out",
            linked.to_str().unwrap(),
        ],
        "symbolic link",
    );
    assert_eq!(std::fs::read_dir(&real).unwrap().count(), 0);
    // A second report into the same folder needs --force, which replaces only its own files.
    let fresh = dir.join("fresh");
    let fresh_s = fresh.to_str().unwrap();
    assert!(
        run_brdfd(&["report", "--all", "--db", db_s, "--out", fresh_s], None)
            .status
            .success()
    );
    refused(
        &["report", "--all", "--db", db_s, "--out", fresh_s],
        "--force",
    );
    assert!(
        run_brdfd(
            &["report", "--all", "--db", db_s, "--out", fresh_s, "--force"],
            None
        )
        .status
        .success()
    );
    // export-format onto the store, its -wal, a link to it; with and without --force.
    std::os::unix::fs::symlink(&db, dir.join("to-store.json")).unwrap();
    let wal = format!("{db_s}-wal");
    let link = dir.join("to-store.json");
    for target in [db_s, wal.as_str(), link.to_str().unwrap()] {
        for force in [false, true] {
            let mut args = export_json(db_s, target);
            if force {
                args.push("--force");
            }
            let out = run_brdfd(&args, None);
            assert_ne!(out.status.code(), Some(0), "{args:?}");
        }
    }
    // A hard link to the store under another name is refused too.
    let copy = dir.join("copy.json");
    std::fs::hard_link(&db, &copy).unwrap();
    let mut args = export_json(db_s, copy.to_str().unwrap());
    args.push("--force");
    refused(&args, "never");
    assert_eq!(store_bytes(dir), before, "the store's file changed");
    // The store and the token are the daemon's user's only.
    use std::os::unix::fs::PermissionsExt;
    for f in ["brdfd.db", "brdfd.token", "brdfd.db-wal", "brdfd.db-shm"] {
        let Ok(meta) = std::fs::metadata(dir.join(f)) else {
            assert!(f.contains('-'), "{f} is missing");
            continue;
        };
        let mode = meta.permissions().mode();
        assert_eq!(mode & 0o077, 0, "{f}: mode {mode:o}");
    }
}

/// The arguments of `brdfd export-format` writing every scan of the store `db` as JSON to `out`.
fn export_json<'a>(db: &'a str, out: &'a str) -> Vec<&'a str> {
    vec![
        "export-format",
        "--format",
        "json",
        "--all",
        "--db",
        db,
        "--out",
        out,
    ]
}

/// An event stream opened by hand: the request sent and the answer's head read.
fn open_stream(addr: SocketAddr, token: &str) -> TcpStream {
    let mut s = connect(addr);
    s.write_all(
        format!("GET /events HTTP/1.1\r\nhost: {addr}\r\nauthorization: Bearer {token}\r\n\r\n")
            .as_bytes(),
    )
    .unwrap();
    let head = read_until(&mut s, "\r\n\r\n", "the stream closed before its head");
    assert!(head.starts_with("HTTP/1.1 200"), "{head}");
    s
}

#[test]
fn silent_sockets_and_idle_event_streams_cannot_keep_the_operator_out() {
    let _serial = serial();
    brdfd::api::server::raise_fd_limit();
    let dir = tempfile::tempdir().unwrap();
    // Long timeouts: what keeps the operator in is the cap's rule, not a timer.
    let cfg = write_simulated_config(
        dir.path(),
        "header_timeout_ms = 60000\nidle_timeout_ms = 60000\nmax_connections = 64\n\
         max_event_subscribers = 100",
        "",
    );
    let d = spawn_serve(&cfg, &[]);
    let streams: Vec<TcpStream> = (0..100).map(|_| open_stream(d.addr, &d.token)).collect();
    let silent: Vec<TcpStream> = (0..300)
        .map(|_| TcpStream::connect(d.addr).unwrap())
        .collect();
    // Half-sent headers too (slowloris), and unauthenticated requests kept alive.
    let mut half: Vec<TcpStream> = (0..50)
        .map(|_| TcpStream::connect(d.addr).unwrap())
        .collect();
    for s in &mut half {
        s.write_all(b"GET /status HTTP/1.1\r\nhost: 127.0.0.1\r\nx-half: ")
            .unwrap();
    }
    let mut worst = Duration::ZERO;
    for _ in 0..20 {
        let t = Instant::now();
        let v = d
            .client
            .get("/status")
            .expect("status answers under the flood");
        worst = worst.max(t.elapsed());
        assert!(v["busy"].is_null(), "{v}");
    }
    assert!(worst < Duration::from_secs(1), "GET /status took {worst:?}");
    // The event streams are all still open (they are not closed to make room).
    let mut open = 0;
    for mut s in streams {
        s.set_nonblocking(true).unwrap();
        let mut buf = [0u8; 64];
        match s.read(&mut buf) {
            Ok(0) => {}
            Ok(_) => open += 1,
            Err(e) if e.kind() == std::io::ErrorKind::WouldBlock => open += 1,
            Err(_) => {}
        }
    }
    assert_eq!(open, 100);
    drop((silent, half));
}

#[test]
fn a_body_promised_over_the_limit_is_refused_before_it_is_sent() {
    let _serial = serial();
    let (_dir, _, d) = serve_fresh("");
    let before = counts(&d.dir);
    let mut s = TcpStream::connect(d.addr).unwrap();
    s.set_read_timeout(Some(Duration::from_secs(5))).unwrap();
    let started = Instant::now();
    s.write_all(
        format!(
            "POST /scans/import HTTP/1.1\r\nhost: {}\r\nauthorization: Bearer {}\r\n\
             content-type: application/json\r\ncontent-length: 10737418240\r\n\r\n{{",
            d.addr, d.token
        )
        .as_bytes(),
    )
    .unwrap();
    let mut out = String::new();
    let _ = s.read_to_string(&mut out);
    assert!(out.starts_with("HTTP/1.1 413"), "{out}");
    assert!(out.contains("over the limit"), "{out}");
    assert!(started.elapsed() < Duration::from_secs(2));
    // A body just over 1 MiB, sent whole, is refused too.
    let big = format!("{{\"x\": \"{}\"}}", "a".repeat(1 << 20));
    let (status, body) = ask(
        d.addr,
        "POST",
        "/scans/import",
        &[
            ("authorization", &format!("Bearer {}", d.token)),
            ("content-type", "application/json"),
        ],
        &big,
    );
    assert_eq!(status, 413, "{body}");
    // A CORS preflight is never granted.
    let (status, _) = ask(
        d.addr,
        "OPTIONS",
        "/reference",
        &[
            ("origin", "https://evil.example"),
            ("access-control-request-method", "POST"),
            ("access-control-request-headers", "authorization"),
        ],
        "",
    );
    assert!(status >= 400, "preflight answered {status}");
    // A refused body shape says what to send, not the parser's field list.
    let e = d
        .client
        .post("/scans", Some(&json!({"sampel": "x"})))
        .unwrap_err()
        .to_string();
    assert!(e.contains("{\"sample\""), "{e}");
    assert!(e.contains("unknown field `sampel`"), "{e}");
    assert!(
        !e.contains("expected `sample`") && !e.contains("line 1"),
        "{e}"
    );
    assert_eq!(counts(&d.dir), before);
}

#[test]
fn an_idle_connection_closes_at_the_configured_idle_timeout() {
    let _serial = serial();
    let dir = tempfile::tempdir().unwrap();
    let cfg = write_simulated_config(
        dir.path(),
        "header_timeout_ms = 5000\nidle_timeout_ms = 1000",
        "",
    );
    let d = spawn_serve(&cfg, &[]);
    let mut s = connect(d.addr);
    let keep_alive = request("GET", "/healthz", &[("host", &d.addr.to_string())], "")
        .replace("connection: close", "connection: keep-alive");
    s.write_all(keep_alive.as_bytes()).unwrap();
    let mut buf = [0u8; 512];
    let n = s.read(&mut buf).unwrap();
    assert!(String::from_utf8_lossy(&buf[..n]).contains("200 OK"));
    let answered = Instant::now();
    loop {
        match s.read(&mut buf) {
            Ok(0) | Err(_) => break,
            Ok(_) => {}
        }
    }
    let idle = answered.elapsed();
    assert!(
        idle >= Duration::from_millis(900) && idle < Duration::from_secs(3),
        "an idle connection closed after {idle:?}, idle_timeout_ms = 1000"
    );
}

/// One raw request's status and its whole answer (head and body).
fn raw_full(addr: SocketAddr, request: &str) -> (u16, String) {
    let out = answer(addr, request);
    (status_of(&out).unwrap_or(0), out)
}

#[test]
fn a_logged_out_session_stays_logged_out_across_a_restart() {
    let _serial = serial();
    let (_dir, cfg, d) = serve_fresh("");
    let cookie_of = |d: &ServeChild| {
        let ticket = d.client.post("/session/ticket", None).unwrap()["ticket"]
            .as_str()
            .unwrap()
            .to_string();
        let (status, answer) = raw_full(
            d.addr,
            &request(
                "GET",
                &format!("/login?ticket={ticket}"),
                &[("host", &d.addr.to_string())],
                "",
            ),
        );
        assert_eq!(status, 303, "{answer}");
        answer
            .lines()
            .find_map(|l| l.strip_prefix("set-cookie: brdfd_session="))
            .and_then(|v| v.split(';').next())
            .unwrap()
            .to_string()
    };
    let ended = cookie_of(&d);
    let kept = cookie_of(&d);
    let status_with = |addr: SocketAddr, cookie: &str| {
        ask(
            addr,
            "GET",
            "/status",
            &[
                ("cookie", &format!("brdfd_session={cookie}")),
                ("sec-fetch-site", "same-origin"),
            ],
            "",
        )
        .0
    };
    assert_eq!(status_with(d.addr, &ended), 200);
    // Log out as the page does: its CSRF value from /session, then the POST.
    let jar = format!("brdfd_session={ended}");
    let own = ("sec-fetch-site", "same-origin");
    let (_, body) = ask(d.addr, "GET", "/session", &[("cookie", &jar), own], "");
    let csrf = serde_json::from_str::<Value>(&body).unwrap()["csrf"]
        .as_str()
        .unwrap()
        .to_string();
    let (status, body) = ask(
        d.addr,
        "POST",
        "/session/logout",
        &[
            ("cookie", &jar),
            own,
            ("content-type", "application/json"),
            ("x-brdfd-csrf", &csrf),
        ],
        "",
    );
    assert_eq!(status, 200, "{body}");
    assert_eq!(status_with(d.addr, &ended), 401);
    drop(d);
    // The next daemon on the same store and token: still logged out; the other session lives.
    let d = spawn_serve(&cfg, &[]);
    assert_eq!(status_with(d.addr, &ended), 401);
    assert_eq!(status_with(d.addr, &kept), 200);
}

#[test]
fn a_token_file_that_is_a_pipe_is_refused_at_start_without_hanging() {
    let _serial = serial();
    let dir = tempfile::tempdir().unwrap();
    let fifo = dir.path().join("brdfd.token");
    let c = std::ffi::CString::new(fifo.to_str().unwrap()).unwrap();
    // SAFETY: mkfifo(3) with a valid path.
    assert_eq!(unsafe { libc::mkfifo(c.as_ptr(), 0o600) }, 0);
    let cfg = config(dir.path(), "");
    let started = Instant::now();
    let stderr = serve_refused(&cfg, &[]);
    assert!(stderr.contains("not a regular file"), "{stderr}");
    assert!(started.elapsed() < Duration::from_secs(20));
}
