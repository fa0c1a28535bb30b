//! `brdfd replay SESSION…`: recorded sessions run against the whole daemon in-process —
//! simulated instruments replaying the files → driver tasks → scan orchestrator → store → fit
//! worker — strict and accelerated by default (`--lenient`, `--realtime`).
//!
//! Sessions come in pairs, one per instrument, for each object measured: the i-th MA-T12
//! session goes with the i-th SRA session, in the order given. A pair whose notes say
//! `reference …` is measured as a reference, one saying `sample NAME` as a scan of NAME. An
//! argument that is not a file but the name of an embedded recording (`synthetic-n9`,
//! `T.Sky blue`, or `builtin` for all nine) stands for both of its sessions.
//!
//! [`replay_objects`] is the engine, shared with `brdfd demo`.

use std::path::PathBuf;
use std::time::{Duration, Instant};

use anyhow::{Context, bail};
use drivers::Instrument;
use drivers::session::Session;
use mock_devices::generate::{is_reference, sample_of};
use mock_devices::{Mode, ReplayOptions, Script, Timing};

use crate::service::{Devices, Service, ServiceOptions, ServiceSettings};
use crate::store::{FitDetail, FitStatus, ReferenceId, ReferenceStatus, ScanId, ScanState, Store};

#[derive(Debug, clap::Args)]
pub struct ReplayArgs {
    /// Session files (`brdfd-session 1`), one per instrument per object, or names of embedded
    /// recordings (`builtin` = the N9 reference and the eight samples).
    #[arg(value_name = "SESSION", required = true)]
    pub sessions: Vec<String>,
    /// Match requests by kind and geometry rather than byte for byte.
    #[arg(long)]
    pub lenient: bool,
    /// Replay at the recorded timing instead of as fast as possible.
    #[arg(long)]
    pub realtime: bool,
    /// Keep the store in this SQLite file (default: in memory, gone at exit).
    #[arg(long, value_name = "FILE")]
    pub db: Option<PathBuf>,
    /// Fits running at once (default: one per core).
    #[arg(long, value_name = "N")]
    pub jobs: Option<usize>,

    /// Print one JSON object (`{"scans": [{"scan", "sample", "state", "fits": [{"id",
    /// "cost_function", "status", "error", "delta_e00_mean", …}]}], "references", "mode",
    /// "replay_s", "total_s", "store"}`) instead of lines.
    #[arg(long)]
    pub json: bool,
}

/// One object measured: its two sessions and what it is.
#[derive(Debug, Clone)]
pub struct ReplayObject {
    /// For messages: the file names or the recording's name.
    pub label: String,
    /// `None` for the reference tile.
    pub sample: Option<String>,
    pub ma_t12: Session,
    pub sra: Session,
}

impl ReplayObject {
    /// The embedded recordings: the N9 reference, then the eight samples.
    pub fn builtin() -> anyhow::Result<Vec<ReplayObject>> {
        mock_devices::recordings::all()
            .iter()
            .map(ReplayObject::from_recording)
            .collect()
    }

    fn from_recording(r: &mock_devices::recordings::Recording) -> anyhow::Result<ReplayObject> {
        Ok(ReplayObject {
            label: r.name.to_string(),
            sample: r.sample.map(str::to_string),
            ma_t12: r
                .session(Instrument::MaT12)
                .with_context(|| format!("embedded recording {}", r.name))?,
            sra: r
                .session(Instrument::Sra)
                .with_context(|| format!("embedded recording {}", r.name))?,
        })
    }
}

/// Reads the arguments into objects (see the module documentation).
pub fn objects_from_args(args: &[String]) -> anyhow::Result<Vec<ReplayObject>> {
    let mut objects = Vec::new();
    let mut loose: [Vec<(String, Session)>; 2] = [Vec::new(), Vec::new()];
    for arg in args {
        let path = std::path::Path::new(arg);
        if path.is_file() {
            let text = std::fs::read_to_string(path)
                .with_context(|| format!("cannot read {}", path.display()))?;
            let session = Session::parse(&text).with_context(|| path.display().to_string())?;
            let slot = match session.instrument {
                Instrument::MaT12 => 0,
                Instrument::Sra => 1,
            };
            loose[slot].push((path.display().to_string(), session));
        } else if arg.eq_ignore_ascii_case("builtin") {
            objects.extend(ReplayObject::builtin()?);
        } else if let Some(r) = mock_devices::recordings::by_name(arg) {
            objects.push(ReplayObject::from_recording(r)?);
        } else {
            bail!(
                "{arg}: no such session file, and not the name of an embedded recording \
                 (e.g. synthetic-n9, \"T.Sky blue\", or builtin for all)"
            );
        }
    }
    let [m, s] = loose;
    if m.len() != s.len() {
        bail!(
            "{} MA-T12 session(s) but {} SRA session(s): give one of each per object measured, \
             in the same order",
            m.len(),
            s.len()
        );
    }
    for ((m_label, m), (s_label, s)) in m.into_iter().zip(s) {
        let sample = sample_of(&m).map(str::to_string);
        if sample.as_deref() != sample_of(&s) || is_reference(&m) != is_reference(&s) {
            bail!(
                "{m_label} and {s_label} are not of the same object (their `note sample …` / \
                 `note reference …` lines differ): pair each MA-T12 session with the SRA \
                 session of the same object"
            );
        }
        if sample.is_none() && !is_reference(&m) {
            bail!(
                "{m_label}: no `note sample NAME` or `note reference …` line, so it is not known \
                 whether it measures the reference tile or a sample; add the note"
            );
        }
        objects.push(ReplayObject {
            label: format!("{m_label} + {s_label}"),
            sample,
            ma_t12: m,
            sra: s,
        });
    }
    Ok(objects)
}

/// What a replay did.
#[derive(Debug, Clone)]
pub struct ReplayOutcome {
    /// The references measured, in order.
    pub references: Vec<ReferenceId>,
    /// The scans measured: (sample, scan id), in order.
    pub scans: Vec<(String, ScanId)>,
    /// Problems: failed references or scans, strict-mode mismatches.
    pub problems: Vec<String>,
    /// From the first request to the last reading.
    pub replay_wall: Duration,
    /// From the first request until every fit had ended.
    pub total_wall: Duration,
    /// How long the wait for the fits' bootstraps took, when waited for.
    pub bootstrap_wall: Option<Duration>,
}

/// Settings of a replay run.
#[derive(Debug, Clone)]
pub struct ReplaySetup {
    pub options: ReplayOptions,
    pub settings: ServiceSettings,
    /// Longest wait for any one measurement and for the fits at the end.
    pub timeout: Duration,
    /// Wait, before stopping, until every finished fit has its bootstrap intervals
    /// (`settings.bootstrap` resamples each); otherwise the service stops once the fits are
    /// done, and bootstraps still running are dropped.
    pub wait_for_bootstraps: bool,
}

/// Runs `objects` through a fresh service on `store` with simulated instruments replaying their
/// sessions; returns when every scan's fits have ended (and, with
/// [`ReplaySetup::wait_for_bootstraps`], their bootstraps). The service is shut down at the end
/// (the store stays open for the caller).
pub async fn replay_objects(
    store: Store,
    objects: &[ReplayObject],
    setup: &ReplaySetup,
) -> anyhow::Result<(ReplayOutcome, crate::service::TimingSplit)> {
    let ma = Script::from_sessions(objects.iter().map(|o| o.ma_t12.clone()))
        .context("MA-T12 sessions")?;
    let sra =
        Script::from_sessions(objects.iter().map(|o| o.sra.clone())).context("SRA sessions")?;
    let devices = Devices::simulated(ma, sra, &setup.options, [None, None])?;
    let service = Service::start(
        store,
        devices,
        setup.settings.clone(),
        ServiceOptions::default(),
    )
    .await?;
    let mut outcome = drive(&service, objects, setup.timeout).await;
    if let Ok(o) = &mut outcome
        && setup.wait_for_bootstraps
        && setup.settings.bootstrap > 0
    {
        let started = Instant::now();
        match wait_bootstraps(&service, &o.scans, setup.timeout).await {
            Ok(()) => o.bootstrap_wall = Some(started.elapsed()),
            Err(e) => outcome = Err(e),
        }
    }
    let timings = service.timings();
    // Keep the store open for the caller: stop the instruments and tasks only.
    let mut problems = Vec::new();
    for (instrument, report) in service.devices().replay_reports() {
        for m in &report.mismatches {
            problems.push(format!(
                "{instrument}: request did not match the recording: {m}"
            ));
        }
    }
    let mut outcome = outcome?;
    outcome.problems.extend(problems);
    service.stop_keeping_store().await;
    Ok((outcome, timings))
}

/// Waits until every finished fit of `scans` has its bootstrap intervals stored. A bootstrap
/// that fails stores none (the daemon logs why): once no bootstrap has been pending for a
/// second, the wait ends with the fits that have them.
async fn wait_bootstraps(
    service: &Service,
    scans: &[(String, ScanId)],
    timeout: Duration,
) -> anyhow::Result<()> {
    let deadline = Instant::now() + timeout;
    let mut idle_since: Option<Instant> = None;
    loop {
        let mut missing = 0;
        for (_, scan) in scans {
            for run in service.store().fits_for_scan(*scan).await? {
                if run.status == FitStatus::Done
                    && service
                        .store()
                        .fit_detail(run.id)
                        .await?
                        .uncertainty
                        .is_none()
                {
                    missing += 1;
                }
            }
        }
        if missing == 0 {
            return Ok(());
        }
        if service.status().await?.bootstraps_pending == 0 {
            // A fit just stored may not have started its bootstrap yet: wait a little.
            let since = *idle_since.get_or_insert_with(Instant::now);
            if since.elapsed() > Duration::from_secs(1) {
                return Ok(());
            }
        } else {
            idle_since = None;
        }
        if Instant::now() >= deadline {
            bail!("{missing} fit(s) still had no bootstrap intervals after {timeout:?}");
        }
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
}

async fn drive(
    service: &Service,
    objects: &[ReplayObject],
    timeout: Duration,
) -> anyhow::Result<ReplayOutcome> {
    let started = Instant::now();
    let mut out = ReplayOutcome {
        references: Vec::new(),
        scans: Vec::new(),
        problems: Vec::new(),
        replay_wall: Duration::ZERO,
        total_wall: Duration::ZERO,
        bootstrap_wall: None,
    };
    for object in objects {
        match &object.sample {
            None => {
                let id = service.request_reference().await?;
                if !service.wait_idle(timeout).await {
                    bail!(
                        "{}: the reference did not finish within {timeout:?}",
                        object.label
                    );
                }
                let r = service.store().reference_detail(id).await?;
                if r.reference.status != ReferenceStatus::Complete {
                    out.problems.push(format!(
                        "{}: reference {id} {}: {}",
                        object.label,
                        r.reference.status,
                        r.reference.reason.unwrap_or_default()
                    ));
                }
                out.references.push(id);
            }
            Some(sample) => {
                let id = service.request_scan(sample).await?;
                if !service.wait_idle(timeout).await {
                    bail!(
                        "{}: the scan did not finish within {timeout:?}",
                        object.label
                    );
                }
                let d = service.store().scan_detail(id).await?;
                if d.scan.state != ScanState::Complete {
                    out.problems.push(format!(
                        "{}: scan {id} {}: {}",
                        object.label,
                        d.scan.state,
                        d.scan.reason.unwrap_or_default()
                    ));
                }
                out.scans.push((sample.clone(), id));
            }
        }
    }
    out.replay_wall = started.elapsed();
    for (_, scan) in &out.scans {
        if !service.wait_settled(*scan, timeout).await? {
            bail!("the fits of scan {scan} did not end within {timeout:?}");
        }
    }
    out.total_wall = started.elapsed();
    Ok(out)
}

/// The fits of each scan, in scan order.
pub async fn fits_of(
    store: &Store,
    scans: &[(String, ScanId)],
) -> anyhow::Result<Vec<Vec<FitDetail>>> {
    let mut all = Vec::new();
    for (_, scan) in scans {
        let mut fits = Vec::new();
        for run in store.fits_for_scan(*scan).await? {
            fits.push(store.fit_detail(run.id).await?);
        }
        all.push(fits);
    }
    Ok(all)
}

/// Replay options from the flags.
pub fn options(lenient: bool, realtime: bool) -> ReplayOptions {
    ReplayOptions {
        mode: if lenient { Mode::Lenient } else { Mode::Strict },
        timing: if realtime {
            Timing::Recorded
        } else {
            Timing::Immediate
        },
        unplug_after: None,
    }
}

/// One fit per core, at least one.
pub fn default_jobs() -> usize {
    std::thread::available_parallelism().map_or(1, |n| n.get())
}

pub fn run(args: &ReplayArgs) -> anyhow::Result<()> {
    crate::cli::serve::init_logging(crate::config::LogLevel::Warn, false);
    let objects = objects_from_args(&args.sessions)?;
    let settings = ServiceSettings {
        max_concurrent_fits: args.jobs.unwrap_or_else(default_jobs).max(1),
        ..ServiceSettings::default()
    };
    let setup = ReplaySetup {
        options: options(args.lenient, args.realtime),
        settings,
        timeout: Duration::from_secs(600),
        wait_for_bootstraps: false,
    };
    crate::cli::serve::runtime()?.block_on(async {
        let store = match &args.db {
            Some(path) => Store::open(path).await?,
            None => Store::open_in_memory().await?,
        };
        let (outcome, timings) = replay_objects(store.clone(), &objects, &setup).await?;
        let fits = fits_of(&store, &outcome.scans).await?;
        if args.json {
            let mut scans = Vec::new();
            for ((sample, scan), fits) in outcome.scans.iter().zip(&fits) {
                let state = store.scan_detail(*scan).await?.scan.state;
                let fits: Vec<serde_json::Value> = fits
                    .iter()
                    .map(|f| {
                        serde_json::json!({
                            "id": f.run.id,
                            "cost_function": f.run.cost_function,
                            "status": f.run.status.to_string(),
                            "error": f.run.error,
                            "delta_e00_mean": f.evaluation.as_ref().map(|e| e.all.mean),
                            "delta_e00_diffuse_mean": f.evaluation.as_ref().map(|e| e.diffuse.mean),
                            "delta_e00_specular_mean": f.evaluation.as_ref().and_then(|e| e.specular.map(|s| s.mean)),
                        })
                    })
                    .collect();
                scans.push(serde_json::json!({
                    "scan": scan, "sample": sample, "state": state.to_string(), "fits": fits,
                }));
            }
            println!(
                "{}",
                serde_json::json!({
                    "scans": scans,
                    "references": outcome.references.len(),
                    "mode": if args.lenient { "lenient" } else { "strict" },
                    "timing": if args.realtime { "recorded" } else { "accelerated" },
                    "replay_s": outcome.replay_wall.as_secs_f64(),
                    "total_s": outcome.total_wall.as_secs_f64(),
                    "store": args.db,
                    "problems": outcome.problems.iter().map(|p| p.to_string()).collect::<Vec<_>>(),
                })
            );
        } else {
        for ((sample, scan), fits) in outcome.scans.iter().zip(&fits) {
            let state = store.scan_detail(*scan).await?.scan.state;
            println!("scan {scan} \"{sample}\": {state}");
            for f in fits {
                match &f.evaluation {
                    Some(e) => println!(
                        "  fit {} {:<4} {}: mean ΔE00 {:.3} (diffuse {:.3}, specular {})",
                        f.run.id,
                        f.run.cost_function.name(),
                        f.run.status,
                        e.all.mean,
                        e.diffuse.mean,
                        e.specular.map_or("none: no specular readings".into(), |s| format!(
                            "{:.3}",
                            s.mean
                        ))
                    ),
                    None => println!(
                        "  fit {} {:<4} {}{}",
                        f.run.id,
                        f.run.cost_function.name(),
                        f.run.status,
                        super::fit_error_suffix(&f.run)
                    ),
                }
            }
        }
        println!(
            "{} reference(s), {} scan(s) replayed ({}, {}) in {:.2} s; fits done after {:.2} s \
             (store {:.3} s, fitting {:.2} s over {} thread(s))",
            outcome.references.len(),
            outcome.scans.len(),
            if args.lenient { "lenient" } else { "strict" },
            if args.realtime {
                "recorded timing"
            } else {
                "accelerated"
            },
            outcome.replay_wall.as_secs_f64(),
            outcome.total_wall.as_secs_f64(),
            timings.store_s,
            timings.fit_s,
            setup.settings.max_concurrent_fits
        );
        match &args.db {
            Some(path) => println!("store: {}", path.display()),
            None => println!("store: in memory (use --db FILE to keep it)"),
        }
        }
        store.close().await;
        if !outcome.problems.is_empty() {
            for p in &outcome.problems {
                eprintln!("problem: {p}");
            }
            bail!("{} problem(s) in the replay", outcome.problems.len());
        }
        Ok(())
    })
}
