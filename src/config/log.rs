//! `[log]`: the log format and the least severe level logged.

use std::fmt;
use std::str::FromStr;

use serde::Deserialize;

use super::check::{Checker, ConfigError, S};

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

impl Default for LogConfig {
    fn default() -> Self {
        LogConfig {
            json: false,
            level: LogLevel::Info,
        }
    }
}

/// Defaults of this section, shared by its `Default` and its checks (and written out in
/// `SHIPPED`).
mod defaults {
    pub const LEVEL: &str = "info";
}

// ---- Stage 1: the section's shape ----------------------------------------------------------

#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawLog {
    json: Option<bool>,
    level: S<String>,
}

// ---- Stage 2: its checks ------------------------------------------------------------------

impl Checker<'_> {
    /// `[log]`
    pub(super) fn log(&self, raw: &RawLog) -> Result<LogConfig, ConfigError> {
        Ok(LogConfig {
            json: raw.json.unwrap_or(false),
            level: self.value("log.level", &raw.level, defaults::LEVEL.into(), |l| {
                l.parse::<LogLevel>()
            })?,
        })
    }
}
