//! `brdfd report`: the study report (SCIENCE.md §9) of stored scans — figures 4–13 as PNG and
//! SVG, and the summary in HTML and Markdown — written into one directory, with progress on
//! stderr. Reads the store directly (no daemon needed): a station's SQLite file, or the lab's
//! central PostgreSQL database (`--db postgres://…`, `--station`).

use std::path::{Path, PathBuf};

use anyhow::{Context, bail};
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};

use crate::config::Config;
use crate::report::load::{Selection, from_central, from_store};
use crate::report::{Study, write_report_with};
use crate::store::central::CentralSelection;
use crate::store::{ScanId, Store};

/// Where `brdfd demo` writes its store by default (its `--dir`, then `brdfd.db`).
pub const DEMO_STORE: &str = "brdfd-demo/brdfd.db";

/// Which stored scans, and where the store is.
#[derive(Debug, clap::Args)]
#[command(group = clap::ArgGroup::new("which").required(true).args(["all", "scans"]))]
pub struct StoreSelection {
    /// Every complete scan in the store, oldest first.
    #[arg(long)]
    pub all: bool,

    /// The scans to include, by id (see `brdfd scans`), in this order.
    #[arg(value_name = "SCAN")]
    pub scans: Vec<i64>,

    /// The store to read: a station's SQLite file, or the lab's central PostgreSQL database
    /// as `postgres://USER[:PASSWORD]@HOST[:PORT]/DATABASE` (every station's scans, filled by
    /// `brdfd sync` or `[sync] url`). Default: the `[store] path` of the configuration
    /// (`brdfd.db`), or, when that file does not exist, the store `brdfd demo` writes
    /// (`brdfd-demo/brdfd.db`).
    #[arg(long, value_name = "PATH|URL")]
    pub db: Option<PathBuf>,

    /// With a postgres:// --db: only this station's scans (its `[station] id`); scan ids are
    /// then that station's. Without it every station's scans are read, and each sample is
    /// named with its station ("T.Sky blue [bench-2]").
    #[arg(long, value_name = "ID")]
    pub station: Option<String>,

    /// Configuration file whose store to read when --db is not given; default: the built-in
    /// defaults (`brdfd.db` in the working directory).
    #[arg(long, value_name = "brdfd.toml")]
    pub config: Option<PathBuf>,

    /// Allow scans measured on simulated instruments in one study with scans from real ones
    /// (refused by default: replayed recordings must not pass for measurements).
    #[arg(long)]
    pub include_simulated: bool,
}

impl StoreSelection {
    /// The store file this selection reads.
    pub fn db_path(&self) -> anyhow::Result<PathBuf> {
        if let Some(p) = &self.db {
            return Ok(p.clone());
        }
        let configured = Config::load_or_default(self.config.as_deref())?.store.path;
        // `brdfd demo` then `brdfd report --all` should just work on a fresh machine, where
        // the daemon's store does not exist but the demo's does.
        let demo = Path::new(DEMO_STORE);
        if self.config.is_none() && !configured.exists() && demo.exists() {
            eprintln!(
                "no store at {}; reading the demo's store {}",
                configured.display(),
                demo.display()
            );
            return Ok(demo.to_path_buf());
        }
        Ok(configured)
    }

    fn selection(&self) -> Selection {
        if self.all {
            Selection::All
        } else {
            Selection::Scans(self.scans.iter().map(|&i| ScanId(i)).collect())
        }
    }

    /// The central database URL, when --db is one.
    fn central_url(&self) -> Option<&str> {
        self.db
            .as_deref()
            .and_then(|p| p.to_str())
            .filter(|s| crate::sync::is_postgres_url(s))
    }

    /// Loads the selected scans and their fits from the store.
    pub fn load(&self) -> anyhow::Result<Study> {
        if let Some(url) = self.central_url() {
            let selection = self.selection();
            let study = load_central_study(url, self.station.as_deref(), &selection)?;
            return crate::study::load::pool_real_study(study, &selection, self.include_simulated)
                .map_err(anyhow::Error::msg);
        }
        if self.station.is_some() {
            bail!("--station only applies to a central database (--db postgres://…)");
        }
        let path = self.db_path()?;
        load_study_checked(&path, &self.selection(), self.include_simulated)
    }
}

/// Loads a study from the lab's central database: one station's scans or every station's.
/// Scan ids are a station's own, so they need --station when several stations forward there.
pub fn load_central_study(
    url: &str,
    station: Option<&str>,
    selection: &Selection,
) -> anyhow::Result<Study> {
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .context("starting the async runtime")?;
    rt.block_on(async {
        let central = crate::sync::Central::connect(url).await?;
        let stations = central.stations().await?;
        let result = async {
            if let Some(s) = station
                && !stations.iter().any(|x| x == s)
            {
                bail!(
                    "no station \"{s}\" in the central database {}; it holds {}",
                    central.url(),
                    if stations.is_empty() {
                        "no station yet".to_string()
                    } else {
                        stations.join(", ")
                    }
                );
            }
            let scans = match selection {
                Selection::All => None,
                Selection::Scans(ids) => {
                    if station.is_none() && stations.len() > 1 {
                        bail!(
                            "scan ids are per station and {} stations forward to {}; say \
                             which with --station ({})",
                            stations.len(),
                            central.url(),
                            stations.join(", ")
                        );
                    }
                    Some(ids.iter().map(|i| i.0).collect())
                }
            };
            let selection = CentralSelection {
                station: station.map(str::to_string),
                scans,
            };
            from_central(central.pool(), &selection)
                .await
                .with_context(|| format!("reading the study from {}", central.url()))
        }
        .await;
        central.close().await;
        result
    })
}

/// Opens an existing store (never creates one: a typo in --db must not look like an empty
/// study) and loads a study from it.
pub fn load_study(path: &Path, selection: &Selection) -> anyhow::Result<Study> {
    load_study_checked(path, selection, true)
}

/// Which of `scans` were measured on simulated instruments and which on real ones; an error
/// naming both kinds when they are mixed and `include_simulated` is false.
pub fn check_provenance_mix(
    scans: &[crate::store::ScanSummary],
    include_simulated: bool,
) -> anyhow::Result<()> {
    let simulated: Vec<i64> = scans
        .iter()
        .filter(|s| s.provenance.simulated())
        .map(|s| s.id.0)
        .collect();
    let real: Vec<i64> = scans
        .iter()
        .filter(|s| s.provenance.real())
        .map(|s| s.id.0)
        .collect();
    if !include_simulated && !simulated.is_empty() && !real.is_empty() {
        bail!(
            "the selection mixes scans from simulated instruments ({}) with scans from real ones \
             ({}); select one kind, or pass --include-simulated to study them together",
            list_ids(&simulated),
            list_ids(&real)
        );
    }
    Ok(())
}

/// What `--all` pools: every scan when they are all of one kind or `include_simulated`; when
/// the store holds real and simulated scans, only the real ones, the left-out simulated ones
/// named on stderr. `None`: every scan, as selected.
fn pool_real(scans: &[crate::store::ScanSummary], include_simulated: bool) -> Option<Vec<ScanId>> {
    let (simulated, real): (Vec<_>, Vec<_>) = scans.iter().partition(|s| s.provenance.simulated());
    if include_simulated || simulated.is_empty() || real.is_empty() {
        return None;
    }
    let ids = |v: &[&crate::store::ScanSummary]| {
        let mut ids: Vec<i64> = v.iter().map(|s| s.id.0).collect();
        ids.sort_unstable();
        ids
    };
    eprintln!(
        "pooling the {} real scans ({}) only; left out {} scans from simulated instruments \
         ({}): pass --include-simulated to pool them too",
        real.len(),
        list_ids(&ids(&real)),
        simulated.len(),
        list_ids(&ids(&simulated))
    );
    Some(ids(&real).into_iter().map(ScanId).collect())
}

fn list_ids(ids: &[i64]) -> String {
    let shown: Vec<String> = ids.iter().take(8).map(|i| format!("scan {i}")).collect();
    let more = ids.len().saturating_sub(8);
    if more > 0 {
        format!("{} and {more} more", shown.join(", "))
    } else {
        shown.join(", ")
    }
}

/// [`load_study`], refusing a mix of simulated and real scans unless `include_simulated`.
pub fn load_study_checked(
    path: &Path,
    selection: &Selection,
    include_simulated: bool,
) -> anyhow::Result<Study> {
    if !path.exists() {
        bail!(
            "no store at {}; run `brdfd demo` or the daemon first, or pass --db PATH",
            path.display()
        );
    }
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .context("starting the async runtime")?;
    rt.block_on(async {
        // Read-only: works beside a running daemon, never migrates or locks.
        let store = Store::open_read_only(path)
            .await
            .with_context(|| format!("opening the store {}", path.display()))?;
        let summaries: Vec<crate::store::ScanSummary> = match selection {
            Selection::All => {
                store
                    .list_scans(&crate::store::ScanFilter {
                        state: Some(crate::store::ScanState::Complete),
                        limit: u32::MAX,
                        ..Default::default()
                    })
                    .await?
            }
            Selection::Scans(ids) => {
                let mut out = Vec::new();
                for id in ids {
                    out.push(store.scan_detail(*id).await?.scan);
                }
                out
            }
        };
        let pooled = match selection {
            Selection::All => pool_real(&summaries, include_simulated).map(Selection::Scans),
            Selection::Scans(_) => None,
        };
        if pooled.is_none()
            && let Err(e) = check_provenance_mix(&summaries, include_simulated)
        {
            store.close().await;
            return Err(e);
        }
        let study = from_store(&store, pooled.as_ref().unwrap_or(selection))
            .await
            .with_context(|| format!("reading the study from {}", path.display()));
        store.close().await;
        study
    })
}

#[derive(Debug, clap::Args)]
pub struct ReportArgs {
    #[command(flatten)]
    pub select: StoreSelection,

    /// Directory to write the figures (`fig04-….png`/`.svg`, …) and `index.html`,
    /// `summary.md` into; created if missing.
    #[arg(long, value_name = "DIR")]
    pub out: PathBuf,

    /// Draw the per-sample figures (swatches, spectra, lightness panels, box plots, previews)
    /// for at most this many samples, the first in report order; the tables and the statistics
    /// always cover every selected scan.
    #[arg(long, value_name = "N", default_value_t = crate::report::ReportOptions::MAX_SAMPLE_FIGURES)]
    pub max_sample_figures: usize,

    /// Replace the files of an earlier report in DIR (refused otherwise). Only plain files
    /// are replaced: never a link, the store or the token.
    #[arg(long)]
    pub force: bool,

    /// Print `{"samples", "figures", "previews", "html", "markdown"}` instead of lines.
    #[arg(long)]
    pub json: bool,
}

pub fn run(args: &ReportArgs) -> anyhow::Result<()> {
    let study = args.select.load()?;
    let bar = ProgressBar::with_draw_target(Some(0), ProgressDrawTarget::stderr());
    bar.set_style(
        ProgressStyle::with_template("{spinner} report [{bar:30}] {pos}/{len} {msg}")
            .expect("a valid template")
            .progress_chars("=> "),
    );
    let opts = crate::report::ReportOptions {
        max_sample_figures: args.max_sample_figures,
        replace: args.force,
    };
    let files = write_report_with(&study, &args.out, &opts, &mut |step, done, total| {
        bar.set_length(total as u64);
        bar.set_position(done as u64);
        bar.set_message(step.to_string());
    })
    .with_context(|| format!("writing the report into {}", args.out.display()))?;
    bar.finish_and_clear();
    if args.json {
        println!(
            "{}",
            serde_json::json!({
                "samples": study.samples.len(),
                "figures": files.figures,
                "previews": files.previews,
                "html": files.html,
                "markdown": files.markdown,
            })
        );
        return Ok(());
    }
    println!(
        "{} samples, {} figures (PNG and SVG) in {}",
        study.samples.len(),
        files.figures.len(),
        args.out.display()
    );
    println!("summary: {}", files.html.display());
    println!("         {}", files.markdown.display());
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::store::{InstrumentProvenance, Provenance, ScanSummary, Source};

    fn scan(id: i64, simulated: Option<bool>) -> ScanSummary {
        let one = InstrumentProvenance {
            simulated,
            ..InstrumentProvenance::unknown()
        };
        let source = if simulated.is_none() {
            Source::Imported
        } else {
            Source::Measured
        };
        ScanSummary {
            id: ScanId(id),
            sample_id: crate::store::SampleId(1),
            sample: "S".into(),
            reference_id: crate::store::ReferenceId(1),
            specular_readings: true,
            state: crate::store::ScanState::Complete,
            reason: None,
            requested_at_ms: 0,
            started_at_ms: None,
            finished_at_ms: None,
            reading_count: 14,
            provenance: Provenance {
                ma_t12: one.clone(),
                sra: one,
                source,
                source_detail: None,
            }
            .settled(true),
        }
    }

    #[test]
    fn all_pools_only_the_real_scans_of_a_mixed_store() {
        // Scan 2 imported from an export (its simulated flags unknown), 3 measured on real
        // instruments, 1 and 4 on simulated ones.
        let store = [
            scan(1, Some(true)),
            scan(2, None),
            scan(3, Some(false)),
            scan(4, Some(true)),
        ];
        assert!(check_provenance_mix(&store, false).is_err());
        assert_eq!(pool_real(&store, false), Some(vec![ScanId(2), ScanId(3)]));
        assert_eq!(pool_real(&store, true), None);
        assert_eq!(pool_real(&store[..1], false), None);
        assert_eq!(pool_real(&store[1..3], false), None);
    }

    #[test]
    fn simulated_and_real_scans_are_not_mixed_unless_asked() {
        let all_sim = [scan(1, Some(true)), scan(2, Some(true))];
        assert!(check_provenance_mix(&all_sim, false).is_ok());
        let imported_and_real = [scan(1, None), scan(2, Some(false))];
        assert!(check_provenance_mix(&imported_and_real, false).is_ok());
        let imported_and_simulated = [scan(1, None), scan(2, Some(true))];
        assert!(check_provenance_mix(&imported_and_simulated, false).is_err());
        let mixed = [
            scan(1, Some(true)),
            scan(2, Some(false)),
            scan(3, Some(false)),
        ];
        let e = check_provenance_mix(&mixed, false).unwrap_err().to_string();
        assert!(e.contains("simulated instruments (scan 1)"), "{e}");
        assert!(e.contains("real ones (scan 2, scan 3)"), "{e}");
        assert!(e.contains("--include-simulated"), "{e}");
        assert!(check_provenance_mix(&mixed, true).is_ok());
    }

    /// A central study of real and simulated scans pools the real ones under `--all`, and
    /// refuses chosen scans that mix them, as a store's does.
    #[test]
    fn a_central_study_does_not_mix_real_and_simulated_scans() {
        let mut study = crate::study::tests::study_from_truth(3, None);
        // Sample 0 real (an import), 1 and 2 replayed on simulated instruments.
        let real = study.samples[0].clone();
        study = crate::study::tests::simulated(study, &["", "rec-a", "rec-b"]);
        study.samples[0] = crate::study::SampleStudy {
            origin: Some(crate::study::Origin {
                station: None,
                measured_at_ms: 0,
                provenance: Provenance {
                    ma_t12: InstrumentProvenance {
                        simulated: Some(false),
                        origin: crate::store::InstrumentOrigin::Imported,
                        ..InstrumentProvenance::unknown()
                    },
                    sra: InstrumentProvenance::unknown(),
                    source: Source::Imported,
                    ..Provenance::unknown()
                },
            }),
            ..real
        };
        assert!(study.samples[0].origin.as_ref().unwrap().provenance.real());
        let pooled =
            crate::study::load::pool_real_study(study.clone(), &Selection::All, false).unwrap();
        assert_eq!(pooled.samples.len(), 1);
        assert_eq!(pooled.samples[0].name, study.samples[0].name);
        let all =
            crate::study::load::pool_real_study(study.clone(), &Selection::All, true).unwrap();
        assert_eq!(all.samples.len(), 3);
        let chosen = Selection::Scans(vec![ScanId(1), ScanId(2)]);
        let e = crate::study::load::pool_real_study(study.clone(), &chosen, false).unwrap_err();
        assert!(e.contains("mixes scans from simulated instruments"), "{e}");
        assert!(e.contains("--include-simulated"), "{e}");
        assert!(crate::study::load::pool_real_study(study, &chosen, true).is_ok());
    }
}
