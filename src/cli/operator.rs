//! What the operator subcommands (`reference`, `scan`, `scans`, `show`, `refit`, `abort`,
//! `status`, `export`, `import`) share: where the daemon is and its token ([`DaemonArgs`]),
//! times as the operator reads them, text made safe for the terminal, and `--json` output.
//!
//! Each subcommand talks to a running daemon over its HTTP API ([`crate::client`]), whose typed
//! calls give the answers as [`crate::wire`] types. Refusals
//! print the daemon's message as it is ("the instruments are busy: scan 12 is in progress …");
//! no daemon gives "no brdfd daemon is listening on … — start one with `brdfd serve`".

use std::net::SocketAddr;
use std::path::{Path, PathBuf};

use serde::Serialize;

use crate::client::Client;
use crate::config::ConfigOrigin;

/// Where the daemon is, and its API token.
#[derive(Debug, Clone, clap::Args)]
pub struct DaemonArgs {
    /// The daemon's API address [default: [api] listen of the configuration, else
    /// 127.0.0.1:7878].
    #[arg(long, value_name = "IP:PORT")]
    pub addr: Option<SocketAddr>,
    /// The file holding the daemon's API token [default: [api] token_file of the
    /// configuration, else brdfd.token beside its store (./brdfd.token without one)]. The
    /// BRDFD_TOKEN environment variable, when set, is used instead of any file.
    #[arg(long, value_name = "FILE")]
    pub token_file: Option<PathBuf>,
    /// The daemon's configuration file, for its address and token file.
    #[arg(long, short, value_name = "FILE", env = "BRDFD_CONFIG")]
    pub config: Option<PathBuf>,
}

impl DaemonArgs {
    fn config(&self) -> anyhow::Result<crate::config::Config> {
        Ok(crate::config::Config::load_or_default(
            self.config.as_deref(),
        )?)
    }

    /// Where the address came from, and how to name another, for the "no daemon" message:
    /// nothing when `--addr` was given.
    fn not_running_hint(&self, origin: &ConfigOrigin) -> String {
        if self.addr.is_some() {
            return String::new();
        }
        not_running_hint(origin, std::env::current_dir().ok().as_deref())
    }

    /// The address asked for: `--addr`, else the configuration's.
    pub fn addr(&self) -> anyhow::Result<SocketAddr> {
        match self.addr {
            Some(a) => Ok(a),
            None => Ok(self.config()?.api.listen),
        }
    }

    /// A client with the token from BRDFD_TOKEN, `--token-file` or the configuration. A token
    /// that cannot be read is not an error yet: the daemon's 401, if it comes, says why.
    pub fn client(&self) -> anyhow::Result<Client> {
        let (config, origin) = crate::config::Config::load_found(self.config.as_deref())?;
        let addr = self.addr.unwrap_or(config.api.listen);
        let client = Client::new(addr).with_not_running_hint(self.not_running_hint(&origin));
        if let Ok(text) = std::env::var("BRDFD_TOKEN") {
            return match crate::api::Token::parse(&text) {
                Some(t) => Ok(client.with_token(&t, "sent the token of BRDFD_TOKEN")),
                None => Err(super::MalformedTokenEnv.into()),
            };
        }
        let path = self
            .token_file
            .clone()
            .unwrap_or_else(|| config.api.token_path(&config.store.path));
        Ok(match crate::api::Token::read(&path) {
            Ok(t) => client.with_token(&t, format!("sent the token of {}", path.display())),
            Err(e) => client.without_token(format!(
                "sent no token: {e}; pass --token-file, --config or BRDFD_TOKEN"
            )),
        })
    }
}
/// "; …" for the "no daemon" message of a command that took its address from `origin` (a
/// configuration file, or the built-in default), run in `cwd`: where the address came from,
/// and `--addr` / `--config` to name another; a `brdfd.toml` or `brdfd.token` in `cwd` that
/// was not read is pointed at.
pub(super) fn not_running_hint(origin: &ConfigOrigin, cwd: Option<&Path>) -> String {
    let (from, used) = match origin {
        ConfigOrigin::File { path, via } => (
            format!("[api] listen of {} (from {via})", path.display()),
            std::path::absolute(path).ok(),
        ),
        ConfigOrigin::Defaults => (
            "the default address (no configuration file was found)".to_string(),
            None,
        ),
    };
    let mut hint = format!(
        "; that is {from}. For a daemon on another address pass --addr IP:PORT, or --config \
         with the daemon's configuration file"
    );
    if let Some(cwd) = cwd {
        let config = cwd.join("brdfd.toml");
        let here = |name: &str| cwd.join(name).is_file();
        if here("brdfd.toml") && std::path::absolute(&config).ok() != used {
            hint.push_str(" (there is one here: --config brdfd.toml)");
        } else if here("brdfd.token") && used.is_none() {
            hint.push_str(" (brdfd.token is here: the daemon that wrote it may listen elsewhere)");
        }
    }
    hint
}

/// A date and time in UTC from milliseconds since the Unix epoch, e.g. `2026-11-24 19:14:14Z`.
pub fn utc(ms: i64) -> String {
    crate::formats::rfc3339_utc(ms.div_euclid(1000)).replacen('T', " ", 1)
}

/// A date and time in the machine's time zone (`TZ`, else `/etc/localtime`) with its UTC
/// offset, e.g. `2026-11-24 20:14:14 +01:00`, as the operator's clock shows it; UTC (`Z`) when
/// the zone cannot be read.
pub fn local_time(ms: i64) -> String {
    local_time_in(
        ms,
        &jiff::tz::TimeZone::try_system().unwrap_or(jiff::tz::TimeZone::UTC),
    )
}

/// [`local_time`] in zone `tz`.
pub fn local_time_in(ms: i64, tz: &jiff::tz::TimeZone) -> String {
    match jiff::Timestamp::from_millisecond(ms) {
        Ok(t) => t
            .to_zoned_datetime(tz.clone())
            .strftime("%Y-%m-%d %H:%M:%S %:z")
            .to_string(),
        Err(_) => utc(ms),
    }
}
/// `text` with every control character escaped (`\u{1b}`), as it is printed: an escape
/// sequence in a name stored before names were checked is shown, never sent to the terminal.
pub fn terminal_safe(text: &str) -> String {
    if text.chars().any(char::is_control) {
        text.chars()
            .map(|c| {
                if c.is_control() {
                    c.escape_unicode().to_string()
                } else {
                    c.to_string()
                }
            })
            .collect()
    } else {
        text.to_string()
    }
}
/// An answer as `--json` prints it on one line: the daemon's fields, keys in alphabetical
/// order at every level (a stable order for scripts that compare outputs).
pub(super) fn json_line<T: Serialize>(value: &T) -> anyhow::Result<String> {
    Ok(serde_json::to_value(value)?.to_string())
}

/// [`json_line`], indented.
pub(super) fn json_pretty<T: Serialize>(value: &T) -> anyhow::Result<String> {
    Ok(serde_json::to_string_pretty(&serde_json::to_value(value)?)?)
}

/// `value` (an answer that is a JSON object) with `"type": kind` among its fields, as one
/// NDJSON line.
pub(super) fn tagged<T: Serialize>(kind: &str, value: &T) -> anyhow::Result<String> {
    #[derive(Serialize)]
    struct Tagged<'a, T> {
        #[serde(rename = "type")]
        kind: &'a str,
        #[serde(flatten)]
        value: &'a T,
    }
    json_line(&Tagged { kind, value })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_tagged_answer_keeps_its_fields_in_alphabetical_order() {
        let answer = crate::wire::Imported {
            already_imported: None,
            colorimetry_checks: None,
            fits: vec![crate::store::FitRunId(4)],
            scan: Some(crate::store::ScanId(2)),
            scans: None,
        };
        assert_eq!(
            tagged("accepted", &answer).unwrap(),
            r#"{"fits":[4],"scan":2,"type":"accepted"}"#
        );
    }

    #[test]
    fn no_daemon_says_where_the_address_came_from_and_how_to_name_another() {
        let dir = tempfile::tempdir().unwrap();
        let defaults = not_running_hint(&ConfigOrigin::Defaults, Some(dir.path()));
        assert!(
            defaults.contains("no configuration file was found"),
            "{defaults}"
        );
        assert!(defaults.contains("--addr IP:PORT"), "{defaults}");
        assert!(defaults.contains("--config"), "{defaults}");
        assert!(!defaults.contains("here"), "{defaults}");
        // A daemon's token in the directory, no configuration read.
        std::fs::write(dir.path().join("brdfd.token"), "x").unwrap();
        let token = not_running_hint(&ConfigOrigin::Defaults, Some(dir.path()));
        assert!(token.contains("brdfd.token is here"), "{token}");
        // A configuration in the directory that was not the one read.
        std::fs::write(dir.path().join("brdfd.toml"), "").unwrap();
        let nearby = not_running_hint(&ConfigOrigin::Defaults, Some(dir.path()));
        assert!(nearby.contains("--config brdfd.toml"), "{nearby}");
        // The one read names itself, and is not suggested again.
        let read = ConfigOrigin::File {
            path: dir.path().join("brdfd.toml"),
            via: "--config",
        };
        let used = not_running_hint(&read, Some(dir.path()));
        assert!(used.contains("[api] listen of"), "{used}");
        assert!(!used.contains("there is one here"), "{used}");
    }

    #[test]
    fn utc_formats_known_instants() {
        assert_eq!(utc(0), "1970-01-01 00:00:00Z");
        // 2000-02-29 12:34:56 UTC = 951827696 s.
        assert_eq!(utc(951_827_696_000), "2000-02-29 12:34:56Z");
        // 2026-11-24 19:14:14 UTC = 1795547654 s.
        assert_eq!(utc(1_795_547_654_000), "2026-11-24 19:14:14Z");
    }

    #[test]
    fn local_times_carry_their_offset() {
        use jiff::tz::{Offset, TimeZone};
        let oslo = TimeZone::fixed(Offset::from_hours(1).unwrap());
        assert_eq!(
            local_time_in(1_795_547_654_000, &oslo),
            "2026-11-24 20:14:14 +01:00"
        );
        let west = TimeZone::fixed(Offset::from_seconds(-(5 * 3600 + 1800)).unwrap());
        assert_eq!(local_time_in(0, &west), "1969-12-31 18:30:00 -05:30");
        assert_eq!(
            local_time_in(0, &TimeZone::UTC),
            "1970-01-01 00:00:00 +00:00"
        );
    }
}
