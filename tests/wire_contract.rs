//! The API's wire contract (`brdfd::wire`) against a running daemon: every route of the
//! router is called over HTTP, and each JSON answer, read from its raw body, must deserialise
//! into its wire type and serialise back to the same JSON. A field the daemon renames or drops
//! fails the first step (or, for an optional field, the second); a field a type would add or
//! spell differently fails the second. The typed calls of `brdfd::client::Client` are checked
//! against the same daemon.

// `serial()` is held for the whole test on purpose (one runtime; see daemon_http.rs).
#![allow(clippy::await_holding_lock)]

mod common;

use std::net::SocketAddr;
use std::time::Duration;

use brdfd::service::Event;
use brdfd::store::FitRunId;
use brdfd::wire;
use serde::Serialize;
use serde::de::DeserializeOwned;
use serde_json::Value;

use common::*;

/// A raw HTTP client: the body exactly as the daemon sent it, whatever the status.
struct Raw {
    addr: SocketAddr,
    token: String,
    agent: ureq::Agent,
}

/// One answer: status, content type, the `Set-Cookie` header and the body.
struct Answer {
    status: u16,
    content_type: String,
    set_cookie: Option<String>,
    body: Vec<u8>,
}

impl Answer {
    fn text(&self) -> &str {
        std::str::from_utf8(&self.body).expect("a text answer")
    }
}

impl Raw {
    fn new(addr: SocketAddr, token_file: &std::path::Path) -> Raw {
        let token = std::fs::read_to_string(token_file)
            .unwrap()
            .trim()
            .to_string();
        let agent = ureq::Agent::config_builder()
            .http_status_as_error(false)
            .max_redirects(0)
            .timeout_global(Some(Duration::from_secs(60)))
            .build()
            .into();
        Raw { addr, token, agent }
    }

    fn finish(r: Result<ureq::http::Response<ureq::Body>, ureq::Error>) -> Answer {
        let mut r = r.expect("the daemon answers");
        let header = |name: &str| {
            r.headers()
                .get(name)
                .and_then(|v| v.to_str().ok())
                .map(str::to_string)
        };
        let content_type = header("content-type").unwrap_or_default();
        let set_cookie = header("set-cookie");
        let body = r
            .body_mut()
            .with_config()
            .limit(64 << 20)
            .read_to_vec()
            .unwrap();
        Answer {
            status: r.status().as_u16(),
            content_type,
            set_cookie,
            body,
        }
    }

    /// `GET path` with the token, or with `headers` instead when given.
    fn get_with(&self, path: &str, headers: &[(&str, &str)]) -> Answer {
        let mut r = self.agent.get(format!("http://{}{path}", self.addr));
        if headers.is_empty() {
            r = r.header("authorization", format!("Bearer {}", self.token));
        }
        for (k, v) in headers {
            r = r.header(*k, *v);
        }
        Self::finish(r.call())
    }

    fn get(&self, path: &str) -> Answer {
        self.get_with(path, &[])
    }

    /// `POST path` with the token and a JSON body (or none).
    fn post(&self, path: &str, body: Option<&str>) -> Answer {
        let r = self
            .agent
            .post(format!("http://{}{path}", self.addr))
            .header("authorization", format!("Bearer {}", self.token))
            .header("content-type", "application/json");
        Self::finish(match body {
            Some(b) => r.send(b),
            None => r.send_empty(),
        })
    }
}

/// `answer` to `route` read as `T` from its raw body, which must be JSON with `status`; `T`
/// serialised again must give the same JSON.
fn contract<T: DeserializeOwned + Serialize>(route: &str, answer: &Answer, status: u16) -> T {
    let text = answer.text();
    assert_eq!(answer.status, status, "{route}: {text}");
    assert!(
        answer.content_type.starts_with("application/json"),
        "{route}: content type {}",
        answer.content_type
    );
    let typed: T = serde_json::from_str(text).unwrap_or_else(|e| {
        panic!(
            "{route}: the answer is not a {}: {e}\n{text}",
            std::any::type_name::<T>()
        )
    });
    let sent: Value = serde_json::from_str(text).unwrap();
    let again = serde_json::to_value(&typed).unwrap();
    assert_eq!(
        again,
        sent,
        "{route}: {} does not give back the daemon's JSON",
        std::any::type_name::<T>()
    );
    typed
}

/// A refusal of `route`: an [`wire::ErrorBody`] with `status`.
fn refusal(route: &str, answer: &Answer, status: u16) -> wire::ErrorBody {
    let e: wire::ErrorBody = contract(route, answer, status);
    assert!(!e.error.is_empty(), "{route}");
    e
}

/// `answer` to `route` is a 200 that is not JSON, of `content_type`.
fn not_json(route: &str, answer: &Answer, content_type: &str) {
    assert_eq!(answer.status, 200, "{route}: {:?}", answer.text());
    assert!(
        answer.content_type.starts_with(content_type),
        "{route}: content type {}",
        answer.content_type
    );
    assert!(!answer.body.is_empty(), "{route}");
}

async fn blocking<T: Send + 'static>(f: impl FnOnce() -> T + Send + 'static) -> T {
    tokio::task::spawn_blocking(f).await.unwrap()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn every_route_answers_with_its_wire_type() {
    let _serial = serial();
    bounded(async {
        // Recorded timing (a measurement takes ~2.4 s): a scan is still running when it is
        // looked at and aborted below.
        let d = start_builtin(mock_devices::ReplayOptions::lenient()).await;
        let (api, client, token_file) = start_api(&d.service, d.dir.path()).await;
        let raw = std::sync::Arc::new(Raw::new(api.local_addr(), &token_file));
        let r = raw.clone();
        let call = move |f: fn(&Raw) -> Answer| {
            let r = r.clone();
            async move { blocking(move || f(&r)).await }
        };

        let a = call(|r| r.get("/healthz")).await;
        let health: wire::Health = contract("GET /healthz", &a, 200);
        assert!(health.ok);

        let a = call(|r| r.get("/status")).await;
        let status: wire::Status = contract("GET /status", &a, 200);
        assert_eq!(status.version, env!("CARGO_PKG_VERSION"));
        assert!(status.busy.is_none() && status.reference.is_none());
        assert_eq!(status.devices.len(), 2);

        let a = call(|r| r.get("/metrics")).await;
        not_json("GET /metrics", &a, "text/plain");

        let a = call(|r| r.get("/bench")).await;
        let bench: wire::Bench = contract("GET /bench", &a, 200);
        assert!(bench.operation.is_none());

        // No reference yet: a refusal, with its kind.
        let a = call(|r| r.post("/scans", Some(r#"{"sample": "contract"}"#))).await;
        let e = refusal("POST /scans", &a, 409);
        assert_eq!(e.kind.as_deref(), Some("no_reference"));

        // The event stream: every event of the reference is an Event, none unknown.
        let c = client.clone();
        let events = blocking(move || c.events().unwrap()).await;
        let reader = std::thread::spawn(move || {
            let mut seen = Vec::new();
            for v in events {
                let text = v.to_string();
                let event: Event = serde_json::from_str(&text)
                    .unwrap_or_else(|e| panic!("GET /events: {e}\n{text}"));
                assert_ne!(event, Event::Unknown, "GET /events: {text}");
                let done = matches!(event, Event::ReferenceComplete { .. });
                seen.push(event);
                if done {
                    break;
                }
            }
            seen
        });
        let a = call(|r| r.post("/reference", None)).await;
        let accepted: wire::ReferenceAccepted = contract("POST /reference", &a, 202);
        let seen = reader.join().unwrap();
        assert!(
            seen.iter()
                .any(|e| e.reference() == Some(accepted.reference)),
            "{seen:?}"
        );
        assert!(d.service.wait_idle(STEP_TIMEOUT).await);

        let a = call(|r| r.post("/scans", Some(r#"{"sample": "contract"}"#))).await;
        let scan = contract::<wire::ScanAccepted>("POST /scans", &a, 202).scan;
        assert!(d.service.wait_settled(scan, STEP_TIMEOUT).await.unwrap());

        // A second scan, looked at while it runs, then aborted.
        let a = call(|r| r.post("/scans", Some(r#"{"sample": "aborted"}"#))).await;
        let second = contract::<wire::ScanAccepted>("POST /scans", &a, 202).scan;
        let a = call(|r| r.get("/status")).await;
        let status: wire::Status = contract("GET /status", &a, 200);
        assert_eq!(
            status.busy.map(|b| b.operation),
            Some(wire::Operation::Scan { scan: second })
        );
        assert_eq!(
            status.reference.map(|r| r.id),
            Some(accepted.reference),
            "the reference in force"
        );
        let a = call(|r| r.get("/bench")).await;
        let bench: wire::Bench = contract("GET /bench", &a, 200);
        let op = bench.operation.expect("the scan in progress");
        assert!(op.in_progress && op.kind.is(wire::BenchKind::Scan) && op.id == second.0);
        let a = call(|r| r.post("/abort", None)).await;
        let aborted: wire::Aborted = contract("POST /abort", &a, 200);
        assert_eq!(aborted.aborted, wire::Operation::Scan { scan: second });
        assert!(d.service.wait_idle(STEP_TIMEOUT).await);

        let a = call(|r| r.get("/scans")).await;
        let list: Vec<wire::ScanSummary> = contract("GET /scans", &a, 200);
        assert_eq!(
            list.iter().map(|s| s.id).collect::<Vec<_>>(),
            [second, scan]
        );
        assert!(list[0].state.is(wire::ScanState::Aborted));
        let a = call(|r| r.get("/scans?sample_contains=CONTR&limit=5")).await;
        let found: Vec<wire::ScanSummary> = contract("GET /scans?sample_contains", &a, 200);
        assert_eq!(found.iter().map(|s| s.id).collect::<Vec<_>>(), [scan]);
        let a = call(|r| r.get("/scans?limit=0")).await;
        refusal("GET /scans?limit=0", &a, 400);

        let path = format!("/scans/{scan}");
        let a = blocking({
            let raw = raw.clone();
            let path = path.clone();
            move || raw.get(&path)
        })
        .await;
        let view: wire::ScanView = contract("GET /scans/{id}", &a, 200);
        assert_eq!(view.scan.id, scan);
        assert_eq!(view.readings.len(), 14);
        assert!(!view.fits.is_empty());
        assert!(
            view.fits
                .iter()
                .all(|f| f.run.status.is(wire::FitStatus::Done))
        );
        let done = view.fits[0].run.id;

        let get = |path: String| {
            let raw = raw.clone();
            async move { blocking(move || raw.get(&path)).await }
        };
        let post = |path: String, body: Option<String>| {
            let raw = raw.clone();
            async move { blocking(move || raw.post(&path, body.as_deref())).await }
        };

        let a = get(format!("/scans/{second}")).await;
        let aborted_view: wire::ScanView = contract("GET /scans/{id} (aborted)", &a, 200);
        assert!(aborted_view.scan.state.is(wire::ScanState::Aborted));
        let a = get("/scans/99999".into()).await;
        assert_eq!(
            refusal("GET /scans/{id}", &a, 404).kind.as_deref(),
            Some("not_found")
        );

        let a = get(format!("/fits/{done}")).await;
        let fit: wire::FitDetail = contract("GET /fits/{id}", &a, 200);
        assert_eq!(fit.run.id, done);
        assert!(fit.evaluation.is_some() && fit.lab.is_some() && fit.colorimetry.is_some());
        let a = get(format!("/fits/{done}/preview.png")).await;
        not_json("GET /fits/{id}/preview.png", &a, "image/png");
        assert!(a.body.starts_with(b"\x89PNG"));

        let a = get(format!("/scans/{scan}/swatches")).await;
        let swatches: wire::Swatches = contract("GET /scans/{id}/swatches", &a, 200);
        assert_eq!(swatches.geometries.len(), 14);
        assert_eq!(swatches.fits.len(), view.fits.len());
        let a = get(format!("/scans/{scan}/readings")).await;
        let readings: Vec<wire::BenchReading> = contract("GET /scans/{id}/readings", &a, 200);
        assert_eq!(readings.len(), 14);
        let a = get("/bench".into()).await;
        let bench: wire::Bench = contract("GET /bench (idle)", &a, 200);
        assert!(!bench.operation.expect("the last scan measured").in_progress);

        // No camera images with a measured scan: the refusal is the contract here.
        let a = get(format!("/scans/{scan}/textures/0.png")).await;
        refusal("GET /scans/{id}/textures/{n}.png", &a, 404);

        let a = get(format!("/scans/{scan}/export")).await;
        assert_eq!(a.status, 200, "{}", a.text());
        let file = wire::ScanFile::from_json(&a.body).expect("GET /scans/{id}/export");
        assert_eq!(file.sample, "contract");
        let a = get(format!("/scans/{scan}/export/csv")).await;
        not_json("GET /scans/{id}/export/{format}", &a, "text/csv");
        let a = get(format!("/report.html?scans={scan}")).await;
        not_json("GET /report.html", &a, "text/html");

        let a = post(
            "/scans/import".into(),
            Some(r#"{"format": "brdfd.scan/9"}"#.into()),
        )
        .await;
        refusal("POST /scans/import (not a scan file)", &a, 422);
        let exported = get(format!("/scans/{scan}/export")).await.body;
        let a = post(
            "/scans/import".into(),
            Some(String::from_utf8(exported).unwrap()),
        )
        .await;
        let imported: wire::Imported = contract("POST /scans/import", &a, 201);
        let imported_scan = imported.scan.expect("the imported scan");
        assert!(imported.scans.is_none() && imported.colorimetry_checks.is_none());
        assert!(
            d.service
                .wait_settled(imported_scan, STEP_TIMEOUT)
                .await
                .unwrap()
        );

        let a = post(
            format!("/scans/{scan}/refit"),
            Some(r#"{"cost_functions": ["cf1", "cf2", "m2"], "seed": 7}"#.into()),
        )
        .await;
        let refit: wire::RefitAccepted = contract("POST /scans/{id}/refit", &a, 202);
        assert_eq!(refit.fits.len(), 3);
        // Two fits run at once: the third is still queued, and is cancelled.
        let last = *refit.fits.last().unwrap();
        let a = post(format!("/fits/{last}/cancel"), None).await;
        let cancelling: wire::Cancelling = contract("POST /fits/{id}/cancel", &a, 202);
        assert_eq!(cancelling.cancelling, last);
        assert!(d.service.wait_settled(scan, STEP_TIMEOUT).await.unwrap());
        let a = post(format!("/fits/{last}/cancel"), None).await;
        refusal("POST /fits/{id}/cancel (ended)", &a, 400);
        let a = post("/abort".into(), None).await;
        assert_eq!(
            refusal("POST /abort (idle)", &a, 409).kind.as_deref(),
            Some("idle")
        );

        // The web page and its session.
        for (path, kind) in [
            ("/", "text/html"),
            ("/app.js", "text/javascript"),
            ("/app.css", "text/css"),
        ] {
            not_json(path, &get(path.into()).await, kind);
        }
        let a = get("/session".into()).await;
        let session: wire::Session = contract("GET /session (token)", &a, 200);
        assert!(matches!(session, wire::Session::SignedOut(_)));
        let a = post("/session/ticket".into(), None).await;
        let ticket: wire::Ticket = contract("POST /session/ticket", &a, 201);
        let r = raw.clone();
        let login = blocking(move || r.get_with(&ticket.path, &[("sec-fetch-site", "none")])).await;
        assert_eq!(login.status, 303, "GET /login: {}", login.text());
        let cookie = login
            .set_cookie
            .expect("the session cookie")
            .split(';')
            .next()
            .unwrap()
            .to_string();
        let r = raw.clone();
        let c = cookie.clone();
        let a = blocking(move || {
            r.get_with(
                "/session",
                &[("cookie", &c), ("sec-fetch-site", "same-origin")],
            )
        })
        .await;
        let session: wire::Session = contract("GET /session (cookie)", &a, 200);
        let wire::Session::SignedIn(signed_in) = session else {
            panic!("GET /session with the cookie: {}", a.text());
        };
        let addr = raw.addr;
        let a = blocking(move || {
            let agent: ureq::Agent = ureq::Agent::config_builder()
                .http_status_as_error(false)
                .build()
                .into();
            Raw::finish(
                agent
                    .post(format!("http://{addr}/session/logout"))
                    .header("cookie", &cookie)
                    .header("content-type", "application/json")
                    .header("sec-fetch-site", "same-origin")
                    .header(&signed_in.csrf_header, &signed_in.csrf)
                    .send_empty(),
            )
        })
        .await;
        let out: wire::LoggedOut = contract("POST /session/logout", &a, 200);
        assert!(out.logged_out);
        let a = post("/session/logout".into(), None).await;
        refusal("POST /session/logout (no session)", &a, 400);

        // The client's typed calls read the same answers.
        let c = client.clone();
        let (status, view, fit, list, swatches, bench, readings) = blocking(move || {
            (
                c.status().unwrap(),
                c.scan(scan).unwrap(),
                c.fit(done).unwrap(),
                c.scans(&wire::ScanQuery {
                    limit: Some(2),
                    ..Default::default()
                })
                .unwrap(),
                c.swatches(scan).unwrap(),
                c.bench().unwrap(),
                c.scan_readings(scan).unwrap(),
            )
        })
        .await;
        assert!(status.busy.is_none());
        assert_eq!(view.scan.id, scan);
        assert_eq!(fit.run.id, done);
        assert_eq!(list.len(), 2);
        assert_eq!(swatches.scan, scan);
        assert!(bench.operation.is_some());
        assert_eq!(readings.len(), 14);
        let c = client.clone();
        let (health, missing, preview) = blocking(move || {
            (
                c.health().unwrap(),
                c.fit(FitRunId(99999)).unwrap_err(),
                c.fit_preview(done).unwrap(),
            )
        })
        .await;
        assert!(health.ok);
        assert!(
            matches!(
                &missing,
                brdfd::client::ClientError::Refused { status: 404, .. }
            ),
            "{missing}"
        );
        assert!(preview.starts_with(b"\x89PNG"));
        api.stop(Duration::from_secs(1)).await;
    })
    .await;
}

/// A field the daemon renamed or dropped is an error of the client, naming the route, not a
/// default: a stand-in daemon answers `GET /status` without `fits_queued`.
#[test]
fn a_renamed_field_is_a_contract_error() {
    use std::io::{Read, Write};
    let listener = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    let addr = listener.local_addr().unwrap();
    let server = std::thread::spawn(move || {
        let (mut s, _) = listener.accept().unwrap();
        let mut buf = [0u8; 4096];
        let _ = s.read(&mut buf).unwrap();
        let body = r#"{"version":"9.9.9","busy":null,"reference":null,"queued":0,
            "fits_running":0,"bootstraps_pending":0,"simulated":{"ma_t12":true,"sra":true},
            "devices":[],"timings":{"acquire_s":0.0,"store_s":0.0,"fit_s":0.0},
            "sync":null,"ingest":null}"#;
        write!(
            s,
            "HTTP/1.1 200 OK\r\ncontent-type: application/json\r\ncontent-length: {}\r\n\
             connection: close\r\n\r\n{body}",
            body.len()
        )
        .unwrap();
    });
    let e = brdfd::client::Client::new(addr).status().unwrap_err();
    server.join().unwrap();
    let text = e.to_string();
    assert!(
        matches!(e, brdfd::client::ClientError::Contract { .. }),
        "{text}"
    );
    assert!(
        text.contains("GET /status") && text.contains("fits_queued"),
        "{text}"
    );
}
