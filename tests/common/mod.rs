//! Helpers shared by the daemon's end-to-end tests (`tests/daemon_*.rs`): a service started
//! in-process on simulated instruments and a store in a temporary directory, driver settings
//! with short reconnection times, the embedded recordings as scripts, a lock that runs one
//! daemon test at a time, and a bound on every test.

#![allow(dead_code)] // each test binary uses a different subset

pub mod serve;

#[allow(unused_imports)] // each test binary uses a different subset
pub use serve::{ServeChild, spawn_serve, wait_until, write_simulated_config};

use std::future::Future;
use std::path::PathBuf;
use std::sync::{Mutex, MutexGuard};
use std::time::Duration;

use brdfd::cost::CostFunction;
use brdfd::fit::{FitReport, FitRequest, fit_scan};
use brdfd::optimise::Settings;
use brdfd::service::{Devices, Service, ServiceOptions, ServiceSettings};
use brdfd::store::{ReferenceId, ReferenceStatus, ScanDetail, ScanId, ScanState, Store};
use drivers::{DriverConfig, Instrument};
use mock_devices::{ReplayOptions, Script};
use tempfile::TempDir;

/// Every test body runs under this: a hang fails the test instead of stalling the suite.
pub const TEST_TIMEOUT: Duration = Duration::from_secs(120);

/// How long one measurement or one scan's fits may take before a helper gives up.
pub const STEP_TIMEOUT: Duration = Duration::from_secs(60);

static ONE_AT_A_TIME: Mutex<()> = Mutex::new(());

/// Daemon tests take this: each starts driver threads, pseudo-terminals and fits, and the
/// timing-sensitive ones (a scan killed mid-way) should not compete for the two cores.
pub fn serial() -> MutexGuard<'static, ()> {
    ONE_AT_A_TIME.lock().unwrap_or_else(|p| p.into_inner())
}

/// Runs `body` under [`TEST_TIMEOUT`].
pub async fn bounded<T>(body: impl Future<Output = T>) -> T {
    tokio::time::timeout(TEST_TIMEOUT, body)
        .await
        .expect("the test did not finish within its time bound")
}

/// Driver settings with quick reconnection: a pulled cable fails the command in well under a
/// second instead of the default's few seconds.
pub fn fast_driver_config() -> DriverConfig {
    DriverConfig {
        reconnect_attempts: 3,
        backoff_initial: Duration::from_millis(10),
        backoff_max: Duration::from_millis(40),
        ..DriverConfig::default()
    }
}

/// Service settings for tests: the defaults (three cost functions, separable, seed 1), two
/// fits at once, the paper's Fresnel factor, flat SRA model and SRA weights (under the luminance default cf2's 200
/// full-search bootstrap refits take minutes per scan in a debug build) and no
/// cross-validation (12 more fits per fit; the tests that check it turn it on). The daemons these
/// tests start from a configuration file (`serve::write_simulated_config`) run the default.
pub fn settings() -> ServiceSettings {
    ServiceSettings {
        max_concurrent_fits: 2,
        sra: brdfd::sra_reading::SraModel::Flat,
        // The simulated instruments replay the paper's model (Schlick on cos θi): fitted with
        // the same factor, their fits recover the recorded truths.
        fresnel: brdfd::optimise::Preset::Paper.fresnel(),
        // And the paper's weights of the SRA readings in every cost function.
        preset: brdfd::optimise::Preset::Paper,
        crossval: false,
        ..ServiceSettings::default()
    }
}

/// One instrument's script of every embedded recording, N9 first.
pub fn playlist(instrument: Instrument) -> Script {
    mock_devices::recordings::playlist(instrument).expect("embedded recordings")
}

/// Strict, accelerated replay.
pub fn strict_fast() -> ReplayOptions {
    ReplayOptions::strict().accelerated()
}

/// One fit of `scan` per cost function, in [`CostFunction::ALL`]'s order, each with `settings`
/// but its cost function.
pub fn fit_every_cost(scan: &brdfd::scan::Scan, settings: Settings) -> Vec<FitReport> {
    CostFunction::ALL
        .iter()
        .map(|&cost| {
            let request = FitRequest {
                settings: Settings { cost, ..settings },
                ..FitRequest::default()
            };
            fit_scan(scan, &request).unwrap()
        })
        .collect()
}

/// Runs `body` to its end on a current-thread runtime of its own (from a synchronous test).
pub fn block_on<F: Future>(body: F) -> F::Output {
    tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .expect("a runtime")
        .block_on(body)
}

/// Both instruments simulated, replaying every embedded recording with `options`.
pub fn simulated(options: &ReplayOptions) -> Devices {
    Devices::simulated(
        playlist(Instrument::MaT12),
        playlist(Instrument::Sra),
        options,
        [None, None],
    )
    .expect("simulated instruments")
}

/// A service and the temporary directory of its store.
pub struct TestDaemon {
    pub service: Service,
    pub store: Store,
    pub db: PathBuf,
    pub dir: TempDir,
}

/// Starts a service on `devices` with a store file in a new temporary directory.
pub async fn start(
    devices: Devices,
    settings: ServiceSettings,
    options: ServiceOptions,
) -> TestDaemon {
    let dir = tempfile::tempdir().expect("temporary directory");
    let db = dir.path().join("brdfd.db");
    let store = Store::open(&db).await.expect("store opens");
    let service = Service::start(store.clone(), devices, settings, options)
        .await
        .expect("service starts");
    TestDaemon {
        service,
        store,
        db,
        dir,
    }
}

/// Starts a service on simulated instruments replaying every embedded recording.
pub async fn start_builtin(options: ReplayOptions) -> TestDaemon {
    start(simulated(&options), settings(), ServiceOptions::default()).await
}

/// Measures the reference and checks it completed.
pub async fn measure_reference(service: &Service) -> ReferenceId {
    let id = service
        .request_reference()
        .await
        .expect("reference accepted");
    assert!(service.wait_idle(STEP_TIMEOUT).await, "reference finishes");
    let r = service.store().reference_detail(id).await.unwrap();
    assert_eq!(
        r.reference.status,
        ReferenceStatus::Complete,
        "reference {id}: {:?}",
        r.reference.reason
    );
    id
}

/// Scans `sample` and waits until the scan and its fits have ended.
pub async fn scan_and_settle(service: &Service, sample: &str) -> ScanId {
    let id = service.request_scan(sample).await.expect("scan accepted");
    assert!(
        service.wait_settled(id, STEP_TIMEOUT).await.unwrap(),
        "scan {id} and its fits end"
    );
    id
}

/// The stored detail of `scan`, checked complete (with the reason it is not, if not).
pub async fn complete_scan(store: &Store, scan: ScanId) -> ScanDetail {
    let detail = store.scan_detail(scan).await.unwrap();
    assert_eq!(
        detail.scan.state,
        ScanState::Complete,
        "{:?}",
        detail.scan.reason
    );
    detail
}

/// The reply frame a session file holds for each FETCH, by geometry: the `<` line that follows
/// the `>` FETCH line, byte for byte (what the simulated instrument sends back).
pub fn fetch_replies(
    session: &drivers::session::Session,
) -> std::collections::HashMap<&'static str, Vec<u8>> {
    use drivers::protocol::{Codec, Request};
    use drivers::session::Direction;
    let frames = &session.frames;
    let mut out = std::collections::HashMap::new();
    for (i, f) in frames.iter().enumerate() {
        if f.direction != Direction::ToDevice {
            continue;
        }
        let request = match session.instrument {
            Instrument::MaT12 => drivers::mat12::codec::Mat12Codec::parse_request(&f.bytes),
            Instrument::Sra => drivers::sra::codec::SraCodec::parse_request(&f.bytes),
        };
        if let Ok(Request::Fetch { geometry }) = request {
            let reply = frames[i + 1..]
                .iter()
                .find(|g| g.direction == Direction::FromDevice)
                .unwrap_or_else(|| panic!("no `<` line after FETCH {geometry}"));
            let before = out.insert(geometry, reply.bytes.clone());
            assert!(before.is_none(), "one FETCH of {geometry} per session");
        }
    }
    out
}

/// [`fetch_replies`] of both of a recording's session files.
pub fn recorded_fetch_replies(
    r: &mock_devices::recordings::Recording,
) -> std::collections::HashMap<&'static str, Vec<u8>> {
    let mut out = fetch_replies(&r.session(Instrument::MaT12).unwrap());
    out.extend(fetch_replies(&r.session(Instrument::Sra).unwrap()));
    assert_eq!(out.len(), 14, "{}: a FETCH reply per geometry", r.name);
    out
}

/// Whether two reading values are identical bit for bit.
pub fn bit_eq(a: &[f64], b: &[f64]) -> bool {
    a.len() == b.len() && a.iter().zip(b).all(|(x, y)| x.to_bits() == y.to_bits())
}

/// The API on 127.0.0.1:0 in front of `service`, with a fresh token written to
/// `dir/brdfd.token` (mode 0600, as the daemon writes it), and a client that sends it.
pub async fn start_api(
    service: &Service,
    dir: &std::path::Path,
) -> (brdfd::api::ApiServer, brdfd::client::Client, PathBuf) {
    use brdfd::api::{Access, ApiOptions, ApiServer, Token};
    let token_file = dir.join("brdfd.token");
    let (token, _) = Token::load_or_create(&token_file).expect("token file");
    let options = ApiOptions::new(Access::new(token.clone()).with_token_file(&token_file));
    let api = ApiServer::start(service.clone(), "127.0.0.1:0".parse().unwrap(), options)
        .await
        .expect("the API starts");
    let client = brdfd::client::Client::new(api.local_addr()).with_token(&token, "test token");
    (api, client, token_file)
}

/// A client of a `brdfd serve` child whose store is in `dir` (token file `dir/brdfd.token`).
pub fn client_of_serve(addr: std::net::SocketAddr, dir: &std::path::Path) -> brdfd::client::Client {
    let token =
        brdfd::api::Token::read(&dir.join("brdfd.token")).expect("the daemon wrote its token");
    brdfd::client::Client::new(addr).with_token(&token, "test token")
}

/// Runs the `brdfd` binary with `args` (in `cwd`, if given), killed and failed if it takes
/// longer than [`TEST_TIMEOUT`]. The environment's BRDFD_TOKEN and BRDFD_CONFIG are removed,
/// so a developer's settings cannot change a test.
pub fn run_brdfd(args: &[&str], cwd: Option<&std::path::Path>) -> std::process::Output {
    run_brdfd_env(args, cwd, &[])
}

/// [`run_brdfd`] with extra environment variables.
pub fn run_brdfd_env(
    args: &[&str],
    cwd: Option<&std::path::Path>,
    env: &[(&str, &str)],
) -> std::process::Output {
    use std::io::Read;
    use std::process::{Command, Stdio};
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_brdfd"));
    cmd.args(args).stdout(Stdio::piped()).stderr(Stdio::piped());
    cmd.env_remove("BRDFD_TOKEN").env_remove("BRDFD_CONFIG");
    for (k, v) in env {
        cmd.env(k, v);
    }
    if let Some(dir) = cwd {
        cmd.current_dir(dir);
    }
    let mut child = cmd.spawn().expect("the brdfd binary runs");
    let mut out = child.stdout.take().unwrap();
    let mut err = child.stderr.take().unwrap();
    let out_reader = std::thread::spawn(move || {
        let mut b = Vec::new();
        let _ = out.read_to_end(&mut b);
        b
    });
    let err_reader = std::thread::spawn(move || {
        let mut b = Vec::new();
        let _ = err.read_to_end(&mut b);
        b
    });
    let deadline = std::time::Instant::now() + TEST_TIMEOUT;
    let status = loop {
        if let Some(status) = child.try_wait().expect("waiting for brdfd") {
            break status;
        }
        if std::time::Instant::now() >= deadline {
            let _ = child.kill();
            let _ = child.wait();
            panic!("brdfd {args:?} did not finish within {TEST_TIMEOUT:?}");
        }
        std::thread::sleep(Duration::from_millis(10));
    };
    std::process::Output {
        status,
        stdout: out_reader.join().unwrap(),
        stderr: err_reader.join().unwrap(),
    }
}
