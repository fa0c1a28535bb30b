//! `[station]`: this station's id in the lab's central database.

use serde::Deserialize;

use super::check::{Checker, ConfigError, S};

/// `[station]`
#[derive(Debug, Clone, PartialEq)]
pub struct StationConfig {
    /// This station's id in the lab's central database, on every row it forwards; default: the
    /// host name.
    pub id: String,
}

impl Default for StationConfig {
    /// The host name.
    fn default() -> Self {
        StationConfig {
            id: crate::sync::default_station_id(),
        }
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

// ---- Stage 1: the section's shape ----------------------------------------------------------

#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawStation {
    id: S<String>,
}

// ---- Stage 2: its checks ------------------------------------------------------------------

impl Checker<'_> {
    /// `[station]`
    pub(super) fn station(&self, raw: &RawStation) -> Result<StationConfig, ConfigError> {
        Ok(StationConfig {
            id: self.value(
                "station.id",
                &raw.id,
                crate::sync::default_station_id(),
                station_id,
            )?,
        })
    }
}
