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
use std::time::Instant;

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

/// One raw HTTP/1.1 request; returns the status code and the body.
fn raw(addr: SocketAddr, request: &str) -> (u16, String) {
    let mut s = TcpStream::connect(addr).unwrap();
    s.set_read_timeout(Some(STEP_TIMEOUT)).unwrap();
    s.write_all(request.as_bytes()).unwrap();
    let mut out = String::new();
    let _ = s.read_to_string(&mut out);
    let status = out
        .split_whitespace()
        .nth(1)
        .and_then(|c| c.parse().ok())
        .unwrap_or_else(|| panic!("no status line in {out:?}"));
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

/// Row counts of the tables an attack could change, read through the read-only store.
fn counts(dir: &Path) -> Vec<(String, i64)> {
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .unwrap();
    rt.block_on(async {
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

#[test]
fn a_web_page_cannot_measure_abort_cancel_or_import() {
    let _serial = serial();
    let dir = tempfile::tempdir().unwrap();
    let d = spawn_serve(&config(dir.path(), ""), &[]);
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
    // The 401 says where the token is.
    let (_, body) = raw(d.addr, &request("GET", "/scans", &[("host", &host)], ""));
    assert!(body.contains("brdfd.token"), "{body}");
    // Nothing started, nothing imported.
    let status = d.client.get("/status").unwrap();
    assert!(
        status["busy"].is_null() && status["reference"].is_null(),
        "{status}"
    );
    assert_eq!(counts(&d.dir), before);
    // Monitoring needs no token; the operator's client works.
    let (status, _) = raw(d.addr, &request("GET", "/healthz", &[("host", &host)], ""));
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
    let cfg = config(dir.path(), "");
    let out = run_brdfd(
        &[
            "serve",
            "--config",
            cfg.to_str().unwrap(),
            "--listen",
            "0.0.0.0:0",
        ],
        None,
    );
    assert_ne!(out.status.code(), Some(0));
    let stderr = String::from_utf8_lossy(&out.stderr);
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
    let dir = tempfile::tempdir().unwrap();
    let cfg = config(dir.path(), "");
    let d = spawn_serve(&cfg, &[]);
    d.client.post("/reference", None).unwrap();
    wait_until("the reference", || idle(&d.client));
    let scan = d
        .client
        .post("/scans", Some(&json!({"sample": "T.Sky blue"})))
        .unwrap()["scan"]
        .as_i64()
        .unwrap();
    // While it measures, a second daemon on the same store is refused at once.
    let out = run_brdfd(
        &[
            "serve",
            "--config",
            cfg.to_str().unwrap(),
            "--listen",
            "127.0.0.1:0",
        ],
        None,
    );
    assert_ne!(out.status.code(), Some(0));
    let stderr = String::from_utf8_lossy(&out.stderr);
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
    let dir = tempfile::tempdir().unwrap();
    let d = spawn_serve(&config(dir.path(), ""), &[]);
    d.client.post("/reference", None).unwrap();
    wait_until("the reference", || idle(&d.client));
    let scan = d
        .client
        .post("/scans", Some(&json!({"sample": "T.Sky blue"})))
        .unwrap()["scan"]
        .as_i64()
        .unwrap();
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
    let dir = tempfile::tempdir().unwrap();
    let d = spawn_serve(
        &config(
            dir.path(),
            "max_connections = 12\nmax_event_subscribers = 2",
        ),
        &[],
    );
    // Slowloris: half a header on each of 10 connections; the server closes them after the
    // header timeout (500 ms here), where it used to keep them forever.
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
    // Connection cap: 12 open connections, the 13th is answered 503.
    // Each held connection is first answered once (and kept open), so the daemon has counted
    // all twelve before the thirteenth comes, however busy the machine is.
    let held: Vec<TcpStream> = (0..12)
        .map(|_| {
            let mut s = TcpStream::connect(d.addr).unwrap();
            s.set_read_timeout(Some(STEP_TIMEOUT)).unwrap();
            let keep_alive = request("GET", "/healthz", &[("host", &d.addr.to_string())], "")
                .replace("connection: close", "connection: keep-alive");
            s.write_all(keep_alive.as_bytes()).unwrap();
            let mut seen = Vec::new();
            let mut buf = [0u8; 512];
            while !String::from_utf8_lossy(&seen).contains("{\"ok\":true}") {
                let n = s.read(&mut buf).unwrap();
                assert!(n > 0, "the connection closed before its answer");
                seen.extend_from_slice(&buf[..n]);
            }
            s
        })
        .collect();
    let (status, body) = raw(
        d.addr,
        &request("GET", "/healthz", &[("host", &d.addr.to_string())], ""),
    );
    assert_eq!(status, 503, "{body}");
    assert!(body.contains("max_connections"), "{body}");
    drop(held);
    wait_until("the cap to free", || {
        raw(
            d.addr,
            &request("GET", "/healthz", &[("host", &d.addr.to_string())], ""),
        )
        .0 == 200
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
    let out = run_brdfd(&["serve", "--config", cfg.to_str().unwrap()], None);
    assert_ne!(out.status.code(), Some(0));
    let stderr = String::from_utf8_lossy(&out.stderr);
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
