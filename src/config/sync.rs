//! `[sync]`: forwarding the store to the lab's central PostgreSQL database.

use serde::Deserialize;

use super::check::{Checker, ConfigError, S};

/// `[sync]`
#[derive(Debug, Clone, PartialEq)]
pub struct SyncConfig {
    /// The lab's central PostgreSQL database; `None`: nothing is forwarded.
    pub url: Option<String>,
    /// Outbox entries forwarded per PostgreSQL transaction.
    pub batch: usize,
}

impl Default for SyncConfig {
    /// Nothing forwarded.
    fn default() -> Self {
        SyncConfig {
            url: None,
            batch: defaults::SYNC_BATCH as usize,
        }
    }
}

/// Defaults of this section, shared by its `Default` and its checks (and written out in
/// `SHIPPED`).
mod defaults {
    pub const SYNC_BATCH: u64 = 500;
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

// ---- Stage 1: the section's shape ----------------------------------------------------------

#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawSync {
    url: S<String>,
    batch: S<u64>,
}

// ---- Stage 2: its checks ------------------------------------------------------------------

impl Checker<'_> {
    /// `[sync]`
    pub(super) fn sync(&self, raw: &RawSync) -> Result<SyncConfig, ConfigError> {
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
}

#[cfg(test)]
mod tests {
    use crate::config::tests::parse;
    use crate::config::*;

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
}
