//! `brdfd serve` as a child process with a temporary configuration (simulated instruments at
//! the recorded timing, the store in a temporary directory, the API on a free loopback port):
//! killed with SIGKILL mid-scan, it leaves a store that opens, passes `PRAGMA
//! integrity_check`, and marks no scan complete that is not; the next start marks the
//! interrupted scan failed, keeping its readings, and scans again. SIGTERM mid-scan shuts it
//! down gracefully: exit status 0, the scan marked aborted with the reason. A `brdfd scan`
//! following either scan exits 3 (no daemon), saying that the daemon stopped.

mod common;

use std::path::Path;
use std::process::Command;
use std::sync::mpsc;

use brdfd::client::Client;
use brdfd::store::{ScanFilter, ScanId, ScanState, Store};
use serde_json::{Value, json};

use common::*;

fn reference(client: &Client) {
    client.post("/reference", None).unwrap();
    wait_until("the reference", || {
        client.get("/status").unwrap()["busy"].is_null()
    });
    assert!(!client.get("/status").unwrap()["reference"].is_null());
}

/// Runs `brdfd scan --sample SAMPLE` against the daemon `d` on a thread of its own, and
/// returns the thread with the scan's id once at least one of its readings is stored.
fn cli_scan_until_some_readings(
    d: &ServeChild,
    sample: &'static str,
) -> (std::thread::JoinHandle<std::process::Output>, i64) {
    let (addr, token) = (d.addr.to_string(), d.dir.join("brdfd.token"));
    let cli = std::thread::spawn(move || {
        run_brdfd(
            &[
                "scan",
                "--sample",
                sample,
                "--addr",
                &addr,
                "--token-file",
                token.to_str().unwrap(),
            ],
            None,
        )
    });
    let mut scan = 0;
    wait_until("the CLI's scan and its first readings", || {
        let list: Value = d.client.get("/scans?limit=1").unwrap();
        match list.as_array().and_then(|l| l.first()) {
            Some(s) if s["sample"] == sample => {
                scan = s["id"].as_i64().unwrap();
                s["reading_count"].as_i64().unwrap_or(0) >= 1
            }
            _ => false,
        }
    });
    (cli, scan)
}

/// The CLI that followed scan `scan` exited 3 (no daemon) with one line saying `why`.
fn exited_no_daemon(out: std::process::Output, scan: i64, why: &str) {
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(3), "{stderr}");
    assert_eq!(stderr.trim_end().lines().count(), 1, "{stderr}");
    assert!(stderr.contains(why), "want {why:?} in {stderr}");
    assert!(
        stderr.contains(&format!("before scan {scan} ended"))
            && stderr.contains(&format!("`brdfd show {scan}`")),
        "{stderr}"
    );
    assert!(!stderr.contains("the scan goes on"), "{stderr}");
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
    let config = write_simulated_config(dir.path(), "", "");
    let db = dir.path().join("brdfd.db");
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .unwrap();
    let (tx, rx) = mpsc::channel();
    let body = std::thread::spawn(move || {
        // SIGKILL mid-scan, under the `brdfd scan` that asked for it.
        let mut d = spawn_serve(&config, &[]);
        reference(&d.client);
        let (cli, killed) = cli_scan_until_some_readings(&d, "T.Killed");
        d.child.kill().unwrap(); // SIGKILL on Unix
        d.child.wait().unwrap();
        exited_no_daemon(
            cli.join().unwrap(),
            killed,
            "the daemon stopped: its event stream closed and nothing answers on",
        );
        let (state, readings) = rt.block_on(async {
            let store = open_and_check(&db).await;
            let detail = store.scan_detail(ScanId(killed)).await.unwrap();
            store.close().await;
            (detail.scan.state, detail.readings.len())
        });
        assert_eq!(state, ScanState::Measuring, "left as it was when killed");
        assert!((1..14).contains(&readings), "{readings} readings");

        // The next start marks it failed, keeping its readings, and scans again.
        let mut d = spawn_serve(&config, &[]);
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
        // Complete in the store comes a moment before the instruments are free (the scan's
        // fits are queued first): wait for both before the next scan.
        wait_until("the scan after restart", || {
            d.client.get(&format!("/scans/{after}")).unwrap()["scan"]["state"] == "complete"
                && d.client.get("/status").unwrap()["busy"].is_null()
        });

        // SIGTERM mid-scan: a graceful stop, which the CLI following the scan hears of.
        let (cli, stopped) = cli_scan_until_some_readings(&d, "T.Terminated");
        let pid = d.child.id().to_string();
        let sent = Command::new("kill").args(["-TERM", &pid]).status().unwrap();
        assert!(sent.success());
        let status = d.child.wait().unwrap();
        assert!(status.success(), "graceful shutdown exits 0: {status}");
        exited_no_daemon(
            cli.join().unwrap(),
            stopped,
            "the daemon stopped: it is shutting down",
        );
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
