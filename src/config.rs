//! The daemon's configuration: `brdfd.toml` → a checked [`Config`].
//!
//! Two stages, as with command-line arguments: serde reads the TOML into raw structs that only
//! know the file's shape (`deny_unknown_fields`, so a misspelt key is an error, not a silently
//! ignored setting); [`Config::from_toml`] then checks every value and builds typed settings
//! (socket addresses, durations, enums). The rest of the daemon only sees [`Config`].
//!
//! Every error names the file, the line and the key (`brdfd.toml:7: api.listen: …`): toml gives
//! the byte span of what it rejects, and values are read as [`toml::Spanned`] so the checks of
//! the second stage can point at them too.
//!
//! [`Config::default()`] is what runs with no file: both instruments simulated (replaying the
//! recordings shipped with brdfd), the store in `brdfd.db` in the working directory, the HTTP
//! API on loopback only. `config/brdfd.toml` spells out exactly these defaults with a comment per
//! key; a test keeps the two equal.

use std::fmt;
use std::net::SocketAddr;
use std::num::NonZeroUsize;
use std::path::{Path, PathBuf};
use std::str::FromStr;
use std::time::Duration;

use serde::Deserialize;
use toml::Spanned;

use crate::cost::CostFunction;
use crate::optimise::Method;
use crate::processing::SpecularStrategy;

/// The configuration file shipped in `config/`, the defaults written out with comments.
pub const SHIPPED: &str = include_str!("../config/brdfd.toml");

/// Where the systemd unit in `config/brdfd.service` points `--config`.
pub const SYSTEM_PATH: &str = "/etc/brdfd/brdfd.toml";

/// Why a configuration could not be loaded.
#[derive(Debug, thiserror::Error)]
pub enum ConfigError {
    /// The file could not be read.
    #[error("cannot read the configuration file {path}: {source}")]
    Read {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },

    /// Not valid TOML, or a key brdfd does not know, or a value of the wrong type.
    #[error("{origin}:{line}:{column}: {message}{}", key_suffix(.key))]
    Syntax {
        /// The file (or "brdfd.toml" for text not read from a file).
        origin: String,
        line: usize,
        column: usize,
        /// The dotted key concerned, when toml says.
        key: Option<String>,
        message: String,
    },

    /// A well-formed value that is not acceptable (out of range, not loopback, unknown name).
    #[error("{origin}:{}{key}: {message}", line_prefix(*.line))]
    Invalid {
        origin: String,
        /// The line of the offending value; `None` when the value is a default.
        line: Option<usize>,
        /// The dotted key, e.g. `api.listen`.
        key: &'static str,
        message: String,
    },
}

fn key_suffix(key: &Option<String>) -> String {
    key.as_ref()
        .map(|k| format!(" (key `{k}`)"))
        .unwrap_or_default()
}

fn line_prefix(line: Option<usize>) -> String {
    line.map(|l| format!("{l}: ")).unwrap_or_else(|| " ".into())
}

/// The checked configuration.
#[derive(Debug, Clone, PartialEq)]
pub struct Config {
    pub store: StoreConfig,
    pub api: ApiConfig,
    pub devices: DevicesConfig,
    pub scan: ScanConfig,
    pub fit: FitConfig,
    /// `[colour]`: observer and weighting of every L*a*b* and ΔE00 (SCIENCE.md §7.1).
    pub colour: crate::colour::Colorimetry,
    pub log: LogConfig,
    pub station: StationConfig,
    pub sync: SyncConfig,
    pub reference: ReferenceConfig,
    pub ingest: IngestConfig,
}

/// `[ingest]`: the watch folder (src/service/ingest.rs).
#[derive(Debug, Clone, PartialEq)]
pub struct IngestConfig {
    /// The folder watched for instrument-software exports and scan files; `None`: no folder.
    pub watch: Option<PathBuf>,
    /// A file is imported once its size and modification time stayed the same this long.
    pub settle: Duration,
    /// How often the folder is listed.
    pub poll: Duration,
    /// How long an MA-T12 export waits for its SRA CSV (and an SRA CSV for its export) before
    /// it is imported alone (or, for an SRA CSV, rejected).
    pub pair_wait: Duration,
    /// In an instrument's export, the object with this name is the white reference tile.
    pub reference: String,
    /// The largest file read, in bytes (`max_file_mib`); a larger one goes to `failed/`
    /// unread.
    pub max_file_bytes: u64,
}

impl Default for IngestConfig {
    fn default() -> Self {
        IngestConfig {
            watch: None,
            settle: Duration::from_millis(defaults::INGEST_SETTLE_MS),
            poll: Duration::from_millis(defaults::INGEST_POLL_MS),
            pair_wait: Duration::from_millis(defaults::INGEST_PAIR_WAIT_MS),
            reference: crate::formats::DEFAULT_REFERENCE.to_string(),
            max_file_bytes: defaults::INGEST_MAX_FILE_MIB << 20,
        }
    }
}

/// `[station]`
#[derive(Debug, Clone, PartialEq)]
pub struct StationConfig {
    /// This station's id in the lab's central database, on every row it forwards; default: the
    /// host name.
    pub id: String,
}

/// `[sync]`
#[derive(Debug, Clone, PartialEq)]
pub struct SyncConfig {
    /// The lab's central PostgreSQL database; `None`: nothing is forwarded.
    pub url: Option<String>,
    /// Outbox entries forwarded per PostgreSQL transaction.
    pub batch: usize,
}

/// `[store]`
#[derive(Debug, Clone, PartialEq)]
pub struct StoreConfig {
    /// The SQLite file; a relative path is relative to the working directory (the systemd unit
    /// sets it to the state directory).
    pub path: PathBuf,
}

/// `[api]`
#[derive(Debug, Clone, PartialEq)]
pub struct ApiConfig {
    /// Where the HTTP API listens. Loopback unless `allow_remote`.
    pub listen: SocketAddr,
    /// Whether a non-loopback `listen` address is allowed (only behind a TLS reverse proxy:
    /// the bearer token would otherwise cross the network in clear text).
    pub allow_remote: bool,
    /// The API token's file; `None` = `brdfd.token` beside the store ([`ApiConfig::token_path`]).
    pub token_file: Option<PathBuf>,
    /// Host names (without port) the API answers to besides the loopback names and addresses:
    /// what a reverse proxy or the lab's DNS name puts in `Host`. Anything else is refused, so
    /// a DNS-rebinding page cannot reach the API under its own name.
    pub allowed_hosts: Vec<String>,
    /// Connections served at once; more are answered 503 and closed.
    pub max_connections: usize,
    /// `GET /events` streams at once; more are answered 503.
    pub max_event_subscribers: usize,
    /// A request's header must arrive whole within this, else the connection is closed.
    pub header_timeout: Duration,
    /// A connection with no traffic in either direction for this long is closed.
    pub idle_timeout: Duration,
}

impl ApiConfig {
    /// The token file in force: `token_file`, else `brdfd.token` in the store's directory.
    pub fn token_path(&self, store: &Path) -> PathBuf {
        self.token_file.clone().unwrap_or_else(|| {
            store
                .parent()
                .map(|d| d.join("brdfd.token"))
                .unwrap_or_else(|| PathBuf::from("brdfd.token"))
        })
    }
}

/// The one check of a listening address, for `[api] listen` and `brdfd serve --listen` alike:
/// anything but loopback needs `allow_remote`.
pub fn check_listen(addr: SocketAddr, allow_remote: bool) -> Result<SocketAddr, String> {
    if !addr.ip().is_loopback() && !allow_remote {
        return Err(format!(
            "{addr} is reachable from other machines; listen on 127.0.0.1, or set              [api] allow_remote = true and put a TLS reverse proxy in front (README:              \"Remote access\"), since the API token must not cross the network in clear text"
        ));
    }
    Ok(addr)
}

/// `[devices.*]`
#[derive(Debug, Clone, PartialEq)]
pub struct DevicesConfig {
    pub ma_t12: MaT12Config,
    pub sra: SraConfig,
}

/// One `[devices.*]` section: how the instrument is reached (`T`) and the settings every
/// instrument has.
#[derive(Debug, Clone, PartialEq)]
pub struct DeviceConfig<T> {
    pub transport: T,
    /// Reply timeout of a measuring command.
    pub timeout: Duration,
    /// Resends of a request after a timeout or a corrupt reply.
    pub retries: u32,
    /// Where the recording tap writes this instrument's traffic; `None` = no recording.
    pub record: Option<PathBuf>,
}

/// `[devices.ma_t12]`
pub type MaT12Config = DeviceConfig<MaT12Transport>;

/// How brdfd reaches the MA-T12.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum MaT12Transport {
    /// The simulated instrument, replaying a session file; `None` = the built-in recording.
    Simulated { session: Option<PathBuf> },
    /// USB bulk; `product_id` narrows the search when several X-Rite devices are attached.
    Usb { product_id: Option<u16> },
}

/// `[devices.sra]`
pub type SraConfig = DeviceConfig<SraTransport>;

/// How brdfd reaches the SRA.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum SraTransport {
    /// The simulated instrument (over a pseudo-terminal), replaying a session file; `None` =
    /// the built-in recording.
    Simulated { session: Option<PathBuf> },
    /// A serial port, e.g. `/dev/ttyUSB0`.
    Serial { port: String, baud: u32 },
    /// No SRA (`transport = "off"`): a lab with only an MA-T12. References and scans are
    /// measured on the 12 MA-T12 geometries and fitted over them (SCIENCE.md §3).
    Off,
}

/// `[scan]`
#[derive(Debug, Clone, PartialEq)]
pub struct ScanConfig {
    /// A scan whose reference set is older than this is flagged, not silently fitted
    /// (SCIENCE.md §3).
    pub reference_max_age: Duration,
}

/// `[fit]`
#[derive(Debug, Clone, PartialEq)]
pub struct FitConfig {
    /// One fit per cost function, per complete scan; no duplicates.
    pub cost_functions: Vec<CostFunction>,
    pub method: Method,
    pub seed: u64,
    /// Fits running at once (each takes one core).
    pub max_concurrent_fits: NonZeroUsize,
    /// How SRA readings become spectra (SCIENCE.md §3).
    pub specular: SpecularStrategy,
    /// How an SRA reading enters the cost: the paper's flat grey spectrum or the luminance
    /// (SCIENCE.md §5.1).
    pub sra: crate::sra_reading::SraModel,
    /// The model's form (SCIENCE.md §4.1): the paper's by default.
    pub model: crate::model::ModelKind,
    /// Bootstrap resamples per fit for the parameter intervals (SCIENCE.md §10); 0 turns the
    /// intervals off.
    pub bootstrap: u32,
}

/// `[reference]`
#[derive(Debug, Clone, PartialEq, Default)]
pub struct ReferenceConfig {
    /// The reference tile's calibrated reflectance factor (SCIENCE.md §3), recorded with every
    /// reference set measured while it is configured; `None`: ρ_ref = 1, results relative to the
    /// tile (the paper's choice).
    pub reflectance: Option<crate::spectral::Spectrum>,
    /// Where it came from, for logs: "one value", "31 values" or the certificate's path.
    pub source: Option<String>,
}

/// `[log]`
#[derive(Debug, Clone, PartialEq)]
pub struct LogConfig {
    /// One JSON object per line (for a log collector) instead of text.
    pub json: bool,
    pub level: LogLevel,
}

/// The least severe level logged.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum LogLevel {
    Error,
    Warn,
    Info,
    Debug,
    Trace,
}

impl LogLevel {
    const ALL: [LogLevel; 5] = [
        LogLevel::Error,
        LogLevel::Warn,
        LogLevel::Info,
        LogLevel::Debug,
        LogLevel::Trace,
    ];

    /// The name in the file, as the `tracing` crate spells levels.
    pub const fn as_str(self) -> &'static str {
        match self {
            LogLevel::Error => "error",
            LogLevel::Warn => "warn",
            LogLevel::Info => "info",
            LogLevel::Debug => "debug",
            LogLevel::Trace => "trace",
        }
    }
}

impl fmt::Display for LogLevel {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

impl FromStr for LogLevel {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        LogLevel::ALL
            .into_iter()
            .find(|l| l.as_str() == s)
            .ok_or_else(|| {
                format!("unknown level \"{s}\": expected one of error, warn, info, debug, trace")
            })
    }
}

/// Defaults, shared by [`Config::default`] and the checks (and written out in `SHIPPED`).
mod defaults {
    pub const STORE_PATH: &str = "brdfd.db";
    pub const LISTEN: &str = "127.0.0.1:7878";
    pub const MAX_CONNECTIONS: usize = 1024;
    pub const MAX_EVENT_SUBSCRIBERS: usize = 512;
    pub const HEADER_TIMEOUT_MS: u64 = 2_000;
    pub const IDLE_TIMEOUT_MS: u64 = 60_000;
    /// The measuring commands' reply timeout of drivers/PROTOCOL.md §4.
    pub const TIMEOUT_MS: u64 = 10_000;
    /// drivers/PROTOCOL.md §4: 3 resends, 4 sends in all.
    pub const RETRIES: u32 = 3;
    pub const SRA_PORT: &str = "/dev/ttyUSB0";
    /// drivers/PROTOCOL.md §3: 9600 baud, 8N1.
    pub const SRA_BAUD: u32 = 9600;
    pub const REFERENCE_MAX_AGE_HOURS: f64 = 24.0;
    pub const SEED: u64 = 1;
    pub const BOOTSTRAP: u32 = 200;
    /// The luminance SRA model for measured scans (SCIENCE.md §10); `brdfd demo` asks for the
    /// paper's flat one.
    pub const SRA: crate::sra_reading::SraModel = crate::sra_reading::SraModel::Luminance;
    pub const LEVEL: &str = "info";
    pub const SYNC_BATCH: u64 = 500;
    pub const INGEST_SETTLE_MS: u64 = 2_000;
    pub const INGEST_POLL_MS: u64 = 1_000;
    pub const INGEST_PAIR_WAIT_MS: u64 = 60_000;
    /// An export of a whole session is a few MiB at most.
    pub const INGEST_MAX_FILE_MIB: u64 = 32;
}

impl Default for Config {
    fn default() -> Self {
        Config {
            store: StoreConfig {
                path: PathBuf::from(defaults::STORE_PATH),
            },
            api: ApiConfig {
                listen: defaults::LISTEN.parse().expect("default listen address"),
                allow_remote: false,
                token_file: None,
                allowed_hosts: Vec::new(),
                max_connections: defaults::MAX_CONNECTIONS,
                max_event_subscribers: defaults::MAX_EVENT_SUBSCRIBERS,
                header_timeout: Duration::from_millis(defaults::HEADER_TIMEOUT_MS),
                idle_timeout: Duration::from_millis(defaults::IDLE_TIMEOUT_MS),
            },
            devices: DevicesConfig {
                ma_t12: MaT12Config {
                    transport: MaT12Transport::Simulated { session: None },
                    timeout: Duration::from_millis(defaults::TIMEOUT_MS),
                    retries: defaults::RETRIES,
                    record: None,
                },
                sra: SraConfig {
                    transport: SraTransport::Simulated { session: None },
                    timeout: Duration::from_millis(defaults::TIMEOUT_MS),
                    retries: defaults::RETRIES,
                    record: None,
                },
            },
            scan: ScanConfig {
                reference_max_age: Duration::from_secs_f64(
                    defaults::REFERENCE_MAX_AGE_HOURS * 3600.0,
                ),
            },
            fit: FitConfig {
                cost_functions: CostFunction::ALL.to_vec(),
                method: Method::default(),
                seed: defaults::SEED,
                max_concurrent_fits: NonZeroUsize::MIN,
                specular: SpecularStrategy::default(),
                sra: defaults::SRA,
                model: crate::model::ModelKind::Paper,
                bootstrap: defaults::BOOTSTRAP,
            },
            colour: crate::colour::Colorimetry::default(),
            log: LogConfig {
                json: false,
                level: LogLevel::Info,
            },
            station: StationConfig {
                id: crate::sync::default_station_id(),
            },
            sync: SyncConfig {
                url: None,
                batch: defaults::SYNC_BATCH as usize,
            },
            reference: ReferenceConfig::default(),
            ingest: IngestConfig::default(),
        }
    }
}

// ---- Stage 1: the file's shape -------------------------------------------------------------

type S<T> = Option<Spanned<T>>;

#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawConfig {
    #[serde(default)]
    store: RawStore,
    #[serde(default)]
    api: RawApi,
    #[serde(default)]
    devices: RawDevices,
    #[serde(default)]
    scan: RawScan,
    #[serde(default)]
    fit: RawFit,
    #[serde(default)]
    colour: RawColour,
    #[serde(default)]
    log: RawLog,
    #[serde(default)]
    station: RawStation,
    #[serde(default)]
    sync: RawSync,
    #[serde(default)]
    reference: RawReference,
    #[serde(default)]
    ingest: RawIngest,
}

#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawIngest {
    watch: S<String>,
    settle_ms: S<u64>,
    poll_ms: S<u64>,
    pair_wait_ms: S<u64>,
    reference: S<String>,
    max_file_mib: S<u64>,
}

#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawStation {
    id: S<String>,
}

#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawSync {
    url: S<String>,
    batch: S<u64>,
}

#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawStore {
    path: S<String>,
}

#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawApi {
    listen: S<String>,
    allow_remote: Option<bool>,
    token_file: S<String>,
    allowed_hosts: S<Vec<String>>,
    max_connections: S<u64>,
    max_event_subscribers: S<u64>,
    header_timeout_ms: S<u64>,
    idle_timeout_ms: S<u64>,
}

#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawDevices {
    #[serde(default)]
    ma_t12: RawMaT12,
    #[serde(default)]
    sra: RawSra,
}

#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawMaT12 {
    transport: S<String>,
    session: S<String>,
    product_id: S<u16>,
    timeout_ms: S<u64>,
    retries: S<u32>,
    record: S<String>,
}

#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawSra {
    transport: S<String>,
    session: S<String>,
    port: S<String>,
    baud: S<u32>,
    timeout_ms: S<u64>,
    retries: S<u32>,
    record: S<String>,
}

#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawScan {
    reference_max_age_hours: S<f64>,
}

#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawFit {
    cost_functions: S<Vec<String>>,
    method: S<String>,
    seed: S<u64>,
    max_concurrent_fits: S<u64>,
    specular: S<String>,
    sra: S<String>,
    model: S<String>,
    bootstrap: S<u32>,
}

#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawColour {
    observer: S<String>,
    weighting: S<String>,
}

#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawReference {
    /// A number, an array of 31 numbers, or a certificate file's path.
    reflectance: S<toml::Value>,
}

#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawLog {
    json: Option<bool>,
    level: S<String>,
}

// ---- Stage 2: checks -----------------------------------------------------------------------

/// Turns byte offsets into line numbers and builds errors for one text.
struct Checker<'a> {
    text: &'a str,
    origin: &'a str,
    /// Whether `[devices.*] transport` must be set (always, for a file read by brdfd).
    require_transport: bool,
}

impl Checker<'_> {
    /// 1-based line and column of byte `offset`.
    fn position(&self, offset: usize) -> (usize, usize) {
        let before = &self.text[..offset.min(self.text.len())];
        let line = before.matches('\n').count() + 1;
        let column = before.rsplit('\n').next().map_or(0, |l| l.chars().count()) + 1;
        (line, column)
    }

    fn invalid<T>(&self, key: &'static str, value: &Spanned<T>, message: String) -> ConfigError {
        ConfigError::Invalid {
            origin: self.origin.to_string(),
            line: Some(self.position(value.span().start).0),
            key,
            message,
        }
    }

    /// The value of `key` or its default, checked by `check`.
    fn value<T: Clone, U>(
        &self,
        key: &'static str,
        raw: &S<T>,
        default: T,
        check: impl FnOnce(T) -> Result<U, String>,
    ) -> Result<U, ConfigError> {
        match raw {
            Some(v) => check(v.get_ref().clone()).map_err(|m| self.invalid(key, v, m)),
            None => check(default).map_err(|message| ConfigError::Invalid {
                origin: self.origin.to_string(),
                line: None,
                key,
                message,
            }),
        }
    }

    /// An optional path: absent, or a non-empty string.
    fn path(&self, key: &'static str, raw: &S<String>) -> Result<Option<PathBuf>, ConfigError> {
        match raw {
            None => Ok(None),
            Some(v) if v.get_ref().trim().is_empty() => Err(self.invalid(
                key,
                v,
                "must not be empty; leave the key out instead".into(),
            )),
            Some(v) => Ok(Some(PathBuf::from(v.get_ref()))),
        }
    }

    fn syntax(&self, mut e: toml::de::Error) -> ConfigError {
        let (line, column) = self.position(e.span().map_or(0, |s| s.start));
        let message = e.message().trim_end().to_string();
        // toml only says which table a key sits in through its Display without the input
        // ("… in `devices.sra`").
        e.set_input(None);
        let key = e
            .to_string()
            .lines()
            .filter_map(|l| l.strip_prefix("in `")?.strip_suffix('`'))
            .next_back()
            .map(str::to_string);
        // For an unknown key toml names the table it sits in; name the key itself.
        let unknown = message
            .strip_prefix("unknown field `")
            .and_then(|m| m.split_once('`'))
            .map(|(k, _)| k.to_string());
        let key = match (key, unknown) {
            (Some(table), Some(k)) => Some(format!("{table}.{k}")),
            (None, Some(k)) => Some(k),
            (key, None) => key,
        };
        ConfigError::Syntax {
            origin: self.origin.to_string(),
            line,
            column,
            key,
            message,
        }
    }
}

/// A configuration file must say which instruments it runs: replayed recordings landing in a
/// production store unnoticed is the failure this prevents. (No file at all runs the simulated
/// instruments, loudly: that is the try-it-out default.)
const REQUIRED_TRANSPORT_MA_T12: &str = "must be set: \"usb\" for the instrument, or \"simulated\" \
     to replay a recording (no instrument; every scan is then marked simulated)";
const REQUIRED_TRANSPORT_SRA: &str = "must be set: \"serial\" for the instrument, \"simulated\" \
     to replay a recording (no instrument; every scan is then marked simulated), or \"off\" \
     when the lab has no SRA (scans then have the 12 MA-T12 geometries only)";

fn bounded_count(n: u64, lo: u64, hi: u64) -> Result<usize, String> {
    if (lo..=hi).contains(&n) {
        Ok(n as usize)
    } else {
        Err(format!("{n} is out of range: {lo} to {hi}"))
    }
}

fn api_timeout(ms: u64) -> Result<Duration, String> {
    if (100..=3_600_000).contains(&ms) {
        Ok(Duration::from_millis(ms))
    } else {
        Err(format!("{ms} is out of range: 100 to 3600000 ms"))
    }
}

fn timeout(ms: u64) -> Result<Duration, String> {
    // Above 10 minutes a dead instrument would hold a scan for longer than any operator waits.
    if (1..=600_000).contains(&ms) {
        Ok(Duration::from_millis(ms))
    } else {
        Err(format!("{ms} is out of range: a timeout is 1 to 600000 ms"))
    }
}

fn retries(n: u32) -> Result<u32, String> {
    if n <= 10 {
        Ok(n)
    } else {
        Err(format!("{n} is out of range: 0 to 10 resends"))
    }
}

/// A station id: 1 to 64 letters, digits, '.', '_' or '-' (it names the station in the central
/// database, in reports and on the command line, so nothing that needs quoting).
fn station_id(id: String) -> Result<String, String> {
    let ok = !id.is_empty()
        && id.len() <= 64
        && id
            .chars()
            .all(|ch| ch.is_ascii_alphanumeric() || matches!(ch, '.' | '_' | '-'));
    if ok {
        Ok(id)
    } else {
        Err(format!(
            "\"{id}\" is not a station id: 1 to 64 letters, digits, '.', '_' or '-'"
        ))
    }
}

/// The central database URL: postgres:// or postgresql://, parsed as sqlx parses it.
fn sync_url(url: &str) -> Result<String, String> {
    use std::str::FromStr;
    let shown = crate::sync::redact(url);
    if !crate::sync::is_postgres_url(url) {
        return Err(format!(
            "\"{shown}\" is not a PostgreSQL URL: write postgres://USER[:PASSWORD]@HOST[:PORT]/DATABASE"
        ));
    }
    sqlx::postgres::PgConnectOptions::from_str(url)
        .map(|_| url.to_string())
        .map_err(|e| format!("\"{shown}\" is not a valid PostgreSQL URL: {e}"))
}

/// `[reference] reflectance`: one value for a flat tile, 31 values (400–700 nm every 10 nm), or
/// a certificate file (CGATS or CxF3, [`crate::formats::certificate`]) whose relative path is
/// relative to the configuration file's directory. Returns the spectrum and where it came from.
fn reference_reflectance(
    v: &toml::Value,
    origin: &str,
) -> Result<(crate::spectral::Spectrum, String), String> {
    use crate::spectral::BANDS;
    let number = |v: &toml::Value| match v {
        toml::Value::Float(f) => Some(*f),
        toml::Value::Integer(i) => Some(*i as f64),
        _ => None,
    };
    let (rho, source) = match v {
        toml::Value::String(path) if path.trim().is_empty() => {
            return Err("must not be empty; leave the key out for ρ_ref = 1".into());
        }
        toml::Value::String(path) => {
            let dir = Path::new(origin).parent().unwrap_or(Path::new(""));
            let full = dir.join(path);
            let text = crate::formats::read_text(&full).map_err(|e| e.to_string())?;
            let rho = crate::formats::certificate::read(&full.display().to_string(), &text)
                .map_err(|e| format!("the tile certificate: {e}"))?;
            (rho, full.display().to_string())
        }
        toml::Value::Array(items) => {
            if items.len() != BANDS {
                return Err(format!(
                    "{} values; give one value or 31 (400, 410, … 700 nm)",
                    items.len()
                ));
            }
            let mut rho = [0.0; BANDS];
            for (i, (slot, item)) in rho.iter_mut().zip(items).enumerate() {
                *slot = number(item).ok_or_else(|| {
                    format!("value {} ({} nm) is not a number", i + 1, 400 + 10 * i)
                })?;
            }
            (rho, "31 values".into())
        }
        other => match number(other) {
            Some(x) => ([x; BANDS], "one value".into()),
            None => {
                return Err(
                    "must be a number (a flat tile), an array of 31 numbers (400–700 nm every \
                     10 nm) or the path of the tile's certificate (CGATS or CxF3)"
                        .into(),
                );
            }
        },
    };
    crate::formats::certificate::check("the calibration", &rho).map_err(|e| e.to_string())?;
    Ok((rho, source))
}

/// Where the configuration in force came from (`brdfd serve` says so at start).
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum ConfigOrigin {
    /// A file, and how it was found: `--config`, `BRDFD_CONFIG`, `$XDG_CONFIG_HOME/brdfd`,
    /// `/etc/brdfd`.
    File { path: PathBuf, via: &'static str },
    /// No file anywhere: the built-in defaults.
    Defaults,
}

impl std::fmt::Display for ConfigOrigin {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            ConfigOrigin::File { path, via } => write!(f, "{} (from {via})", path.display()),
            ConfigOrigin::Defaults => f.write_str(
                "built-in defaults (no --config, BRDFD_CONFIG, $XDG_CONFIG_HOME/brdfd/brdfd.toml \
                 or /etc/brdfd/brdfd.toml)",
            ),
        }
    }
}

/// What [`Config::search`] looks at, taken from the process (or made up in tests).
#[derive(Debug, Clone, Default)]
pub struct SearchEnv {
    pub brdfd_config: Option<PathBuf>,
    pub xdg_config_home: Option<PathBuf>,
    pub home: Option<PathBuf>,
    /// `/etc`.
    pub etc: PathBuf,
}

impl SearchEnv {
    pub fn from_process() -> SearchEnv {
        SearchEnv {
            brdfd_config: std::env::var_os("BRDFD_CONFIG").map(PathBuf::from),
            xdg_config_home: std::env::var_os("XDG_CONFIG_HOME").map(PathBuf::from),
            home: std::env::var_os("HOME").map(PathBuf::from),
            etc: PathBuf::from("/etc"),
        }
    }
}

impl Config {
    /// Reads and checks a configuration file.
    pub fn load(path: &Path) -> Result<Config, ConfigError> {
        let text = std::fs::read_to_string(path).map_err(|source| ConfigError::Read {
            path: path.to_path_buf(),
            source,
        })?;
        Config::from_toml(&text, &path.display().to_string())
    }

    /// The file at `path` if given, else the first found by [`Config::search`] (the built-in
    /// defaults when there is none).
    pub fn load_or_default(path: Option<&Path>) -> Result<Config, ConfigError> {
        Config::load_found(path).map(|(c, _)| c)
    }

    /// [`Config::load_or_default`], also saying where the configuration came from.
    pub fn load_found(path: Option<&Path>) -> Result<(Config, ConfigOrigin), ConfigError> {
        let origin = match path {
            Some(p) => ConfigOrigin::File {
                path: p.to_path_buf(),
                via: "--config",
            },
            None => Config::search(&SearchEnv::from_process()),
        };
        let config = match &origin {
            ConfigOrigin::File { path, .. } => Config::load(path)?,
            ConfigOrigin::Defaults => Config::default(),
        };
        Ok((config, origin))
    }

    /// Where a command without `--config` finds its configuration, first match wins:
    /// `BRDFD_CONFIG`, `$XDG_CONFIG_HOME/brdfd/brdfd.toml` (`~/.config/brdfd/brdfd.toml` when
    /// XDG_CONFIG_HOME is unset), `/etc/brdfd/brdfd.toml`; else the built-in defaults
    /// (simulated instruments). `BRDFD_CONFIG` names a file that must exist; the others are
    /// used only if they do.
    pub fn search(env: &SearchEnv) -> ConfigOrigin {
        if let Some(p) = env
            .brdfd_config
            .as_ref()
            .filter(|p| !p.as_os_str().is_empty())
        {
            return ConfigOrigin::File {
                path: p.clone(),
                via: "BRDFD_CONFIG",
            };
        }
        let user = env
            .xdg_config_home
            .clone()
            .filter(|p| p.is_absolute())
            .or_else(|| env.home.as_ref().map(|h| h.join(".config")))
            .map(|d| d.join("brdfd").join("brdfd.toml"));
        let candidates = [
            (user, "$XDG_CONFIG_HOME/brdfd"),
            (Some(env.etc.join("brdfd").join("brdfd.toml")), "/etc/brdfd"),
        ];
        for (path, via) in candidates {
            if let Some(path) = path.filter(|p| p.is_file()) {
                return ConfigOrigin::File { path, via };
            }
        }
        ConfigOrigin::Defaults
    }

    /// Parses and checks TOML text; `origin` names it in errors (the file name). Keys left out
    /// take their defaults.
    pub fn from_toml(text: &str, origin: &str) -> Result<Config, ConfigError> {
        Config::parse_text(text, origin, true)
    }

    /// [`Config::from_toml`], with `require_transport` false for tests of other sections.
    fn parse_text(
        text: &str,
        origin: &str,
        require_transport: bool,
    ) -> Result<Config, ConfigError> {
        let c = Checker {
            text,
            origin,
            require_transport,
        };
        let raw: RawConfig = toml::from_str(text).map_err(|e| c.syntax(e))?;

        Ok(Config {
            store: c.store(&raw.store)?,
            api: c.api(&raw.api)?,
            devices: DevicesConfig {
                ma_t12: c.ma_t12(&raw.devices.ma_t12)?,
                sra: c.sra(&raw.devices.sra)?,
            },
            scan: c.scan(&raw.scan)?,
            fit: c.fit(&raw.fit)?,
            colour: c.colour(&raw.colour)?,
            log: c.log(&raw.log)?,
            station: c.station(&raw.station)?,
            sync: c.sync(&raw.sync)?,
            reference: c.reference(&raw.reference)?,
            ingest: c.ingest(&raw.ingest)?,
        })
    }
}

// ---- Stage 2, per section: each `[section]` of the raw file checked into its settings ------

/// The full names of the keys every `[devices.*]` section has, for messages.
struct DeviceKeys {
    transport: &'static str,
    session: &'static str,
    timeout_ms: &'static str,
    retries: &'static str,
    record: &'static str,
}

/// The [`DeviceKeys`] of section `$section` (e.g. `"devices.sra"`).
macro_rules! device_keys {
    ($section:literal) => {
        DeviceKeys {
            transport: concat!($section, ".transport"),
            session: concat!($section, ".session"),
            timeout_ms: concat!($section, ".timeout_ms"),
            retries: concat!($section, ".retries"),
            record: concat!($section, ".record"),
        }
    };
}

impl Checker<'_> {
    /// `[store]`
    fn store(&self, raw: &RawStore) -> Result<StoreConfig, ConfigError> {
        Ok(StoreConfig {
            path: self.value("store.path", &raw.path, defaults::STORE_PATH.into(), |p| {
                if p.trim().is_empty() {
                    Err("must name the SQLite file, e.g. \"brdfd.db\"".into())
                } else {
                    Ok(PathBuf::from(p))
                }
            })?,
        })
    }

    /// `[api]`
    fn api(&self, raw: &RawApi) -> Result<ApiConfig, ConfigError> {
        let allow_remote = raw.allow_remote.unwrap_or(false);
        Ok(ApiConfig {
            listen: self.value("api.listen", &raw.listen, defaults::LISTEN.into(), |s| {
                let addr: SocketAddr = s.parse().map_err(|_| {
                    format!("\"{s}\" is not an IP address and port, e.g. \"127.0.0.1:7878\"")
                })?;
                check_listen(addr, allow_remote)
            })?,
            allow_remote,
            token_file: self.path("api.token_file", &raw.token_file)?,
            allowed_hosts: self.value(
                "api.allowed_hosts",
                &raw.allowed_hosts,
                Vec::new(),
                |hosts| {
                    for h in &hosts {
                        let ok = !h.is_empty()
                            && h.len() <= 253
                            && h.chars()
                                .all(|c| c.is_ascii_alphanumeric() || "-._[]:".contains(c));
                        if !ok {
                            return Err(format!(
                                "\"{h}\" is not a host name: letters, digits, '-', '.' (an IP \
                             address in brackets for IPv6), without a port"
                            ));
                        }
                    }
                    Ok(hosts.into_iter().map(|h| h.to_ascii_lowercase()).collect())
                },
            )?,
            max_connections: self.value(
                "api.max_connections",
                &raw.max_connections,
                defaults::MAX_CONNECTIONS as u64,
                |n| bounded_count(n, 1, 10_000),
            )?,
            max_event_subscribers: self.value(
                "api.max_event_subscribers",
                &raw.max_event_subscribers,
                defaults::MAX_EVENT_SUBSCRIBERS as u64,
                |n| bounded_count(n, 1, 10_000),
            )?,
            header_timeout: self.value(
                "api.header_timeout_ms",
                &raw.header_timeout_ms,
                defaults::HEADER_TIMEOUT_MS,
                api_timeout,
            )?,
            idle_timeout: self.value(
                "api.idle_timeout_ms",
                &raw.idle_timeout_ms,
                defaults::IDLE_TIMEOUT_MS,
                api_timeout,
            )?,
        })
    }

    /// `[scan]`
    fn scan(&self, raw: &RawScan) -> Result<ScanConfig, ConfigError> {
        Ok(ScanConfig {
            reference_max_age: self.value(
                "scan.reference_max_age_hours",
                &raw.reference_max_age_hours,
                defaults::REFERENCE_MAX_AGE_HOURS,
                |h| {
                    // A year bounds it so that a typo cannot switch the check off silently.
                    if h.is_finite() && h > 0.0 && h <= 8760.0 {
                        Ok(Duration::from_secs_f64(h * 3600.0))
                    } else {
                        Err(format!(
                            "{h} is out of range: more than 0 and at most 8760 hours"
                        ))
                    }
                },
            )?,
        })
    }

    /// `[fit]`
    fn fit(&self, raw: &RawFit) -> Result<FitConfig, ConfigError> {
        let method = self.value(
            "fit.method",
            &raw.method,
            Method::default().name().into(),
            |m| m.parse::<Method>().map_err(|e| e.to_string()),
        )?;
        Ok(FitConfig {
            cost_functions: self.value(
                "fit.cost_functions",
                &raw.cost_functions,
                CostFunction::ALL
                    .iter()
                    .map(|cf| cf.name().to_string())
                    .collect(),
                |names| {
                    let mut out: Vec<CostFunction> = Vec::new();
                    for n in &names {
                        let cf: CostFunction = n.parse().map_err(|e| format!("{e}"))?;
                        if out.contains(&cf) {
                            return Err(format!("{cf} is listed twice"));
                        }
                        out.push(cf);
                    }
                    if out.is_empty() {
                        return Err("must list at least one of \"cf1\", \"cf2\", \"m2\"".into());
                    }
                    Ok(out)
                },
            )?,
            method,
            seed: self.value("fit.seed", &raw.seed, defaults::SEED, Ok)?,
            max_concurrent_fits: self.value(
                "fit.max_concurrent_fits",
                &raw.max_concurrent_fits,
                1,
                |n| match usize::try_from(n).ok().and_then(NonZeroUsize::new) {
                    Some(n) if n.get() <= 256 => Ok(n),
                    _ => Err(format!("{n} is out of range: 1 to 256 fits at once")),
                },
            )?,
            specular: self.value(
                "fit.specular",
                &raw.specular,
                SpecularStrategy::default().name().into(),
                |s| s.parse::<SpecularStrategy>().map_err(|e| e.to_string()),
            )?,
            sra: self.value("fit.sra", &raw.sra, defaults::SRA.name().into(), |s| {
                s.parse::<crate::sra_reading::SraModel>()
                    .map_err(|e| e.to_string())
            })?,
            model: self.value(
                "fit.model",
                &raw.model,
                crate::model::ModelKind::default().name().into(),
                |s| {
                    let m = s.parse::<crate::model::ModelKind>()?;
                    if m != crate::model::ModelKind::Paper && method == Method::Paper {
                        return Err(format!(
                            "model {m} needs the separable method (fit.method = \"separable\")"
                        ));
                    }
                    Ok(m)
                },
            )?,
            bootstrap: self.value("fit.bootstrap", &raw.bootstrap, defaults::BOOTSTRAP, |n| {
                if n <= 10_000 {
                    Ok(n)
                } else {
                    Err(format!(
                        "{n} is out of range: 0 (off) to 10000 resamples; 200 gives 95 % intervals"
                    ))
                }
            })?,
        })
    }

    /// `[colour]`
    fn colour(&self, raw: &RawColour) -> Result<crate::colour::Colorimetry, ConfigError> {
        Ok(crate::colour::Colorimetry {
            observer: self.value(
                "colour.observer",
                &raw.observer,
                crate::colour::Observer::default().to_string(),
                |o| {
                    o.parse()
                        .map_err(|e: crate::colour::ColorimetryError| e.to_string())
                },
            )?,
            weighting: self.value(
                "colour.weighting",
                &raw.weighting,
                crate::colour::Weighting::default().to_string(),
                |w| {
                    w.parse()
                        .map_err(|e: crate::colour::ColorimetryError| e.to_string())
                },
            )?,
        })
    }

    /// `[log]`
    fn log(&self, raw: &RawLog) -> Result<LogConfig, ConfigError> {
        Ok(LogConfig {
            json: raw.json.unwrap_or(false),
            level: self.value("log.level", &raw.level, defaults::LEVEL.into(), |l| {
                l.parse::<LogLevel>()
            })?,
        })
    }

    /// `[station]`
    fn station(&self, raw: &RawStation) -> Result<StationConfig, ConfigError> {
        Ok(StationConfig {
            id: self.value(
                "station.id",
                &raw.id,
                crate::sync::default_station_id(),
                station_id,
            )?,
        })
    }

    /// `[sync]`
    fn sync(&self, raw: &RawSync) -> Result<SyncConfig, ConfigError> {
        Ok(SyncConfig {
            url: match &raw.url {
                None => None,
                Some(v) => Some(sync_url(v.get_ref()).map_err(|m| self.invalid("sync.url", v, m))?),
            },
            batch: self.value("sync.batch", &raw.batch, defaults::SYNC_BATCH, |n| {
                if (1..=10_000).contains(&n) {
                    Ok(n as usize)
                } else {
                    Err(format!(
                        "{n} is out of range: 1 to 10000 rows per transaction"
                    ))
                }
            })?,
        })
    }

    /// `[reference]`
    fn reference(&self, raw: &RawReference) -> Result<ReferenceConfig, ConfigError> {
        Ok(match &raw.reflectance {
            None => ReferenceConfig::default(),
            Some(v) => {
                let (rho, source) = reference_reflectance(v.get_ref(), self.origin)
                    .map_err(|m| self.invalid("reference.reflectance", v, m))?;
                ReferenceConfig {
                    reflectance: Some(rho),
                    source: Some(source),
                }
            }
        })
    }

    /// `[ingest]`
    fn ingest(&self, raw: &RawIngest) -> Result<IngestConfig, ConfigError> {
        let ms_in = |lo: u64, hi: u64| {
            move |ms: u64| {
                if (lo..=hi).contains(&ms) {
                    Ok(Duration::from_millis(ms))
                } else {
                    Err(format!("{ms} is out of range: {lo} to {hi} ms"))
                }
            }
        };
        Ok(IngestConfig {
            watch: self.path("ingest.watch", &raw.watch)?,
            settle: self.value(
                "ingest.settle_ms",
                &raw.settle_ms,
                defaults::INGEST_SETTLE_MS,
                ms_in(10, 3_600_000),
            )?,
            poll: self.value(
                "ingest.poll_ms",
                &raw.poll_ms,
                defaults::INGEST_POLL_MS,
                ms_in(10, 60_000),
            )?,
            pair_wait: self.value(
                "ingest.pair_wait_ms",
                &raw.pair_wait_ms,
                defaults::INGEST_PAIR_WAIT_MS,
                ms_in(0, 86_400_000),
            )?,
            reference: self.value(
                "ingest.reference",
                &raw.reference,
                crate::formats::DEFAULT_REFERENCE.to_string(),
                |r| {
                    if r.trim().is_empty() {
                        Err("must name the reference tile, e.g. \"Munsell N9\"".into())
                    } else {
                        Ok(r)
                    }
                },
            )?,
            max_file_bytes: self.value(
                "ingest.max_file_mib",
                &raw.max_file_mib,
                defaults::INGEST_MAX_FILE_MIB,
                |n| bounded_count(n, 1, 1024).map(|n| (n as u64) << 20),
            )?,
        })
    }

    /// `[devices.ma_t12]`: the transport, then the keys every instrument has.
    fn ma_t12(&self, raw: &RawMaT12) -> Result<MaT12Config, ConfigError> {
        const KEYS: DeviceKeys = device_keys!("devices.ma_t12");
        let usb = self.real_transport(&KEYS, &raw.transport, "usb", REQUIRED_TRANSPORT_MA_T12)?;
        let transport = if usb {
            MaT12Transport::Usb {
                product_id: raw.product_id.as_ref().map(|p| *p.get_ref()),
            }
        } else {
            MaT12Transport::Simulated {
                session: self.path(KEYS.session, &raw.session)?,
            }
        };
        self.device(&KEYS, transport, &raw.timeout_ms, &raw.retries, &raw.record)
    }

    /// `[devices.sra]`: the transport and the serial settings (checked whichever transport is
    /// chosen), then the keys every instrument has.
    fn sra(&self, raw: &RawSra) -> Result<SraConfig, ConfigError> {
        const KEYS: DeviceKeys = device_keys!("devices.sra");
        let off = raw
            .transport
            .as_ref()
            .is_some_and(|t| t.get_ref().trim() == "off");
        let serial =
            !off && self.real_transport(&KEYS, &raw.transport, "serial", REQUIRED_TRANSPORT_SRA)?;
        let port = self.value(
            "devices.sra.port",
            &raw.port,
            defaults::SRA_PORT.into(),
            |p| {
                if p.trim().is_empty() {
                    Err("must name the serial device, e.g. \"/dev/ttyUSB0\"".into())
                } else {
                    Ok(p)
                }
            },
        )?;
        let baud = self.value("devices.sra.baud", &raw.baud, defaults::SRA_BAUD, |b| {
            if (50..=4_000_000).contains(&b) {
                Ok(b)
            } else {
                Err(format!("{b} is not a serial speed: 50 to 4000000 baud"))
            }
        })?;
        let transport = if off {
            SraTransport::Off
        } else if serial {
            SraTransport::Serial { port, baud }
        } else {
            SraTransport::Simulated {
                session: self.path(KEYS.session, &raw.session)?,
            }
        };
        self.device(&KEYS, transport, &raw.timeout_ms, &raw.retries, &raw.record)
    }

    /// A section's `transport`: `true` for the real one (`real`, e.g. "usb"), `false` for
    /// "simulated" (or, when the file need not choose, nothing).
    fn real_transport(
        &self,
        keys: &DeviceKeys,
        raw: &S<String>,
        real: &str,
        required: &'static str,
    ) -> Result<bool, ConfigError> {
        self.value(keys.transport, raw, String::new(), |t| match t.as_str() {
            "" if self.require_transport => Err(required.into()),
            "" => Ok(false),
            "simulated" => Ok(false),
            t if t == real => Ok(true),
            other if keys.transport == "devices.sra.transport" => Err(format!(
                "unknown transport \"{other}\": expected \"simulated\", \"{real}\" or \"off\""
            )),
            other => Err(format!(
                "unknown transport \"{other}\": expected \"simulated\" or \"{real}\""
            )),
        })
    }

    /// The device block every `[devices.*]` section shares: `timeout_ms`, `retries` and
    /// `record`, around the section's checked `transport`.
    fn device<T>(
        &self,
        keys: &DeviceKeys,
        transport: T,
        timeout_ms: &S<u64>,
        retries_raw: &S<u32>,
        record: &S<String>,
    ) -> Result<DeviceConfig<T>, ConfigError> {
        Ok(DeviceConfig {
            transport,
            timeout: self.value(keys.timeout_ms, timeout_ms, defaults::TIMEOUT_MS, timeout)?,
            retries: self.value(keys.retries, retries_raw, defaults::RETRIES, retries)?,
            record: self.path(keys.record, record)?,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_configuration_is_searched_in_the_documented_order() {
        let dir = tempfile::tempdir().unwrap();
        let etc = dir.path().join("etc");
        let xdg = dir.path().join("xdg");
        let home = dir.path().join("home");
        let env = |brdfd: Option<PathBuf>| SearchEnv {
            brdfd_config: brdfd,
            xdg_config_home: Some(xdg.clone()),
            home: Some(home.clone()),
            etc: etc.clone(),
        };
        // Nothing anywhere: the defaults.
        assert_eq!(Config::search(&env(None)), ConfigOrigin::Defaults);
        // /etc/brdfd/brdfd.toml.
        std::fs::create_dir_all(etc.join("brdfd")).unwrap();
        std::fs::write(etc.join("brdfd/brdfd.toml"), "").unwrap();
        assert_eq!(
            Config::search(&env(None)),
            ConfigOrigin::File {
                path: etc.join("brdfd/brdfd.toml"),
                via: "/etc/brdfd"
            }
        );
        // The user's file wins over /etc.
        std::fs::create_dir_all(xdg.join("brdfd")).unwrap();
        std::fs::write(xdg.join("brdfd/brdfd.toml"), "").unwrap();
        assert_eq!(
            Config::search(&env(None)),
            ConfigOrigin::File {
                path: xdg.join("brdfd/brdfd.toml"),
                via: "$XDG_CONFIG_HOME/brdfd"
            }
        );
        // Without XDG_CONFIG_HOME: ~/.config.
        let mut no_xdg = env(None);
        no_xdg.xdg_config_home = None;
        std::fs::create_dir_all(home.join(".config/brdfd")).unwrap();
        std::fs::write(home.join(".config/brdfd/brdfd.toml"), "").unwrap();
        assert_eq!(
            Config::search(&no_xdg),
            ConfigOrigin::File {
                path: home.join(".config/brdfd/brdfd.toml"),
                via: "$XDG_CONFIG_HOME/brdfd"
            }
        );
        // BRDFD_CONFIG wins over both, even when the file is missing (then loading says so).
        let named = dir.path().join("named.toml");
        assert_eq!(
            Config::search(&env(Some(named.clone()))),
            ConfigOrigin::File {
                path: named,
                via: "BRDFD_CONFIG"
            }
        );
        assert!(
            ConfigOrigin::Defaults
                .to_string()
                .contains("/etc/brdfd/brdfd.toml")
        );
    }

    /// Sections other than `[devices.*]` on their own: transports may be left out.
    fn parse(text: &str) -> Result<Config, ConfigError> {
        Config::parse_text(text, "test.toml", false)
    }

    #[test]
    fn the_shipped_file_names_real_instruments_and_otherwise_gives_the_defaults() {
        let shipped = Config::from_toml(SHIPPED, "config/brdfd.toml").unwrap();
        // The shipped file is what the systemd unit installs: real instruments.
        assert_eq!(
            shipped.devices.ma_t12.transport,
            MaT12Transport::Usb { product_id: None }
        );
        assert_eq!(
            shipped.devices.sra.transport,
            SraTransport::Serial {
                port: "/dev/ttyUSB0".into(),
                baud: 9600
            }
        );
        let mut expected = Config::default();
        expected.devices.ma_t12.transport = shipped.devices.ma_t12.transport.clone();
        expected.devices.sra.transport = shipped.devices.sra.transport.clone();
        assert_eq!(shipped, expected);
        // No file at all runs with no instrument (loudly) and writes a local SQLite file.
        assert!(matches!(
            Config::default().devices.ma_t12.transport,
            MaT12Transport::Simulated { session: None }
        ));
        assert!(matches!(
            Config::default().devices.sra.transport,
            SraTransport::Simulated { session: None }
        ));
        assert!(shipped.store.path.is_relative());
        assert!(shipped.api.listen.ip().is_loopback());
        assert_eq!(shipped.fit.max_concurrent_fits.get(), 1);
        assert_eq!(shipped.fit.cost_functions, CostFunction::ALL);
        assert_eq!(shipped.fit.specular, SpecularStrategy::Ratio);
    }

    #[test]
    fn reference_reflectance_is_one_value_31_values_or_a_certificate() {
        assert_eq!(Config::default().reference.reflectance, None);
        let c = parse("[reference]\nreflectance = 0.77\n").unwrap();
        assert_eq!(c.reference.reflectance, Some([0.77; 31]));
        let values: Vec<String> = (0..31).map(|i| format!("0.{}", 40 + i)).collect();
        let c = parse(&format!(
            "[reference]\nreflectance = [{}]\n",
            values.join(", ")
        ))
        .unwrap();
        assert_eq!(c.reference.reflectance.unwrap()[30], 0.7);
        let e = parse("[reference]\nreflectance = [0.7, 0.8]\n")
            .unwrap_err()
            .to_string();
        assert_eq!(
            e,
            "test.toml:2: reference.reflectance: 2 values; give one value or 31 (400, 410, … 700 nm)"
        );
        let e = parse("[reference]\nreflectance = 77\n")
            .unwrap_err()
            .to_string();
        assert!(e.contains("divided by 100"), "{e}");
        let e = parse("[reference]\nreflectance = 0\n")
            .unwrap_err()
            .to_string();
        assert!(e.contains("400 nm is 0"), "{e}");

        // A certificate next to the configuration file.
        let dir = tempfile::tempdir().unwrap();
        let mut cert = String::from("CGATS.17\nBEGIN_DATA_FORMAT\nSAMPLE_ID");
        for nm in crate::spectral::wavelengths_nm() {
            cert.push_str(&format!(" SPECTRAL_NM{nm}"));
        }
        cert.push_str("\nEND_DATA_FORMAT\nBEGIN_DATA\n1");
        for _ in 0..31 {
            cert.push_str(" 0.765");
        }
        cert.push_str("\nEND_DATA\n");
        std::fs::write(dir.path().join("n9.cgats"), cert).unwrap();
        let toml_path = dir.path().join("brdfd.toml");
        std::fs::write(
            &toml_path,
            "[reference]\nreflectance = \"n9.cgats\"\n[devices.ma_t12]\ntransport = \"usb\"\n\
             [devices.sra]\ntransport = \"serial\"\n",
        )
        .unwrap();
        let c = Config::load(&toml_path).unwrap();
        assert_eq!(c.reference.reflectance, Some([0.765; 31]));
        let e = parse("[reference]\nreflectance = \"missing.cgats\"\n")
            .unwrap_err()
            .to_string();
        assert!(
            e.starts_with("test.toml:2: reference.reflectance: cannot read missing.cgats"),
            "{e}"
        );
    }

    #[test]
    fn every_key_of_the_shipped_file_is_there_with_a_comment() {
        // Every key of the raw structs, set or shown commented out (`# key = …`).
        const KEYS: [&str; 33] = [
            "path",
            "listen",
            "allow_remote",
            "token_file",
            "allowed_hosts",
            "max_connections",
            "max_event_subscribers",
            "header_timeout_ms",
            "idle_timeout_ms",
            "transport",
            "session",
            "product_id",
            "timeout_ms",
            "retries",
            "record",
            "port",
            "baud",
            "reference_max_age_hours",
            "cost_functions",
            "method",
            "seed",
            "max_concurrent_fits",
            "specular",
            "sra",
            "json",
            "level",
            "reflectance",
            "watch",
            "settle_ms",
            "poll_ms",
            "pair_wait_ms",
            "reference",
            "max_file_mib",
        ];
        let lines: Vec<&str> = SHIPPED.lines().collect();
        for key in KEYS {
            let shown = lines
                .iter()
                .any(|l| l.trim_start_matches("# ").starts_with(&format!("{key} = ")));
            assert!(shown, "config/brdfd.toml does not show `{key}`");
        }
        // Each key that is set has a comment line right above it.
        for (i, line) in lines.iter().enumerate() {
            if !line.starts_with('#') && !line.starts_with('[') && line.contains(" = ") {
                assert!(
                    i > 0 && lines[i - 1].starts_with('#'),
                    "config/brdfd.toml line {}: `{line}` has no comment above it",
                    i + 1
                );
            }
        }
    }

    #[test]
    fn ingest_settings() {
        let d = Config::default().ingest;
        assert_eq!(d.watch, None);
        assert_eq!(d.settle, Duration::from_secs(2));
        let c = parse(
            "[ingest]\nwatch = \"/srv/inbox\"\nsettle_ms = 50\npoll_ms = 20\npair_wait_ms = 0\n\
             reference = \"N9 tile\"\n",
        )
        .unwrap();
        assert_eq!(c.ingest.watch, Some(PathBuf::from("/srv/inbox")));
        assert_eq!(c.ingest.settle, Duration::from_millis(50));
        assert_eq!(c.ingest.poll, Duration::from_millis(20));
        assert_eq!(c.ingest.pair_wait, Duration::ZERO);
        assert_eq!(c.ingest.reference, "N9 tile");
        let e = parse("[ingest]\nsettle_ms = 5\n").unwrap_err().to_string();
        assert_eq!(
            e,
            "test.toml:2: ingest.settle_ms: 5 is out of range: 10 to 3600000 ms"
        );
        let e = parse("[ingest]\nwatch = \"\"\n").unwrap_err().to_string();
        assert!(e.contains("ingest.watch: must not be empty"), "{e}");
    }

    #[test]
    fn station_and_sync_settings() {
        let c = parse("[station]\nid = \"bench-2\"\n[sync]\nurl = \"postgres://lab@db/brdfd\"\n")
            .unwrap();
        assert_eq!(c.station.id, "bench-2");
        assert_eq!(c.sync.url.as_deref(), Some("postgres://lab@db/brdfd"));
        assert_eq!(c.sync.batch, 500);
        let e = parse("[station]\nid = \"bench 2\"\n")
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("station.id") && e.contains("test.toml:2:"),
            "{e}"
        );
        let e = parse("[sync]\nurl = \"mysql://u:pw@h/db\"\n")
            .unwrap_err()
            .to_string();
        assert!(e.contains("sync.url") && !e.contains("pw"), "{e}");
        let e = parse("[sync]\nbatch = 0\n").unwrap_err().to_string();
        assert!(e.contains("sync.batch"), "{e}");
        for key in ["id = ", "url = ", "batch = "] {
            assert!(
                SHIPPED
                    .lines()
                    .any(|l| l.trim_start_matches("# ").starts_with(key)),
                "config/brdfd.toml does not show `{key}`"
            );
        }
    }

    #[test]
    fn no_file_and_an_empty_file_give_the_defaults() {
        assert_eq!(Config::load_or_default(None).unwrap(), Config::default());
        assert_eq!(parse("").unwrap(), Config::default());
    }

    #[test]
    fn a_file_must_choose_its_instruments() {
        let e = Config::from_toml("", "brdfd.toml").unwrap_err();
        assert!(
            e.to_string().starts_with(
                "brdfd.toml: devices.ma_t12.transport: must be set: \"usb\" for the instrument"
            ),
            "{e}"
        );
        let e =
            Config::from_toml("[devices.ma_t12]\ntransport = \"usb\"\n", "brdfd.toml").unwrap_err();
        assert!(
            e.to_string().contains("devices.sra.transport: must be set"),
            "{e}"
        );
        let c = Config::from_toml(
            "[devices.ma_t12]\ntransport = \"simulated\"\n[devices.sra]\ntransport = \"simulated\"\n",
            "brdfd.toml",
        )
        .unwrap();
        assert_eq!(c, Config::default());
    }

    #[test]
    fn api_limits_and_hosts_are_checked() {
        let c = parse(
            "[api]\ntoken_file = \"/run/brdfd/token\"\nallowed_hosts = [\"Lab-PC.example\"]\n\
             max_connections = 10\nmax_event_subscribers = 2\nheader_timeout_ms = 500\n\
             idle_timeout_ms = 20000\n",
        )
        .unwrap();
        assert_eq!(
            c.api.token_path(Path::new("x/brdfd.db")),
            PathBuf::from("/run/brdfd/token")
        );
        assert_eq!(c.api.allowed_hosts, ["lab-pc.example"]);
        assert_eq!(
            (c.api.max_connections, c.api.max_event_subscribers),
            (10, 2)
        );
        assert_eq!(c.api.header_timeout, Duration::from_millis(500));
        assert_eq!(c.api.idle_timeout, Duration::from_secs(20));
        // The token file defaults to the store's directory.
        let d = Config::default();
        assert_eq!(
            d.api.token_path(Path::new("/var/lib/brdfd/brdfd.db")),
            PathBuf::from("/var/lib/brdfd/brdfd.token")
        );
        assert_eq!(
            d.api.token_path(Path::new("brdfd.db")),
            PathBuf::from("brdfd.token")
        );
        for bad in [
            "allowed_hosts = [\"evil.example:80/x\"]",
            "allowed_hosts = [\"\"]",
            "max_connections = 0",
            "max_event_subscribers = 100000",
            "header_timeout_ms = 1",
            "token_file = \"\"",
        ] {
            let e = parse(&format!("[api]\n{bad}\n")).unwrap_err();
            assert!(e.to_string().starts_with("test.toml:2: api."), "{bad}: {e}");
        }
        assert!(
            check_listen("0.0.0.0:1".parse().unwrap(), false)
                .unwrap_err()
                .contains("allow_remote")
        );
        assert!(check_listen("0.0.0.0:1".parse().unwrap(), true).is_ok());
    }

    #[test]
    fn an_unknown_key_is_rejected_naming_key_and_line() {
        let text =
            "[store]\npath = \"x.db\"\n\n[devices.sra]\ntransport = \"serial\"\nbaudrate = 19200\n";
        let e = parse(text).unwrap_err();
        let ConfigError::Syntax {
            line, key, message, ..
        } = &e
        else {
            panic!("{e:?}")
        };
        assert_eq!(*line, 6);
        assert!(message.contains("unknown field `baudrate`"), "{message}");
        assert_eq!(key.as_deref(), Some("devices.sra.baudrate"), "{e}");
        let shown = e.to_string();
        assert!(
            shown.starts_with("test.toml:6:1: unknown field `baudrate`"),
            "{shown}"
        );
        // An unknown section too.
        let e = parse("[fitt]\nseed = 3\n").unwrap_err();
        assert!(
            matches!(&e, ConfigError::Syntax { line: 1, message, .. } if message.contains("unknown field `fitt`")),
            "{e}"
        );
    }

    #[test]
    fn a_value_of_the_wrong_type_names_its_line() {
        let e = parse("[fit]\nmethod = \"paper\"\nseed = \"seven\"\n").unwrap_err();
        assert!(matches!(e, ConfigError::Syntax { line: 3, .. }), "{e}");
        assert!(e.to_string().contains("fit.seed"), "{e}");
    }

    #[test]
    fn remote_listening_needs_allow_remote() {
        let e = parse("[api]\n\nlisten = \"0.0.0.0:7878\"\n").unwrap_err();
        let shown = e.to_string();
        assert!(
            shown.starts_with(
                "test.toml:3: api.listen: 0.0.0.0:7878 is reachable from other machines"
            ),
            "{shown}"
        );
        let c = parse("[api]\nlisten = \"0.0.0.0:7878\"\nallow_remote = true\n").unwrap();
        assert_eq!(c.api.listen, "0.0.0.0:7878".parse().unwrap());
        let c = parse("[api]\nlisten = \"[::1]:9000\"\n").unwrap();
        assert_eq!(c.api.listen.port(), 9000);
        let e = parse("[api]\nlisten = \"localhost:7878\"\n").unwrap_err();
        assert!(
            e.to_string().contains("is not an IP address and port"),
            "{e}"
        );
    }

    #[test]
    fn real_transports_and_their_settings() {
        let c = parse(
            "[devices.ma_t12]\ntransport = \"usb\"\nproduct_id = 0x1234\ntimeout_ms = 5000\n\
             [devices.sra]\ntransport = \"serial\"\nport = \"/dev/ttyS1\"\nbaud = 19200\n\
             record = \"sra.session\"\nretries = 0\n",
        )
        .unwrap();
        assert_eq!(
            c.devices.ma_t12.transport,
            MaT12Transport::Usb {
                product_id: Some(0x1234)
            }
        );
        assert_eq!(c.devices.ma_t12.timeout, Duration::from_secs(5));
        assert_eq!(
            c.devices.sra.transport,
            SraTransport::Serial {
                port: "/dev/ttyS1".into(),
                baud: 19200
            }
        );
        assert_eq!(c.devices.sra.retries, 0);
        assert_eq!(c.devices.sra.record, Some(PathBuf::from("sra.session")));
        let c = parse("[devices.sra]\nsession = \"recordings/sra-glossy.session\"\n").unwrap();
        assert_eq!(
            c.devices.sra.transport,
            SraTransport::Simulated {
                session: Some("recordings/sra-glossy.session".into())
            }
        );
        let e = parse("[devices.sra]\ntransport = \"rs232\"\n").unwrap_err();
        assert_eq!(
            e.to_string(),
            "test.toml:2: devices.sra.transport: unknown transport \"rs232\": expected \
             \"simulated\", \"serial\" or \"off\""
        );
        // A lab with only an MA-T12 turns the SRA off; the serial keys are still checked.
        let c = parse("[devices.sra]\ntransport = \"off\"\n").unwrap();
        assert_eq!(c.devices.sra.transport, SraTransport::Off);
        let e = parse("[devices.sra]\ntransport = \"off\"\nbaud = 3\n").unwrap_err();
        assert!(e.to_string().contains("devices.sra.baud"), "{e}");
        let e = parse("[devices.ma_t12]\n\ntimeout_ms = 0\n").unwrap_err();
        assert!(
            matches!(
                &e,
                ConfigError::Invalid {
                    line: Some(3),
                    key: "devices.ma_t12.timeout_ms",
                    ..
                }
            ),
            "{e}"
        );
    }

    #[test]
    fn fit_settings_are_checked_by_name() {
        let c = parse(
            "[fit]\ncost_functions = [\"m2\", \"cf1\"]\nmethod = \"paper\"\nseed = 42\n\
             max_concurrent_fits = 2\nspecular = \"paper-eq9\"\n",
        )
        .unwrap();
        assert_eq!(c.fit.cost_functions, [CostFunction::M2, CostFunction::Cf1]);
        assert_eq!(c.fit.method, Method::Paper);
        assert_eq!(c.fit.seed, 42);
        assert_eq!(c.fit.max_concurrent_fits.get(), 2);
        assert_eq!(c.fit.specular, SpecularStrategy::PaperEq9);
        let cases = [
            (
                "cost_functions = [\"cf3\"]",
                "fit.cost_functions",
                "unknown cost function \"cf3\"",
            ),
            (
                "cost_functions = [\"cf1\", \"cf1\"]",
                "fit.cost_functions",
                "cf1 is listed twice",
            ),
            ("cost_functions = []", "fit.cost_functions", "at least one"),
            (
                "method = \"annealing\"",
                "fit.method",
                "unknown fit method \"annealing\"",
            ),
            (
                "max_concurrent_fits = 0",
                "fit.max_concurrent_fits",
                "out of range",
            ),
            (
                "specular = \"mirror\"",
                "fit.specular",
                "unknown specular strategy \"mirror\"",
            ),
        ];
        for (line, key, says) in cases {
            let e = parse(&format!("[fit]\n{line}\n")).unwrap_err();
            let shown = e.to_string();
            assert!(
                shown.starts_with(&format!("test.toml:2: {key}: ")),
                "{shown}"
            );
            assert!(shown.contains(says), "{shown}");
        }
    }

    #[test]
    fn sra_setting() {
        use crate::sra_reading::SraModel;
        assert_eq!(parse("").unwrap().fit.sra, SraModel::Luminance);
        let c = parse("[fit]\nsra = \"flat\"\n").unwrap();
        assert_eq!(c.fit.sra, SraModel::Flat);
        let e = parse("[fit]\nsra = \"grey\"\n").unwrap_err().to_string();
        assert!(e.contains("fit.sra") && e.contains("luminance"), "{e}");
    }

    #[test]
    fn model_setting() {
        use crate::model::ModelKind;
        assert_eq!(parse("").unwrap().fit.model, ModelKind::Paper);
        let c = parse("[fit]\nmodel = \"oren-nayar\"\n").unwrap();
        assert_eq!(c.fit.model, ModelKind::OrenNayar);
        assert_eq!(
            crate::service::ServiceSettings::from_config(&c)
                .fit_settings(CostFunction::Cf2, Method::Separable, 1)
                .model,
            ModelKind::OrenNayar
        );
        let e = parse("[fit]\nmodel = \"lambert\"\n")
            .unwrap_err()
            .to_string();
        assert!(e.contains("fit.model") && e.contains("two-lobe"), "{e}");
        let e = parse("[fit]\nmethod = \"paper\"\nmodel = \"two-lobe\"\n")
            .unwrap_err()
            .to_string();
        assert!(e.contains("fit.model") && e.contains("separable"), "{e}");
    }

    #[test]
    fn colour_and_bootstrap_settings() {
        let c =
            parse("[colour]\nobserver = \"10\"\nweighting = \"astm-e308\"\n[fit]\nbootstrap = 0\n")
                .unwrap();
        assert_eq!(c.colour.observer, crate::colour::Observer::Cie1964TenDegree);
        assert_eq!(c.colour.weighting, crate::colour::Weighting::AstmE308);
        assert_eq!(c.fit.bootstrap, 0);
        let e = parse("[colour]\nobserver = \"5\"\n")
            .unwrap_err()
            .to_string();
        assert!(e.contains("colour.observer") && e.contains("\"10\""), "{e}");
        let e = parse("[fit]\nbootstrap = 20000\n").unwrap_err().to_string();
        assert!(e.contains("fit.bootstrap"), "{e}");
    }

    #[test]
    fn scan_and_log_settings() {
        let c =
            parse("[scan]\nreference_max_age_hours = 8\n[log]\njson = true\nlevel = \"debug\"\n")
                .unwrap();
        assert_eq!(c.scan.reference_max_age, Duration::from_secs(8 * 3600));
        assert!(c.log.json);
        assert_eq!(c.log.level, LogLevel::Debug);
        let c = parse("[scan]\nreference_max_age_hours = 0.5\n").unwrap();
        assert_eq!(c.scan.reference_max_age, Duration::from_secs(1800));
        let e = parse("[scan]\nreference_max_age_hours = -1\n").unwrap_err();
        assert!(
            e.to_string().contains("scan.reference_max_age_hours"),
            "{e}"
        );
        let e = parse("[log]\nlevel = \"verbose\"\n").unwrap_err();
        assert!(
            e.to_string()
                .starts_with("test.toml:2: log.level: unknown level"),
            "{e}"
        );
    }

    #[test]
    fn load_reads_a_file_and_names_it() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("brdfd.toml");
        std::fs::write(
            &path,
            "[store]\npath = \"/var/lib/brdfd/brdfd.db\"\n[devices.ma_t12]\ntransport = \"usb\"\n\
             [devices.sra]\ntransport = \"serial\"\n",
        )
        .unwrap();
        let c = Config::load(&path).unwrap();
        assert_eq!(c.store.path, PathBuf::from("/var/lib/brdfd/brdfd.db"));
        std::fs::write(&path, "[store]\npath = \"\"\n").unwrap();
        let e = Config::load(&path).unwrap_err();
        assert!(
            e.to_string()
                .starts_with(&format!("{}:2: store.path: must name", path.display())),
            "{e}"
        );
        let missing = dir.path().join("missing.toml");
        let e = Config::load(&missing).unwrap_err();
        assert!(matches!(e, ConfigError::Read { .. }), "{e}");
    }
}

/// Property tests: whatever text a configuration file holds, [`Config::from_toml`] returns
/// (never panics), an error names a problem, and a configuration it accepts keeps the rules
/// its checks enforce.
#[cfg(test)]
mod proptests {
    use super::*;
    use crate::scan::proptests::{apply, assert_names_a_problem, mutations};
    use proptest::prelude::*;

    fn check(text: &str) -> Result<(), TestCaseError> {
        match Config::from_toml(text, "brdfd.toml") {
            Err(e) => assert_names_a_problem(&e)?,
            Ok(c) => {
                prop_assert!(c.api.allow_remote || c.api.listen.ip().is_loopback());
                for d in [&c.devices.ma_t12.timeout, &c.devices.sra.timeout] {
                    prop_assert!(*d >= Duration::from_millis(1));
                    prop_assert!(*d <= Duration::from_millis(600_000));
                }
                prop_assert!(c.devices.ma_t12.retries <= 10 && c.devices.sra.retries <= 10);
                prop_assert!(!c.fit.cost_functions.is_empty());
                prop_assert!(c.fit.max_concurrent_fits.get() <= 256);
                let age = c.scan.reference_max_age;
                prop_assert!(age > Duration::ZERO && age <= Duration::from_secs(8760 * 3600));
                if let SraTransport::Serial { port, baud } = &c.devices.sra.transport {
                    prop_assert!(!port.trim().is_empty() && (50..=4_000_000).contains(baud));
                }
            }
        }
        Ok(())
    }

    /// Pieces of brdfd.toml: tables, keys, values, TOML punctuation.
    const PIECES: [&str; 36] = [
        "[store]",
        "[api]",
        "[devices.ma_t12]",
        "[devices.sra]",
        "[scan]",
        "[fit]",
        "[log]",
        "[[fit]]",
        "path",
        "listen",
        "allow_remote",
        "transport",
        "timeout_ms",
        "baud",
        "reference_max_age_hours",
        "cost_functions",
        "max_concurrent_fits",
        "level",
        " = ",
        "\n",
        "\"\"",
        "\"0.0.0.0:1\"",
        "\"serial\"",
        "\"usb\"",
        "[\"cf1\", \"m2\"]",
        "true",
        "0",
        "-1",
        "1e999",
        "nan",
        "inf",
        "18446744073709551616",
        "0x10000",
        "\"é",
        "'''",
        "# ",
    ];

    proptest! {
        #![proptest_config(crate::test_support::proptest_config())]

        #[test]
        fn arbitrary_text_is_rejected_or_checked(text in any::<String>()) {
            check(&text)?;
        }

        #[test]
        fn toml_pieces_are_rejected_or_checked(
            pieces in proptest::collection::vec(proptest::sample::select(PIECES.to_vec()), 0..24)
        ) {
            check(&pieces.concat())?;
        }

        #[test]
        fn a_mutated_shipped_file_is_rejected_or_checked(ms in mutations()) {
            check(&apply(SHIPPED, &ms))?;
        }
    }
}
