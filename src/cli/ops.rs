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

use crate::client::Client;
use crate::cost::CostFunction;
use crate::optimise::Method;

/// Where the daemon is, and its API token.
#[derive(Debug, Clone, clap::Args)]
pub struct DaemonArgs {
    /// The daemon's API address [default: [api] listen of the configuration, else
    /// 127.0.0.1:7878].
    #[arg(long, value_name = "IP:PORT")]
    pub addr: Option<SocketAddr>,
    /// The file holding the daemon's API token [default: [api] token_file of the
    /// configuration, else brdfd.token beside its store (./brdfd.token without one)]. The
    /// BRDFD_TOKEN environment variable, when set, is used instead of any file.
    #[arg(long, value_name = "FILE")]
    pub token_file: Option<PathBuf>,
    /// The daemon's configuration file, for its address and token file.
    #[arg(long, short, value_name = "FILE", env = "BRDFD_CONFIG")]
    pub config: Option<PathBuf>,
}

impl DaemonArgs {
    fn config(&self) -> anyhow::Result<crate::config::Config> {
        Ok(crate::config::Config::load_or_default(
            self.config.as_deref(),
        )?)
    }

    /// The address asked for: `--addr`, else the configuration's.
    pub fn addr(&self) -> anyhow::Result<SocketAddr> {
        match self.addr {
            Some(a) => Ok(a),
            None => Ok(self.config()?.api.listen),
        }
    }

    /// A client with the token from BRDFD_TOKEN, `--token-file` or the configuration. A token
    /// that cannot be read is not an error yet: the daemon's 401, if it comes, says why.
    pub fn client(&self) -> anyhow::Result<Client> {
        let config = self.config()?;
        let addr = self.addr.unwrap_or(config.api.listen);
        let client = Client::new(addr);
        if let Ok(text) = std::env::var("BRDFD_TOKEN") {
            return match crate::api::Token::parse(&text) {
                Some(t) => Ok(client.with_token(&t, "sent the token of BRDFD_TOKEN")),
                None => bail!(
                    "BRDFD_TOKEN does not hold an API token (64 hex digits); unset it to use the token file"
                ),
            };
        }
        let path = self
            .token_file
            .clone()
            .unwrap_or_else(|| config.api.token_path(&config.store.path));
        Ok(match crate::api::Token::read(&path) {
            Ok(t) => client.with_token(&t, format!("sent the token of {}", path.display())),
            Err(e) => client.without_token(format!(
                "sent no token: {e}; pass --token-file, --config or BRDFD_TOKEN"
            )),
        })
    }
}

#[derive(Debug, clap::Args)]
pub struct ReferenceArgs {
    #[command(flatten)]
    pub daemon: DaemonArgs,
    /// Return once the daemon has accepted the request, without following progress.
    #[arg(long)]
    pub detach: bool,
    /// NDJSON on stdout: the daemon's answer, then each of its events about this reference
    /// (`GET /events` objects), one per line.
    #[arg(long)]
    pub json: bool,
}

/// `brdfd status` and `brdfd abort`.
#[derive(Debug, clap::Args)]
pub struct StatusArgs {
    #[command(flatten)]
    pub daemon: DaemonArgs,
    /// Print the daemon's JSON answer.
    #[arg(long)]
    pub json: bool,
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
    /// NDJSON on stdout: the daemon's answer, each of its events about this scan and its fits
    /// (`GET /events` objects), then `{"type":"result","scan":…}` with the scan's detail.
    #[arg(long)]
    pub json: bool,
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
    /// At most this many (1 to 500).
    #[arg(long, value_name = "N", default_value_t = 50)]
    pub limit: u32,
    /// Only scans older than scan ID: the next page after a listing whose last id was ID.
    #[arg(long, value_name = "ID")]
    pub before: Option<i64>,
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
    /// NDJSON on stdout, as for `brdfd scan --json`.
    #[arg(long)]
    pub json: bool,
}

#[derive(Debug, clap::Args)]
pub struct ExportArgs {
    #[command(flatten)]
    pub daemon: DaemonArgs,
    /// The scan's id.
    #[arg(value_name = "SCAN")]
    pub scan: i64,
    /// Write here instead of stdout (refused if it exists, unless --force).
    #[arg(long, short, value_name = "FILE")]
    pub output: Option<PathBuf>,
    /// Replace FILE if it exists.
    #[arg(long)]
    pub force: bool,
    /// With --output: print `{"scan":…,"file":…}` instead of the sentence.
    #[arg(long)]
    pub json: bool,
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
    /// NDJSON on stdout, as for `brdfd scan --json`.
    #[arg(long)]
    pub json: bool,
}

/// A date and time in UTC from milliseconds since the Unix epoch, e.g. `2026-11-24 19:14:14Z`.
pub fn utc(ms: i64) -> String {
    crate::formats::rfc3339_utc(ms.div_euclid(1000)).replacen('T', " ", 1)
}

/// A date and time in the machine's time zone (`TZ`, else `/etc/localtime`) with its UTC
/// offset, e.g. `2026-11-24 20:14:14 +01:00`, as the operator's clock shows it; UTC (`Z`) when
/// the zone cannot be read.
pub fn local_time(ms: i64) -> String {
    local_time_in(
        ms,
        &jiff::tz::TimeZone::try_system().unwrap_or(jiff::tz::TimeZone::UTC),
    )
}

/// [`local_time`] in zone `tz`.
pub fn local_time_in(ms: i64, tz: &jiff::tz::TimeZone) -> String {
    match jiff::Timestamp::from_millisecond(ms) {
        Ok(t) => t
            .to_zoned_datetime(tz.clone())
            .strftime("%Y-%m-%d %H:%M:%S %:z")
            .to_string(),
        Err(_) => utc(ms),
    }
}

fn id(v: &Value, key: &str) -> i64 {
    v.get(key).and_then(Value::as_i64).unwrap_or(-1)
}

fn f(v: &Value, key: &str) -> f64 {
    v.get(key).and_then(Value::as_f64).unwrap_or(f64::NAN)
}

/// A text field for the terminal: control characters (an escape sequence in a name stored
/// before names were checked) are shown escaped, never sent to the terminal.
fn s(v: &Value, key: &str) -> String {
    terminal_safe(v.get(key).and_then(Value::as_str).unwrap_or(""))
}

/// `text` with every control character escaped (`\u{1b}`), as it is printed.
pub fn terminal_safe(text: &str) -> String {
    if text.chars().any(char::is_control) {
        text.chars()
            .map(|c| {
                if c.is_control() {
                    c.escape_unicode().to_string()
                } else {
                    c.to_string()
                }
            })
            .collect()
    } else {
        text.to_string()
    }
}

/// One instrument's provenance as `show` prints it.
fn instrument_line(p: &Value) -> String {
    let simulated = match p["simulated"].as_bool() {
        Some(true) => " — SIMULATED",
        Some(false) => "",
        None => " — simulated or real: not recorded",
    };
    format!(
        "{} serial {} firmware {}{simulated}",
        s(p, "model"),
        s(p, "serial"),
        s(p, "firmware")
    )
}

/// "sim" when either instrument was simulated, "?" when not recorded, "" for real ones.
fn simulated_mark(provenance: &Value) -> &'static str {
    let flags = [
        provenance["ma_t12"]["simulated"].as_bool(),
        provenance["sra"]["simulated"].as_bool(),
    ];
    if flags.contains(&Some(true)) {
        "sim"
    } else if flags.contains(&None) {
        "?"
    } else {
        ""
    }
}

/// Progress display: bars on a terminal, plain lines otherwise.
struct Progress {
    bars: MultiProgress,
    tty: bool,
    /// NDJSON mode: no bars, no sentences; the events themselves go to stdout.
    json: bool,
}

impl Progress {
    fn new(json: bool) -> Progress {
        let tty = std::io::stderr().is_terminal() && !json;
        let bars = MultiProgress::with_draw_target(if tty {
            ProgressDrawTarget::stderr()
        } else {
            ProgressDrawTarget::hidden()
        });
        Progress { bars, tty, json }
    }

    fn line(&self, text: &str) {
        if self.json {
            return;
        }
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
    json: bool,
) -> anyhow::Result<()> {
    let p = Progress::new(json);
    let readings = p.bar(14, "readings".into());
    if scan.is_none() && reference.is_none() {
        readings.finish_and_clear();
    }
    let mut fit_bars: std::collections::HashMap<i64, ProgressBar> = Default::default();
    // Fits named up front mean a refit or an import: nothing is measured, and following ends
    // when they have. Otherwise a reference or scan is being measured.
    let mut measuring = reference.is_some() || (scan.is_some() && fits_pending.is_empty());
    let mut failed: Option<String> = None;
    // Set when what was followed has ended; an event stream that closes before is a lost
    // daemon (restarted, killed, or the connection cut), not a success.
    let mut finished = false;
    for ev in events {
        let ty = s(&ev, "type");
        let mine_scan = scan.is_some_and(|id_| id(&ev, "scan") == id_);
        let mine_ref = reference.is_some_and(|id_| id(&ev, "reference") == id_);
        if p.json && (mine_scan || mine_ref || ty == "shutting_down") {
            println!("{ev}");
        }
        match ty.as_str() {
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
                    finished = true;
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
                let text = match ty.as_str() {
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
                    finished = true;
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
        None if finished => Ok(()),
        None => {
            let what = match (scan, reference) {
                (Some(scan), _) => format!("the scan goes on: `brdfd show {scan}`"),
                (None, Some(r)) => format!("reference {r} may go on: `brdfd status`"),
                (None, None) => "`brdfd status` says what the daemon is doing".into(),
            };
            bail!("lost the daemon's event stream; {what}")
        }
    }
}

pub fn reference(args: &ReferenceArgs) -> anyhow::Result<()> {
    let client = args.daemon.client()?;
    let events = (!args.detach).then(|| client.events()).transpose()?;
    let v = client.post("/reference", None)?;
    let reference = id(&v, "reference");
    if args.json {
        println!("{}", tagged("accepted", &v));
    } else {
        println!(
            "reference {reference} started: measuring the Munsell N9 tile on both instruments"
        );
    }
    match events {
        Some(events) => follow(
            &client,
            events,
            Some(reference),
            None,
            Vec::new(),
            args.json,
        ),
        None => Ok(()),
    }
}

pub fn scan(args: &ScanArgs) -> anyhow::Result<()> {
    let client = args.daemon.client()?;
    let events = (!args.detach).then(|| client.events()).transpose()?;
    let v = client.post("/scans", Some(&json!({ "sample": args.sample })))?;
    let scan = id(&v, "scan");
    if args.json {
        println!("{}", tagged("accepted", &v));
    } else {
        println!("scan {scan} started: sample \"{}\"", args.sample);
    }
    match events {
        Some(events) => {
            follow(&client, events, None, Some(scan), Vec::new(), args.json)?;
            result(&client.get(&format!("/scans/{scan}"))?, args.json);
            Ok(())
        }
        None => Ok(()),
    }
}

pub fn scans(args: &ScansArgs) -> anyhow::Result<()> {
    let client = args.daemon.client()?;
    let mut query = format!("/scans?limit={}", args.limit);
    if let Some(before) = args.before {
        query.push_str(&format!("&before={before}"));
    }
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
        "{:>5}  {:<22} {:<9} {:>8}  {:<26}  {:<4} reason",
        "id", "sample", "state", "readings", "requested (local time)", "sim"
    );
    let mut last = None;
    for r in &rows {
        println!(
            "{:>5}  {:<22} {:<9} {:>8}  {:<26}  {:<4} {}",
            id(r, "id"),
            s(r, "sample"),
            s(r, "state"),
            id(r, "reading_count"),
            local_time(r["requested_at_ms"].as_i64().unwrap_or(0)),
            simulated_mark(&r["provenance"]),
            s(r, "reason")
        );
        last = Some(id(r, "id"));
    }
    if let Some(last) = last
        && rows.len() as u32 == args.limit
    {
        eprintln!("(more may follow: `brdfd scans --before {last}`)");
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
        print_fit_extras(&fit);
    }
}

/// Under a fit's row: the colorimetry of its ΔE00 and, once the bootstrap has run, the 95 %
/// intervals of the lobe parameters (SCIENCE.md §7.1, §10).
fn print_fit_extras(fit: &Value) {
    let c = &fit["colorimetry"];
    if c.is_object() {
        println!(
            "       ΔE00 under D65/{}° {}",
            s(c, "observer"),
            s(c, "weighting")
        );
    }
    let u = &fit["uncertainty"];
    if u.is_object() {
        let iv = |k: &str| {
            format!(
                "[{:.4}, {:.4}]",
                u[k][0].as_f64().unwrap_or(f64::NAN),
                u[k][1].as_f64().unwrap_or(f64::NAN)
            )
        };
        println!(
            "       95 % intervals ({} resamples): ks {}  alpha {}  ior {}  ΔE00 mean {}",
            u["resamples"],
            iv("ks"),
            iv("alpha"),
            iv("ior"),
            iv("delta_e00_mean")
        );
    }
}

pub fn show(args: &ShowArgs) -> anyhow::Result<()> {
    let client = args.daemon.client()?;
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
        local_time(scan["requested_at_ms"].as_i64().unwrap_or(0)),
        scan["reading_count"]
    );
    let provenance = &scan["provenance"];
    println!(
        "measured by: MA-T12 {}; SRA {}",
        instrument_line(&provenance["ma_t12"]),
        instrument_line(&provenance["sra"])
    );
    println!(
        "source: {}{}",
        s(provenance, "source"),
        provenance["source_detail"]
            .as_str()
            .map(|d| format!(" ({})", terminal_safe(d)))
            .unwrap_or_default()
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
    let client = args.daemon.client()?;
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
    if args.json {
        println!("{}", tagged("accepted", &v));
    } else {
        println!("scan {}: fits {fits:?} queued", args.scan);
    }
    if let Some(events) = events.filter(|_| !fits.is_empty()) {
        follow(&client, events, None, Some(args.scan), fits, args.json)?;
        result(&client.get(&format!("/scans/{}", args.scan))?, args.json);
    }
    Ok(())
}

pub fn abort(args: &StatusArgs) -> anyhow::Result<()> {
    let v = args.daemon.client()?.post("/abort", None)?;
    if args.json {
        println!("{v}");
        return Ok(());
    }
    let op = &v["aborted"];
    match s(op, "kind").as_str() {
        "scan" => println!(
            "scan {} aborting; its readings so far are kept",
            id(op, "scan")
        ),
        _ => println!("reference {} aborting", id(op, "reference")),
    }
    Ok(())
}

pub fn status(args: &StatusArgs) -> anyhow::Result<()> {
    let v = args.daemon.client()?.get("/status")?;
    if args.json {
        println!("{}", serde_json::to_string_pretty(&v)?);
        return Ok(());
    }
    println!("brdfd {} on {}", s(&v, "version"), args.daemon.addr()?);
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
    if let Some(sync) = v["sync"].as_object() {
        println!(
            "forwarding as station {} to {}: {} rows waiting, {} forwarded since start{}",
            sync["station"].as_str().unwrap_or("?"),
            sync["central"].as_str().unwrap_or("?"),
            sync["backlog"],
            sync["rows_forwarded"],
            match sync["last_error"].as_str() {
                Some(e) => format!("; last error: {e}"),
                None => String::new(),
            }
        );
    }
    if let Some(ingest) = v["ingest"].as_object() {
        println!(
            "watch folder {}: {} imported, {} rejected since start, {} waiting{}",
            ingest["dir"].as_str().unwrap_or("?"),
            ingest["imported"],
            ingest["rejected"],
            ingest["waiting"],
            match ingest["last_error"].as_str() {
                Some(e) => format!("; last error: {e}"),
                None => String::new(),
            }
        );
    }
    Ok(())
}

pub fn export(args: &ExportArgs) -> anyhow::Result<()> {
    let text = args
        .daemon
        .client()?
        .get_text(&format!("/scans/{}/export", args.scan))?;
    match &args.output {
        Some(path) => {
            super::write_new_file(path, text.as_bytes(), args.force)?;
            if args.json {
                println!("{}", json!({ "scan": args.scan, "file": path }));
            } else {
                eprintln!("scan {} written to {}", args.scan, path.display());
            }
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
    let client = args.daemon.client()?;
    let events = (!args.detach).then(|| client.events()).transpose()?;
    let v = client.post_text("/scans/import", &text)?;
    let scan = id(&v, "scan");
    let fits: Vec<i64> = v["fits"]
        .as_array()
        .into_iter()
        .flatten()
        .filter_map(Value::as_i64)
        .collect();
    if args.json {
        println!("{}", tagged("accepted", &v));
    } else {
        println!(
            "{} imported as scan {scan}; fits {fits:?} queued",
            args.file.display()
        );
    }
    if let Some(events) = events {
        if !fits.is_empty() {
            // Fits may already have finished before the stream saw them: check first.
            let pending = pending_fits(&client, scan)?;
            if !pending.is_empty() {
                follow(&client, events, None, Some(scan), pending, args.json)?;
            }
        }
        result(&client.get(&format!("/scans/{scan}"))?, args.json);
    }
    Ok(())
}

/// `value` (a JSON object) with `"type": kind` in front, as one NDJSON line.
fn tagged(kind: &str, value: &Value) -> Value {
    let mut out = serde_json::Map::new();
    out.insert("type".into(), Value::from(kind));
    if let Some(fields) = value.as_object() {
        out.extend(fields.clone());
    }
    Value::Object(out)
}

/// The end of a followed scan: its fits as a table, or `{"type":"result","scan":…}`.
fn result(detail: &Value, json: bool) {
    if json {
        println!("{}", json!({ "type": "result", "scan": detail }));
    } else {
        print_fits(detail);
    }
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
    fn local_times_carry_their_offset() {
        use jiff::tz::{Offset, TimeZone};
        let oslo = TimeZone::fixed(Offset::from_hours(1).unwrap());
        assert_eq!(
            local_time_in(1_795_547_654_000, &oslo),
            "2026-11-24 20:14:14 +01:00"
        );
        let west = TimeZone::fixed(Offset::from_seconds(-(5 * 3600 + 1800)).unwrap());
        assert_eq!(local_time_in(0, &west), "1969-12-31 18:30:00 -05:30");
        assert_eq!(
            local_time_in(0, &TimeZone::UTC),
            "1970-01-01 00:00:00 +00:00"
        );
    }

    #[test]
    fn query_values_are_percent_encoded() {
        assert_eq!(urlencode("T.Sky blue"), "T.Sky%20blue");
        assert_eq!(urlencode("a&b=c"), "a%26b%3Dc");
    }
}
