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
//!
//! One file per section (`store.rs`, `api.rs`, `devices.rs`, …): its checked settings, their
//! defaults, its raw serde struct and its check, so that a new key is added in one place (and
//! in `config/brdfd.toml`, which a test keeps equal to the defaults). `check.rs` holds what
//! every section's check uses; this file joins the sections into [`Config`].

mod api;
mod check;
mod colour;
mod devices;
mod fit;
mod ingest;
mod log;
mod reference;
mod scan;
mod station;
mod store;
mod sync;

pub use api::{ApiConfig, check_listen};
pub use check::ConfigError;
pub use devices::{
    DeviceConfig, DevicesConfig, MaT12Config, MaT12Transport, SraConfig, SraTransport,
};
pub use fit::FitConfig;
pub use ingest::IngestConfig;
pub use log::{LogConfig, LogLevel};
pub use reference::ReferenceConfig;
pub use scan::ScanConfig;
pub use station::StationConfig;
pub use store::StoreConfig;
pub use sync::SyncConfig;

use std::path::{Path, PathBuf};

use serde::Deserialize;

use check::Checker;

/// The configuration file shipped in `config/`, the defaults written out with comments.
pub const SHIPPED: &str = include_str!("../../config/brdfd.toml");

/// Where the systemd unit in `config/brdfd.service` points `--config`.
pub const SYSTEM_PATH: &str = "/etc/brdfd/brdfd.toml";

/// The checked configuration; its `Default` is every section's.
#[derive(Debug, Clone, PartialEq, Default)]
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

// ---- Stage 1: the file's shape (each section's raw struct is in its file) -------------------

#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawConfig {
    #[serde(default)]
    store: store::RawStore,
    #[serde(default)]
    api: api::RawApi,
    #[serde(default)]
    devices: devices::RawDevices,
    #[serde(default)]
    scan: scan::RawScan,
    #[serde(default)]
    fit: fit::RawFit,
    #[serde(default)]
    colour: colour::RawColour,
    #[serde(default)]
    log: log::RawLog,
    #[serde(default)]
    station: station::RawStation,
    #[serde(default)]
    sync: sync::RawSync,
    #[serde(default)]
    reference: reference::RawReference,
    #[serde(default)]
    ingest: ingest::RawIngest,
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
    /// Reads and checks a configuration file. Its relative paths (`[store] path`,
    /// `[api] token_file`, `[ingest] watch`, `[devices.*] session` and `record`, a
    /// `[reference]` certificate) are relative to the file's directory, whoever reads it from
    /// wherever: the daemon and every command agree on the store and the token.
    pub fn load(path: &Path) -> Result<Config, ConfigError> {
        let text = std::fs::read_to_string(path).map_err(|source| ConfigError::Read {
            path: path.to_path_buf(),
            source,
        })?;
        let base = std::path::absolute(path)
            .ok()
            .and_then(|p| p.parent().map(Path::to_path_buf));
        Config::parse_text(
            &text,
            &path.display().to_string(),
            true,
            Some(base.as_deref().unwrap_or(Path::new(""))),
        )
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
    /// take their defaults. Paths are kept as written (a `[reference]` certificate's is
    /// relative to `origin`'s directory); [`Config::load`] makes a file's relative to it.
    pub fn from_toml(text: &str, origin: &str) -> Result<Config, ConfigError> {
        Config::parse_text(text, origin, true, None)
    }

    /// [`Config::from_toml`], with `require_transport` false for tests of other sections, and
    /// `base` the directory relative paths are relative to.
    fn parse_text(
        text: &str,
        origin: &str,
        require_transport: bool,
        base: Option<&Path>,
    ) -> Result<Config, ConfigError> {
        let c = Checker {
            text,
            origin,
            require_transport,
            base,
        };
        let raw: RawConfig = toml::from_str(text).map_err(|e| c.syntax(e))?;

        Ok(Config {
            store: c.store(&raw.store)?,
            api: c.api(&raw.api)?,
            devices: c.devices(&raw.devices)?,
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cost::CostFunction;
    use crate::processing::SpecularStrategy;

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
    pub(super) fn parse(text: &str) -> Result<Config, ConfigError> {
        Config::parse_text(text, "test.toml", false, None)
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
        // The store where the systemd unit keeps the daemon's state: a relative path would be
        // relative to /etc/brdfd, where the file is installed.
        expected.store.path = PathBuf::from("/var/lib/brdfd/brdfd.db");
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
        assert!(Config::default().store.path.is_relative());
        assert!(shipped.api.listen.ip().is_loopback());
        assert_eq!(shipped.fit.max_concurrent_fits.get(), 1);
        assert_eq!(shipped.fit.cost_functions, CostFunction::ALL);
        assert_eq!(shipped.fit.specular, SpecularStrategy::Ratio);
    }

    #[test]
    fn every_key_of_the_shipped_file_is_there_with_a_comment() {
        // Every key of the raw structs, set or shown commented out (`# key = …`).
        const KEYS: [&str; 40] = [
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
            "crossval",
            "json",
            "level",
            "reflectance",
            "watch",
            "settle_ms",
            "poll_ms",
            "pair_wait_ms",
            "reference",
            "max_file_mib",
            "max_sheet_cells",
            "max_images",
            "max_image_mib",
            "max_image_megapixels",
            "max_records",
            "max_held_mib",
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

    #[test]
    fn relative_paths_in_a_file_are_relative_to_its_directory() {
        let dir = tempfile::tempdir().unwrap();
        let lab = dir.path().join("lab");
        std::fs::create_dir(&lab).unwrap();
        std::fs::write(lab.join("tile.cgats"), "not read: the key is left out").unwrap();
        let text = "[store]\npath = \"data/brdfd.db\"\n\
                    [api]\ntoken_file = \"secret/brdfd.token\"\n\
                    [ingest]\nwatch = \"inbox\"\n\
                    [devices.ma_t12]\ntransport = \"simulated\"\nsession = \"rec/ma.session\"\n\
                    record = \"ma-recorded.session\"\n\
                    [devices.sra]\ntransport = \"simulated\"\nsession = \"/abs/sra.session\"\n\
                    record = \"../sra-recorded.session\"\n";
        std::fs::write(lab.join("brdfd.toml"), text).unwrap();
        // Read as `--config lab/brdfd.toml` would name it from `dir`, whatever the working
        // directory of the process: every relative path is under lab/.
        let c = Config::load(&lab.join("brdfd.toml")).unwrap();
        let lab = std::path::absolute(&lab).unwrap();
        assert_eq!(c.store.path, lab.join("data/brdfd.db"));
        assert_eq!(c.api.token_file, Some(lab.join("secret/brdfd.token")));
        assert_eq!(c.ingest.watch, Some(lab.join("inbox")));
        assert_eq!(
            c.devices.ma_t12.transport,
            MaT12Transport::Simulated {
                session: Some(lab.join("rec/ma.session"))
            }
        );
        assert_eq!(
            c.devices.ma_t12.record,
            Some(lab.join("ma-recorded.session"))
        );
        // Absolute paths stay as they are.
        assert_eq!(
            c.devices.sra.transport,
            SraTransport::Simulated {
                session: Some(PathBuf::from("/abs/sra.session"))
            }
        );
        assert_eq!(
            c.devices.sra.record,
            Some(lab.join("../sra-recorded.session"))
        );
        // Without token_file, the token beside the store: the one the daemon writes.
        std::fs::write(
            lab.join("brdfd.toml"),
            "[store]\npath = \"brdfd.db\"\n[devices.ma_t12]\ntransport = \"simulated\"\n\
             [devices.sra]\ntransport = \"simulated\"\n",
        )
        .unwrap();
        let c = Config::load(&lab.join("brdfd.toml")).unwrap();
        assert_eq!(c.store.path, lab.join("brdfd.db"));
        assert_eq!(c.api.token_path(&c.store.path), lab.join("brdfd.token"));
        // Text not read from a file keeps its paths as written.
        let c = Config::from_toml(text, "lab/brdfd.toml").unwrap();
        assert_eq!(c.store.path, PathBuf::from("data/brdfd.db"));
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
    use std::time::Duration;

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
