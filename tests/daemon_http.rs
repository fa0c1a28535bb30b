//! The HTTP API on 127.0.0.1:0 with real requests, and the operator commands (the `brdfd`
//! binary) against it: status, a second scan refused while one runs (409, and the CLI prints
//! the daemon's message), listing, showing, exporting and importing, the event stream, and
//! the message when no daemon is listening.

// `serial()` is held for a whole test on purpose: each test has its own runtime, so holding
// it across awaits cannot deadlock, and it keeps the daemon tests from competing for cores.
#![allow(clippy::await_holding_lock)]

mod common;

use std::net::SocketAddr;
use std::time::{Duration, Instant};

use brdfd::client::{Client, ClientError};
use serde_json::{Value, json};

use common::*;

fn brdfd(args: &[&str]) -> std::process::Output {
    run_brdfd(args, None)
}

/// Polls `GET /status` in a blocking thread until the instruments are idle.
async fn wait_idle_http(client: &Client) {
    let client = client.clone();
    tokio::task::spawn_blocking(move || {
        let deadline = Instant::now() + STEP_TIMEOUT;
        loop {
            let v = client.get("/status").unwrap();
            if v["busy"].is_null() {
                return;
            }
            assert!(Instant::now() < deadline, "still busy: {v}");
            std::thread::sleep(Duration::from_millis(20));
        }
    })
    .await
    .unwrap();
}

async fn blocking<T: Send + 'static>(f: impl FnOnce() -> T + Send + 'static) -> T {
    tokio::task::spawn_blocking(f).await.unwrap()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_api_serves_scans_refuses_a_second_scan_and_streams_events() {
    let _serial = serial();
    bounded(async {
        // Recorded timing (a measurement takes ~2.4 s): long enough to be refused during it.
        let d = start_builtin(mock_devices::ReplayOptions::lenient()).await;
        let (api, client, token_file) = start_api(&d.service, d.dir.path()).await;
        let addr = api.local_addr();
        assert!(addr.ip().is_loopback() && addr.port() != 0);
        let addr_arg = addr.to_string();
        // Leaked so that the closure is Copy and each blocking call below can take it.
        let token_arg: &'static str = Box::leak(token_file.display().to_string().into_boxed_str());
        let brdfd = move |args: &[&str]| {
            let mut all = args.to_vec();
            all.extend(["--token-file", token_arg]);
            run_brdfd(&all, None)
        };

        let c = client.clone();
        let status = blocking(move || c.get("/status").unwrap()).await;
        assert_eq!(status["version"], env!("CARGO_PKG_VERSION"));
        assert!(status["busy"].is_null() && status["reference"].is_null());

        // No reference yet: 409 with what to do.
        let c = client.clone();
        let e =
            blocking(move || c.post("/scans", Some(&json!({"sample": "x"}))).unwrap_err()).await;
        assert!(e.is_conflict(), "{e}");
        assert!(e.to_string().contains("brdfd reference"), "{e}");

        // The event stream, read in a thread until the scan's fits are done.
        let c = client.clone();
        let events = blocking(move || c.events().unwrap()).await;
        let reader = std::thread::spawn(move || {
            let mut seen: Vec<Value> = Vec::new();
            for ev in events {
                let done = ev["type"] == "fit_done";
                seen.push(ev);
                if done && seen.iter().filter(|e| e["type"] == "fit_done").count() == 3 {
                    break;
                }
            }
            seen
        });

        let c = client.clone();
        let r = blocking(move || c.post("/reference", None).unwrap()).await;
        assert!(r["reference"].as_i64().unwrap() > 0);
        // While the reference is measured, a scan is refused — through the CLI too.
        let out = blocking({
            let a = addr_arg.clone();
            move || brdfd(&["scan", "--sample", "T.Busy", "--addr", &a])
        })
        .await;
        // Exit 4: busy, retry later.
        assert_eq!(out.status.code(), Some(4));
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(
            stderr.starts_with("error: the instruments are busy: reference"),
            "{stderr}"
        );
        assert!(stderr.contains("brdfd abort"), "{stderr}");
        assert_eq!(stderr.lines().count(), 1, "one line: {stderr}");
        wait_idle_http(&client).await;

        let c = client.clone();
        let v = blocking(move || {
            c.post("/scans", Some(&json!({"sample": "T.Http"})))
                .unwrap()
        })
        .await;
        let scan = v["scan"].as_i64().unwrap();
        let c = client.clone();
        let e = blocking(move || {
            c.post("/scans", Some(&json!({"sample": "T.Second"})))
                .unwrap_err()
        })
        .await;
        match &e {
            ClientError::Refused {
                status, message, ..
            } => {
                assert_eq!(*status, 409);
                assert!(
                    message.contains(&format!("scan {scan} is in progress")),
                    "{message}"
                );
            }
            other => panic!("expected a 409, got {other}"),
        }
        assert!(
            d.service
                .wait_settled(brdfd::store::ScanId(scan), STEP_TIMEOUT)
                .await
                .unwrap()
        );

        // The events arrived in order over SSE.
        let seen = blocking(move || reader.join().unwrap()).await;
        let kinds: Vec<&str> = seen.iter().filter_map(|e| e["type"].as_str()).collect();
        let first = |k: &str| kinds.iter().position(|x| *x == k).unwrap_or(usize::MAX);
        assert!(first("reference_started") < first("reference_complete"));
        assert!(first("reference_complete") < first("scan_started"));
        assert!(first("scan_started") < first("scan_complete"));
        assert!(first("scan_complete") < first("fit_done"));
        assert_eq!(kinds.iter().filter(|k| **k == "scan_reading").count(), 14);
        assert_eq!(
            kinds.iter().filter(|k| **k == "reference_reading").count(),
            14
        );

        // Listing, showing, fits.
        let c = client.clone();
        let (list, shown, missing, bad) = blocking(move || {
            (
                c.get("/scans?state=complete&sample=T.Http").unwrap(),
                c.get(&format!("/scans/{scan}")).unwrap(),
                c.get("/scans/99999").unwrap_err(),
                c.get("/scans/abc").unwrap_err(),
            )
        })
        .await;
        assert_eq!(list.as_array().unwrap().len(), 1);
        assert_eq!(list[0]["id"], scan);
        assert_eq!(shown["scan"]["state"], "complete");
        assert_eq!(shown["readings"].as_array().unwrap().len(), 14);
        assert_eq!(shown["fits"].as_array().unwrap().len(), 3);
        assert_eq!(shown["reference_stale"], false);
        for f in shown["fits"].as_array().unwrap() {
            assert_eq!(f["run"]["status"], "done");
            assert_eq!(
                f["evaluation"]["per_geometry"].as_array().unwrap().len(),
                14
            );
        }
        assert!(
            matches!(missing, ClientError::Refused { status: 404, .. }),
            "{missing}"
        );
        assert!(
            missing.to_string().contains("scan 99999 does not exist"),
            "{missing}"
        );
        assert!(
            matches!(bad, ClientError::Refused { status: 400, .. }),
            "{bad}"
        );
        let fit = shown["fits"][0]["run"]["id"].as_i64().unwrap();
        let c = client.clone();
        let f = blocking(move || c.get(&format!("/fits/{fit}")).unwrap()).await;
        assert_eq!(f["run"]["cost_function"], "cf1");

        // The same state in Prometheus text format, behind the token.
        let c = client.clone();
        let metrics = blocking(move || c.get_text("/metrics").unwrap()).await;
        for line in [
            "brdfd_scans{state=\"complete\"} 1",
            "brdfd_readings 14",
            "brdfd_fit_runs{status=\"done\",cost_function=\"cf1\"} 1",
            "brdfd_fits_queued 0",
            "brdfd_busy 0",
            "brdfd_simulated{instrument=\"sra\"} 1",
            "# TYPE brdfd_device_transitions_total counter",
        ] {
            assert!(metrics.lines().any(|l| l == line), "{line} in\n{metrics}");
        }
        assert!(
            metrics.contains(
                "brdfd_device_transitions_total{instrument=\"ma_t12\",state=\"connected\"}"
            ),
            "{metrics}"
        );
        let anonymous = brdfd::client::Client::new(addr).without_token("sent no token");
        let refused = blocking(move || anonymous.get_text("/metrics").unwrap_err()).await;
        assert!(
            matches!(refused, ClientError::Unauthorized { .. }),
            "{refused}"
        );

        // The CLI's views of the same.
        let out = blocking({
            let a = addr_arg.clone();
            move || brdfd(&["show", &scan.to_string(), "--addr", &a])
        })
        .await;
        assert!(out.status.success());
        let text = String::from_utf8_lossy(&out.stdout);
        assert!(text.contains("sample \"T.Http\", complete"), "{text}");
        assert_eq!(text.matches(" done ").count(), 3, "{text}");
        let out = blocking({
            let a = addr_arg.clone();
            move || brdfd(&["scans", "--addr", &a])
        })
        .await;
        assert!(String::from_utf8_lossy(&out.stdout).contains("T.Http"));

        // Export through the CLI, import the file back through the CLI.
        let file = d.dir.path().join("exported.scan.json");
        let out = blocking({
            let a = addr_arg.clone();
            let f = file.display().to_string();
            move || brdfd(&["export", &scan.to_string(), "-o", &f, "--addr", &a])
        })
        .await;
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        let exported = brdfd::scan::Scan::read_file(&file).unwrap();
        assert_eq!(exported.sample, "T.Http");
        let out = blocking({
            let a = addr_arg.clone();
            let f = file.display().to_string();
            move || brdfd(&["import", &f, "--addr", &a])
        })
        .await;
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        let text = String::from_utf8_lossy(&out.stdout);
        assert!(text.contains("imported as scan"), "{text}");
        assert_eq!(text.matches(" done ").count(), 3, "{text}");

        // A malformed import is refused naming the problem.
        let c = client.clone();
        let e = blocking(move || {
            c.post_text("/scans/import", "{\"format\": \"brdfd.scan/9\"}")
                .unwrap_err()
        })
        .await;
        assert!(matches!(e, ClientError::Refused { status: 422, .. }), "{e}");

        d.service.shutdown().await;
        api.stop(Duration::from_secs(1)).await;
    })
    .await;
}

#[test]
fn every_operator_command_says_when_no_daemon_is_listening() {
    // A port nothing listens on: bind one, note it, close it.
    let addr: SocketAddr = {
        let l = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
        l.local_addr().unwrap()
    };
    let a = addr.to_string();
    for args in [
        vec!["status", "--addr", &a],
        vec!["reference", "--addr", &a],
        vec!["scan", "--sample", "x", "--addr", &a],
        vec!["scans", "--addr", &a],
        vec!["show", "1", "--addr", &a],
    ] {
        let out = brdfd(&args);
        // Exit 3: no daemon.
        assert_eq!(out.status.code(), Some(3), "{args:?}");
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(
            stderr.trim_end(),
            format!("error: no brdfd daemon is listening on {addr} — start one with `brdfd serve`"),
            "{args:?}"
        );
    }
}

/// A port nothing listens on now: bound, noted, closed.
fn free_port() -> u16 {
    let l = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    l.local_addr().unwrap().port()
}

/// `dir/brdfd.toml` with simulated instruments, listening on `port`, its store `brdfd.db` as
/// a relative path.
fn relative_config(dir: &std::path::Path, port: u16) {
    std::fs::write(
        dir.join("brdfd.toml"),
        format!(
            "[store]\npath = \"brdfd.db\"\n\n[api]\nlisten = \"127.0.0.1:{port}\"\n\n\
             [fit]\ncrossval = false\n\n[log]\nlevel = \"warn\"\n\n\
             [devices.ma_t12]\ntransport = \"simulated\"\n\n[devices.sra]\ntransport = \"simulated\"\n"
        ),
    )
    .unwrap();
}

/// A `brdfd serve` child, killed when dropped.
struct Child(std::process::Child);

impl Drop for Child {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

#[test]
fn a_configuration_read_from_another_directory_keeps_its_own_paths() {
    let _serial = serial();
    let tmp = tempfile::tempdir().unwrap();
    let lab = tmp.path().join("lab");
    std::fs::create_dir(&lab).unwrap();
    let port = free_port();
    relative_config(&lab, port);
    // The daemon started in its own directory, as an operator does.
    let mut child = Child(
        std::process::Command::new(env!("CARGO_BIN_EXE_brdfd"))
            .args(["serve", "--config", "brdfd.toml"])
            .current_dir(&lab)
            .env_remove("BRDFD_TOKEN")
            .env_remove("BRDFD_CONFIG")
            .stdout(std::process::Stdio::piped())
            .stderr(std::process::Stdio::null())
            .spawn()
            .unwrap(),
    );
    let line = common::serve::first_line(&mut child.0).expect("the daemon prints where it listens");
    assert!(line.contains(&format!("127.0.0.1:{port}")), "{line}");
    assert!(lab.join("brdfd.db").is_file() && lab.join("brdfd.token").is_file());
    // From the directory above, naming the same file: the same store and token (a scan that
    // does not exist is the daemon's 404, exit 6, not a missing token, exit 5).
    for (args, code) in [
        (vec!["show", "99", "--config", "lab/brdfd.toml"], 6),
        (vec!["status", "--config", "lab/brdfd.toml"], 0),
    ] {
        let out = run_brdfd(&args, Some(tmp.path()));
        assert_eq!(
            out.status.code(),
            Some(code),
            "{args:?}: {}",
            String::from_utf8_lossy(&out.stderr)
        );
    }
    drop(child);
    // A store left in the working directory by the old reading of relative paths is named,
    // not silently replaced by a new one beside the file.
    let old = tmp.path().join("old");
    std::fs::create_dir(&old).unwrap();
    std::fs::create_dir(old.join("etc")).unwrap();
    relative_config(&old.join("etc"), port);
    std::fs::write(old.join("brdfd.db"), "").unwrap();
    let out = run_brdfd(&["status", "--config", "etc/brdfd.toml"], Some(&old));
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{stderr}");
    assert!(stderr.contains("store.path"), "{stderr}");
    assert!(stderr.contains("Write its full path"), "{stderr}");
    assert!(!old.join("etc/brdfd.db").exists());
}

#[test]
fn no_daemon_on_the_configured_address_says_how_to_name_another() {
    let tmp = tempfile::tempdir().unwrap();
    let port = free_port();
    relative_config(tmp.path(), port);
    let out = run_brdfd(&["status", "--config", "brdfd.toml"], Some(tmp.path()));
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(3), "{stderr}");
    assert!(
        stderr.contains(&format!("no brdfd daemon is listening on 127.0.0.1:{port}")),
        "{stderr}"
    );
    assert!(stderr.contains("[api] listen of brdfd.toml"), "{stderr}");
    assert!(stderr.contains("--addr IP:PORT"), "{stderr}");
    assert!(stderr.contains("--config"), "{stderr}");
}

#[test]
fn a_port_in_use_is_said_once_with_the_option_that_moves_it() {
    let _serial = serial();
    let tmp = tempfile::tempdir().unwrap();
    relative_config(tmp.path(), 0);
    let taken = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    let addr = taken.local_addr().unwrap().to_string();
    let out = run_brdfd(
        &["serve", "--config", "brdfd.toml", "--listen", &addr],
        Some(tmp.path()),
    );
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "{stderr}");
    let error: Vec<&str> = stderr.lines().filter(|l| l.starts_with("error:")).collect();
    assert_eq!(error.len(), 1, "{stderr}");
    assert_eq!(
        error[0].to_lowercase().matches("in use").count(),
        1,
        "{stderr}"
    );
    assert!(error[0].contains("--listen 127.0.0.1:PORT"), "{stderr}");
    assert!(error[0].contains("[api] listen"), "{stderr}");
}
