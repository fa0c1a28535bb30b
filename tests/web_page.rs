//! The operator's web page in a real headless Chromium, driven through chromedriver
//! (`fantoccini`), against the daemon's service and HTTP API on loopback with simulated
//! instruments at recorded timing.
//!
//! One browser session walks through what an operator does: log in through `brdfd open`'s link,
//! measure the reference, scan a sample (the 14 cells and the 3 fits appear without a reload,
//! coloured as the sample's own recording), open the result, download a CxF3 export, list the
//! scans, abort a scan midway, pull the SRA's cable (fault injection) and see the page say so,
//! restart the daemon and see the page reconnect. A page on another loopback port, in the same
//! browser with the session cookie set, tries every way it has to trigger the daemon and
//! fails. The browser's console must hold no error. Screenshots of each view are saved under
//! `target/tmp/web-screenshots/`; the page's own figures (committed → painted latency, first
//! render, page weight) are printed.
//!
//! Needs Debian's `chromium` and `chromium-driver` (`.ci/run` installs them); without them the
//! test fails and says so.

mod common;

use std::net::SocketAddr;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use brdfd::api::{Access, ApiOptions, ApiServer, Token};
use brdfd::service::{Devices, ReadingShown, Service, ServiceOptions, devices::Simulators};
use brdfd::store::{FitStatus, ReadingValues, ReferenceId, ScanState, ScanSummary, Store};
use drivers::protocol::ReadingValue;
use drivers::{DriverConfig, Instrument};
use fantoccini::{Client, ClientBuilder, Locator};
use mock_devices::{ReplayOptions, SimMat12, SimSra};
use serde_json::{Value, json};

const CHROMEDRIVER: &str = "/usr/bin/chromedriver";
const CHROMIUM: &str = "/usr/bin/chromium";
const WAIT: Duration = Duration::from_secs(60);

fn screenshots_dir() -> PathBuf {
    let d = Path::new(env!("CARGO_TARGET_TMPDIR")).join("web-screenshots");
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// chromedriver on a free loopback port, killed when dropped.
struct Driver {
    child: Child,
    port: u16,
}

impl Drop for Driver {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

fn free_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port()
}

fn start_chromedriver() -> Driver {
    for tool in [CHROMEDRIVER, CHROMIUM] {
        assert!(
            Path::new(tool).exists(),
            "{tool} is missing: install Debian's chromium and chromium-driver (`.ci/run` does)"
        );
    }
    let port = free_port();
    let child = Command::new(CHROMEDRIVER)
        .arg(format!("--port={port}"))
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .expect("chromedriver starts");
    let deadline = Instant::now() + Duration::from_secs(20);
    while std::net::TcpStream::connect(("127.0.0.1", port)).is_err() {
        assert!(Instant::now() < deadline, "chromedriver did not listen");
        std::thread::sleep(Duration::from_millis(50));
    }
    Driver { child, port }
}

async fn browser(driver: &Driver, downloads: &Path) -> Client {
    let mut caps = serde_json::Map::new();
    caps.insert(
        "goog:chromeOptions".into(),
        json!({
            "binary": CHROMIUM,
            "args": ["--headless=new", "--no-sandbox", "--disable-gpu",
                     "--disable-dev-shm-usage", "--window-size=1280,800",
                     "--no-first-run", "--disable-extensions"],
            "prefs": {
                "download.default_directory": downloads.to_str().unwrap(),
                "download.prompt_for_download": false,
            },
        }),
    );
    caps.insert("goog:loggingPrefs".into(), json!({ "browser": "ALL" }));
    ClientBuilder::new(hyper_util::client::legacy::connect::HttpConnector::new())
        .capabilities(caps)
        .connect(&format!("http://127.0.0.1:{}", driver.port))
        .await
        .expect("a Chromium session")
}

/// The browser's console messages at level SEVERE since the last call (chromedriver's log
/// endpoint, which fantoccini does not wrap).
fn console_errors(driver: &Driver, session: &str) -> Vec<String> {
    let url = format!("http://127.0.0.1:{}/session/{session}/se/log", driver.port);
    let answer: Value = ureq::post(&url)
        .send_json(json!({ "type": "browser" }))
        .expect("chromedriver's log")
        .body_mut()
        .read_json()
        .expect("JSON");
    answer["value"]
        .as_array()
        .cloned()
        .unwrap_or_default()
        .into_iter()
        .filter(|e| e["level"] == "SEVERE")
        .map(|e| e["message"].as_str().unwrap_or("").to_string())
        .collect()
}

/// The simulated instruments of the embedded recordings (lenient, as `brdfd serve`) at
/// recorded timing times `speed` (1.0: as recorded; 0.25: four times slower), the SRA's cable
/// pulled for good after frame `sra_unplug_after`.
fn instruments(sra_unplug_after: Option<usize>, speed: f64) -> Devices {
    let options = ReplayOptions::lenient().speed(speed);
    let m = SimMat12::new(common::playlist(Instrument::MaT12), options.clone()).unwrap();
    let s = SimSra::new(
        common::playlist(Instrument::Sra),
        ReplayOptions {
            unplug_after: sra_unplug_after,
            ..options
        },
    )
    .unwrap();
    let config = DriverConfig {
        reconnect_attempts: 2,
        backoff_initial: Duration::from_millis(200),
        ..DriverConfig::default()
    };
    Devices {
        ma_t12: brdfd::service::devices::spawn_mat12_with(m.factory(), config.clone(), None),
        sra: Some(brdfd::service::devices::spawn_sra_with(
            s.factory(),
            config,
            None,
        )),
        simulators: Simulators {
            ma_t12: Some(m),
            sra: Some(s),
        },
        recorders: Vec::new(),
    }
}

/// A daemon: the service on the store in `dir` and the API on `addr`.
struct Daemon {
    service: Service,
    api: ApiServer,
}

async fn start_daemon(dir: &Path, addr: SocketAddr, devices: Devices) -> Daemon {
    let store = Store::open(&dir.join("brdfd.db")).await.unwrap();
    let service = Service::start(
        store,
        devices,
        common::settings(),
        ServiceOptions::default(),
    )
    .await
    .unwrap();
    let token_file = dir.join("brdfd.token");
    let (token, _) = Token::load_or_create(&token_file).unwrap();
    let options = ApiOptions::new(Access::new(token).with_token_file(&token_file));
    let api = ApiServer::start(service.clone(), addr, options)
        .await
        .expect("the API starts");
    Daemon { service, api }
}

impl Daemon {
    async fn stop(self) {
        self.api.stop(Duration::from_secs(1)).await;
        self.service.shutdown().await;
    }

    /// Every scan in the daemon's store.
    async fn scans(&self) -> Vec<ScanSummary> {
        self.service
            .store()
            .list_scans(&Default::default())
            .await
            .unwrap()
    }

    /// The store's reference in force, if any.
    async fn latest_reference(&self) -> Option<ReferenceId> {
        let latest = self.service.store().latest_reference().await.unwrap();
        latest.map(|r| r.id)
    }
}

/// What `script` returns on the page.
async fn eval(c: &Client, script: &str) -> Value {
    c.execute(script, vec![]).await.unwrap()
}

/// The text of the element `locator` finds. The page re-renders a view when news arrives, so
/// an element found may be replaced before its text is read: it is then found again.
async fn text_of(c: &Client, locator: Locator<'_>) -> String {
    for _ in 0..20 {
        match c.find(locator).await.unwrap().text().await {
            Ok(text) => return text,
            Err(fantoccini::error::CmdError::Standard(e))
                if e.error == fantoccini::error::ErrorStatus::StaleElementReference =>
            {
                tokio::time::sleep(Duration::from_millis(50)).await;
            }
            Err(e) => panic!("reading the text of {locator:?}: {e}"),
        }
    }
    panic!("the element {locator:?} was replaced 20 times while its text was read")
}

/// Polls a script until it returns true.
async fn wait_js(c: &Client, what: &str, script: &str) {
    let deadline = Instant::now() + WAIT;
    loop {
        if eval(c, script).await == Value::Bool(true) {
            return;
        }
        if Instant::now() > deadline {
            let body = eval(c, "return document.body.innerText").await;
            panic!(
                "timed out waiting for {what}; the page says:\n{}",
                body.as_str().unwrap_or("")
            );
        }
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
}

async fn shot(c: &Client, name: &str) {
    let png = c.screenshot().await.unwrap();
    assert_eq!(&png[1..4], b"PNG");
    std::fs::write(screenshots_dir().join(format!("{name}.png")), png).unwrap();
}

async fn click(c: &Client, css: &str) {
    c.wait()
        .at_most(WAIT)
        .for_element(Locator::Css(css))
        .await
        .unwrap_or_else(|e| panic!("{css}: {e}"))
        .click()
        .await
        .unwrap_or_else(|e| panic!("click {css}: {e}"));
}

/// Types `text` into the field `css` (WebDriver key codes such as Enter, `\u{E007}`, work).
async fn type_into(c: &Client, css: &str, text: &str) {
    c.find(Locator::Css(css))
        .await
        .unwrap_or_else(|e| panic!("{css}: {e}"))
        .send_keys(text)
        .await
        .unwrap_or_else(|e| panic!("typing into {css}: {e}"));
}

/// The states of the page the walk waits for, by name (what a timeout reports): each a
/// script that returns true once the page shows it.
const PAGE_STATES: &[(&str, &str)] = &[
    (
        "the sign-in prompt",
        "return document.body.innerText.includes('brdfd open')",
    ),
    (
        "the bench",
        "return !!document.getElementById('measure-reference') && document.querySelectorAll('[data-device]').length === 2",
    ),
    (
        "the reference",
        "const op = document.getElementById('op'); return op.dataset.state === 'complete' && op.dataset.readings === '14'",
    ),
    (
        "the reference in force",
        "return !!document.getElementById('reference-age')",
    ),
    (
        "the scan's readings",
        "const op = document.getElementById('op'); return op.dataset.readings === '14' && op.dataset.state === 'complete'",
    ),
    (
        "three finished fits",
        "return document.querySelectorAll('#fits tr[data-status=done]').length === 3",
    ),
    (
        "the result view",
        "const best = document.querySelector('#de-table .best');
         const held = [...document.querySelectorAll('#de-table td.held-out')].map((td) => td.dataset.heldOut);
         const byHeld = held.length === 3 && held.every((v) => v !== undefined);
         const min = Math.min(...held.map(Number));
         const bestHeld = best && best.closest('tr').querySelector('td.held-out').dataset.heldOut;
         return document.querySelectorAll('#de-table tbody tr').length === 3 && !!best
           && (byHeld ? best.dataset.by === 'held-out' && best.textContent === '★ predicts best' && Number(bestHeld) === min
                      : best.dataset.by === 'fitted' && best.textContent === '★ best fit')
           && document.querySelectorAll('#de-table td.reach').length === 3
           && [...document.querySelectorAll('#de-table td.reach')].every((td) => ['in-reach', 'marginal', 'out-of-reach'].includes(td.dataset.reach) && /expect ΔE00 \\d/.test(td.textContent))",
    ),
    (
        "measured and fitted swatches",
        "return document.querySelectorAll('#swatches tbody tr').length === 4 && [...document.querySelectorAll('#swatches .sw')].every((s) => s.style.background !== '')",
    ),
    (
        "the residuals",
        "const rows = document.querySelectorAll('#residuals tbody tr');
         return rows.length === 3 && [...rows].every((r) => r.querySelectorAll('td').length === 14
           && [...r.querySelectorAll('td')].every((td) => /^[+-]\\d+\\.\\d\\d$/.test(td.textContent)))",
    ),
    (
        "the previews",
        "const imgs = [...document.querySelectorAll('.previews button.enlarge img')]; return imgs.length === 3 && imgs.every((i) => i.complete && i.naturalWidth > 0)",
    ),
    (
        "the enlarged preview",
        "const d = document.getElementById('preview-dialog'); const i = d && d.querySelector('img'); return !!d && d.open && !!i && i.complete && i.clientWidth > document.querySelector('.previews button.enlarge img').clientWidth",
    ),
    (
        "the refit's answer",
        "const b = document.getElementById('banner'); return !b.hidden && /^Fits \\d+ queued/.test(b.textContent)",
    ),
    (
        "the scan list",
        "return document.querySelectorAll('#scan-list tbody tr').length >= 1",
    ),
    (
        "the search for \"sky B\"",
        "const rows = document.querySelectorAll('#scan-list tbody tr'); return document.getElementById('f-sample').value === 'sky B' && rows.length === 1 && rows[0].textContent.includes('T.Sky blue')",
    ),
    (
        "the search for \"lavender\"",
        "return document.getElementById('f-sample').value === 'lavender' && document.body.innerText.includes('No scans match.')",
    ),
    (
        "the whole list again",
        "return document.getElementById('f-sample').value === '' && document.querySelectorAll('#scan-list tbody tr').length >= 1",
    ),
    (
        "the bench, ready to scan",
        "return !!document.querySelector('#scan:not([disabled])')",
    ),
    (
        "the abort",
        "return document.getElementById('op').dataset.state === 'aborted'",
    ),
    (
        "both instruments connected after the abort",
        "return [...document.querySelectorAll('[data-device] .badge[data-state]')].every((b) => b.dataset.state === 'connected') && !!document.querySelector('#scan:not([disabled])')",
    ),
    (
        "the aborted scan's view",
        "return !!document.getElementById('kept-cells') && !!document.getElementById('not-fitted')",
    ),
    (
        "the SRA's state on the page",
        "const d = document.querySelector('[data-device=sra] .badge'); return !!d && d.dataset.state !== 'connected' && d.dataset.state !== 'unknown'",
    ),
    (
        "the banner",
        "const b = document.getElementById('banner'); return !b.hidden && b.textContent.includes('RA-532H')",
    ),
    (
        "the failed scan",
        "return document.getElementById('op').dataset.state === 'failed'",
    ),
    (
        "the lost connection",
        "return document.getElementById('stream').classList.contains('down')",
    ),
    (
        "the reconnection",
        "return document.getElementById('stream').textContent === 'live' && document.getElementById('banner').textContent.includes('Reconnected')",
    ),
    (
        "both instruments connected again",
        "return [...document.querySelectorAll('[data-device] .badge[data-state]')].every((b) => b.dataset.state === 'connected')",
    ),
    (
        "the bench rebuilt from the daemon",
        "return (window.brdfdMetrics || {syncs: []}).syncs.length >= 1",
    ),
    (
        "14 of 14 readings after the reload",
        "const op = document.getElementById('op'); return !!op && op.dataset.readings === '14' && op.dataset.state === 'complete' && document.querySelectorAll('#cells .cell.done').length === 14 && op.textContent.includes('14 of 14 readings') && op.textContent.includes('T.Saffron yellow')",
    ),
    (
        "the scan's fits in the second tab",
        "return document.querySelectorAll('#fits tr[data-status]').length === 3",
    ),
    (
        "the hostile page's attempts",
        "return document.getElementById('result').textContent !== 'running'",
    ),
    (
        "the camera's images, loaded",
        "const i = document.querySelectorAll('#textures img');
         return i.length > 0 && [...i].every((e) => e.complete && e.naturalWidth > 0)",
    ),
    (
        "the bench before logging out",
        "return !!document.getElementById('measure-reference')",
    ),
    (
        "the sign-in prompt after logging out",
        "return document.body.innerText.includes('You logged out')",
    ),
    (
        "the sign-in prompt after reload",
        "return document.body.innerText.includes('brdfd open')",
    ),
];

/// Waits until the page shows each of `states` in turn (names of [`PAGE_STATES`]).
async fn see(c: &Client, states: &[&str]) {
    for what in states {
        let (_, script) = PAGE_STATES
            .iter()
            .find(|(name, _)| name == what)
            .unwrap_or_else(|| panic!("no page state is named {what:?}"));
        wait_js(c, what, script).await;
    }
}

/// Opens `path` of the page served at `addr` and waits until it shows each of `states`.
async fn open(c: &Client, addr: SocketAddr, path: &str, states: &[&str]) {
    c.goto(&format!("http://{addr}{path}")).await.unwrap();
    see(c, states).await;
}

/// Scans `sample` from the bench with the mouse and waits until the page shows each of
/// `states`.
async fn scan(c: &Client, sample: &str, states: &[&str]) {
    type_into(c, "#sample", sample).await;
    click(c, "#scan:not([disabled])").await;
    see(c, states).await;
}

/// Scans `sample` from the bench with the keyboard alone (Enter in the sample field submits
/// it) and waits for its first reading on the page.
async fn scan_by_keyboard(c: &Client, sample: &str) {
    type_into(c, "#sample", &format!("{sample}\u{E007}")).await;
    wait_js(
        c,
        &format!("a first reading of {sample}"),
        &format!(
            "const op = document.getElementById('op'); return !!op && op.textContent.includes('{sample}') && Number(op.dataset.readings || 0) >= 1"
        ),
    )
    .await;
}

/// The page's swatch colour of a cell, as `#rrggbb`.
async fn cell_colour(c: &Client, geometry: &str) -> String {
    let v = c
        .execute(
            "const el = document.querySelector(`#cell-${arguments[0]} .sw`);
             const m = getComputedStyle(el).backgroundColor.match(/\\d+/g).map(Number);
             return '#' + m.slice(0, 3).map((x) => x.toString(16).padStart(2, '0')).join('');",
            vec![json!(geometry)],
        )
        .await
        .unwrap();
    v.as_str().unwrap().to_string()
}

/// What the page must paint for a recording's MA-T12 reading at `geometry`.
fn recorded_colour(sample: &str, geometry: &str) -> String {
    let r = mock_devices::recordings::by_name(sample).unwrap();
    let reading = r
        .script(Instrument::MaT12)
        .unwrap()
        .readings()
        .into_iter()
        .find(|x| x.geometry == geometry)
        .unwrap();
    let ReadingValue::Reflectance(s) = reading.value else {
        panic!("an MA-T12 reading is a spectrum")
    };
    ReadingShown::of(&ReadingValues::Spectrum(s), 0)
        .srgb
        .unwrap()
}

fn percentile(sorted: &[f64], p: f64) -> f64 {
    let i = ((sorted.len() as f64 - 1.0) * p).round() as usize;
    sorted[i]
}

/// The hostile page: on another loopback port, it tries to make the daemon at `target`
/// measure a reference, by every means a page has, and to read its status; it writes what
/// happened into `#result`.
async fn serve_hostile_page(target: SocketAddr) -> (SocketAddr, tokio::task::JoinHandle<()>) {
    let page = format!(
        r#"<!doctype html><html><body><p id="result">running</p>
<form id="f" method="POST" action="http://{target}/reference" enctype="text/plain" target="sink">
<input name='{{"a":"' value='"}}'></form><iframe name="sink"></iframe>
<script>
const T = "http://{target}";
const out = [];
async function attempt(name, f) {{
  try {{ const r = await f(); out.push(name + ":" + (r && r.type ? r.type + "/" + r.status : "ok")); }}
  catch (e) {{ out.push(name + ":blocked"); }}
}}
(async () => {{
  await attempt("no-cors-json", () => fetch(T + "/reference", {{method: "POST", mode: "no-cors", credentials: "include", headers: {{"Content-Type": "application/json"}}, body: "{{}}"}}));
  await attempt("no-cors-text", () => fetch(T + "/reference", {{method: "POST", mode: "no-cors", credentials: "include", headers: {{"Content-Type": "text/plain"}}, body: "{{}}"}}));
  await attempt("cors-csrf", () => fetch(T + "/reference", {{method: "POST", credentials: "include", headers: {{"Content-Type": "application/json", "X-Brdfd-Csrf": "guess"}}, body: "{{}}"}}));
  await attempt("read-status", async () => {{ const r = await fetch(T + "/status", {{credentials: "include"}}); return {{type: "read", status: (await r.text()).length}}; }});
  await attempt("read-session", async () => {{ const r = await fetch(T + "/session", {{credentials: "include"}}); return {{type: "read", status: (await r.text()).length}}; }});
  await attempt("beacon", async () => {{ navigator.sendBeacon(T + "/scans", JSON.stringify({{sample: "x"}})); }});
  document.getElementById("f").submit();
  await new Promise((r) => setTimeout(r, 1500));
  document.getElementById("result").textContent = out.join(" ");
}})();
</script></body></html>"#
    );
    let app = axum::Router::new().route(
        "/",
        axum::routing::get(move || {
            let page = page.clone();
            async move { axum::response::Html(page) }
        }),
    );
    let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
    let addr = listener.local_addr().unwrap();
    let task = tokio::spawn(async move {
        axum::serve(listener, app).await.unwrap();
    });
    (addr, task)
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn an_operator_scans_watches_and_judges_a_sample_in_a_real_browser() {
    let dir = tempfile::tempdir().unwrap();
    let downloads = tempfile::tempdir().unwrap();
    let addr: SocketAddr = format!("127.0.0.1:{}", free_port()).parse().unwrap();
    // The SRA's cable comes out during the scan of the last recording (T.Pebble grey): after
    // the first reply of that session.
    let sra = common::playlist(Instrument::Sra);
    let pebble = sra.session_of(Some("T.Pebble grey")).unwrap();
    let unplug_frame = sra
        .exchanges()
        .iter()
        .filter(|e| e.session == pebble && e.request.is_some())
        .flat_map(|e| e.replies.iter().map(|r| r.index))
        .nth(1)
        .unwrap();
    let daemon = start_daemon(dir.path(), addr, instruments(Some(unplug_frame), 1.0)).await;
    let driver = start_chromedriver();
    let c = browser(&driver, downloads.path()).await;
    // The study report is drawn on request: on a busy two-core machine that takes longer than
    // WebDriver's default 30 s script timeout.
    c.update_timeouts(fantoccini::wd::TimeoutConfiguration::new(
        Some(Duration::from_secs(180)),
        Some(Duration::from_secs(300)),
        Some(Duration::ZERO),
    ))
    .await
    .unwrap();
    let session_id = c.session_id().await.unwrap().unwrap();

    // Not signed in: the page says how to sign in.
    open(&c, addr, "/", &["the sign-in prompt"]).await;

    // Log in through `brdfd open`'s link.
    let token = std::fs::read_to_string(dir.path().join("brdfd.token")).unwrap();
    let out = common::run_brdfd_env(
        &["open", "--addr", &addr.to_string(), "--no-browser"],
        None,
        &[("BRDFD_TOKEN", token.trim())],
    );
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let url = String::from_utf8(out.stdout).unwrap().trim().to_string();
    assert!(
        url.starts_with(&format!("http://{addr}/login?ticket=")),
        "{url}"
    );
    c.goto(&url).await.unwrap();
    see(&c, &["the bench"]).await;
    assert_eq!(c.current_url().await.unwrap().path(), "/");
    // The link was spent: a second use is refused.
    let again = ureq::get(&url).call();
    assert!(
        matches!(again, Err(ureq::Error::StatusCode(401))),
        "{again:?}"
    );
    // The cookie is HttpOnly: the page's script cannot see it.
    assert_eq!(eval(&c, "return document.cookie").await, json!(""));
    assert_eq!(
        eval(
            &c,
            "return [...document.querySelectorAll('.badge.sim')].length"
        )
        .await,
        json!(2),
        "both instruments carry the SIMULATED badge"
    );
    shot(&c, "1-bench-signed-in").await;

    // Measure the reference: 14 cells fill in, then the reference is in force.
    click(&c, "#measure-reference:not([disabled])").await;
    see(&c, &["the reference", "the reference in force"]).await;

    // Scan T.Sky blue: it is answered from T.Sky blue's recording (not the playlist's next,
    // Freesia pink), 14 cells and 3 fits appear without a reload.
    scan(
        &c,
        "T.Sky blue",
        &["the scan's readings", "three finished fits"],
    )
    .await;
    for g in ["15as15", "45as45", "15as-45"] {
        assert_eq!(
            cell_colour(&c, g).await,
            recorded_colour("T.Sky blue", g),
            "{g}: the cell shows T.Sky blue's own recording"
        );
    }
    let sra_text = text_of(&c, Locator::Css("#cell-sra-20 .num")).await;
    assert!(sra_text.contains("intensity"), "{sra_text}");
    shot(&c, "2-bench-scan-done").await;
    let metrics = eval(&c, "return window.brdfdMetrics").await;
    let mut latency: Vec<f64> = metrics["readingLatencyMs"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_f64().unwrap())
        .collect();
    assert!(
        latency.len() >= 28,
        "reference and scan readings: {latency:?}"
    );
    latency.sort_by(f64::total_cmp);
    let weight = brdfd::api::web::INDEX_HTML.len()
        + brdfd::api::web::APP_JS.len()
        + brdfd::api::web::APP_CSS.len();
    println!(
        "web page figures: reading committed → cell painted p50 {:.0} ms, p99 {:.0} ms over {} readings; first render {:.0} ms; page weight {} bytes (HTML + CSS + JS, uncompressed)",
        percentile(&latency, 0.5),
        percentile(&latency, 0.99),
        latency.len(),
        metrics["firstRenderMs"].as_f64().unwrap_or(f64::NAN),
        weight
    );
    assert!(
        metrics["errors"].as_array().unwrap().is_empty(),
        "{metrics}"
    );

    // The result view: swatches per geometry and cost function, ΔE00 with the best marked.
    let scan_id = eval(
        &c,
        "return document.querySelector('#op a').getAttribute('href')",
    )
    .await;
    let href = scan_id.as_str().unwrap().to_string();
    click(&c, "#op a").await;
    see(&c, &["the result view", "measured and fitted swatches"]).await;
    shot(&c, "3-result-1280").await;
    // Where the model misses: one row of signed ΔL* per finished fit, one cell per geometry,
    // each value the measured minus the fitted L* the daemon computed.
    see(&c, &["the residuals"]).await;
    // Previews keep the aspect ratio of the picture the daemon draws; a click enlarges one.
    see(&c, &["the previews"]).await;
    let ratios = eval(
        &c,
        "return [...document.querySelectorAll('.previews button.enlarge img')].map((i) => [i.naturalWidth / i.naturalHeight, i.clientWidth / i.clientHeight])",
    )
    .await;
    for r in ratios.as_array().unwrap() {
        let (natural, shown) = (r[0].as_f64().unwrap(), r[1].as_f64().unwrap());
        assert!(
            (natural - shown).abs() / natural < 0.02,
            "a preview is shown at its own aspect ratio: {ratios}"
        );
    }
    click(&c, ".previews button.enlarge").await;
    see(&c, &["the enlarged preview"]).await;
    shot(&c, "3b-preview-enlarged").await;
    click(&c, "#preview-dialog button[type=submit]").await;
    // Three widths: a phone (390 px), a laptop (1280 px), a wide screen (1920 px). The page
    // never scrolls sideways as a whole; a table wider than the screen scrolls in its own box,
    // and every ΔE00 column can be reached.
    for (w, name) in [
        (390, "4-result-phone-390"),
        (1920, "4b-result-wide-1920"),
        (1280, "4c-result-1280"),
    ] {
        c.set_window_size(w, 1000).await.unwrap();
        let layout = eval(
            &c,
            "return new Promise((done) => requestAnimationFrame(() => requestAnimationFrame(() => {
               const de = document.getElementById('de-table');
               const box = de.closest('.scroll');
               box.scrollLeft = box.scrollWidth;
               const last = de.querySelector('thead th:nth-child(5)').getBoundingClientRect();
               done({ inner: window.innerWidth, page: document.documentElement.scrollWidth,
                      boxed: [...document.querySelectorAll('main table')].every((t) => !!t.closest('.scroll') || t.getBoundingClientRect().width <= window.innerWidth),
                      lastRight: last.right, lastWidth: last.width,
                      wider: [...document.querySelectorAll('body *')].filter((e) => e.getBoundingClientRect().right > window.innerWidth + 0.5 && !e.closest('.scroll'))
                        .slice(0, 5).map((e) => `${e.tagName}#${e.id}.${e.className}`) });
             })))",
        )
        .await;
        let inner = layout["inner"].as_f64().unwrap();
        assert!(
            (inner - w as f64).abs() < 20.0,
            "the window is {w} px wide: {layout}"
        );
        assert!(
            layout["page"].as_f64().unwrap() <= inner + 1.0,
            "{w} px: the page does not overflow sideways: {layout}"
        );
        assert_eq!(layout["boxed"], json!(true), "{w} px: {layout}");
        assert!(
            layout["lastRight"].as_f64().unwrap() <= inner + 1.0
                && layout["lastWidth"].as_f64().unwrap() > 0.0,
            "{w} px: the ΔE00 'all' column can be scrolled into view: {layout}"
        );
        shot(&c, name).await;
    }
    c.set_window_size(1280, 800).await.unwrap();

    // Download the CxF3 export.
    click(&c, "#dl-cxf3").await;
    let deadline = Instant::now() + WAIT;
    let cxf = loop {
        let done = std::fs::read_dir(downloads.path())
            .unwrap()
            .filter_map(Result::ok)
            .map(|e| e.path())
            .find(|p| p.extension().is_some_and(|e| e == "cxf"));
        if let Some(p) = done {
            break std::fs::read_to_string(p).unwrap();
        }
        assert!(Instant::now() < deadline, "no CxF3 file was downloaded");
        tokio::time::sleep(Duration::from_millis(100)).await;
    };
    assert!(
        cxf.contains("CxF") && cxf.contains("T.Sky blue"),
        "{}",
        &cxf[..cxf.len().min(400)]
    );

    // The study report of this scan, as the page's link downloads it: one HTML file with its
    // figures inlined.
    let report = c
        .execute_async(
            "const done = arguments[arguments.length - 1];
             fetch(document.getElementById('dl-report').href).then(async (r) =>
               done([r.status, r.headers.get('content-disposition'), await r.text()]));",
            vec![],
        )
        .await
        .unwrap();
    assert_eq!(report[0], json!(200), "{}", report[2]);
    assert!(report[1].as_str().unwrap().contains("brdfd-report.html"));
    let html = report[2].as_str().unwrap();
    assert!(html.contains("T.Sky blue") && html.contains("<img src=\"data:image/png;base64,"));
    assert!(!html.contains("<img src=\"fig"), "every figure is inlined");

    // Refit with other settings: cf1 alone, another seed.
    for cf in ["cf2", "m2"] {
        click(&c, &format!("#refit-{cf}")).await;
    }
    type_into(&c, "#refit-seed", "7").await;
    click(&c, "#refit-go").await;
    see(&c, &["the refit's answer"]).await;

    // The scan list.
    open(&c, addr, "/#/scans", &["the scan list"]).await;
    let row = text_of(&c, Locator::Css("#scan-list tbody tr")).await;
    assert!(
        row.contains("T.Sky blue") && row.contains("complete"),
        "{row}"
    );
    assert!(
        row.contains("simulated — replayed from synthetic-t-sky-blue"),
        "the list says which recording answered: {row}"
    );
    // The sample search matches any part of the name, in any case.
    for (query, state) in [
        ("?sample=sky%20B", "the search for \"sky B\""),
        ("?sample=lavender", "the search for \"lavender\""),
        ("", "the whole list again"),
    ] {
        open(&c, addr, &format!("/#/scans{query}"), &[state]).await;
    }
    shot(&c, "5-scan-list").await;

    // Abort a scan midway: some cells filled, then the scan is aborted and keeps them.
    open(&c, addr, "/#/", &["the bench, ready to scan"]).await;
    scan_by_keyboard(&c, "T.Lavender blue").await;
    click(&c, "#abort:not([disabled])").await;
    see(&c, &["the abort"]).await;
    let aborted = daemon
        .scans()
        .await
        .into_iter()
        .find(|s| s.sample == "T.Lavender blue")
        .unwrap();
    assert_eq!(aborted.state, ScanState::Aborted);
    assert!(
        aborted.reading_count < 14,
        "aborted midway: {}",
        aborted.reading_count
    );
    shot(&c, "6-bench-aborted").await;
    // The simulated instruments answer ABORT as the drivers expect: after the abort both stay
    // connected (no red "error"), nothing is left in the banner, and Scan's tooltip follows.
    tokio::time::sleep(Duration::from_millis(1500)).await;
    see(&c, &["both instruments connected after the abort"]).await;
    for d in daemon.service.status().await.unwrap().devices {
        assert_eq!(d.state, "connected", "{}: {}", d.instrument, d.detail);
    }
    let after_abort = eval(
        &c,
        "return [document.getElementById('banner').hidden, document.getElementById('scan').getAttribute('title')]",
    )
    .await;
    assert_eq!(
        after_abort,
        json!([true, null]),
        "no banner, no stale tooltip"
    );
    // The aborted scan's view: the readings it kept, why it stopped, and only what works.
    let aborted_path = format!("/#/scans/{}", aborted.id);
    open(&c, addr, &aborted_path, &["the aborted scan's view"]).await;
    let view = eval(
        &c,
        "return [document.querySelectorAll('#kept-cells [data-kept=yes]').length,
                 document.getElementById('result-state').textContent,
                 document.getElementById('not-fitted').textContent,
                 !!document.getElementById('refit'), !!document.getElementById('dl-cxf3'),
                 !!document.getElementById('dl-scan'), !!document.getElementById('no-downloads'),
                 document.body.innerText.includes('No finished fit yet')]",
    )
    .await;
    assert_eq!(
        view[0],
        json!(aborted.reading_count),
        "every kept reading is shown: {view}"
    );
    assert!(
        view[1]
            .as_str()
            .unwrap()
            .contains("aborted by the operator"),
        "{view}"
    );
    assert!(
        view[2].as_str().unwrap().contains("Scan the sample again"),
        "{view}"
    );
    assert_eq!(
        &view.as_array().unwrap()[3..],
        &[
            json!(false),
            json!(false),
            json!(false),
            json!(true),
            json!(false)
        ],
        "no refit and no download is offered for an aborted scan: {view}"
    );
    shot(&c, "6b-result-aborted").await;

    // Pull the SRA's cable: the scan of T.Pebble grey fails and the page says the SRA is gone.
    open(&c, addr, "/#/", &["the bench, ready to scan"]).await;
    let unplugged = [
        "the SRA's state on the page",
        "the banner",
        "the failed scan",
    ];
    scan(&c, "T.Pebble grey", &unplugged).await;
    shot(&c, "7-bench-sra-unplugged").await;

    // Restart the daemon (same store, token and port): the page notices, then reconnects.
    daemon.stop().await;
    see(&c, &["the lost connection"]).await;
    shot(&c, "8-bench-daemon-gone").await;
    // The restarted daemon's instruments are four times slower than recorded (a scan takes
    // about ten seconds), so that a reload lands mid-scan on any machine.
    let daemon = start_daemon(dir.path(), addr, instruments(None, 0.25)).await;
    see(
        &c,
        &["the reconnection", "both instruments connected again"],
    )
    .await;
    shot(&c, "9-bench-reconnected").await;
    // The console, read once (chromedriver's log command itself can make Chromium drop an
    // open event stream, so it is not read while the page runs): no error but the other
    // event stream's, while the daemon was down.
    let errors: Vec<String> = console_errors(&driver, &session_id)
        .into_iter()
        .filter(|e| {
            !(e.contains(&format!("{addr}/events"))
                && (e.contains("ERR_CONNECTION_REFUSED")
                    || e.contains("ERR_INCOMPLETE_CHUNKED_ENCODING")))
        })
        .collect();
    assert_eq!(errors, Vec::<String>::new());

    // Reload mid-scan: the page rebuilds the scan from the daemon (sample, every reading
    // stored so far), then follows it to 14 of 14; a second tab shows the same.
    scan_by_keyboard(&c, "T.Saffron yellow").await;
    c.refresh().await.unwrap();
    see(&c, &["the bench rebuilt from the daemon"]).await;
    let sync = eval(&c, "return window.brdfdMetrics.syncs[0]").await;
    assert_eq!(sync["kind"], json!("scan"), "{sync}");
    assert_eq!(sync["inProgress"], json!(true), "reloaded mid-scan: {sync}");
    let before_reload = sync["readings"].as_u64().unwrap();
    assert!(
        (1..14).contains(&before_reload),
        "the daemon had some readings, not all: {sync}"
    );
    let painted = eval(
        &c,
        "return document.querySelectorAll('#cells .cell.done').length",
    )
    .await;
    assert!(
        painted.as_u64().unwrap() >= before_reload,
        "every reading stored before the reload is painted after it ({painted} cells, {sync})"
    );
    let op_text = text_of(&c, Locator::Id("op")).await;
    assert!(op_text.contains("\"T.Saffron yellow\""), "{op_text}");
    let first_tab = c.window().await.unwrap();
    let second_tab = c.new_window(true).await.unwrap().handle;
    c.switch_to_window(second_tab.clone()).await.unwrap();
    c.goto(&format!("http://{addr}/#/")).await.unwrap();
    for tab in [second_tab.clone(), first_tab.clone()] {
        c.switch_to_window(tab).await.unwrap();
        see(&c, &["14 of 14 readings after the reload"]).await;
        for g in ["15as-45", "45as110"] {
            assert_eq!(
                cell_colour(&c, g).await,
                recorded_colour("T.Saffron yellow", g),
                "{g}: the rebuilt cell shows T.Saffron yellow's recording"
            );
        }
        let waiting = eval(
            &c,
            "return document.getElementById('cells').innerText.includes('waiting')",
        )
        .await;
        assert_eq!(waiting, json!(false), "no cell is left waiting");
    }
    c.switch_to_window(second_tab).await.unwrap();
    see(&c, &["the scan's fits in the second tab"]).await;
    shot(&c, "10-bench-second-tab").await;
    c.close_window().await.unwrap();
    c.switch_to_window(first_tab).await.unwrap();
    shot(&c, "11-bench-after-reload").await;
    let log = text_of(&c, Locator::Id("log")).await;
    assert!(
        log.contains("T.Pebble grey"),
        "the event log survives the reload: {log}"
    );

    // A page on another loopback port, in this browser (the session cookie is set), tries
    // to make the daemon measure.
    let refs_before = daemon.latest_reference().await;
    let scans_before = daemon.scans().await.len();
    let (hostile, hostile_task) = serve_hostile_page(addr).await;
    open(&c, hostile, "/", &["the hostile page's attempts"]).await;
    let result = text_of(&c, Locator::Id("result")).await;
    println!("the other page's attempts: {result}");
    assert!(result.contains("cors-csrf:blocked"), "{result}");
    assert!(result.contains("read-status:blocked"), "{result}");
    assert!(result.contains("read-session:blocked"), "{result}");
    tokio::time::sleep(Duration::from_millis(500)).await;
    assert_eq!(
        daemon.latest_reference().await,
        refs_before,
        "no reference was started from the other page ({result})"
    );
    assert_eq!(
        daemon.scans().await.len(),
        scans_before,
        "no scan was started from the other page"
    );
    assert!(daemon.service.status().await.unwrap().busy.is_none());
    hostile_task.abort();

    // A real X-Rite export with the instrument camera's images: the result view shows them
    // beside the swatches, loaded through the page's session like every other request.
    let real_dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/real-mat12");
    let x = std::fs::read_dir(&real_dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "xlsx"))
        .flat_map(|p| brdfd::formats::xrite::read_file(&p, &Default::default()).unwrap())
        .find(|x| !x.textures.is_empty())
        .expect("a shared export with texture images");
    let (provenance, taken) = brdfd::service::imported_provenance(&x.scan, "test import").unwrap();
    let (imported, _) = daemon
        .service
        .import_scan_as(&x.scan, &provenance, taken, &x.textures)
        .await
        .unwrap();
    // A report of the real import and a simulated scan together is refused unless asked for,
    // as `brdfd report` refuses it.
    let simulated_scan = daemon
        .scans()
        .await
        .iter()
        .find(|s| s.provenance.simulated())
        .expect("a scan on the simulated instruments")
        .id;
    let report = |query: String| {
        ureq::get(&format!("http://{addr}/report.html?{query}"))
            .header("Authorization", &format!("Bearer {}", token.trim()))
            .call()
    };
    match report(format!("scans={simulated_scan},{imported}")) {
        Err(ureq::Error::StatusCode(400)) => {}
        other => panic!("a mixed report was not refused: {other:?}"),
    }
    assert!(
        report(format!(
            "scans={simulated_scan},{imported}&include_simulated=true"
        ))
        .is_ok()
    );
    let imported_path = format!("/#/scans/{imported}");
    open(&c, addr, &imported_path, &["the camera's images, loaded"]).await;
    let labels = eval(
        &c,
        "return [...document.querySelectorAll('#textures figcaption')].map((f) => f.textContent)",
    )
    .await;
    let want: Vec<&str> = x.textures.iter().map(|t| t.geometry.as_str()).collect();
    assert_eq!(
        labels,
        json!(want),
        "one captioned image per texture, in the file's order"
    );
    shot(&c, "result-textures").await;

    // Log out: the session is over, the page asks for a new link.
    open(&c, addr, "/#/", &["the bench before logging out"]).await;
    click(&c, "#logout").await;
    see(&c, &["the sign-in prompt after logging out"]).await;
    c.refresh().await.unwrap();
    see(&c, &["the sign-in prompt after reload"]).await;

    c.close().await.unwrap();
    daemon.stop().await;
    let _ = href;
}

/// The page of a daemon with its SRA turned off, and of a real X-Rite export, on a phone: the
/// bench speaks of the MA-T12 alone (the SRA "turned off", its cells "SRA off" after the scan,
/// the measure buttons usable), the result page of the 12-geometry scan says "all (12)" and
/// never "SRA: unknown"; the export's page at 390 px does not scroll sideways, its camera
/// images open at full size on a tap, and a residual's ΔC*, ΔH*, ΔE00 are one tap away.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn an_sra_off_bench_and_an_imported_scan_read_truthfully_on_a_phone() {
    let dir = tempfile::tempdir().unwrap();
    let downloads = tempfile::tempdir().unwrap();
    let addr: SocketAddr = format!("127.0.0.1:{}", free_port()).parse().unwrap();
    let devices = Devices::simulated_mat12_only(
        common::playlist(Instrument::MaT12),
        &ReplayOptions::lenient().accelerated(),
    )
    .unwrap();
    let daemon = start_daemon(dir.path(), addr, devices).await;
    let driver = start_chromedriver();
    let c = browser(&driver, downloads.path()).await;
    let session_id = c.session_id().await.unwrap().unwrap();
    let token = std::fs::read_to_string(dir.path().join("brdfd.token")).unwrap();
    let out = common::run_brdfd_env(
        &["open", "--addr", &addr.to_string(), "--no-browser"],
        None,
        &[("BRDFD_TOKEN", token.trim())],
    );
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    c.goto(String::from_utf8(out.stdout).unwrap().trim())
        .await
        .unwrap();
    see(&c, &["the bench"]).await;

    // The SRA is off: said so, no identity awaited, and the bench can still measure.
    let sra = text_of(&c, Locator::Css("[data-device=sra]")).await;
    assert!(sra.contains("turned off"), "{sra}");
    assert!(!sra.contains("no identity yet"), "{sra}");
    click(&c, "#measure-reference:not([disabled])").await;
    wait_js(
        &c,
        "the 12-geometry reference",
        "const op = document.getElementById('op'); return op.dataset.state === 'complete' && op.dataset.readings === '12'",
    )
    .await;
    see(&c, &["the reference in force"]).await;
    scan(&c, "T.Sky blue", &[]).await;
    wait_js(
        &c,
        "the 12-geometry scan and its three fits",
        "const op = document.getElementById('op'); return op.dataset.state === 'complete' && op.dataset.readings === '12'
           && document.querySelectorAll('#fits tr[data-status=done]').length === 3",
    )
    .await;
    for g in ["sra-20", "sra-60"] {
        let cell = text_of(&c, Locator::Css(&format!("#cell-{g} .num"))).await;
        assert_eq!(cell, "SRA off", "{g} after the scan completed");
    }
    shot(&c, "sra-off-bench").await;
    let scan_id = daemon.scans().await[0].id;
    open(&c, addr, &format!("/#/scans/{scan_id}"), &[]).await;
    wait_js(
        &c,
        "the SRA-off scan's result",
        "return document.querySelectorAll('#de-table tbody tr').length === 3",
    )
    .await;
    let head = text_of(&c, Locator::Css("#de-table thead")).await;
    assert!(
        head.contains("all (12)") && !head.contains("all (14)"),
        "{head}"
    );
    let body = eval(&c, "return document.body.innerText").await;
    let body = body.as_str().unwrap();
    assert!(!body.contains("SRA: unknown"), "{body}");
    shot(&c, "sra-off-result").await;
    // The same result page and the SRA-off bench on a phone: nothing scrolls sideways, and the
    // bench still says the SRA is off.
    c.set_window_size(390, 900).await.unwrap();
    for (what, path) in [
        ("the SRA-off scan's result", format!("/#/scans/{scan_id}")),
        ("the SRA-off bench", "/#/".to_string()),
    ] {
        open(&c, addr, &path, &[]).await;
        let layout = eval(
            &c,
            "return new Promise((done) => requestAnimationFrame(() => requestAnimationFrame(() =>
               done({ inner: window.innerWidth, page: document.documentElement.scrollWidth,
                      text: document.body.innerText }))))",
        )
        .await;
        let (inner, page) = (
            layout["inner"].as_f64().unwrap(),
            layout["page"].as_f64().unwrap(),
        );
        assert!(
            inner <= 390.0 && page <= inner,
            "{what} scrolls sideways at 390 px: inner {inner}, page {page}"
        );
        let text = layout["text"].as_str().unwrap();
        assert!(!text.contains("SRA: unknown"), "{what}: {text}");
        if path == "/#/" {
            assert!(text.contains("turned off"), "{what}: {text}");
        }
    }
    shot(&c, "sra-off-bench-phone-390").await;
    c.set_window_size(1280, 800).await.unwrap();

    // A real X-Rite export (its camera images, its SHA-256 in the provenance) on a phone.
    let real_dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/real-mat12");
    let x = std::fs::read_dir(&real_dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "xlsx"))
        .flat_map(|p| brdfd::formats::xrite::read_file(&p, &Default::default()).unwrap())
        .find(|x| !x.textures.is_empty())
        .expect("a shared export with texture images");
    let (provenance, taken) =
        brdfd::service::imported_provenance(&x.scan, "uploaded X-Rite QC .xlsx export").unwrap();
    let (imported, _) = daemon
        .service
        .import_scan_as(&x.scan, &provenance, taken, &x.textures)
        .await
        .unwrap();
    // Its fits end after the import; the page is opened once they have.
    let deadline = Instant::now() + 3 * WAIT;
    loop {
        let fits = daemon
            .service
            .store()
            .fits_for_scan(imported)
            .await
            .unwrap();
        if fits.len() == 3 && fits.iter().all(|f| f.status == FitStatus::Done) {
            break;
        }
        assert!(
            Instant::now() < deadline,
            "the import's fits did not finish: {:?}",
            fits.iter().map(|f| (f.id, f.status)).collect::<Vec<_>>()
        );
        tokio::time::sleep(Duration::from_millis(200)).await;
    }
    c.set_window_size(390, 900).await.unwrap();
    open(
        &c,
        addr,
        &format!("/#/scans/{imported}"),
        &["the camera's images, loaded"],
    )
    .await;
    wait_js(
        &c,
        "the import's residuals",
        "return document.querySelectorAll('#residuals tbody tr').length === 3",
    )
    .await;
    let layout = eval(
        &c,
        "return new Promise((done) => requestAnimationFrame(() => requestAnimationFrame(() =>
           done({ inner: window.innerWidth, page: document.documentElement.scrollWidth,
                  wider: [...document.querySelectorAll('body *')].filter((e) => e.getBoundingClientRect().right > window.innerWidth + 0.5 && !e.closest('.scroll'))
                    .slice(0, 5).map((e) => `${e.tagName}#${e.id}.${e.className}`) }))))",
    )
    .await;
    let inner = layout["inner"].as_f64().unwrap();
    assert!(inner <= 390.0, "{layout}");
    assert!(
        layout["page"].as_f64().unwrap() <= 390.0 && layout["page"].as_f64().unwrap() <= inner,
        "the imported scan's page scrolls sideways at 390 px: {layout}"
    );
    shot(&c, "imported-phone-390").await;
    // A camera image opens at its full size.
    click(&c, "#textures button.enlarge").await;
    wait_js(
        &c,
        "the camera image at full size",
        "const d = document.getElementById('texture-dialog'); const i = d && d.querySelector('img');
         return !!d && d.open && !!i && i.complete && i.naturalWidth > 0
           && i.clientWidth >= Math.min(i.naturalWidth, window.innerWidth * 0.9) - 1
           && i.clientWidth > document.querySelector('#textures img').clientWidth",
    )
    .await;
    shot(&c, "imported-texture-full-size").await;
    click(&c, "#texture-dialog button[type=submit]").await;
    // A residual's other differences, without hovering.
    click(&c, "#residuals td.res").await;
    let detail = text_of(&c, Locator::Id("residual-detail")).await;
    assert!(
        detail.contains("ΔC*") && detail.contains("ΔH*") && detail.contains("ΔE00"),
        "{detail}"
    );
    let errors = console_errors(&driver, &session_id);
    assert!(errors.is_empty(), "console errors: {errors:?}");
    c.close().await.unwrap();
    daemon.stop().await;
}
