//! `brdfd serve`: the daemon. Reads the configuration (`--config`, else the defaults: simulated
//! instruments replaying the embedded recordings, `brdfd.db` in the working directory, the API
//! on 127.0.0.1:7878), opens the store, starts the instruments' driver tasks, the service and
//! the HTTP API, prints one line saying where it listens, and runs until SIGTERM or SIGINT,
//! when it shuts down gracefully (see [`crate::service::Service::shutdown`]).
//!
//! Simulated instruments answer in lenient mode at the recorded timing: any sequence of
//! references and scans gets the recorded readings in turn, at the pace of real instruments.

use std::net::SocketAddr;
use std::path::{Path, PathBuf};
use std::time::Duration;

use anyhow::Context;

use crate::api::ApiServer;
use crate::config::{Config, LogLevel};
use crate::service::{Devices, Service, ServiceOptions, ServiceSettings};
use crate::store::Store;

#[derive(Debug, clap::Args)]
pub struct ServeArgs {
    /// The configuration file (see config/brdfd.toml, every key commented). Without it:
    /// BRDFD_CONFIG, else $XDG_CONFIG_HOME/brdfd/brdfd.toml (~/.config/…), else
    /// /etc/brdfd/brdfd.toml, else the built-in defaults on simulated instruments.
    #[arg(long, short, value_name = "FILE")]
    pub config: Option<PathBuf>,

    /// Listen here instead of [api] listen (port 0: any free port; the line printed at start
    /// says which).
    #[arg(long, value_name = "IP:PORT")]
    pub listen: Option<SocketAddr>,

    /// Use this SQLite file instead of [store] path.
    #[arg(long, value_name = "FILE")]
    pub db: Option<PathBuf>,
}

/// Sets up `tracing` output: to journald when the daemon runs under systemd with its output
/// in the journal (`JOURNAL_STREAM` set, see [`journald_layer`]), else on stderr as text or one
/// JSON object per line, at `level` (the `RUST_LOG` environment variable, if set, takes
/// precedence). Safe to call twice.
pub fn init_logging(level: LogLevel, json: bool) {
    use tracing_subscriber::layer::SubscriberExt;
    use tracing_subscriber::util::SubscriberInitExt;
    let filter = || {
        tracing_subscriber::EnvFilter::try_from_default_env()
            .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new(level.as_str()))
    };
    if std::env::var_os("JOURNAL_STREAM").is_some()
        && let Ok(journald) = journald_layer()
    {
        let _ = tracing_subscriber::registry()
            .with(filter())
            .with(journald)
            .try_init();
        return;
    }
    let builder = tracing_subscriber::fmt()
        .with_env_filter(filter())
        .with_writer(std::io::stderr)
        .with_ansi(std::io::IsTerminal::is_terminal(&std::io::stderr()));
    let _ = if json {
        builder.json().try_init()
    } else {
        builder.try_init()
    };
}

/// The journald output: each event's level as its `PRIORITY` (error 3, warn 4, info 5, debug
/// 6, trace 7), its fields as journal fields of the same name upper-cased without a prefix —
/// `scan = 12` becomes `SCAN=12`, so `journalctl -u brdfd SCAN=12` shows one scan's story and
/// `journalctl -u brdfd -p warning` the problems — and `SYSLOG_IDENTIFIER=brdfd`. Fails when
/// no journald socket answers.
pub fn journald_layer() -> std::io::Result<tracing_journald::Layer> {
    Ok(tracing_journald::layer()?
        .with_field_prefix(None)
        .with_syslog_identifier("brdfd".into()))
}

/// A runtime for the daemon: two worker threads (the lab PC has two cores; fits run on the
/// blocking pool), which also keeps the idle footprint small.
pub fn runtime() -> anyhow::Result<tokio::runtime::Runtime> {
    tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .context("cannot start the async runtime")
}

pub fn run(args: &ServeArgs) -> anyhow::Result<()> {
    let (mut config, origin) = Config::load_found(args.config.as_deref())?;
    let explicit_config = origin != crate::config::ConfigOrigin::Defaults;
    eprintln!("configuration: {origin}");
    if let Some(listen) = args.listen {
        // The same check as [api] listen: the flag must not be a way around it.
        config.api.listen = crate::config::check_listen(listen, config.api.allow_remote)
            .map_err(|m| anyhow::anyhow!("--listen {listen}: {m}"))?;
    }
    if let Some(db) = &args.db {
        config.store.path = db.clone();
    }
    init_logging(config.log.level, config.log.json);
    runtime()?.block_on(serve(config, explicit_config))
}

/// The line printed at start when any instrument is simulated: replayed recordings must never
/// be mistaken for measurements.
pub fn simulated_banner(config: &Config) -> Option<String> {
    use crate::config::{MaT12Transport, SraTransport};
    let mut which = Vec::new();
    if matches!(
        config.devices.ma_t12.transport,
        MaT12Transport::Simulated { .. }
    ) {
        which.push("MA-T12");
    }
    if matches!(config.devices.sra.transport, SraTransport::Simulated { .. }) {
        which.push("SRA");
    }
    (!which.is_empty()).then(|| {
        format!(
            "*** SIMULATED INSTRUMENTS ({}): readings are replayed recordings, not measurements; \
             every scan is stored as simulated. Set [devices.*] transport in the configuration \
             for real instruments. ***",
            which.join(" and ")
        )
    })
}

/// The line printed once at start when any instrument is reached through a real transport (USB
/// or a serial port): the wire protocols are brdfd's own reading of the instruments
/// (drivers/PROTOCOL.md), checked against the simulated instruments only, never against an
/// MA-T12 or RA-532H.
pub fn real_transport_banner(config: &Config) -> Option<String> {
    use crate::config::{MaT12Transport, SraTransport};
    let mut which = Vec::new();
    if let MaT12Transport::Usb { .. } = config.devices.ma_t12.transport {
        which.push("MA-T12 on USB".to_string());
    }
    if let SraTransport::Serial { port, .. } = &config.devices.sra.transport {
        which.push(format!("SRA on {port}"));
    }
    (!which.is_empty()).then(|| {
        format!(
            "*** UNVERIFIED PROTOCOLS ({}): brdfd's wire protocols for these instruments \
             (drivers/PROTOCOL.md) have been tested against its simulated instruments only, \
             never against a real MA-T12 or RA-532H. Check the first scans against the \
             instrument's own software before trusting \
             them. ***",
            which.join(", ")
        )
    })
}

/// The line printed at start when the SRA is turned off: every reference and scan this daemon
/// measures then has the 12 MA-T12 geometries only, and its fits say "no specular readings".
pub fn sra_off_banner(config: &Config) -> Option<String> {
    matches!(
        config.devices.sra.transport,
        crate::config::SraTransport::Off
    )
    .then(|| {
        "*** SRA TURNED OFF ([devices.sra] transport = \"off\"): references and scans are \
         measured on the 12 MA-T12 geometries only and fitted without specular readings, so \
         the specular lobe is pinned weakly (see the fits' intervals). Set [devices.sra] \
         transport to \"serial\" when an RA-532H is connected. ***"
            .to_string()
    })
}

/// Files the daemon writes must be distinct: a recording named like the store would truncate
/// the store at start, two recordings into one file would interleave.
pub fn check_distinct_files(config: &Config, token: &Path) -> anyhow::Result<()> {
    let absolute = |p: &Path| std::path::absolute(p).unwrap_or_else(|_| p.to_path_buf());
    let store = absolute(&config.store.path);
    let lock = absolute(&crate::store::lock::lock_path(&config.store.path));
    let mut seen: Vec<(&str, PathBuf)> = vec![
        ("[store] path", store.clone()),
        (
            "the store's write-ahead log",
            PathBuf::from(format!("{}-wal", store.display())),
        ),
        ("the store's lock file", lock),
        ("the API token file", absolute(token)),
    ];
    for (key, path) in [
        ("[devices.ma_t12] record", &config.devices.ma_t12.record),
        ("[devices.sra] record", &config.devices.sra.record),
    ] {
        let Some(path) = path else { continue };
        let path = absolute(path);
        if let Some((other, _)) = seen.iter().find(|(_, p)| *p == path) {
            anyhow::bail!(
                "{key} = {} is the same file as {other}: give the recording its own file name",
                path.display()
            );
        }
        seen.push((key, path));
    }
    Ok(())
}

async fn serve(config: Config, explicit_config: bool) -> anyhow::Result<()> {
    let token_path = config.api.token_path(&config.store.path);
    check_distinct_files(&config, &token_path)?;
    let (token, created) = crate::api::Token::load_or_create(&token_path)?;
    let store = Store::open(&config.store.path).await?;
    let devices = Devices::from_config(&config.devices, &mock_devices::ReplayOptions::lenient())?;
    let service = Service::start(
        store,
        devices,
        ServiceSettings::from_config(&config),
        ServiceOptions::default(),
    )
    .await?;
    // Logouts of the web page's sessions, kept across restarts beside the store.
    let mut revocations = config.store.path.as_os_str().to_os_string();
    revocations.push(".sessions");
    let access = crate::api::Access::new(token)
        .with_token_file(&token_path)
        .with_revocation_file(std::path::Path::new(&revocations))?;
    let options = crate::api::ApiOptions::from_config(&config.api, access);
    let api = ApiServer::start(service.clone(), config.api.listen, options).await?;
    service
        .store()
        .describe_owner(&format!("brdfd serve on http://{}", api.local_addr()));
    // The one line on stdout: scripts (and the end-to-end tests) read the address from it.
    println!(
        "brdfd {} listening on http://{} (store {}, token {})",
        env!("CARGO_PKG_VERSION"),
        api.local_addr(),
        config.store.path.display(),
        token_path.display()
    );
    if let Some(banner) = real_transport_banner(&config) {
        eprintln!("{banner}");
        tracing::warn!("{banner}");
    }
    if let Some(banner) = sra_off_banner(&config) {
        eprintln!("{banner}");
        tracing::warn!("{banner}");
    }
    if let Some(banner) = simulated_banner(&config) {
        eprintln!("{banner}");
        tracing::warn!(
            config = if explicit_config {
                "file"
            } else {
                "built-in defaults"
            },
            "{banner}"
        );
    }
    if !api.local_addr().ip().is_loopback() {
        let warning = "the API listens beyond loopback over plain HTTP: put a TLS reverse proxy in \
                       front (README: \"Remote access\") so the API token never crosses the \
                       network in clear text";
        eprintln!("WARNING: {warning}");
        tracing::warn!("{warning}");
    }
    if created {
        tracing::info!(file = %token_path.display(), "created the API token file");
    }
    // Listening for SIGTERM before saying "serving" (and READY=1 to systemd): a stop sent the
    // moment the daemon says it is up must find the handler, not the default action.
    let stop = StopSignals::listen()?;
    tracing::info!(addr = %api.local_addr(), store = %config.store.path.display(), "serving");
    notify_systemd(&service, api.local_addr());
    stop.wait().await?;
    tracing::info!("shutting down");
    let _ = sd_notify::notify(&[sd_notify::NotifyState::Stopping]);
    // The measurement in progress is aborted at once (its readings kept, the scan marked
    // aborted), while the API stops taking connections and finishes its requests in flight;
    // the store closes only once both are done, so no request reaches a closed store.
    let (_, clean) = tokio::join!(
        api.stop(Duration::from_secs(1)),
        service.stop_keeping_store()
    );
    service.store().close().await;
    if !clean {
        anyhow::bail!("some tasks did not stop within the grace period");
    }
    tracing::info!("stopped");
    Ok(())
}

/// Under systemd (`Type=notify`): READY=1 once the API answers, and, with `WatchdogSec=`, a
/// watchdog ping every half period for as long as the runtime runs and the store answers a
/// status query — a daemon whose store hangs is restarted. Without NOTIFY_SOCKET (not under
/// systemd) nothing is sent.
fn notify_systemd(service: &Service, addr: std::net::SocketAddr) {
    use sd_notify::NotifyState;
    let status = format!("listening on http://{addr}");
    if let Err(e) = sd_notify::notify(&[NotifyState::Ready, NotifyState::Status(&status)]) {
        tracing::warn!(error = %e, "cannot tell systemd that brdfd is ready");
    }
    let Some(period) = sd_notify::watchdog_enabled() else {
        return;
    };
    let service = service.clone();
    tokio::spawn(async move {
        let mut tick = tokio::time::interval(period / 2);
        loop {
            tick.tick().await;
            match tokio::time::timeout(period / 2, service.status()).await {
                Ok(Ok(_)) => {
                    let _ = sd_notify::notify(&[NotifyState::Watchdog]);
                }
                Ok(Err(e)) => {
                    tracing::error!(error = %e, "store check failed: not petting the watchdog")
                }
                Err(_) => tracing::error!("status check hung: not petting the watchdog"),
            }
        }
    });
}

/// SIGTERM (systemd's stop) or SIGINT (Ctrl-C), listened for from [`StopSignals::listen`] on.
struct StopSignals {
    #[cfg(unix)]
    term: tokio::signal::unix::Signal,
    #[cfg(unix)]
    int: tokio::signal::unix::Signal,
}

impl StopSignals {
    fn listen() -> anyhow::Result<Self> {
        #[cfg(unix)]
        {
            use tokio::signal::unix::{SignalKind, signal};
            let term = signal(SignalKind::terminate()).context("cannot listen for SIGTERM")?;
            let int = signal(SignalKind::interrupt()).context("cannot listen for SIGINT")?;
            Ok(StopSignals { term, int })
        }
        #[cfg(not(unix))]
        Ok(StopSignals {})
    }

    async fn wait(mut self) -> anyhow::Result<()> {
        #[cfg(unix)]
        tokio::select! {
            _ = self.term.recv() => {}
            _ = self.int.recv() => {}
        }
        #[cfg(not(unix))]
        tokio::signal::ctrl_c()
            .await
            .context("cannot listen for Ctrl-C")?;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn real_transports_are_announced_as_unverified_and_the_shipped_config_says_so() {
        let shipped = Config::from_toml(crate::config::SHIPPED, "config/brdfd.toml").unwrap();
        let banner =
            real_transport_banner(&shipped).expect("the shipped file names USB and serial");
        assert!(banner.contains("MA-T12 on USB"), "{banner}");
        assert!(banner.contains("SRA on /dev/ttyUSB0"), "{banner}");
        assert!(banner.contains("drivers/PROTOCOL.md"), "{banner}");
        assert_eq!(real_transport_banner(&Config::default()), None);
        assert_eq!(sra_off_banner(&Config::default()), None);
        let off = Config::from_toml(
            "[devices.ma_t12]\ntransport = \"simulated\"\n[devices.sra]\ntransport = \"off\"\n",
            "off.toml",
        )
        .unwrap();
        assert!(sra_off_banner(&off).is_some_and(|b| b.contains("12 MA-T12 geometries")));
        assert_eq!(real_transport_banner(&off), None);
        let head: String = crate::config::SHIPPED
            .lines()
            .take(12)
            .collect::<Vec<_>>()
            .join("\n");
        assert!(
            head.contains("not been verified") && head.contains("drivers/PROTOCOL.md"),
            "the shipped configuration's first lines say the protocols are unverified:\n{head}"
        );
    }

    /// journald's native protocol: `KEY=VALUE\n`, or `KEY\n` + 64-bit little-endian length +
    /// value + `\n` for values with line breaks.
    fn journal_fields(mut payload: &[u8]) -> Vec<(String, String)> {
        let mut out = Vec::new();
        while !payload.is_empty() {
            let end = payload.iter().position(|&b| b == b'\n').unwrap();
            let line = &payload[..end];
            if let Some(eq) = line.iter().position(|&b| b == b'=') {
                out.push((
                    String::from_utf8_lossy(&line[..eq]).into_owned(),
                    String::from_utf8_lossy(&line[eq + 1..]).into_owned(),
                ));
                payload = &payload[end + 1..];
            } else {
                let rest = &payload[end + 1..];
                let len = u64::from_le_bytes(rest[..8].try_into().unwrap()) as usize;
                out.push((
                    String::from_utf8_lossy(line).into_owned(),
                    String::from_utf8_lossy(&rest[8..8 + len]).into_owned(),
                ));
                payload = &rest[8 + len + 1..];
            }
        }
        out
    }

    /// The two entries `log` sends, received on a socket bound where journald's would be.
    fn stand_in_journald(path: &std::path::Path, log: impl Fn()) -> Vec<Vec<(String, String)>> {
        use std::os::unix::net::UnixDatagram;
        std::fs::create_dir_all(path.parent().unwrap()).unwrap_or_else(|e| {
            panic!(
                "cannot stand in for journald at {} ({e}): run the tests as root, as .ci/run \
                 does on CI machines, or where journald runs",
                path.display()
            )
        });
        let socket = UnixDatagram::bind(path).unwrap();
        struct Remove<'a>(&'a std::path::Path);
        impl Drop for Remove<'_> {
            fn drop(&mut self) {
                let _ = std::fs::remove_file(self.0);
            }
        }
        let _remove = Remove(path);
        socket
            .set_read_timeout(Some(std::time::Duration::from_secs(5)))
            .unwrap();
        log();
        let mut messages = Vec::new();
        let mut buf = vec![0u8; 1 << 16];
        while messages.len() < 2 {
            let n = socket.recv(&mut buf).unwrap();
            // The layer's connection probe is an empty datagram.
            if n > 0 {
                messages.push(journal_fields(&buf[..n]));
            }
        }
        messages
    }

    /// This run's two entries as the real journal stored them (`journalctl -o json`), oldest
    /// first; fails if journalctl cannot be run or they do not appear within 10 s.
    fn journal_entries(run: &str) -> Vec<Vec<(String, String)>> {
        let deadline = std::time::Instant::now() + std::time::Duration::from_secs(10);
        loop {
            let out = std::process::Command::new("journalctl")
                .args(["-o", "json", "--no-pager", "-t", "brdfd"])
                .arg(format!("TEST_RUN={run}"))
                .output()
                .expect("journalctl runs (a real journald listens on this machine)");
            let entries: Vec<Vec<(String, String)>> = String::from_utf8_lossy(&out.stdout)
                .lines()
                .filter_map(|l| serde_json::from_str::<serde_json::Value>(l).ok())
                .filter_map(|v| {
                    v.as_object().map(|o| {
                        o.iter()
                            .filter_map(|(k, v)| Some((k.clone(), v.as_str()?.to_string())))
                            .collect()
                    })
                })
                .collect();
            if entries.len() >= 2 {
                return entries;
            }
            assert!(
                std::time::Instant::now() < deadline,
                "journald did not store the test's entries: {}",
                String::from_utf8_lossy(&out.stderr)
            );
            std::thread::sleep(std::time::Duration::from_millis(100));
        }
    }

    #[test]
    fn journald_gets_priorities_and_plain_field_names() {
        use tracing_subscriber::layer::SubscriberExt;
        let path = std::path::Path::new("/run/systemd/journal/socket");
        // A field that finds this run's two entries in a real journal.
        let run = format!("{}-{}", std::process::id(), crate::store::now_ms());
        let log = || {
            let subscriber = tracing_subscriber::registry().with(journald_layer().unwrap());
            tracing::subscriber::with_default(subscriber, || {
                tracing::warn!(scan = 12, instrument = "sra", test_run = %run, "lost the SRA");
                tracing::error!(scan = 12, test_run = %run, "cannot mark the scan failed");
            });
        };
        let messages = if path.exists() {
            // A real journald owns the socket: read the entries back from the journal.
            log();
            journal_entries(&run)
        } else {
            stand_in_journald(path, log)
        };
        let has = |m: &[(String, String)], k: &str, v: &str| {
            m.iter().any(|(key, value)| key == k && value == v)
        };
        let warn = &messages[0];
        assert!(has(warn, "PRIORITY", "4"), "{warn:?}");
        assert!(has(warn, "MESSAGE", "lost the SRA"), "{warn:?}");
        assert!(has(warn, "SCAN", "12"), "{warn:?}");
        assert!(has(warn, "INSTRUMENT", "sra"), "{warn:?}");
        assert!(has(warn, "SYSLOG_IDENTIFIER", "brdfd"), "{warn:?}");
        assert!(has(&messages[1], "PRIORITY", "3"), "{:?}", messages[1]);
    }
}
