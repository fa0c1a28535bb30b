//! The operator paths end to end, over loopback HTTP with the bearer token and through the
//! `brdfd` binary: `refit` of every cost function and with `--method paper`, a stale reference
//! refused and `--allow-stale-reference` accepted, `abort`, a fit cancelled while it provably
//! runs (`POST /fits/{id}/cancel`), `[fit] max_concurrent_fits` held, and the exit status and
//! one-line message of every operator command on error.
//!
//! Decisions:
//! - The paper GA runs inside the daemon through the real fit computation, with its population
//!   and generations shrunk by a test-only wrapper (`ServiceOptions::fit_fn`) so that a debug
//!   build fits in a second; the default GA is compared with the default method in the release
//!   job of `.ci/run` (the reliability harness).
//! - No sleeps and no wall-clock bounds: a fit that must be running is one that has told the
//!   test so from inside the fit computation (a channel), and it runs until cancelled; the
//!   concurrency bound is a counter kept by the fit computation itself.

// `serial()` is held for a whole test on purpose: each test has its own runtime, so holding
// it across awaits cannot deadlock, and it keeps the daemon tests from competing for cores.
#![allow(clippy::await_holding_lock)]

mod common;

use std::ops::ControlFlow;
use std::path::Path;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Arc, Mutex, mpsc};
use std::time::Duration;

use brdfd::client::{Client, ClientError};
use brdfd::fit::FitScanError;
use brdfd::optimise::{FitError, GaSettings, Method, Progress};
use brdfd::service::{FitFn, FitJob, ServiceOptions, ServiceSettings, default_fit_fn};
use serde_json::{Value, json};

use common::*;

/// A refit with this seed runs a fit computation that never ends by itself.
const ENDLESS_SEED: u64 = 4242;

/// What the test-only fit computation tells the test.
#[derive(Clone)]
struct FitProbe {
    /// Fit ids of endless fits, sent once each is running inside the computation.
    started: Arc<Mutex<mpsc::Sender<i64>>>,
    /// Fit computations running now, and the most ever running at once.
    running: Arc<AtomicUsize>,
    most: Arc<AtomicUsize>,
    /// Endless fits that saw the cancellation through their observer.
    cancelled: Arc<AtomicUsize>,
}

/// The real fit computation, except that a paper-GA fit runs with a small GA (40 × 60) and a
/// fit with [`ENDLESS_SEED`] reports progress until it is cancelled. Every computation is
/// counted while it runs.
fn probed_fit_fn() -> (FitFn, FitProbe, mpsc::Receiver<i64>) {
    let (tx, rx) = mpsc::channel();
    let probe = FitProbe {
        started: Arc::new(Mutex::new(tx)),
        running: Arc::new(AtomicUsize::new(0)),
        most: Arc::new(AtomicUsize::new(0)),
        cancelled: Arc::new(AtomicUsize::new(0)),
    };
    let p = probe.clone();
    let real = default_fit_fn();
    let fit_fn: FitFn = Arc::new(move |job: &FitJob, observer| {
        let now = p.running.fetch_add(1, Ordering::SeqCst) + 1;
        p.most.fetch_max(now, Ordering::SeqCst);
        let out = if job.request.settings.seed == ENDLESS_SEED {
            p.started.lock().unwrap().send(job.fit.0).unwrap();
            let mut generation = 0;
            loop {
                generation += 1;
                let progress = Progress {
                    generation,
                    generations_total: u32::MAX,
                    best_cost: 1.0,
                    evaluations: u64::from(generation),
                };
                if let ControlFlow::Break(()) = observer(&progress) {
                    p.cancelled.fetch_add(1, Ordering::SeqCst);
                    break Err(FitScanError::Fit {
                        sample: job.sample.clone(),
                        cost: job.request.settings.cost,
                        source: FitError::Cancelled,
                    });
                }
                std::thread::yield_now();
            }
        } else if job.request.settings.method == Method::Paper {
            let mut small = FitJob {
                fit: job.fit,
                scan: job.scan,
                sample: job.sample.clone(),
                reference: job.reference.clone(),
                measured: job.measured,
                request: job.request.clone(),
            };
            small.request.settings.paper = GaSettings {
                population: 40,
                generations: 60,
                stall_generations: 0,
                ..GaSettings::default()
            };
            real(&small, observer)
        } else {
            real(job, observer)
        };
        p.running.fetch_sub(1, Ordering::SeqCst);
        out
    });
    (fit_fn, probe, rx)
}

/// Runs `brdfd` with `--addr` and `--token-file` of the API under test appended.
fn cli(addr: &str, token_file: &Path, args: &[&str]) -> std::process::Output {
    let token = token_file.display().to_string();
    let mut all = args.to_vec();
    all.extend(["--addr", addr, "--token-file", &token]);
    run_brdfd(&all, None)
}

/// [`cli`] on the blocking pool.
async fn cli_blocking(
    addr: &str,
    token_file: &Path,
    args: Vec<&'static str>,
) -> std::process::Output {
    let (addr, token_file) = (addr.to_string(), token_file.to_path_buf());
    blocking(move || cli(&addr, &token_file, &args)).await
}

/// Exit status 0, or the test fails with what the command said.
fn ok(out: &std::process::Output, what: &str) -> String {
    assert!(
        out.status.success(),
        "{what}: exit {:?}, stderr {}",
        out.status.code(),
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout).into_owned()
}

/// Exit status `code` (GUIDE.md "Exit status": 1 failed, 6 refused by the daemon's state) with
/// exactly one line on stderr, starting `error: ` and containing `want`.
fn fails(out: &std::process::Output, code: i32, want: &str, what: &str) {
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(code), "{what}: {stderr}");
    assert_eq!(
        stderr.trim_end().lines().count(),
        1,
        "{what}: one line: {stderr}"
    );
    assert!(stderr.starts_with("error: "), "{what}: {stderr}");
    assert!(stderr.contains(want), "{what}: want {want:?} in {stderr}");
}

async fn blocking<T: Send + 'static>(f: impl FnOnce() -> T + Send + 'static) -> T {
    tokio::task::spawn_blocking(f).await.unwrap()
}

/// `GET /scans/{scan}`'s fits as (id, cost function, method, status).
fn fits_of(client: &Client, scan: i64) -> Vec<(i64, String, String, String)> {
    let v: Value = client.get(&format!("/scans/{scan}")).unwrap();
    v["fits"]
        .as_array()
        .unwrap()
        .iter()
        .map(|f| {
            let r = &f["run"];
            (
                r["id"].as_i64().unwrap(),
                r["cost_function"].as_str().unwrap().to_owned(),
                r["method"].as_str().unwrap().to_owned(),
                r["status"].as_str().unwrap().to_owned(),
            )
        })
        .collect()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn refit_cancel_abort_and_every_operator_error_through_http_and_the_cli() {
    let _serial = serial();
    bounded(async {
        let (fit_fn, probe, started) = probed_fit_fn();
        // Recorded timing: a measurement takes ~2.4 s, so an abort sent after the first reading
        // lands while the scan is measuring.
        let devices = simulated(&mock_devices::ReplayOptions::lenient());
        let d = start(
            devices,
            ServiceSettings {
                max_concurrent_fits: 2,
                ..settings()
            },
            ServiceOptions {
                fit_fn: Some(fit_fn),
            },
        )
        .await;
        let (api, client, token_file) = start_api(&d.service, d.dir.path()).await;
        let addr = api.local_addr().to_string();
        let run = |args: Vec<&'static str>| cli_blocking(&addr, &token_file, args);

        // Errors before anything is measured: one line naming what to do; exit 6 where the
        // daemon's state refuses it, 1 for a bad file.
        fails(&run(vec!["abort"]).await, 6, "nothing", "abort while idle");
        fails(
            &run(vec!["refit", "99", "--cost", "cf1"]).await,
            6,
            "99",
            "refit unknown scan",
        );
        fails(&run(vec!["show", "99"]).await, 6, "99", "show unknown scan");
        let out_file = d.dir.path().join("x.scan.json");
        let out_s: &'static str = Box::leak(out_file.display().to_string().into_boxed_str());
        fails(
            &run(vec!["export", "99", "-o", out_s]).await,
            6,
            "99",
            "export unknown scan",
        );
        assert!(!out_file.exists(), "a failed export writes nothing");
        let bad = d.dir.path().join("bad.scan.json");
        std::fs::write(&bad, "{\"format\": \"brdfd.scan/9\"}").unwrap();
        let bad_s: &'static str = Box::leak(bad.display().to_string().into_boxed_str());
        fails(
            &run(vec!["import", bad_s]).await,
            1,
            "bad.scan.json",
            "import a bad file",
        );
        fails(
            &run(vec!["import", "/nonexistent/x.scan.json"]).await,
            1,
            "x.scan.json",
            "import a missing file",
        );
        fails(
            &run(vec!["scan", "--sample", "T.First"]).await,
            6,
            "brdfd reference",
            "scan without a reference",
        );
        // A wrong token: refused, and said so.
        let wrong = d.dir.path().join("wrong.token");
        std::fs::write(
            &wrong,
            "0000000000000000000000000000000000000000000000000000000000000000\n",
        )
        .unwrap();
        {
            let addr = addr.clone();
            let out = blocking(move || cli(&addr, &wrong, &["status"])).await;
            assert_eq!(
                out.status.code(),
                Some(5),
                "{}",
                String::from_utf8_lossy(&out.stderr)
            );
        }
        // Usage errors exit 2.
        assert_eq!(
            run(vec!["refit", "1", "--cost", "cf9"]).await.status.code(),
            Some(2)
        );

        // The reference and a scan, through the CLI; the scan is fitted by all three.
        ok(&run(vec!["reference"]).await, "reference");
        let out = ok(&run(vec!["scan", "--sample", "T.Operator"]).await, "scan");
        assert!(out.contains("ΔE00"), "{out}");
        let scans: Value = client.get("/scans").unwrap();
        let scan = scans[0]["id"].as_i64().unwrap();
        assert_eq!(
            scan, 1,
            "the first scan of a new store; the commands below name it"
        );
        let first = fits_of(&client, scan);
        assert_eq!(first.len(), 3, "{first:?}");
        assert!(first.iter().all(|f| f.3 == "done"), "{first:?}");
        let status = ok(&run(vec!["status"]).await, "status");
        assert!(status.contains("instruments idle"), "{status}");

        // refit: every cost function again, then the paper GA, through the CLI.
        let out = ok(
            &run(vec!["refit", "1", "--cost", "cf1,cf2,m2", "--seed", "7"]).await,
            "refit all",
        );
        assert!(out.contains("queued"), "{out}");
        let after = fits_of(&client, scan);
        assert_eq!(after.len(), 6, "{after:?}");
        let mut refitted: Vec<&str> = after[3..].iter().map(|f| f.1.as_str()).collect();
        refitted.sort_unstable();
        assert_eq!(refitted, ["cf1", "cf2", "m2"]);
        assert!(after.iter().all(|f| f.3 == "done"), "{after:?}");
        ok(
            &run(vec![
                "refit", "1", "--cost", "cf2", "--method", "paper", "--seed", "3",
            ])
            .await,
            "refit --method paper",
        );
        let paper = fits_of(&client, scan).pop().unwrap();
        assert_eq!(
            (paper.1.as_str(), paper.2.as_str(), paper.3.as_str()),
            ("cf2", "paper", "done")
        );
        let detail: Value = client.get(&format!("/fits/{}", paper.0)).unwrap();
        // 40 initial, then 38 children in each of 60 generations: the GA really ran.
        assert_eq!(
            detail["run"]["result"]["evaluations"],
            40 + 60 * 38,
            "{detail}"
        );
        assert_eq!(detail["run"]["result"]["generations"], 60, "{detail}");

        // Three fits that run until cancelled, with `max_concurrent_fits` = 2: two run (each
        // told us so from inside the computation) and the third waits, queued, until one of
        // them is cancelled. Then it runs, and is cancelled in turn.
        let out = ok(
            &run(vec![
                "refit",
                "1",
                "--cost",
                "cf1,cf2,m2",
                "--seed",
                "4242",
                "--detach",
            ])
            .await,
            "refit (endless)",
        );
        assert!(out.contains("queued"), "{out}");
        let started = Arc::new(Mutex::new(started));
        let next = || {
            let started = started.clone();
            blocking(move || started.lock().unwrap().recv_timeout(STEP_TIMEOUT).unwrap())
        };
        let (a, b) = (next().await, next().await);
        let endless: Vec<i64> = fits_of(&client, scan)[7..].iter().map(|f| f.0).collect();
        assert_eq!(endless.len(), 3, "{endless:?}");
        let third = *endless.iter().find(|f| **f != a && **f != b).unwrap();
        for (fit, want) in [(a, "running"), (b, "running"), (third, "queued")] {
            let v: Value = client.get(&format!("/fits/{fit}")).unwrap();
            assert_eq!(v["run"]["status"], want, "fit {fit}: {v}");
        }
        let st: Value = client.get("/status").unwrap();
        assert_eq!(
            (st["fits_running"].as_u64(), st["fits_queued"].as_u64()),
            (Some(2), Some(1)),
            "{st}"
        );
        let r = client.post(&format!("/fits/{a}/cancel"), None).unwrap();
        assert_eq!(r["cancelling"], a);
        assert_eq!(
            next().await,
            third,
            "the queued fit starts when a slot frees"
        );
        for fit in [b, third] {
            client.post(&format!("/fits/{fit}/cancel"), None).unwrap();
        }
        assert!(
            d.service
                .wait_settled(brdfd::store::ScanId(scan), STEP_TIMEOUT)
                .await
                .unwrap()
        );
        for fit in [a, b, third] {
            let v: Value = client.get(&format!("/fits/{fit}")).unwrap();
            assert_eq!(v["run"]["status"], "cancelled", "{v}");
        }
        assert_eq!(
            probe.cancelled.load(Ordering::SeqCst),
            3,
            "each computation saw its cancel"
        );
        // A finished fit cannot be cancelled (400), an unknown one is not found (404).
        let e = client.post(&format!("/fits/{a}/cancel"), None).unwrap_err();
        assert!(
            matches!(e, ClientError::Refused { status: 400, .. }),
            "{e:?}"
        );
        assert!(e.to_string().contains("is cancelled"), "{e}");
        let e = client.post("/fits/9999/cancel", None).unwrap_err();
        assert!(
            matches!(e, ClientError::Refused { status: 404, .. }),
            "{e:?}"
        );

        // Abort a scan once a reading is in: through the CLI, the readings kept.
        let mut events = d.service.subscribe();
        let v = client
            .post("/scans", Some(&json!({"sample": "T.Aborted"})))
            .unwrap();
        let aborted = v["scan"].as_i64().unwrap();
        loop {
            if let brdfd::service::Event::ScanReading { scan, .. } = events.recv().await.unwrap()
                && scan.0 == aborted
            {
                break;
            }
        }
        let out = ok(&run(vec!["abort"]).await, "abort");
        assert!(out.contains(&format!("scan {aborted} aborting")), "{out}");
        assert!(d.service.wait_idle(STEP_TIMEOUT).await);
        let v: Value = client.get(&format!("/scans/{aborted}")).unwrap();
        assert_eq!(v["scan"]["state"], "aborted", "{v}");
        let n = v["readings"].as_array().unwrap().len();
        assert!((1..14).contains(&n), "{n} readings kept");
        fails(
            &run(vec!["refit", "2"]).await,
            6,
            "aborted",
            "refit an aborted scan",
        );

        // --json: `status` is the daemon's JSON; `scan` is NDJSON — the answer, every event of
        // this scan in order, then the scan's detail — and nothing else on stdout.
        let status: Value =
            serde_json::from_str(&ok(&run(vec!["status", "--json"]).await, "status --json"))
                .unwrap();
        assert!(status["busy"].is_null(), "{status}");
        let out = ok(
            &run(vec!["scan", "--sample", "T.Json", "--json"]).await,
            "scan --json",
        );
        let lines: Vec<Value> = out
            .lines()
            .map(|l| serde_json::from_str(l).unwrap_or_else(|e| panic!("{e}: {l}")))
            .collect();
        let types: Vec<&str> = lines.iter().map(|v| v["type"].as_str().unwrap()).collect();
        assert_eq!(types.first(), Some(&"accepted"), "{types:?}");
        assert_eq!(types.last(), Some(&"result"), "{types:?}");
        let scan = lines[0]["scan"].as_i64().unwrap();
        assert_eq!(
            types.iter().filter(|t| **t == "scan_reading").count(),
            14,
            "{types:?}"
        );
        assert!(types.contains(&"scan_complete"), "{types:?}");
        assert_eq!(
            types.iter().filter(|t| **t == "fit_done").count(),
            3,
            "{types:?}"
        );
        let result = &lines.last().unwrap()["scan"];
        assert_eq!(result["scan"]["id"].as_i64(), Some(scan), "{result}");
        assert_eq!(result["scan"]["state"], "complete", "{result}");
        assert!(
            lines[1..lines.len() - 1]
                .iter()
                .all(|e| e["scan"].as_i64() == Some(scan)),
            "only this scan's events"
        );

        // export, refit and import with --json: one object naming the file; NDJSON ending in
        // the scan's detail.
        let file = d.dir.path().join("json.scan.json");
        let file_s: &'static str = Box::leak(file.display().to_string().into_boxed_str());
        let scan_s: &'static str = Box::leak(scan.to_string().into_boxed_str());
        let v: Value = serde_json::from_str(&ok(
            &run(vec!["export", scan_s, "-o", file_s, "--json"]).await,
            "export --json",
        ))
        .unwrap();
        assert_eq!(v["scan"].as_i64(), Some(scan), "{v}");
        assert_eq!(v["file"], file_s, "{v}");
        let ndjson = |out: String| -> Vec<Value> {
            out.lines()
                .map(|l| serde_json::from_str(l).unwrap_or_else(|e| panic!("{e}: {l}")))
                .collect()
        };
        let refit = ndjson(ok(
            &run(vec!["refit", scan_s, "--cost", "cf1", "--json"]).await,
            "refit --json",
        ));
        assert_eq!(refit[0]["type"], "accepted", "{refit:?}");
        assert_eq!(refit.last().unwrap()["type"], "result", "{refit:?}");
        assert!(refit.iter().any(|e| e["type"] == "fit_done"), "{refit:?}");
        let import = ndjson(ok(
            &run(vec!["import", file_s, "--json"]).await,
            "import --json",
        ));
        assert_eq!(import[0]["type"], "accepted", "{import:?}");
        let result = &import.last().unwrap()["scan"];
        assert_eq!(result["scan"]["state"], "complete", "{result}");
        assert_eq!(
            result["scan"]["provenance"]["source"], "imported",
            "{result}"
        );

        // Never more fits at once than `[fit] max_concurrent_fits` (2) over everything above.
        assert_eq!(
            probe.most.load(Ordering::SeqCst),
            2,
            "most fit computations at once"
        );
        api.stop(Duration::from_secs(1)).await;
        d.service.shutdown().await;
    })
    .await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_stale_reference_is_refused_by_refit_until_allowed() {
    let _serial = serial();
    bounded(async {
        // A zero age limit: the reference is stale from the first millisecond after it
        // completes. The test waits for the daemon to say so instead of sleeping.
        let devices = simulated(&strict_fast());
        let d = start(
            devices,
            ServiceSettings {
                reference_max_age: Duration::ZERO,
                ..settings()
            },
            ServiceOptions::default(),
        )
        .await;
        let (api, client, token_file) = start_api(&d.service, d.dir.path()).await;
        let addr = api.local_addr().to_string();
        let run = |args: Vec<&'static str>| cli_blocking(&addr, &token_file, args);
        ok(&run(vec!["reference"]).await, "reference");
        let c = client.clone();
        blocking(move || {
            while c.get("/status").unwrap()["reference"]["stale"] != true {
                // A polling interval; the state is what is waited for.
                std::thread::sleep(Duration::from_millis(2));
            }
        })
        .await;
        let status = ok(&run(vec!["status"]).await, "status");
        assert!(status.contains("too old"), "{status}");
        let out = ok(&run(vec!["scan", "--sample", "T.Stale"]).await, "scan");
        assert!(
            out.contains("--allow-stale-reference"),
            "the scan says it was not fitted: {out}"
        );
        assert!(fits_of(&client, 1).is_empty());
        fails(
            &run(vec!["refit", "1", "--cost", "cf2"]).await,
            6,
            "--allow-stale-reference",
            "refit against a stale reference",
        );
        let e = client
            .post("/scans/1/refit", Some(&json!({"cost_functions": ["cf2"]})))
            .unwrap_err();
        assert!(e.is_conflict(), "{e}");
        assert!(
            fits_of(&client, 1).is_empty(),
            "nothing queued by a refused refit"
        );
        ok(
            &run(vec![
                "refit",
                "1",
                "--cost",
                "cf1,cf2",
                "--allow-stale-reference",
            ])
            .await,
            "refit --allow-stale-reference",
        );
        let fits = fits_of(&client, 1);
        assert_eq!(fits.len(), 2, "{fits:?}");
        assert!(fits.iter().all(|f| f.3 == "done"), "{fits:?}");
        api.stop(Duration::from_secs(1)).await;
        d.service.shutdown().await;
    })
    .await;
}

/// `brdfd refit --all` queues, per chosen scan, only the fits it lacks in the configuration
/// asked for, follows them to the end, and queues nothing the second time (a run stopped half
/// way goes on where it was); `--sample` narrows it.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn refit_all_brings_every_scan_to_a_configuration_once() {
    let _serial = serial();
    bounded(async {
        let d = start(
            simulated(&strict_fast()),
            ServiceSettings {
                cost_functions: vec![brdfd::cost::CostFunction::Cf1],
                bootstrap: 0,
                ..settings()
            },
            ServiceOptions::default(),
        )
        .await;
        let (api, client, token_file) = start_api(&d.service, d.dir.path()).await;
        let addr = api.local_addr().to_string();
        let run = |args: Vec<&'static str>| cli_blocking(&addr, &token_file, args);
        ok(&run(vec!["reference"]).await, "reference");
        ok(
            &run(vec!["scan", "--sample", "T.Archive one"]).await,
            "scan 1",
        );
        ok(
            &run(vec!["scan", "--sample", "T.Archive two"]).await,
            "scan 2",
        );
        // The scans were fitted under these tests' settings: the paper's configuration.
        let out = ok(
            &run(vec!["refit", "--all", "--preset", "paper"]).await,
            "refit --all --preset paper",
        );
        assert!(
            out.contains("2 scans: 0 fits queued, 2 scans already had these fits"),
            "{out}"
        );
        let out = ok(
            &run(vec!["refit", "--all", "--preset", "measured"]).await,
            "refit --all --preset measured",
        );
        assert!(
            out.contains("2 scans: 2 fits queued, 0 scans already had these fits"),
            "{out}"
        );
        assert!(out.contains("every queued fit has ended"), "{out}");
        for scan in [1, 2] {
            let v: Value = client.get(&format!("/scans/{scan}")).unwrap();
            let fresnels: Vec<(String, String)> = v["fits"]
                .as_array()
                .unwrap()
                .iter()
                .map(|f| {
                    (
                        f["run"]["settings"]["fresnel"].as_str().unwrap().to_owned(),
                        f["run"]["status"].as_str().unwrap().to_owned(),
                    )
                })
                .collect();
            assert_eq!(
                fresnels,
                [
                    ("incidence".to_owned(), "done".to_owned()),
                    ("exact".to_owned(), "done".to_owned())
                ],
                "scan {scan}"
            );
        }
        // Again: nothing is missing any more.
        let out = ok(
            &run(vec!["refit", "--all", "--preset", "measured", "--json"]).await,
            "refit --all again",
        );
        let v: Value = serde_json::from_str(out.lines().next().unwrap()).unwrap();
        assert_eq!(v["queued_fits"], json!([]), "{out}");
        assert_eq!(v["scans_already_current"], 2, "{out}");
        // Narrowed to one sample, another configuration.
        let out = ok(
            &run(vec![
                "refit",
                "--all",
                "--sample",
                "one",
                "--fresnel",
                "light-half",
                "--detach",
            ])
            .await,
            "refit --all --sample",
        );
        assert!(out.contains("1 scans: 1 fits queued"), "{out}");
        // --all and a scan id do not go together; a scan id or --all is needed.
        let out = run(vec!["refit", "1", "--all"]).await;
        assert!(!out.status.success());
        let out = run(vec!["refit"]).await;
        assert!(!out.status.success());
        api.stop(Duration::from_secs(1)).await;
        d.service.shutdown().await;
    })
    .await;
}
