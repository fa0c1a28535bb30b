//! `[api]`: where the HTTP API listens, who may reach it, and its limits.

use std::net::SocketAddr;
use std::path::{Path, PathBuf};
use std::time::Duration;

use serde::Deserialize;

use super::check::{Checker, ConfigError, S, bounded_count};

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

impl Default for ApiConfig {
    fn default() -> Self {
        ApiConfig {
            listen: defaults::LISTEN.parse().expect("default listen address"),
            allow_remote: false,
            token_file: None,
            allowed_hosts: Vec::new(),
            max_connections: defaults::MAX_CONNECTIONS,
            max_event_subscribers: defaults::MAX_EVENT_SUBSCRIBERS,
            header_timeout: Duration::from_millis(defaults::HEADER_TIMEOUT_MS),
            idle_timeout: Duration::from_millis(defaults::IDLE_TIMEOUT_MS),
        }
    }
}

/// Defaults of this section, shared by its `Default` and its checks (and written out in
/// `SHIPPED`).
mod defaults {
    pub const LISTEN: &str = "127.0.0.1:7878";
    pub const MAX_CONNECTIONS: usize = 1024;
    pub const MAX_EVENT_SUBSCRIBERS: usize = 512;
    pub const HEADER_TIMEOUT_MS: u64 = 2_000;
    pub const IDLE_TIMEOUT_MS: u64 = 60_000;
}

fn api_timeout(ms: u64) -> Result<Duration, String> {
    if (100..=3_600_000).contains(&ms) {
        Ok(Duration::from_millis(ms))
    } else {
        Err(format!("{ms} is out of range: 100 to 3600000 ms"))
    }
}

// ---- Stage 1: the section's shape ----------------------------------------------------------

#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawApi {
    listen: S<String>,
    allow_remote: Option<bool>,
    token_file: S<String>,
    allowed_hosts: S<Vec<String>>,
    max_connections: S<u64>,
    max_event_subscribers: S<u64>,
    header_timeout_ms: S<u64>,
    idle_timeout_ms: S<u64>,
}

// ---- Stage 2: its checks ------------------------------------------------------------------

impl Checker<'_> {
    /// `[api]`
    pub(super) fn api(&self, raw: &RawApi) -> Result<ApiConfig, ConfigError> {
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
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::tests::parse;
    use crate::config::*;

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
}
