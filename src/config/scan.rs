//! `[scan]`: how old a reference set may be before a scan is flagged.

use std::time::Duration;

use serde::Deserialize;

use super::check::{Checker, ConfigError, S};

/// `[scan]`
#[derive(Debug, Clone, PartialEq)]
pub struct ScanConfig {
    /// A scan whose reference set is older than this is flagged, not silently fitted
    /// (SCIENCE.md §3).
    pub reference_max_age: Duration,
}

impl Default for ScanConfig {
    fn default() -> Self {
        ScanConfig {
            reference_max_age: Duration::from_secs_f64(defaults::REFERENCE_MAX_AGE_HOURS * 3600.0),
        }
    }
}

/// Defaults of this section, shared by its `Default` and its checks (and written out in
/// `SHIPPED`).
mod defaults {
    pub const REFERENCE_MAX_AGE_HOURS: f64 = 24.0;
}

// ---- Stage 1: the section's shape ----------------------------------------------------------

#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawScan {
    reference_max_age_hours: S<f64>,
}

// ---- Stage 2: its checks ------------------------------------------------------------------

impl Checker<'_> {
    /// `[scan]`
    pub(super) fn scan(&self, raw: &RawScan) -> Result<ScanConfig, ConfigError> {
        Ok(ScanConfig {
            reference_max_age: self.value(
                "scan.reference_max_age_hours",
                &raw.reference_max_age_hours,
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
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::tests::parse;
    use crate::config::*;

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
}
