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
    pub log: LogConfig,
    pub reference: ReferenceConfig,
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
    /// Whether a non-loopback `listen` address is allowed (the API has no authentication).
    pub allow_remote: bool,
}

/// `[devices.*]`
#[derive(Debug, Clone, PartialEq)]
pub struct DevicesConfig {
    pub ma_t12: MaT12Config,
    pub sra: SraConfig,
}

/// `[devices.ma_t12]`
#[derive(Debug, Clone, PartialEq)]
pub struct MaT12Config {
    pub transport: MaT12Transport,
    /// Reply timeout of a measuring command.
    pub timeout: Duration,
    /// Resends of a request after a timeout or a corrupt reply.
    pub retries: u32,
    /// Where the recording tap writes this instrument's traffic; `None` = no recording.
    pub record: Option<PathBuf>,
}

/// How brdfd reaches the MA-T12.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum MaT12Transport {
    /// The simulated instrument, replaying a session file; `None` = the built-in recording.
    Simulated { session: Option<PathBuf> },
    /// USB bulk; `product_id` narrows the search when several X-Rite devices are attached.
    Usb { product_id: Option<u16> },
}

/// `[devices.sra]`
#[derive(Debug, Clone, PartialEq)]
pub struct SraConfig {
    pub transport: SraTransport,
    /// Reply timeout of a measuring command.
    pub timeout: Duration,
    /// Resends of a request after a timeout or a corrupt reply.
    pub retries: u32,
    /// Where the recording tap writes this instrument's traffic; `None` = no recording.
    pub record: Option<PathBuf>,
}

/// How brdfd reaches the SRA.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum SraTransport {
    /// The simulated instrument (over a pseudo-terminal), replaying a session file; `None` =
    /// the built-in recording.
    Simulated { session: Option<PathBuf> },
    /// A serial port, e.g. `/dev/ttyUSB0`.
    Serial { port: String, baud: u32 },
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
    /// The measuring commands' reply timeout of drivers/PROTOCOL.md §4.
    pub const TIMEOUT_MS: u64 = 10_000;
    /// drivers/PROTOCOL.md §4: 3 resends, 4 sends in all.
    pub const RETRIES: u32 = 3;
    pub const SRA_PORT: &str = "/dev/ttyUSB0";
    /// drivers/PROTOCOL.md §3: 9600 baud, 8N1.
    pub const SRA_BAUD: u32 = 9600;
    pub const REFERENCE_MAX_AGE_HOURS: f64 = 24.0;
    pub const SEED: u64 = 1;
    pub const LEVEL: &str = "info";
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
            },
            log: LogConfig {
                json: false,
                level: LogLevel::Info,
            },
            reference: ReferenceConfig::default(),
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
    log: RawLog,
    #[serde(default)]
    reference: RawReference,
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

impl Config {
    /// Reads and checks a configuration file.
    pub fn load(path: &Path) -> Result<Config, ConfigError> {
        let text = std::fs::read_to_string(path).map_err(|source| ConfigError::Read {
            path: path.to_path_buf(),
            source,
        })?;
        Config::from_toml(&text, &path.display().to_string())
    }

    /// The file at `path` if given, else the defaults.
    pub fn load_or_default(path: Option<&Path>) -> Result<Config, ConfigError> {
        path.map_or_else(|| Ok(Config::default()), Config::load)
    }

    /// Parses and checks TOML text; `origin` names it in errors (the file name). Keys left out
    /// take their defaults.
    pub fn from_toml(text: &str, origin: &str) -> Result<Config, ConfigError> {
        let c = Checker { text, origin };
        let raw: RawConfig = toml::from_str(text).map_err(|e| c.syntax(e))?;

        let store = StoreConfig {
            path: c.value(
                "store.path",
                &raw.store.path,
                defaults::STORE_PATH.into(),
                |p| {
                    if p.trim().is_empty() {
                        Err("must name the SQLite file, e.g. \"brdfd.db\"".into())
                    } else {
                        Ok(PathBuf::from(p))
                    }
                },
            )?,
        };

        let allow_remote = raw.api.allow_remote.unwrap_or(false);
        let api = ApiConfig {
            listen: c.value(
                "api.listen",
                &raw.api.listen,
                defaults::LISTEN.into(),
                |s| {
                    let addr: SocketAddr = s.parse().map_err(|_| {
                        format!("\"{s}\" is not an IP address and port, e.g. \"127.0.0.1:7878\"")
                    })?;
                    if !addr.ip().is_loopback() && !allow_remote {
                        return Err(format!(
                            "{addr} is reachable from other machines and the API has no \
                             authentication; listen on 127.0.0.1, or set api.allow_remote = true"
                        ));
                    }
                    Ok(addr)
                },
            )?,
            allow_remote,
        };

        let m = &raw.devices.ma_t12;
        let usb = c.value(
            "devices.ma_t12.transport",
            &m.transport,
            "simulated".into(),
            |t| match t.as_str() {
                "simulated" => Ok(false),
                "usb" => Ok(true),
                other => Err(format!(
                    "unknown transport \"{other}\": expected \"simulated\" or \"usb\""
                )),
            },
        )?;
        let ma_t12 = MaT12Config {
            transport: if usb {
                MaT12Transport::Usb {
                    product_id: m.product_id.as_ref().map(|p| *p.get_ref()),
                }
            } else {
                MaT12Transport::Simulated {
                    session: c.path("devices.ma_t12.session", &m.session)?,
                }
            },
            timeout: c.value(
                "devices.ma_t12.timeout_ms",
                &m.timeout_ms,
                defaults::TIMEOUT_MS,
                timeout,
            )?,
            retries: c.value(
                "devices.ma_t12.retries",
                &m.retries,
                defaults::RETRIES,
                retries,
            )?,
            record: c.path("devices.ma_t12.record", &m.record)?,
        };

        let s = &raw.devices.sra;
        let serial = c.value(
            "devices.sra.transport",
            &s.transport,
            "simulated".into(),
            |t| match t.as_str() {
                "simulated" => Ok(false),
                "serial" => Ok(true),
                other => Err(format!(
                    "unknown transport \"{other}\": expected \"simulated\" or \"serial\""
                )),
            },
        )?;
        let port = c.value(
            "devices.sra.port",
            &s.port,
            defaults::SRA_PORT.into(),
            |p| {
                if p.trim().is_empty() {
                    Err("must name the serial device, e.g. \"/dev/ttyUSB0\"".into())
                } else {
                    Ok(p)
                }
            },
        )?;
        let baud = c.value("devices.sra.baud", &s.baud, defaults::SRA_BAUD, |b| {
            if (50..=4_000_000).contains(&b) {
                Ok(b)
            } else {
                Err(format!("{b} is not a serial speed: 50 to 4000000 baud"))
            }
        })?;
        let sra = SraConfig {
            transport: if serial {
                SraTransport::Serial { port, baud }
            } else {
                SraTransport::Simulated {
                    session: c.path("devices.sra.session", &s.session)?,
                }
            },
            timeout: c.value(
                "devices.sra.timeout_ms",
                &s.timeout_ms,
                defaults::TIMEOUT_MS,
                timeout,
            )?,
            retries: c.value(
                "devices.sra.retries",
                &s.retries,
                defaults::RETRIES,
                retries,
            )?,
            record: c.path("devices.sra.record", &s.record)?,
        };

        let scan = ScanConfig {
            reference_max_age: c.value(
                "scan.reference_max_age_hours",
                &raw.scan.reference_max_age_hours,
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
        };

        let f = &raw.fit;
        let fit = FitConfig {
            cost_functions: c.value(
                "fit.cost_functions",
                &f.cost_functions,
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
            method: c.value(
                "fit.method",
                &f.method,
                Method::default().name().into(),
                |m| m.parse::<Method>().map_err(|e| e.to_string()),
            )?,
            seed: c.value("fit.seed", &f.seed, defaults::SEED, Ok)?,
            max_concurrent_fits: c.value(
                "fit.max_concurrent_fits",
                &f.max_concurrent_fits,
                1,
                |n| match usize::try_from(n).ok().and_then(NonZeroUsize::new) {
                    Some(n) if n.get() <= 256 => Ok(n),
                    _ => Err(format!("{n} is out of range: 1 to 256 fits at once")),
                },
            )?,
            specular: c.value(
                "fit.specular",
                &f.specular,
                SpecularStrategy::default().name().into(),
                |s| s.parse::<SpecularStrategy>().map_err(|e| e.to_string()),
            )?,
        };

        let log = LogConfig {
            json: raw.log.json.unwrap_or(false),
            level: c.value("log.level", &raw.log.level, defaults::LEVEL.into(), |l| {
                l.parse::<LogLevel>()
            })?,
        };

        let reference = match &raw.reference.reflectance {
            None => ReferenceConfig::default(),
            Some(v) => {
                let (rho, source) = reference_reflectance(v.get_ref(), origin)
                    .map_err(|m| c.invalid("reference.reflectance", v, m))?;
                ReferenceConfig {
                    reflectance: Some(rho),
                    source: Some(source),
                }
            }
        };

        Ok(Config {
            store,
            api,
            devices: DevicesConfig { ma_t12, sra },
            scan,
            fit,
            log,
            reference,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(text: &str) -> Result<Config, ConfigError> {
        Config::from_toml(text, "test.toml")
    }

    #[test]
    fn the_shipped_file_parses_to_the_defaults() {
        let shipped = Config::from_toml(SHIPPED, "config/brdfd.toml").unwrap();
        assert_eq!(shipped, Config::default());
        // The defaults run with no instrument and write a local SQLite file.
        assert!(matches!(
            shipped.devices.ma_t12.transport,
            MaT12Transport::Simulated { session: None }
        ));
        assert!(matches!(
            shipped.devices.sra.transport,
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
        std::fs::write(&toml_path, "[reference]\nreflectance = \"n9.cgats\"\n").unwrap();
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
        const KEYS: [&str; 20] = [
            "path",
            "listen",
            "allow_remote",
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
            "json",
            "level",
            "reflectance",
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
    fn no_file_and_an_empty_file_give_the_defaults() {
        assert_eq!(Config::load_or_default(None).unwrap(), Config::default());
        assert_eq!(parse("").unwrap(), Config::default());
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
             \"simulated\" or \"serial\""
        );
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
        std::fs::write(&path, "[store]\npath = \"/var/lib/brdfd/brdfd.db\"\n").unwrap();
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
        #![proptest_config(ProptestConfig::with_cases(256))]

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
