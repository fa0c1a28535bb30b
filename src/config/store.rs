//! `[store]`: where the SQLite store lives.

use std::path::PathBuf;

use serde::Deserialize;

use super::check::{Checker, ConfigError, S};

/// `[store]`
#[derive(Debug, Clone, PartialEq)]
pub struct StoreConfig {
    /// The SQLite file; a relative path is relative to the working directory (the systemd unit
    /// sets it to the state directory).
    pub path: PathBuf,
}

impl Default for StoreConfig {
    fn default() -> Self {
        StoreConfig {
            path: PathBuf::from(defaults::STORE_PATH),
        }
    }
}

/// Defaults of this section, shared by its `Default` and its checks (and written out in
/// `SHIPPED`).
mod defaults {
    pub const STORE_PATH: &str = "brdfd.db";
}

// ---- Stage 1: the section's shape ----------------------------------------------------------

#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawStore {
    path: S<String>,
}

// ---- Stage 2: its checks ------------------------------------------------------------------

impl Checker<'_> {
    /// `[store]`
    pub(super) fn store(&self, raw: &RawStore) -> Result<StoreConfig, ConfigError> {
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
}
