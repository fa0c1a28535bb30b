//! `[ingest]`: the watch folder for instrument-software exports and scan files
//! (src/service/ingest.rs).

use std::path::PathBuf;
use std::time::Duration;

use serde::Deserialize;

use super::check::{Checker, ConfigError, S, bounded_count};
use crate::formats::budget::Budget;

/// `[ingest]`: the watch folder (src/service/ingest.rs).
#[derive(Debug, Clone, PartialEq)]
pub struct IngestConfig {
    /// The folder watched for instrument-software exports and scan files; `None`: no folder.
    pub watch: Option<PathBuf>,
    /// A file is imported once its size and modification time stayed the same this long.
    pub settle: Duration,
    /// How often the folder is listed.
    pub poll: Duration,
    /// How long an MA-T12 export waits for its SRA CSV (and an SRA CSV for its export) before
    /// it is imported alone (or, for an SRA CSV, rejected).
    pub pair_wait: Duration,
    /// In an instrument's export, the object with this name is the white reference tile.
    pub reference: String,
    /// The limits every imported file is read within, by every door (`max_file_mib`: the
    /// largest file read, a larger one goes to `failed/` unread; `max_sheet_cells`,
    /// `max_images`, `max_image_mib`, `max_image_megapixels`, `max_records`).
    pub budget: Budget,
    /// The import bodies held in memory at once, in bytes (`max_held_mib`), across the watch
    /// folder and `POST /scans/import` (src/service/import_budget.rs).
    pub max_held_bytes: u64,
}

impl Default for IngestConfig {
    fn default() -> Self {
        IngestConfig {
            watch: None,
            settle: Duration::from_millis(defaults::INGEST_SETTLE_MS),
            poll: Duration::from_millis(defaults::INGEST_POLL_MS),
            pair_wait: Duration::from_millis(defaults::INGEST_PAIR_WAIT_MS),
            reference: crate::formats::DEFAULT_REFERENCE.to_string(),
            budget: Budget::default(),
            max_held_bytes: defaults::INGEST_MAX_HELD_MIB << 20,
        }
    }
}

/// Defaults of this section, shared by its `Default` and its checks (and written out in
/// `SHIPPED`).
mod defaults {
    pub const INGEST_SETTLE_MS: u64 = 2_000;
    pub const INGEST_POLL_MS: u64 = 1_000;
    pub const INGEST_PAIR_WAIT_MS: u64 = 60_000;
    /// Two of the largest uploads `POST /scans/import` takes (64 MiB each), or dozens of real
    /// exports; well inside the shipped unit's `MemoryMax=1G` with the readers' own budgets.
    pub const INGEST_MAX_HELD_MIB: u64 = 128;
    /// The smallest bound: one upload of the largest size the API takes always fits.
    pub const INGEST_MAX_HELD_MIB_MIN: u64 = 64;
}

// ---- Stage 1: the section's shape ----------------------------------------------------------

#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawIngest {
    watch: S<String>,
    settle_ms: S<u64>,
    poll_ms: S<u64>,
    pair_wait_ms: S<u64>,
    reference: S<String>,
    max_file_mib: S<u64>,
    max_sheet_cells: S<u64>,
    max_images: S<u64>,
    max_image_mib: S<u64>,
    max_image_megapixels: S<u64>,
    max_records: S<u64>,
    max_held_mib: S<u64>,
}

// ---- Stage 2: its checks ------------------------------------------------------------------

impl Checker<'_> {
    /// `[ingest]`
    pub(super) fn ingest(&self, raw: &RawIngest) -> Result<IngestConfig, ConfigError> {
        let ms_in = |lo: u64, hi: u64| {
            move |ms: u64| {
                if (lo..=hi).contains(&ms) {
                    Ok(Duration::from_millis(ms))
                } else {
                    Err(format!("{ms} is out of range: {lo} to {hi} ms"))
                }
            }
        };
        let config = IngestConfig {
            watch: self.path("ingest.watch", &raw.watch)?,
            settle: self.value(
                "ingest.settle_ms",
                &raw.settle_ms,
                defaults::INGEST_SETTLE_MS,
                ms_in(10, 3_600_000),
            )?,
            poll: self.value(
                "ingest.poll_ms",
                &raw.poll_ms,
                defaults::INGEST_POLL_MS,
                ms_in(10, 60_000),
            )?,
            pair_wait: self.value(
                "ingest.pair_wait_ms",
                &raw.pair_wait_ms,
                defaults::INGEST_PAIR_WAIT_MS,
                ms_in(0, 86_400_000),
            )?,
            reference: self.value(
                "ingest.reference",
                &raw.reference,
                crate::formats::DEFAULT_REFERENCE.to_string(),
                |r| {
                    if r.trim().is_empty() {
                        Err("must name the reference tile, e.g. \"Munsell N9\"".into())
                    } else {
                        Ok(r)
                    }
                },
            )?,
            budget: self.budget(raw)?,
            max_held_bytes: self.value(
                "ingest.max_held_mib",
                &raw.max_held_mib,
                defaults::INGEST_MAX_HELD_MIB,
                |n| {
                    bounded_count(n, defaults::INGEST_MAX_HELD_MIB_MIN, 65_536)
                        .map(|n| (n as u64) << 20)
                },
            )?,
        };
        if config.max_held_bytes < config.budget.max_file_bytes {
            let message = format!(
                "max_held_mib ({} MiB) is less than max_file_mib ({} MiB): a file the watch \
                 folder takes could never be held; raise max_held_mib or lower max_file_mib",
                config.max_held_bytes >> 20,
                config.budget.max_file_bytes >> 20
            );
            return Err(match &raw.max_held_mib {
                Some(v) => self.invalid("ingest.max_held_mib", v, message),
                None => self.invalid(
                    "ingest.max_file_mib",
                    raw.max_file_mib
                        .as_ref()
                        .expect("the default max_held_mib holds the default max_file_mib"),
                    message,
                ),
            });
        }
        Ok(config)
    }

    /// The `[ingest]` keys of the import budget (src/formats/budget.rs), each within a range
    /// that keeps an import inside the memory the daemon is given.
    fn budget(&self, raw: &RawIngest) -> Result<Budget, ConfigError> {
        use crate::formats::budget::defaults as d;
        let d0 = Budget::default();
        let count = |lo: u64, hi: u64| move |n: u64| bounded_count(n, lo, hi).map(|n| n as u64);
        Ok(Budget {
            max_file_bytes: self.value(
                "ingest.max_file_mib",
                &raw.max_file_mib,
                d::MAX_FILE_MIB,
                |n| bounded_count(n, 1, 1024).map(|n| (n as u64) << 20),
            )?,
            max_sheet_cells: self.value(
                "ingest.max_sheet_cells",
                &raw.max_sheet_cells,
                d::MAX_SHEET_CELLS,
                count(1_000, 1_000_000),
            )?,
            max_images: self.value(
                "ingest.max_images",
                &raw.max_images,
                d::MAX_IMAGES,
                count(0, 1_000),
            )?,
            max_image_bytes: self.value(
                "ingest.max_image_mib",
                &raw.max_image_mib,
                d::MAX_IMAGE_MIB,
                |n| bounded_count(n, 1, 16).map(|n| (n as u64) << 20),
            )?,
            max_image_pixels: self.value(
                "ingest.max_image_megapixels",
                &raw.max_image_megapixels,
                d::MAX_IMAGE_MEGAPIXELS,
                |n| bounded_count(n, 1, 100).map(|n| n as u64 * 1_000_000),
            )?,
            max_records: self.value(
                "ingest.max_records",
                &raw.max_records,
                d::MAX_RECORDS,
                count(1, 200_000),
            )?,
            ..d0
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::tests::parse;
    use crate::config::*;

    #[test]
    fn ingest_settings() {
        let d = Config::default().ingest;
        assert_eq!(d.watch, None);
        assert_eq!(d.settle, Duration::from_secs(2));
        let c = parse(
            "[ingest]\nwatch = \"/srv/inbox\"\nsettle_ms = 50\npoll_ms = 20\npair_wait_ms = 0\n\
             reference = \"N9 tile\"\n",
        )
        .unwrap();
        assert_eq!(c.ingest.watch, Some(PathBuf::from("/srv/inbox")));
        assert_eq!(c.ingest.settle, Duration::from_millis(50));
        assert_eq!(c.ingest.poll, Duration::from_millis(20));
        assert_eq!(c.ingest.pair_wait, Duration::ZERO);
        assert_eq!(c.ingest.reference, "N9 tile");
        let e = parse("[ingest]\nsettle_ms = 5\n").unwrap_err().to_string();
        assert_eq!(
            e,
            "test.toml:2: ingest.settle_ms: 5 is out of range: 10 to 3600000 ms"
        );
        let e = parse("[ingest]\nwatch = \"\"\n").unwrap_err().to_string();
        assert!(e.contains("ingest.watch: must not be empty"), "{e}");
        assert_eq!(d.max_held_bytes, 128 << 20);
        let c = parse("[ingest]\nmax_held_mib = 512\n").unwrap();
        assert_eq!(c.ingest.max_held_bytes, 512 << 20);
        let e = parse("[ingest]\nmax_held_mib = 32\n")
            .unwrap_err()
            .to_string();
        assert_eq!(
            e,
            "test.toml:2: ingest.max_held_mib: 32 is out of range: 64 to 65536"
        );
        // A file the folder takes must fit the bound on what is held at once.
        let e = parse("[ingest]\nmax_file_mib = 200\n")
            .unwrap_err()
            .to_string();
        assert!(
            e.contains(
                "ingest.max_file_mib: max_held_mib (128 MiB) is less than max_file_mib (200 MiB)"
            ),
            "{e}"
        );
    }
}
