//! `brdfd refit`: fit a stored scan again, then follow the new fits; `brdfd refit --all`
//! brings every complete scan (or those chosen by sample and date) to a configuration,
//! queuing only the fits each lacks, so that a stopped run goes on where it was.

use super::follow::{follow_scan, print_scan_result};
use super::operator::{DaemonArgs, tagged};
use crate::cost::CostFunction;
use crate::optimise::Method;
use crate::store::ScanId;
use crate::wire::RefitRequest;

#[derive(Debug, clap::Args)]
pub struct RefitArgs {
    #[command(flatten)]
    pub daemon: DaemonArgs,
    /// The scan's id (or `--all`).
    #[arg(
        value_name = "SCAN",
        required_unless_present = "all",
        conflicts_with = "all"
    )]
    pub scan: Option<i64>,
    /// Refit every complete scan in the store (narrowed by `--sample` and `--since`), queuing
    /// only the fits a scan lacks in the configuration asked for (the same cost function,
    /// method, model, Fresnel factor and SRA model, done or still queued): after a stop, the
    /// same command goes on where it was. To bring an archive to a new default: `brdfd refit
    /// --all --preset measured`. The daemon runs the fits `[fit] max_concurrent_fits` at a
    /// time (2 uses both cores of a small lab PC); a bar shows the scans queued, then the fits
    /// left.
    #[arg(long)]
    pub all: bool,
    /// With `--all`: only samples whose name holds this text (case ignored).
    #[arg(long, value_name = "TEXT", requires = "all")]
    pub sample: Option<String>,
    /// With `--all`: only scans requested on or after this day (YYYY-MM-DD, local time).
    #[arg(long, value_name = "YYYY-MM-DD", requires = "all", value_parser = parse_day)]
    pub since: Option<jiff::civil::Date>,
    /// Cost functions to fit (repeat or separate with commas); default: the configured ones.
    #[arg(long, value_name = "cf1|cf2|m2", value_delimiter = ',')]
    pub cost: Vec<CostFunction>,
    /// Optimiser; default: the configured one.
    #[arg(long, value_name = "NAME")]
    pub method: Option<Method>,
    /// Seed; default: the configured one.
    #[arg(long, value_name = "N")]
    pub seed: Option<u64>,
    /// The science defaults for `--model`, `--fresnel`, `--sra` and `--sra-weight`: `measured` (exact Fresnel,
    /// luminance SRA: what predicts real materials best) or `paper` (the paper's
    /// configuration); default: the configured choices (`[fit]`). Brings a stored scan to
    /// another configuration; its earlier fits keep theirs.
    #[arg(long, value_name = "measured|paper")]
    pub preset: Option<crate::optimise::Preset>,
    /// The model's form: `paper`, `oren-nayar` or `two-lobe` (the options need the separable
    /// method); default: the preset's, else the configured one.
    #[arg(long, value_name = "paper|oren-nayar|two-lobe")]
    pub model: Option<crate::model::ModelKind>,
    /// The lobe's Fresnel factor: `exact`, `incidence` (the paper's Schlick on cos θi) or
    /// `light-half`; default: the preset's, else the configured one.
    #[arg(long, value_name = "exact|incidence|light-half")]
    pub fresnel: Option<crate::model::FresnelCosine>,
    /// How the SRA's readings enter the fit: `flat` (the paper's grey spectrum) or `luminance`
    /// (the model's luminous reflectance; SCIENCE.md §5.1); default: the preset's, else the
    /// configured one.
    #[arg(long, value_name = "flat|luminance")]
    pub sra: Option<crate::sra_reading::SraModel>,
    /// How much the SRA readings weigh in the cost: `balanced` (scaled down to the MA-T12
    /// readings' level when above it) or `paper` (every geometry by cos θi; SCIENCE.md §5.2);
    /// default: the preset's for each cost function, else the configured one.
    #[arg(long, value_name = "balanced|paper")]
    pub sra_weight: Option<crate::sra_reading::SraWeight>,
    /// Fit even though the scan's reference is older than the configured limit.
    #[arg(long)]
    pub allow_stale_reference: bool,
    /// Return once queued, without following progress.
    #[arg(long)]
    pub detach: bool,
    /// NDJSON on stdout, as for `brdfd scan --json`.
    #[arg(long)]
    pub json: bool,
}
/// A day as `--since` takes it.
fn parse_day(s: &str) -> Result<jiff::civil::Date, String> {
    s.parse()
        .map_err(|e| format!("\"{s}\" is not a day (YYYY-MM-DD): {e}"))
}

/// The request the options make.
fn request(args: &RefitArgs) -> RefitRequest {
    RefitRequest {
        cost_functions: args.cost.clone(),
        method: args.method,
        seed: args.seed,
        preset: args.preset,
        sra: args.sra,
        sra_weight: args.sra_weight,
        model: args.model,
        fresnel: args.fresnel,
        allow_stale_reference: args.allow_stale_reference,
        missing_only: args.all,
    }
}

pub fn refit(args: &RefitArgs) -> anyhow::Result<()> {
    let Some(scan) = args.scan else {
        return refit_all(args);
    };
    let client = args.daemon.client()?;
    let events = (!args.detach).then(|| client.events()).transpose()?;
    let request = request(args);
    let scan = ScanId(scan);
    let v = client.refit(scan, &request)?;
    if args.json {
        println!("{}", tagged("accepted", &v)?);
    } else {
        let ids: Vec<i64> = v.fits.iter().map(|f| f.0).collect();
        println!("scan {scan}: fits {ids:?} queued");
    }
    if let Some(events) = events.filter(|_| !v.fits.is_empty()) {
        follow_scan(&client, events, scan, v.fits.clone(), args.json)?;
        print_scan_result(&client.scan(scan)?, args.json)?;
    }
    Ok(())
}

/// `brdfd refit --all`: every complete scan chosen, oldest first, refitted where it lacks a fit
/// of the configuration asked for; then, unless `--detach`, the daemon's queue followed until
/// it is empty.
fn refit_all(args: &RefitArgs) -> anyhow::Result<()> {
    use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
    use std::io::IsTerminal;
    let client = args.daemon.client()?;
    let since_ms = match args.since {
        Some(day) => Some(
            jiff::tz::TimeZone::try_system()
                .unwrap_or(jiff::tz::TimeZone::UTC)
                .to_timestamp(day.to_datetime(jiff::civil::Time::midnight()))?
                .as_millisecond(),
        ),
        None => None,
    };
    // Every page of complete scans, newest first, then oldest first for the run.
    let mut chosen = Vec::new();
    let mut before = None;
    loop {
        const PAGE: u32 = 500;
        let page = client.scans(&crate::wire::ScanQuery {
            state: Some("complete".into()),
            sample: None,
            sample_contains: args.sample.clone(),
            limit: Some(PAGE),
            before,
        })?;
        let full = page.len() as u32 == PAGE;
        before = page.last().map(|r| r.id.0);
        chosen.extend(
            page.into_iter()
                .filter(|r| since_ms.is_none_or(|t| r.requested_at_ms >= t))
                .map(|r| (r.id, r.sample)),
        );
        if !full {
            break;
        }
    }
    chosen.reverse();
    let request = request(args);
    let tty = std::io::stderr().is_terminal() && !args.json;
    // A bar on the terminal only (never in --json or a pipe).
    let new_bar = |len: usize, prefix: &'static str| {
        let bar = ProgressBar::with_draw_target(
            Some(len as u64),
            if tty {
                ProgressDrawTarget::stderr()
            } else {
                ProgressDrawTarget::hidden()
            },
        );
        bar.set_style(
            ProgressStyle::with_template("{prefix:<12} [{bar:30}] {pos}/{len} {msg}")
                .unwrap_or_else(|_| ProgressStyle::default_bar())
                .progress_chars("=> "),
        );
        bar.set_prefix(prefix);
        bar
    };
    let bar = new_bar(chosen.len(), "scans");
    let (mut queued, mut current, mut refused) = (Vec::new(), 0usize, Vec::new());
    for (scan, sample) in &chosen {
        bar.set_message(super::operator::terminal_safe(sample));
        match client.refit(*scan, &request) {
            Ok(v) if v.fits.is_empty() => current += 1,
            Ok(v) => queued.extend(v.fits),
            // A scan that cannot be refitted (a stale reference, say) does not stop the rest.
            Err(
                e @ crate::client::ClientError::Refused {
                    status: 400 | 404 | 409 | 422,
                    ..
                },
            ) => {
                refused.push(format!(
                    "scan {scan} ({}): {e}",
                    super::operator::terminal_safe(sample)
                ));
            }
            Err(e) => return Err(e.into()),
        }
        bar.inc(1);
    }
    bar.finish_and_clear();
    let summary = serde_json::json!({
        "scans": chosen.len(),
        "queued_fits": queued.iter().map(|f| f.0).collect::<Vec<_>>(),
        "scans_already_current": current,
        "refused": refused,
    });
    if args.json {
        println!("{}", tagged("accepted", &summary)?);
    } else {
        println!(
            "{} scans: {} fits queued, {} scans already had these fits{}",
            chosen.len(),
            queued.len(),
            current,
            if refused.is_empty() {
                String::new()
            } else {
                format!(", {} refused:", refused.len())
            }
        );
        for r in &refused {
            println!("  {r}");
        }
    }
    if !args.detach && !queued.is_empty() {
        // The daemon's queue, followed until it is empty (these fits, and any others).
        let wait = new_bar(queued.len(), "fits");
        loop {
            let s = client.status()?;
            let left = (s.fits_queued + s.fits_running).min(queued.len());
            wait.set_position((queued.len() - left) as u64);
            wait.set_message(format!(
                "{} running, {} queued",
                s.fits_running, s.fits_queued
            ));
            if s.fits_queued + s.fits_running == 0 {
                break;
            }
            std::thread::sleep(std::time::Duration::from_millis(500));
        }
        wait.finish_and_clear();
        if !args.json {
            println!("every queued fit has ended (`brdfd scans`, `brdfd show SCAN` for each)");
        }
    }
    if !refused.is_empty() {
        anyhow::bail!(
            "{} of {} scans were refused (listed above); the others were refitted",
            refused.len(),
            chosen.len()
        );
    }
    Ok(())
}
