//! `brdfd serve` as a child process with a temporary configuration (simulated instruments at
//! the recorded timing, the store in a temporary directory, the API on a free loopback port):
//! killed with SIGKILL mid-scan, it leaves a store that opens, passes `PRAGMA
//! integrity_check`, and marks no scan complete that is not; the next start marks the
//! interrupted scan failed, keeping its readings, and scans again. SIGTERM mid-scan shuts it
//! down gracefully: exit status 0, the scan marked aborted with the reason.

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
    let config = write_simulated_config(dir.path(), "", "");
    let db = dir.path().join("brdfd.db");
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .unwrap();
    let (tx, rx) = mpsc::channel();
    let body = std::thread::spawn(move || {
        // SIGKILL mid-scan.
        let mut d = spawn_serve(&config, &[]);
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
