//! `brdfd report`: the study report (SCIENCE.md §9) of stored scans — figures 4–12 as PNG and
//! SVG, and the summary in HTML and Markdown — written into one directory, with progress on
//! stderr. Reads the store directly (no daemon needed).

use std::path::{Path, PathBuf};

use anyhow::{Context, bail};
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};

use crate::config::Config;
use crate::report::load::{Selection, from_store};
use crate::report::{Study, write_report};
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

    /// The SQLite store to read; default: the `[store] path` of the configuration
    /// (`brdfd.db`), or, when that file does not exist, the store `brdfd demo` writes
    /// (`brdfd-demo/brdfd.db`).
    #[arg(long, value_name = "PATH")]
    pub db: Option<PathBuf>,

    /// Configuration file whose store to read when --db is not given; default: the built-in
    /// defaults (`brdfd.db` in the working directory).
    #[arg(long, value_name = "brdfd.toml")]
    pub config: Option<PathBuf>,
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

    /// Loads the selected scans and their fits from the store.
    pub fn load(&self) -> anyhow::Result<Study> {
        let path = self.db_path()?;
        load_study(&path, &self.selection())
    }
}

/// Opens an existing store (never creates one: a typo in --db must not look like an empty
/// study) and loads a study from it.
pub fn load_study(path: &Path, selection: &Selection) -> anyhow::Result<Study> {
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
        let study = from_store(&store, selection)
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
}

pub fn run(args: &ReportArgs) -> anyhow::Result<()> {
    let study = args.select.load()?;
    let bar = ProgressBar::with_draw_target(Some(0), ProgressDrawTarget::stderr());
    bar.set_style(
        ProgressStyle::with_template("{spinner} report [{bar:30}] {pos}/{len} {msg}")
            .expect("a valid template")
            .progress_chars("=> "),
    );
    let files = write_report(&study, &args.out, &mut |step, done, total| {
        bar.set_length(total as u64);
        bar.set_position(done as u64);
        bar.set_message(step.to_string());
    })
    .with_context(|| format!("writing the report into {}", args.out.display()))?;
    bar.finish_and_clear();
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
