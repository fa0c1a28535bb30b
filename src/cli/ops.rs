//! The operator commands that talk to a running daemon over its HTTP API ([`crate::client`]):
//! `reference`, `scan`, `scans`, `show`, `refit`, `abort`, `status`, `export`, `import`.
//!
//! `reference` and `scan` subscribe to the event stream before asking, then show progress per
//! reading and per fit (`indicatif` bars on a terminal, one line per step otherwise) until the
//! scan and its fits have ended. Refusals print the daemon's message as it is ("the
//! instruments are busy: scan 12 is in progress …"); no daemon gives "no brdfd daemon is
//! listening on … — start one with `brdfd serve`".

use std::io::IsTerminal;
use std::net::SocketAddr;
use std::path::PathBuf;

use anyhow::{Context, bail};
use indicatif::{MultiProgress, ProgressBar, ProgressDrawTarget, ProgressStyle};
use serde_json::{Value, json};

use crate::client::{Client, DEFAULT_ADDR};
use crate::cost::CostFunction;
use crate::optimise::Method;

/// Where the daemon is.
#[derive(Debug, Clone, clap::Args)]
pub struct DaemonArgs {
    /// The daemon's API address ([api] listen of its configuration).
    #[arg(long, value_name = "IP:PORT", default_value = DEFAULT_ADDR)]
    pub addr: SocketAddr,
}

impl DaemonArgs {
    fn client(&self) -> Client {
        Client::new(self.addr)
    }
}

#[derive(Debug, clap::Args)]
pub struct ReferenceArgs {
    #[command(flatten)]
    pub daemon: DaemonArgs,
    /// Return once the daemon has accepted the request, without following progress.
    #[arg(long)]
    pub detach: bool,
}

#[derive(Debug, clap::Args)]
pub struct ScanArgs {
    #[command(flatten)]
    pub daemon: DaemonArgs,
    /// The sample's name, e.g. "T.Sky blue".
    #[arg(long, value_name = "NAME")]
    pub sample: String,
    /// Return once the daemon has accepted the request, without following progress.
    #[arg(long)]
    pub detach: bool,
}

#[derive(Debug, clap::Args)]
pub struct ScansArgs {
    #[command(flatten)]
    pub daemon: DaemonArgs,
    /// Only scans in this state: requested, measuring, complete, failed, aborted.
    #[arg(long, value_name = "STATE")]
    pub state: Option<String>,
    /// Only scans of this sample.
    #[arg(long, value_name = "NAME")]
    pub sample: Option<String>,
    /// At most this many.
    #[arg(long, value_name = "N", default_value_t = 50)]
    pub limit: u32,
    /// Print the daemon's JSON.
    #[arg(long)]
    pub json: bool,
}

#[derive(Debug, clap::Args)]
pub struct ShowArgs {
    #[command(flatten)]
    pub daemon: DaemonArgs,
    /// The scan's id (see `brdfd scans`).
    #[arg(value_name = "SCAN")]
    pub scan: i64,
    /// Print the daemon's JSON (every reading, raw frames in hex, every fit).
    #[arg(long)]
    pub json: bool,
    /// Also write each finished fit's sphere preview (`GET /fits/{id}/preview.png`) into DIR
    /// as `fit-<id>-<cost>.png` (see `brdfd render --help` for what the picture shows).
    #[arg(long, value_name = "DIR")]
    pub preview: Option<std::path::PathBuf>,
}

#[derive(Debug, clap::Args)]
pub struct RefitArgs {
    #[command(flatten)]
    pub daemon: DaemonArgs,
    /// The scan's id.
    #[arg(value_name = "SCAN")]
    pub scan: i64,
    /// Cost functions to fit (repeat or separate with commas); default: the configured ones.
    #[arg(long, value_name = "cf1|cf2|m2", value_delimiter = ',')]
    pub cost: Vec<CostFunction>,
    /// Optimiser; default: the configured one.
    #[arg(long, value_name = "NAME")]
    pub method: Option<Method>,
    /// Seed; default: the configured one.
    #[arg(long, value_name = "N")]
    pub seed: Option<u64>,
    /// Fit even though the scan's reference is older than the configured limit.
    #[arg(long)]
    pub allow_stale_reference: bool,
    /// Return once queued, without following progress.
    #[arg(long)]
    pub detach: bool,
}

#[derive(Debug, clap::Args)]
pub struct ExportArgs {
    #[command(flatten)]
    pub daemon: DaemonArgs,
    /// The scan's id.
    #[arg(value_name = "SCAN")]
    pub scan: i64,
    /// Write here instead of stdout.
    #[arg(long, short, value_name = "FILE")]
    pub output: Option<PathBuf>,
}

#[derive(Debug, clap::Args)]
pub struct ImportArgs {
    #[command(flatten)]
    pub daemon: DaemonArgs,
    /// A brdfd.scan/1 file.
    #[arg(value_name = "FILE")]
    pub file: PathBuf,
    /// Return once imported, without following the fits.
    #[arg(long)]
    pub detach: bool,
}

/// A date and time in UTC from milliseconds since the Unix epoch, e.g. `2026-11-24 19:14:14Z`.
pub fn utc(ms: i64) -> String {
    crate::formats::rfc3339_utc(ms.div_euclid(1000)).replacen('T', " ", 1)
}

fn id(v: &Value, key: &str) -> i64 {
    v.get(key).and_then(Value::as_i64).unwrap_or(-1)
}

fn f(v: &Value, key: &str) -> f64 {
    v.get(key).and_then(Value::as_f64).unwrap_or(f64::NAN)
}

fn s<'a>(v: &'a Value, key: &str) -> &'a str {
    v.get(key).and_then(Value::as_str).unwrap_or("")
}

/// Progress display: bars on a terminal, plain lines otherwise.
struct Progress {
    bars: MultiProgress,
    tty: bool,
}

impl Progress {
    fn new() -> Progress {
        let tty = std::io::stderr().is_terminal();
        let bars = MultiProgress::with_draw_target(if tty {
            ProgressDrawTarget::stderr()
        } else {
            ProgressDrawTarget::hidden()
        });
        Progress { bars, tty }
    }

    fn line(&self, text: &str) {
        if self.tty {
            let _ = self.bars.println(text);
        } else {
            println!("{text}");
        }
    }

    fn bar(&self, len: u64, prefix: String) -> ProgressBar {
        let bar = self.bars.add(ProgressBar::new(len));
        bar.set_style(
            ProgressStyle::with_template("{prefix:<22} [{bar:30}] {pos}/{len} {msg}")
                .unwrap_or_else(|_| ProgressStyle::default_bar())
                .progress_chars("=> "),
        );
        bar.set_prefix(prefix);
        bar
    }
}

/// Follows a reference (`reference`) or a scan (`scan`) and its fits on the event stream
/// until everything has ended; fails if the measurement failed.
fn follow(
    client: &Client,
    events: crate::client::EventStream,
    reference: Option<i64>,
    scan: Option<i64>,
    mut fits_pending: Vec<i64>,
) -> anyhow::Result<()> {
    let p = Progress::new();
    let readings = p.bar(14, "readings".into());
    if scan.is_none() && reference.is_none() {
        readings.finish_and_clear();
    }
    let mut fit_bars: std::collections::HashMap<i64, ProgressBar> = Default::default();
    let mut measuring = scan.is_some() || reference.is_some();
    let mut failed: Option<String> = None;
    for ev in events {
        let ty = s(&ev, "type");
        let mine_scan = scan.is_some_and(|id_| id(&ev, "scan") == id_);
        let mine_ref = reference.is_some_and(|id_| id(&ev, "reference") == id_);
        match ty {
            "scan_reading" if mine_scan => {
                readings.set_position(ev["k"].as_u64().unwrap_or(0));
                readings.set_message(format!("{} {}", s(&ev, "device"), s(&ev, "geometry")));
                if !p.tty {
                    p.line(&format!(
                        "reading {}/14: {} {}",
                        ev["k"],
                        s(&ev, "device"),
                        s(&ev, "geometry")
                    ));
                }
            }
            "reference_reading" if mine_ref => {
                readings.set_position(ev["k"].as_u64().unwrap_or(0));
                readings.set_message(format!("{} {}", s(&ev, "device"), s(&ev, "geometry")));
                if !p.tty {
                    p.line(&format!(
                        "reference reading {}/14: {} {}",
                        ev["k"],
                        s(&ev, "device"),
                        s(&ev, "geometry")
                    ));
                }
            }
            "scan_complete" if mine_scan => {
                readings.finish_with_message("complete");
                p.line(&format!(
                    "scan {} complete: 14 readings stored",
                    id(&ev, "scan")
                ));
                measuring = false;
                // The fits are queued right after; their events follow.
                if let Ok(detail) = client.get(&format!("/scans/{}", id(&ev, "scan"))) {
                    for fit in detail["fits"].as_array().into_iter().flatten() {
                        let status = fit["run"]["status"].as_str().unwrap_or("");
                        if matches!(status, "queued" | "running") {
                            fits_pending.push(id(&fit["run"], "id"));
                        }
                    }
                }
            }
            "reference_complete" if mine_ref => {
                readings.finish_with_message("complete");
                p.line(&format!(
                    "reference {} complete: in force for new scans",
                    id(&ev, "reference")
                ));
                return Ok(());
            }
            "scan_failed" | "scan_aborted" if mine_scan => {
                readings.abandon_with_message(ty.replace("scan_", ""));
                failed = Some(format!(
                    "scan {} {}: {}",
                    id(&ev, "scan"),
                    ty.trim_start_matches("scan_"),
                    s(&ev, "reason")
                ));
                break;
            }
            "reference_failed" if mine_ref => {
                readings.abandon_with_message("failed");
                failed = Some(format!(
                    "reference {} failed: {}",
                    id(&ev, "reference"),
                    s(&ev, "reason")
                ));
                break;
            }
            "reference_stale" | "processing_failed" if mine_scan => {
                let text = if ty == "reference_stale" {
                    format!(
                        "scan {} not fitted: its reference is {:.1} h old (limit {} h); measure a \
                         new reference (`brdfd reference`) and scan again, or `brdfd refit {} \
                         --allow-stale-reference`",
                        id(&ev, "scan"),
                        f(&ev, "age_hours"),
                        f(&ev, "max_age_hours"),
                        id(&ev, "scan")
                    )
                } else {
                    format!("scan {} not fitted: {}", id(&ev, "scan"), s(&ev, "reason"))
                };
                p.line(&text);
                if fits_pending.is_empty() {
                    break;
                }
            }
            "fit_queued" if mine_scan => {
                let fit = id(&ev, "fit");
                if !fits_pending.contains(&fit) {
                    fits_pending.push(fit);
                }
            }
            "fit_started" | "fit_progress" if mine_scan => {
                let fit = id(&ev, "fit");
                let bar = fit_bars.entry(fit).or_insert_with(|| {
                    let cost = s(&ev, "cost_function");
                    p.bar(1, format!("fit {fit} {cost}"))
                });
                if ty == "fit_progress" {
                    bar.set_length(ev["generations_total"].as_u64().unwrap_or(1));
                    bar.set_position(ev["generation"].as_u64().unwrap_or(0));
                    bar.set_message(format!("best cost {:.4e}", f(&ev, "best_cost")));
                } else if !p.tty {
                    p.line(&format!("fit {fit} ({}) started", s(&ev, "cost_function")));
                }
            }
            "fit_done" | "fit_failed" | "fit_cancelled" if mine_scan => {
                let fit = id(&ev, "fit");
                let text = match ty {
                    "fit_done" => format!(
                        "fit {fit} ({}) done: mean ΔE00 {:.3} (diffuse {:.3}, specular {:.3}), \
                         cost {:.4e}, {:.0} ms",
                        s(&ev, "cost_function"),
                        f(&ev, "delta_e00_mean"),
                        f(&ev, "delta_e00_diffuse_mean"),
                        f(&ev, "delta_e00_specular_mean"),
                        f(&ev, "cost"),
                        f(&ev, "wall_ms")
                    ),
                    "fit_failed" => format!("fit {fit} failed: {}", s(&ev, "error")),
                    _ => format!("fit {fit} cancelled"),
                };
                if let Some(bar) = fit_bars.remove(&fit) {
                    bar.finish_and_clear();
                }
                p.line(&text);
                fits_pending.retain(|&x| x != fit);
                if !measuring && fits_pending.is_empty() {
                    break;
                }
            }
            "shutting_down" => {
                failed = Some("the daemon is shutting down".into());
                break;
            }
            _ => {}
        }
    }
    match failed {
        Some(reason) => bail!(reason),
        None => Ok(()),
    }
}

pub fn reference(args: &ReferenceArgs) -> anyhow::Result<()> {
    let client = args.daemon.client();
    let events = (!args.detach).then(|| client.events()).transpose()?;
    let v = client.post("/reference", None)?;
    let reference = id(&v, "reference");
    println!("reference {reference} started: measuring the Munsell N9 tile on both instruments");
    match events {
        Some(events) => follow(&client, events, Some(reference), None, Vec::new()),
        None => Ok(()),
    }
}

pub fn scan(args: &ScanArgs) -> anyhow::Result<()> {
    let client = args.daemon.client();
    let events = (!args.detach).then(|| client.events()).transpose()?;
    let v = client.post("/scans", Some(&json!({ "sample": args.sample })))?;
    let scan = id(&v, "scan");
    println!("scan {scan} started: sample \"{}\"", args.sample);
    match events {
        Some(events) => {
            follow(&client, events, None, Some(scan), Vec::new())?;
            print_fits(&client.get(&format!("/scans/{scan}"))?);
            Ok(())
        }
        None => Ok(()),
    }
}

pub fn scans(args: &ScansArgs) -> anyhow::Result<()> {
    let client = args.daemon.client();
    let mut query = format!("/scans?limit={}", args.limit);
    if let Some(state) = &args.state {
        query.push_str(&format!("&state={}", urlencode(state)));
    }
    if let Some(sample) = &args.sample {
        query.push_str(&format!("&sample={}", urlencode(sample)));
    }
    let v = client.get(&query)?;
    if args.json {
        println!("{}", serde_json::to_string_pretty(&v)?);
        return Ok(());
    }
    let rows = v.as_array().cloned().unwrap_or_default();
    if rows.is_empty() {
        println!("no scans");
        return Ok(());
    }
    println!(
        "{:>5}  {:<22} {:<9} {:>8}  {:<20}  reason",
        "id", "sample", "state", "readings", "requested (UTC)"
    );
    for r in rows {
        println!(
            "{:>5}  {:<22} {:<9} {:>8}  {:<20}  {}",
            id(&r, "id"),
            s(&r, "sample"),
            s(&r, "state"),
            id(&r, "reading_count"),
            utc(r["requested_at_ms"].as_i64().unwrap_or(0)),
            s(&r, "reason")
        );
    }
    Ok(())
}

/// A percent-encoding of a query value (sample names have spaces and dots).
fn urlencode(text: &str) -> String {
    text.bytes()
        .map(|b| match b {
            b'A'..=b'Z' | b'a'..=b'z' | b'0'..=b'9' | b'-' | b'.' | b'_' | b'~' => {
                (b as char).to_string()
            }
            _ => format!("%{b:02X}"),
        })
        .collect()
}

fn print_fits(detail: &Value) {
    let fits = detail["fits"].as_array().cloned().unwrap_or_default();
    if fits.is_empty() {
        println!("no fits");
        return;
    }
    println!(
        "{:>5}  {:<4} {:<9} {:<9} {:>11} {:>8} {:>8} {:>8} {:>9}",
        "fit", "cost", "method", "status", "cost value", "ΔE00", "diffuse", "specular", "wall ms"
    );
    for fit in fits {
        let run = &fit["run"];
        let e = &fit["evaluation"];
        let result = &run["result"];
        println!(
            "{:>5}  {:<4} {:<9} {:<9} {:>11.4e} {:>8.3} {:>8.3} {:>8.3} {:>9.1}{}",
            id(run, "id"),
            s(run, "cost_function"),
            s(run, "method"),
            s(run, "status"),
            f(result, "cost"),
            f(&e["all"], "mean"),
            f(&e["diffuse"], "mean"),
            f(&e["specular"], "mean"),
            f(result, "wall_ms"),
            run["error"]
                .as_str()
                .map(|e| format!("  {e}"))
                .unwrap_or_default()
        );
    }
}

pub fn show(args: &ShowArgs) -> anyhow::Result<()> {
    let client = args.daemon.client();
    let v = client.get(&format!("/scans/{}", args.scan))?;
    if args.json {
        println!("{}", serde_json::to_string_pretty(&v)?);
        return Ok(());
    }
    let scan = &v["scan"];
    println!(
        "scan {}: sample \"{}\", {}{}",
        id(scan, "id"),
        s(scan, "sample"),
        s(scan, "state"),
        scan["reason"]
            .as_str()
            .map(|r| format!(" ({r})"))
            .unwrap_or_default()
    );
    println!(
        "requested {}, {} of 14 readings",
        utc(scan["requested_at_ms"].as_i64().unwrap_or(0)),
        scan["reading_count"]
    );
    let reference = &v["reference"]["reference"];
    println!(
        "reference {} ({}), measured {:.1} h before the scan{}",
        id(reference, "id"),
        s(reference, "name"),
        f(&v, "reference_age_hours"),
        if v["reference_stale"].as_bool() == Some(true) {
            " — older than the configured limit: not fitted automatically"
        } else {
            ""
        }
    );
    for r in v["readings"].as_array().into_iter().flatten() {
        let values = &r["values"];
        let text = match values.as_array() {
            Some(a) => format!(
                "reflectance 400 nm {:.4}, 550 nm {:.4}, 700 nm {:.4}",
                a.first().and_then(Value::as_f64).unwrap_or(f64::NAN),
                a.get(15).and_then(Value::as_f64).unwrap_or(f64::NAN),
                a.get(30).and_then(Value::as_f64).unwrap_or(f64::NAN)
            ),
            None => format!("intensity {:.4}", values.as_f64().unwrap_or(f64::NAN)),
        };
        println!("  {:<7} {:<9} {text}", s(r, "device"), s(r, "geometry"));
    }
    print_fits(&v);
    if let Some(dir) = &args.preview {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
        for fit in v["fits"].as_array().into_iter().flatten() {
            let run = &fit["run"];
            if run["status"] != "done" {
                continue;
            }
            let path = dir.join(format!(
                "fit-{}-{}.png",
                id(run, "id"),
                s(run, "cost_function")
            ));
            let png = client.get_bytes(&format!("/fits/{}/preview.png", id(run, "id")))?;
            std::fs::write(&path, png).with_context(|| format!("writing {}", path.display()))?;
            println!("preview {}", path.display());
        }
    }
    Ok(())
}

pub fn refit(args: &RefitArgs) -> anyhow::Result<()> {
    let client = args.daemon.client();
    let events = (!args.detach).then(|| client.events()).transpose()?;
    let body = json!({
        "cost_functions": args.cost,
        "method": args.method,
        "seed": args.seed,
        "allow_stale_reference": args.allow_stale_reference,
    });
    let v = client.post(&format!("/scans/{}/refit", args.scan), Some(&body))?;
    let fits: Vec<i64> = v["fits"]
        .as_array()
        .into_iter()
        .flatten()
        .filter_map(Value::as_i64)
        .collect();
    println!("scan {}: fits {fits:?} queued", args.scan);
    if let Some(events) = events {
        follow(&client, events, None, Some(args.scan), fits)?;
        print_fits(&client.get(&format!("/scans/{}", args.scan))?);
    }
    Ok(())
}

pub fn abort(args: &DaemonArgs) -> anyhow::Result<()> {
    let v = args.client().post("/abort", None)?;
    let op = &v["aborted"];
    match s(op, "kind") {
        "scan" => println!(
            "scan {} aborting; its readings so far are kept",
            id(op, "scan")
        ),
        _ => println!("reference {} aborting", id(op, "reference")),
    }
    Ok(())
}

pub fn status(args: &DaemonArgs) -> anyhow::Result<()> {
    let v = args.client().get("/status")?;
    println!("brdfd {} on {}", s(&v, "version"), args.addr);
    match v["busy"].as_object() {
        Some(b) => {
            let op = &b["operation"];
            let what = if s(op, "kind") == "scan" {
                format!("scan {}", id(op, "scan"))
            } else {
                format!("reference {}", id(op, "reference"))
            };
            println!(
                "measuring: {what} for {:.0} s",
                b["seconds"].as_f64().unwrap_or(0.0)
            );
        }
        None => println!("instruments idle"),
    }
    match v["reference"].as_object() {
        Some(r) => println!(
            "reference in force: {} ({}), {:.1} h old{}",
            r["id"],
            r["name"].as_str().unwrap_or(""),
            r["age_hours"].as_f64().unwrap_or(0.0),
            if r["stale"].as_bool() == Some(true) {
                " — too old: measure a new one with `brdfd reference`"
            } else {
                ""
            }
        ),
        None => println!("no reference measured yet: run `brdfd reference`"),
    }
    println!(
        "fits: {} queued, {} running; instruments simulated: MA-T12 {}, SRA {}",
        v["fits_queued"], v["fits_running"], v["simulated"]["ma_t12"], v["simulated"]["sra"]
    );
    Ok(())
}

pub fn export(args: &ExportArgs) -> anyhow::Result<()> {
    let text = args
        .daemon
        .client()
        .get_text(&format!("/scans/{}/export", args.scan))?;
    match &args.output {
        Some(path) => {
            std::fs::write(path, text.as_bytes())
                .with_context(|| format!("cannot write {}", path.display()))?;
            eprintln!("scan {} written to {}", args.scan, path.display());
        }
        None => println!("{text}"),
    }
    Ok(())
}

pub fn import(args: &ImportArgs) -> anyhow::Result<()> {
    let text = std::fs::read_to_string(&args.file)
        .with_context(|| format!("cannot read {}", args.file.display()))?;
    // Checked here too, so a bad file is named with its path before anything is sent.
    crate::scan::Scan::from_json(text.as_bytes())
        .with_context(|| format!("{}", args.file.display()))?;
    let client = args.daemon.client();
    let events = (!args.detach).then(|| client.events()).transpose()?;
    let v = client.post_text("/scans/import", &text)?;
    let scan = id(&v, "scan");
    let fits: Vec<i64> = v["fits"]
        .as_array()
        .into_iter()
        .flatten()
        .filter_map(Value::as_i64)
        .collect();
    println!(
        "{} imported as scan {scan}; fits {fits:?} queued",
        args.file.display()
    );
    if let Some(events) = events {
        if !fits.is_empty() {
            // Fits may already have finished before the stream saw them: check first.
            let pending = pending_fits(&client, scan)?;
            if !pending.is_empty() {
                follow(&client, events, None, Some(scan), pending)?;
            }
        }
        print_fits(&client.get(&format!("/scans/{scan}"))?);
    }
    Ok(())
}

fn pending_fits(client: &Client, scan: i64) -> anyhow::Result<Vec<i64>> {
    let detail = client.get(&format!("/scans/{scan}"))?;
    Ok(detail["fits"]
        .as_array()
        .into_iter()
        .flatten()
        .filter(|f| matches!(f["run"]["status"].as_str(), Some("queued" | "running")))
        .map(|f| id(&f["run"], "id"))
        .collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn utc_formats_known_instants() {
        assert_eq!(utc(0), "1970-01-01 00:00:00Z");
        // 2000-02-29 12:34:56 UTC = 951827696 s.
        assert_eq!(utc(951_827_696_000), "2000-02-29 12:34:56Z");
        // 2026-11-24 19:14:14 UTC = 1795547654 s.
        assert_eq!(utc(1_795_547_654_000), "2026-11-24 19:14:14Z");
    }

    #[test]
    fn query_values_are_percent_encoded() {
        assert_eq!(urlencode("T.Sky blue"), "T.Sky%20blue");
        assert_eq!(urlencode("a&b=c"), "a%26b%3Dc");
    }
}
