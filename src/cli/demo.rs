//! `brdfd demo`: the main job on the embedded default, through the whole daemon. With nothing
//! configured it replays the committed recordings — the Munsell N9 reference, then the eight
//! synthetic matt samples — on the simulated MA-T12 and SRA (strict, accelerated), through the
//! driver tasks, the scan orchestrator and the store (a local SQLite file, by default
//! `./brdfd-demo/brdfd.db`), fits every scan with the three cost functions on the fit worker,
//! and prints per sample and cost function the mean ΔE00 (diffuse and specular), the mean over
//! samples with its 95 % interval and the sign tests between cost functions (SCIENCE.md §8),
//! where the database and the outputs are, and where the time went (replay, store, fit).
//!
//! Its fits have no bootstrap intervals unless `--bootstrap N` asks for them: the service then
//! bootstraps every fit (one at a time) and the demo waits for all of them before it stops, so
//! the report on its database has Table 4's intervals and Fig. 8's error bars. The printed
//! report says which, and how to get them when not.
//!
//! Running it again reuses the database: the new run's reference, scans and fits are added
//! beside the old ones (nothing is deleted), and the report covers the new run. The outputs
//! (`report.txt`, `scans/*.scan.json`) are rewritten.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use anyhow::Context;

use crate::cost::CostFunction;
use crate::optimise::{Method, Settings};
use crate::service::{ServiceSettings, TimingSplit, scan_from_detail};
use crate::stats::{mean_ci95, sign_test};
use crate::store::{EvaluationRecord, FitDetail, Store};

use super::replay::{ReplayObject, ReplayOutcome, ReplaySetup, default_jobs, fits_of, options};

#[derive(Debug, clap::Args)]
pub struct DemoArgs {
    /// Directory for the database and the outputs (created if missing).
    #[arg(long, value_name = "DIR", default_value = "brdfd-demo")]
    pub dir: PathBuf,

    /// Optimiser for every fit (see `brdfd fit --help`).
    #[arg(long, value_name = "NAME", default_value_t = Method::default())]
    pub method: Method,

    /// Seed of every fit.
    #[arg(long, value_name = "N", default_value_t = Settings::default().seed)]
    pub seed: u64,

    /// Fits running at once (default: one per core).
    #[arg(long, value_name = "N")]
    pub jobs: Option<usize>,

    /// Bootstrap resamples per fit (SCIENCE.md §10): with N above 0 the demo waits until every
    /// fit has its 95 % intervals, so `brdfd report` on its database has them (Table 4, Fig. 8's
    /// error bars). One fit's bootstrap at a time: 200 resamples take minutes (the cf2 fits
    /// dominate), 20 about a tenth of that. 0 (the default) leaves the fits without intervals
    /// and the demo takes seconds.
    #[arg(long, value_name = "N", default_value_t = 0)]
    pub bootstrap: u32,

    /// Print one JSON object (`{"database", "report", "scans_dir", "fits": [{"sample", "scan",
    /// "cost_function", "cost", "wall_ms", "delta_e00": {…}}], "timing": {…}}`) instead of the
    /// report text (which is still written to report.txt).
    #[arg(long)]
    pub json: bool,
}

/// One row of the report: a sample's fit under one cost function.
#[derive(Debug, Clone, serde::Serialize)]
pub struct DemoRow {
    pub sample: String,
    pub scan: i64,
    pub cost_function: CostFunction,
    pub evaluation: EvaluationRecord,
    pub cost: f64,
    pub wall_ms: f64,
}

/// Everything the demo measured, for the report.
#[derive(Debug, Clone)]
pub struct DemoResult {
    /// `rows[sample][cost function]`, cost functions in [`CostFunction::ALL`] order.
    pub rows: Vec<Vec<DemoRow>>,
    pub outcome: ReplayOutcome,
    pub timings: TimingSplit,
    pub jobs: usize,
    pub method: Method,
    pub seed: u64,
    /// Bootstrap resamples per fit (0: none).
    pub bootstrap: u32,
}

/// Runs the demo into `db`; the service is stopped at the end, the store left open.
pub async fn run_demo(store: &Store, args: &DemoArgs) -> anyhow::Result<DemoResult> {
    let objects = ReplayObject::builtin()?;
    let jobs = args.jobs.unwrap_or_else(default_jobs).max(1);
    let settings = ServiceSettings {
        cost_functions: CostFunction::ALL.to_vec(),
        method: args.method,
        seed: args.seed,
        max_concurrent_fits: jobs,
        // The paper's configuration (`[fit] preset = "paper"`): the demo reproduces the paper.
        sra: crate::optimise::Preset::Paper.sra(),
        fresnel: crate::optimise::Preset::Paper.fresnel(),
        model: crate::optimise::Preset::Paper.model(),
        preset: crate::optimise::Preset::Paper,
        // The paper's figures are fits to every reading; no held-out fits.
        crossval: false,
        // Intervals only when asked for, and then every one of them (waited for below).
        bootstrap: args.bootstrap,
        ..ServiceSettings::default()
    };
    let setup = ReplaySetup {
        options: options(false, false),
        settings,
        timeout: Duration::from_secs(3600),
        wait_for_bootstraps: true,
    };
    let (outcome, timings) = super::replay::replay_objects(store.clone(), &objects, &setup).await?;
    if !outcome.problems.is_empty() {
        anyhow::bail!("the replay went wrong: {}", outcome.problems.join("; "));
    }
    let fits = fits_of(store, &outcome.scans).await?;
    let mut rows = Vec::new();
    for ((sample, scan), fits) in outcome.scans.iter().zip(fits) {
        let mut per_cost = Vec::new();
        for cost in CostFunction::ALL {
            let f = fits
                .iter()
                .find(|f| f.run.cost_function == cost)
                .with_context(|| format!("scan {scan} has no {cost} fit"))?;
            per_cost.push(row(sample, scan.0, f)?);
        }
        rows.push(per_cost);
    }
    Ok(DemoResult {
        rows,
        outcome,
        timings,
        jobs,
        method: args.method,
        seed: args.seed,
        bootstrap: args.bootstrap,
    })
}

fn row(sample: &str, scan: i64, f: &FitDetail) -> anyhow::Result<DemoRow> {
    let (Some(evaluation), Some(result)) = (f.evaluation, f.run.result.as_ref()) else {
        anyhow::bail!(
            "fit {} of scan {scan} ({}) is {}{}",
            f.run.id,
            f.run.cost_function,
            f.run.status,
            super::fit_error_suffix(&f.run)
        );
    };
    Ok(DemoRow {
        sample: sample.to_string(),
        scan,
        cost_function: f.run.cost_function,
        evaluation,
        cost: result.cost,
        wall_ms: result.wall_ms,
    })
}

pub fn run(args: &DemoArgs) -> anyhow::Result<()> {
    crate::cli::serve::init_logging(crate::config::LogLevel::Warn, false);
    let started = Instant::now();
    std::fs::create_dir_all(&args.dir)
        .with_context(|| format!("cannot create {}", args.dir.display()))?;
    let db = args.dir.join("brdfd.db");
    let existed = db.exists();
    crate::cli::serve::runtime()?.block_on(async {
        let store = Store::open(&db).await?;
        let result = run_demo(&store, args).await?;
        let scans_dir = args.dir.join("scans");
        write_scans(&store, &result, &scans_dir).await?;
        store.close().await;
        let wall = started.elapsed();
        let mut text = summary(&result);
        let _ = writeln!(
            text,
            "timing: {:.2} s wall in all; replay of the 9 recordings through the devices {:.2} s \
             (instruments measuring {:.2} s), store {:.3} s, fitting {:.2} s of fit time on {} \
             thread(s), fits all done {:.2} s after the first request",
            wall.as_secs_f64(),
            result.outcome.replay_wall.as_secs_f64(),
            result.timings.acquire_s,
            result.timings.store_s,
            result.timings.fit_s,
            result.jobs,
            result.outcome.total_wall.as_secs_f64()
        );
        let _ = writeln!(text, "{}", intervals_line(&result));
        let report = args.dir.join("report.txt");
        let _ = writeln!(
            text,
            "database: {} ({}; `brdfd serve --db {}` serves it, `sqlite3` reads it)",
            db.display(),
            if existed {
                "reused: this run's scans were added"
            } else {
                "new"
            },
            db.display()
        );
        let _ = writeln!(
            text,
            "outputs: {} (this report), {}/ (the 8 scans as brdfd.scan/1; `brdfd fit --input` \
             refits one)",
            report.display(),
            scans_dir.display()
        );
        crate::safe_fs::write_file(&report, text.as_bytes(), crate::safe_fs::Replace::OwnKind)?;
        if args.json {
            let fits: Vec<&DemoRow> = result.rows.iter().flatten().collect();
            println!(
                "{}",
                serde_json::json!({
                    "database": db,
                    "database_reused": existed,
                    "report": report,
                    "scans_dir": scans_dir,
                    "method": result.method.to_string(),
                    "seed": result.seed,
                    "fits": fits,
                    "bootstrap": result.bootstrap,
                    "timing": {
                        "wall_s": wall.as_secs_f64(),
                        "bootstrap_s": result.outcome.bootstrap_wall.map(|d| d.as_secs_f64()),
                        "replay_s": result.outcome.replay_wall.as_secs_f64(),
                        "acquire_s": result.timings.acquire_s,
                        "store_s": result.timings.store_s,
                        "fit_s": result.timings.fit_s,
                        "jobs": result.jobs,
                    },
                })
            );
        } else {
            print!("{text}");
        }
        Ok(())
    })
}

async fn write_scans(store: &Store, result: &DemoResult, dir: &Path) -> anyhow::Result<()> {
    std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
    for (sample, scan) in &result.outcome.scans {
        let detail = store.scan_detail(*scan).await?;
        let file = scan_from_detail(&detail)?;
        let path = dir.join(format!("{}.scan.json", crate::synth::slug(sample)));
        let text = file.to_json_pretty()?;
        crate::safe_fs::write_file(&path, text.as_bytes(), crate::safe_fs::Replace::OwnKind)?;
    }
    Ok(())
}

/// The demo's printed report.
pub fn summary(result: &DemoResult) -> String {
    let rows = &result.rows;
    let mut t = String::new();
    let scans: Vec<String> = result
        .outcome
        .scans
        .iter()
        .map(|(_, id)| id.to_string())
        .collect();
    let _ = writeln!(
        t,
        "replayed the committed recordings (synthetic N9 reference + {} samples) through the \
         daemon: reference {}, scans {}; {} cost functions, method {}, seed {}",
        rows.len(),
        result
            .outcome
            .references
            .iter()
            .map(ToString::to_string)
            .collect::<Vec<_>>()
            .join(","),
        scans.join(","),
        CostFunction::ALL.len(),
        result.method,
        result.seed
    );
    let _ = writeln!(
        t,
        "preset: paper (the paper's configuration: Schlick's Fresnel on cos θi, each SRA reading \
         spread into a grey spectrum); `brdfd serve` fits under [fit] preset = \"measured\" \
         (exact Fresnel, luminance SRA) by default, so the same recording's ΔE00 differs there \
         (SCIENCE.md §4.1, §12.2)"
    );
    let _ = writeln!(t, "mean ΔE00 between measured and fitted colour per sample");
    let _ = writeln!(
        t,
        "specular: ΔE00 at sra-20 and sra-60 against the grey spectrum the SRA reading is spread \
         into (the paper's metric, not a colour measured there); `brdfd show` adds |ΔL*|"
    );
    let _ = writeln!(
        t,
        "{:<20} {:>4} {:<4} {:>9} {:>9} {:>9} {:>10} {:>9}",
        "sample", "scan", "cost", "diffuse", "specular", "all", "cost value", "wall ms"
    );
    for sample in rows {
        for r in sample {
            let e = &r.evaluation;
            let _ = writeln!(
                t,
                "{:<20} {:>4} {:<4} {:>9.3} {:>9.3} {:>9.3} {:>10.3e} {:>9.1}",
                r.sample,
                r.scan,
                r.cost_function.name(),
                e.diffuse.mean,
                e.specular.map_or(f64::NAN, |s| s.mean),
                e.all.mean,
                r.cost,
                r.wall_ms
            );
        }
    }
    let _ = writeln!(
        t,
        "over samples: mean of the per-sample means, 95 % CI (Student t)"
    );
    for (k, cost) in CostFunction::ALL.iter().enumerate() {
        let ci = |pick: fn(&DemoRow) -> f64| {
            let xs: Vec<f64> = rows.iter().map(|s| pick(&s[k])).collect();
            match mean_ci95(&xs) {
                Some(c) => format!("{:.3} ± {:.3}", c.mean, c.half_width),
                None => "n/a".to_string(),
            }
        };
        let _ = writeln!(
            t,
            "  {:<4} diffuse {}   specular {}   all {}",
            cost.name(),
            ci(|r| r.evaluation.diffuse.mean),
            ci(|r| r.evaluation.specular.map_or(f64::NAN, |s| s.mean)),
            ci(|r| r.evaluation.all.mean)
        );
    }
    let _ = writeln!(
        t,
        "sign tests on paired ΔE00 per (sample, geometry), ties dropped"
    );
    let paired = |k: usize| -> Vec<f64> {
        rows.iter()
            .flat_map(|s| s[k].evaluation.per_geometry)
            .collect()
    };
    for (a, b) in [(0, 1), (0, 2), (1, 2)] {
        let st = sign_test(&paired(a), &paired(b));
        let _ = writeln!(
            t,
            "  {} vs {}: {} pairs, {} lower with {}, {} lower with {}, p = {}",
            CostFunction::ALL[a],
            CostFunction::ALL[b],
            st.n,
            st.minus,
            CostFunction::ALL[a],
            st.plus,
            CostFunction::ALL[b],
            format_p(st.p)
        );
    }
    t
}

/// Whether the demo's fits carry bootstrap intervals, and how to get them when not.
fn intervals_line(result: &DemoResult) -> String {
    match result.outcome.bootstrap_wall {
        Some(d) => format!(
            "intervals: every fit bootstrapped with {} resamples ({:.1} s, one fit at a time); \
             `brdfd report --all --db <the database> --out DIR` tables and draws them (Table 4, \
             Fig. 8's error bars)",
            result.bootstrap,
            d.as_secs_f64()
        ),
        None => "intervals: none (no bootstrap); `brdfd demo --bootstrap 200` computes the 95 % \
                 intervals of every fit and waits for them (minutes), for the report's Table 4 \
                 and Fig. 8"
            .to_string(),
    }
}

/// A p-value readably: three decimals, or scientific notation below 0.001.
fn format_p(p: f64) -> String {
    if p < 1e-3 {
        format!("{p:.1e}")
    } else {
        format!("{p:.3}")
    }
}
