//! `brdfd serve` as a child process with a temporary configuration (simulated instruments at
//! the recorded timing, the store in a temporary directory, the API on a free loopback port):
//! killed with SIGKILL mid-scan, it leaves a store that opens, passes `PRAGMA
//! integrity_check`, and marks no scan complete that is not; the next start marks the
//! interrupted scan failed, keeping its readings, and scans again. SIGTERM mid-scan shuts it
//! down gracefully: exit status 0, the scan marked aborted with the reason.

mod common;

use std::io::{BufRead, BufReader};
use std::net::SocketAddr;
use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::sync::mpsc;
use std::time::{Duration, Instant};

use brdfd::client::Client;
use brdfd::store::{ScanFilter, ScanId, ScanState, Store};
use serde_json::{Value, json};

use common::*;

/// A running `brdfd serve` and the address it printed.
struct Daemon {
    child: Child,
    client: Client,
}

impl Drop for Daemon {
    fn drop(&mut self) {
        // A test that failed half-way must not leave a daemon behind.
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

fn write_config(dir: &Path) -> std::path::PathBuf {
    let config = dir.join("brdfd.toml");
    let text = format!(
        "[store]\npath = \"{}\"\n\n[api]\nlisten = \"127.0.0.1:0\"\n\n[log]\nlevel = \"warn\"\n\n\
         [devices.ma_t12]\ntransport = \"simulated\"\n\n[devices.sra]\ntransport = \"simulated\"\n",
        dir.join("brdfd.db").display()
    );
    std::fs::write(&config, text).unwrap();
    config
}

fn spawn_daemon(config: &Path) -> Daemon {
    let mut child = Command::new(env!("CARGO_BIN_EXE_brdfd"))
        .args(["serve", "--config"])
        .arg(config)
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .expect("brdfd serve starts");
    let stdout = child.stdout.take().unwrap();
    let (tx, rx) = mpsc::channel();
    std::thread::spawn(move || {
        let mut line = String::new();
        let _ = BufReader::new(stdout).read_line(&mut line);
        let _ = tx.send(line);
    });
    let line = rx
        .recv_timeout(STEP_TIMEOUT)
        .expect("the daemon prints where it listens");
    let addr: SocketAddr = line
        .split("http://")
        .nth(1)
        .and_then(|rest| rest.split_whitespace().next())
        .and_then(|a| a.parse().ok())
        .unwrap_or_else(|| panic!("no address in {line:?}"));
    Daemon {
        child,
        client: client_of_serve(addr, config.parent().unwrap()),
    }
}

fn wait_until(what: &str, mut done: impl FnMut() -> bool) {
    let deadline = Instant::now() + STEP_TIMEOUT;
    while !done() {
        assert!(Instant::now() < deadline, "timed out waiting for {what}");
        std::thread::sleep(Duration::from_millis(10));
    }
}

fn reference(client: &Client) {
    client.post("/reference", None).unwrap();
    wait_until("the reference", || {
        client.get("/status").unwrap()["busy"].is_null()
    });
    assert!(!client.get("/status").unwrap()["reference"].is_null());
}

/// Starts a scan and returns once at least one of its readings is stored (and not all).
fn scan_until_some_readings(client: &Client, sample: &str) -> i64 {
    let v = client
        .post("/scans", Some(&json!({ "sample": sample })))
        .unwrap();
    let scan = v["scan"].as_i64().unwrap();
    wait_until("the first readings", || {
        let s: Value = client.get(&format!("/scans/{scan}")).unwrap();
        s["scan"]["reading_count"].as_i64().unwrap_or(0) >= 1
    });
    scan
}

async fn open_and_check(db: &Path) -> Store {
    let store = Store::open(db).await.expect("the store opens");
    assert_eq!(store.integrity_check().await.unwrap(), ["ok"]);
    let all = store
        .list_scans(&ScanFilter {
            limit: 1000,
            ..ScanFilter::default()
        })
        .await
        .unwrap();
    for s in &all {
        if s.state == ScanState::Complete {
            assert_eq!(
                s.reading_count, 14,
                "scan {} complete with fewer readings",
                s.id
            );
        }
    }
    store
}

#[test]
fn sigkill_mid_scan_leaves_a_sound_store_and_sigterm_aborts_the_scan_gracefully() {
    let _serial = serial();
    let dir = tempfile::tempdir().unwrap();
    let config = write_config(dir.path());
    let db = dir.path().join("brdfd.db");
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .unwrap();
    let (tx, rx) = mpsc::channel();
    let body = std::thread::spawn(move || {
        // SIGKILL mid-scan.
        let mut d = spawn_daemon(&config);
        reference(&d.client);
        let killed = scan_until_some_readings(&d.client, "T.Killed");
        d.child.kill().unwrap(); // SIGKILL on Unix
        d.child.wait().unwrap();
        let (state, readings) = rt.block_on(async {
            let store = open_and_check(&db).await;
            let detail = store.scan_detail(ScanId(killed)).await.unwrap();
            store.close().await;
            (detail.scan.state, detail.readings.len())
        });
        assert_eq!(state, ScanState::Measuring, "left as it was when killed");
        assert!((1..14).contains(&readings), "{readings} readings");

        // The next start marks it failed, keeping its readings, and scans again.
        let mut d = spawn_daemon(&config);
        let shown = d.client.get(&format!("/scans/{killed}")).unwrap();
        assert_eq!(shown["scan"]["state"], "failed");
        assert_eq!(shown["scan"]["reason"], "daemon stopped during the scan");
        assert_eq!(shown["readings"].as_array().unwrap().len(), readings);
        // The reference measured before the kill is still in force.
        assert!(!d.client.get("/status").unwrap()["reference"].is_null());
        let v = d
            .client
            .post("/scans", Some(&json!({ "sample": "T.After" })))
            .unwrap();
        let after = v["scan"].as_i64().unwrap();
        wait_until("the scan after restart", || {
            d.client.get(&format!("/scans/{after}")).unwrap()["scan"]["state"] == "complete"
        });

        // SIGTERM mid-scan: a graceful stop.
        let stopped = scan_until_some_readings(&d.client, "T.Terminated");
        let pid = d.child.id().to_string();
        let sent = Command::new("kill").args(["-TERM", &pid]).status().unwrap();
        assert!(sent.success());
        let status = d.child.wait().unwrap();
        assert!(status.success(), "graceful shutdown exits 0: {status}");
        rt.block_on(async {
            let store = open_and_check(&db).await;
            let detail = store.scan_detail(ScanId(stopped)).await.unwrap();
            assert_eq!(detail.scan.state, ScanState::Aborted);
            assert_eq!(
                detail.scan.reason.as_deref(),
                Some("the daemon was shut down during the measurement")
            );
            assert!(!detail.readings.is_empty() && detail.readings.len() < 14);
            store.close().await;
        });
        tx.send(()).unwrap();
    });
    rx.recv_timeout(TEST_TIMEOUT)
        .expect("the test finishes within its time bound");
    body.join().unwrap();
}
