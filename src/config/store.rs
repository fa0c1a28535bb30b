//! `[store]`: where the SQLite store lives.

use std::path::PathBuf;

use serde::Deserialize;

use super::check::{Checker, ConfigError, S};

/// `[store]`
#[derive(Debug, Clone, PartialEq)]
pub struct StoreConfig {
    /// The SQLite file. In a configuration file, a relative path is relative to the file's
    /// directory; with no file (the built-in defaults), to the working directory.
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
                    return Err("must name the SQLite file, e.g. \"brdfd.db\"".into());
                }
                let path = self.resolve(&p);
                // Relative paths were once taken from the working directory: a store found
                // there and not beside the file is that store, which must not be replaced by
                // a new empty one without a word.
                let in_working_dir = PathBuf::from(&p);
                if self.base.is_some()
                    && in_working_dir.is_relative()
                    && !path.exists()
                    && in_working_dir.is_file()
                {
                    let here = std::env::current_dir()
                        .map(|d| d.join(&p))
                        .unwrap_or(in_working_dir);
                    return Err(format!(
                        "\"{p}\" is relative, so it is taken from this file's directory: {} (no \
                         such file); the store {} in the working directory is not read. Write \
                         its full path, path = \"{}\"",
                        path.display(),
                        here.display(),
                        here.display()
                    ));
                }
                Ok(path)
            })?,
        })
    }
}
