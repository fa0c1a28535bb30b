//! Following a reference, a scan or a scan's fits on the daemon's event stream (`GET /events`)
//! until everything has ended: progress per reading and per fit (`indicatif` bars on a
//! terminal, one line per step otherwise), or the events themselves as NDJSON with `--json`.
//! Used by `reference`, `scan`, `refit` and `import`.

use std::collections::HashMap;
use std::io::IsTerminal;

use super::operator::{json_line, terminal_safe};
use crate::client::{Client, EventStream};
use crate::service::Event;
use crate::store::{FitRunId, ReferenceId, ScanId};
use crate::wire::ScanView;
use anyhow::bail;
use indicatif::{MultiProgress, ProgressBar, ProgressDrawTarget, ProgressStyle};
use serde::Deserialize;

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

/// What is followed: a reference being measured, or a scan (being measured, or only its fits
/// after a refit or an import).
#[derive(Debug, Clone, Copy)]
enum Followed {
    Reference(ReferenceId),
    Scan(ScanId),
}

/// What one event did to the following.
enum Step {
    /// Keep reading events.
    Continue,
    /// Everything followed has ended well.
    Finished,
    /// The measurement failed: the reason.
    Failed(String),
    /// The daemon said it is shutting down.
    DaemonStopping,
}

/// The daemon went away under a followed operation (its event stream closed before the end,
/// or it said it was shutting down): exit status 3, no daemon, as a refused connection.
#[derive(Debug, thiserror::Error)]
#[error("{why} before {what} ended; {advice}")]
pub struct DaemonGone {
    /// What happened, as seen from the client.
    why: String,
    /// `scan 49`, `reference 3`.
    what: String,
    /// Where to look now.
    advice: String,
}

/// The state of a following: what is followed, what is still running, the display.
struct Follower<'a> {
    client: &'a Client,
    followed: Followed,
    progress: Progress,
    readings: ProgressBar,
    fit_bars: HashMap<FitRunId, ProgressBar>,
    fits_pending: Vec<FitRunId>,
    /// A reference or scan is being measured; false once it is complete, or from the start
    /// when only fits are followed.
    measuring: bool,
}

impl Follower<'_> {
    /// Whether `event` is about what is followed (and so is printed in NDJSON mode).
    fn concerns(&self, event: &Event) -> bool {
        match self.followed {
            Followed::Scan(scan) => event.scan() == Some(scan),
            Followed::Reference(reference) => event.reference() == Some(reference),
        }
    }

    /// The one transition: moves the display and the state on by `event`, and says whether
    /// the following goes on.
    fn on_event(&mut self, event: &Event) -> Step {
        let (p, readings) = (&self.progress, &self.readings);
        let mine = self.concerns(event);
        match event {
            Event::ScanReading {
                device,
                geometry,
                k,
                n,
                ..
            } if mine => self.reading("reading", device, geometry, *k, *n),
            Event::ReferenceReading {
                device,
                geometry,
                k,
                n,
                ..
            } if mine => self.reading("reference reading", device, geometry, *k, *n),
            Event::ScanComplete { scan } if mine => {
                readings.finish_with_message("complete");
                let stored = readings.position();
                p.line(&format!("scan {scan} complete: {stored} readings stored"));
                self.measuring = false;
                // The fits are queued right after; their events follow.
                if let Ok(pending) = pending_fits(self.client, *scan) {
                    self.fits_pending.extend(pending);
                }
            }
            Event::ReferenceComplete { reference } if mine => {
                readings.finish_with_message("complete");
                p.line(&format!(
                    "reference {reference} complete: in force for new scans"
                ));
                return Step::Finished;
            }
            Event::ScanFailed { scan, reason } if mine => {
                readings.abandon_with_message("failed");
                let reason = terminal_safe(reason);
                return Step::Failed(format!("scan {scan} failed: {reason}"));
            }
            Event::ScanAborted { scan, reason } if mine => {
                readings.abandon_with_message("aborted");
                let reason = terminal_safe(reason);
                return Step::Failed(format!("scan {scan} aborted: {reason}"));
            }
            Event::ReferenceFailed { reference, reason } if mine => {
                readings.abandon_with_message("failed");
                let reason = terminal_safe(reason);
                return Step::Failed(format!("reference {reference} failed: {reason}"));
            }
            Event::ReferenceStale {
                scan,
                age_hours,
                max_age_hours,
                ..
            } if self.follows_scan(*scan) => {
                p.line(&stale_reference_line(*scan, *age_hours, *max_age_hours));
                return self.not_fitted();
            }
            Event::ProcessingFailed { scan, reason } if self.follows_scan(*scan) => {
                let reason = terminal_safe(reason);
                p.line(&format!("scan {scan} not fitted: {reason}"));
                return self.not_fitted();
            }
            Event::FitQueued { fit, .. } if mine && !self.fits_pending.contains(fit) => {
                self.fits_pending.push(*fit);
            }
            Event::FitStarted {
                fit, cost_function, ..
            } if mine => {
                let cost = terminal_safe(cost_function.name());
                self.fit_bars
                    .entry(*fit)
                    .or_insert_with(|| p.bar(1, format!("fit {fit} {cost}")));
                if !p.tty {
                    p.line(&format!("fit {fit} ({cost}) started"));
                }
            }
            Event::FitProgress {
                fit,
                generation,
                generations_total,
                best_cost,
                ..
            } if mine => {
                // A progress event before the start event names no cost function: the bar's
                // prefix then has an empty one, as the stream gave nothing better.
                let bar = self
                    .fit_bars
                    .entry(*fit)
                    .or_insert_with(|| p.bar(1, format!("fit {fit} ")));
                bar.set_length(u64::from(*generations_total));
                bar.set_position(u64::from(*generation));
                bar.set_message(format!("best cost {best_cost:.4e}"));
            }
            Event::FitDone {
                fit,
                cost_function,
                cost,
                delta_e00_mean,
                delta_e00_diffuse_mean,
                delta_e00_specular_mean,
                wall_ms,
                ..
            } if mine => {
                let specular = if delta_e00_specular_mean.is_nan() {
                    "none: no specular readings".to_string()
                } else {
                    format!("{delta_e00_specular_mean:.3} vs the paper's grey spectrum")
                };
                let text = format!(
                    "fit {fit} ({}) done: mean ΔE00 {delta_e00_mean:.3} (diffuse \
                     {delta_e00_diffuse_mean:.3}, specular {specular}), cost \
                     {cost:.4e}, {wall_ms:.0} ms",
                    terminal_safe(cost_function.name())
                );
                return self.fit_ended(*fit, &text);
            }
            Event::FitFailed { fit, error, .. } if mine => {
                let text = format!("fit {fit} failed: {}", terminal_safe(error));
                return self.fit_ended(*fit, &text);
            }
            Event::FitCancelled { fit, .. } if mine => {
                return self.fit_ended(*fit, &format!("fit {fit} cancelled"));
            }
            Event::ShuttingDown => return Step::DaemonStopping,
            _ => {}
        }
        Step::Continue
    }

    /// Reading `k` of `n` (14, or 12 with the SRA turned off) stored: the bar moves, and
    /// without a terminal a line says so.
    fn reading(&self, label: &str, device: &str, geometry: &str, k: usize, n: usize) {
        let (device, geometry) = (terminal_safe(device), terminal_safe(geometry));
        self.readings.set_length(n as u64);
        self.readings.set_position(k as u64);
        self.readings.set_message(format!("{device} {geometry}"));
        if !self.progress.tty {
            self.progress
                .line(&format!("{label} {k}/{n}: {device} {geometry}"));
        }
    }

    /// Whether a scan is followed and it is `scan`.
    fn follows_scan(&self, scan: ScanId) -> bool {
        matches!(self.followed, Followed::Scan(followed) if followed == scan)
    }

    /// The followed scan will not be fitted: done, unless fits named up front still run.
    fn not_fitted(&self) -> Step {
        if self.fits_pending.is_empty() {
            Step::Finished
        } else {
            Step::Continue
        }
    }

    /// Fit `fit` has ended with `text`: done when nothing is measured and no fit is pending.
    fn fit_ended(&mut self, fit: FitRunId, text: &str) -> Step {
        if let Some(bar) = self.fit_bars.remove(&fit) {
            bar.finish_and_clear();
        }
        self.progress.line(text);
        self.fits_pending.retain(|&x| x != fit);
        if !self.measuring && self.fits_pending.is_empty() {
            Step::Finished
        } else {
            Step::Continue
        }
    }

    /// The error for a daemon gone before the end: `stopping` (it said so), or the event
    /// stream closed; then whether it still answers tells a stopped daemon from a broken
    /// connection.
    fn daemon_gone(&self, stopping: bool) -> DaemonGone {
        let what = match self.followed {
            Followed::Scan(scan) => format!("scan {scan}"),
            Followed::Reference(r) => format!("reference {r}"),
        };
        let see = match self.followed {
            Followed::Scan(scan) => format!("`brdfd show {scan}`"),
            Followed::Reference(_) => "`brdfd status`".to_string(),
        };
        let addr = self.client.addr();
        let answers = !stopping && self.client.health().is_ok();
        let (why, advice) = if answers {
            (
                format!(
                    "the connection to the daemon broke (its event stream closed; the daemon \
                     still answers on {addr})"
                ),
                format!("it goes on without this command: {see}"),
            )
        } else {
            (
                if stopping {
                    "the daemon stopped: it is shutting down".to_string()
                } else {
                    format!(
                        "the daemon stopped: its event stream closed and nothing answers on \
                         {addr} any more"
                    )
                },
                format!(
                    "start it again (`systemctl start brdfd`, or `brdfd serve`), then {see} \
                     says what became of it (a measurement the daemon stopped under is marked \
                     failed or aborted, its readings kept; unfinished fits are queued again)"
                ),
            )
        };
        DaemonGone { why, what, advice }
    }
}

/// Why scan `scan` was not fitted: its reference is too old, and what to do.
fn stale_reference_line(scan: ScanId, age_hours: f64, max_age_hours: f64) -> String {
    format!(
        "scan {scan} not fitted: its reference is {age_hours:.1} h old (limit {max_age_hours} \
         h); measure a new reference (`brdfd reference`) and scan again, or `brdfd refit \
         {scan} --allow-stale-reference`"
    )
}

/// Follows reference `reference` on the event stream until it has ended; fails if the
/// measurement failed.
pub(super) fn follow_reference(
    client: &Client,
    events: EventStream,
    reference: ReferenceId,
    json: bool,
) -> anyhow::Result<()> {
    follow(
        client,
        events,
        Followed::Reference(reference),
        Vec::new(),
        json,
    )
}

/// Follows scan `scan` on the event stream: its measurement and then its fits when `fits` is
/// empty, else only the fits `fits` (a refit or an import). Fails if the measurement failed.
pub(super) fn follow_scan(
    client: &Client,
    events: EventStream,
    scan: ScanId,
    fits: Vec<FitRunId>,
    json: bool,
) -> anyhow::Result<()> {
    follow(client, events, Followed::Scan(scan), fits, json)
}

/// Feeds every event to one [`Follower`] until it says the following is over. In NDJSON mode
/// the events about what is followed (and `shutting_down`) go to stdout as the daemon sent them.
fn follow(
    client: &Client,
    events: EventStream,
    followed: Followed,
    fits_pending: Vec<FitRunId>,
    json: bool,
) -> anyhow::Result<()> {
    let progress = Progress::new(json);
    let readings = progress.bar(14, "readings".into());
    // Fits named up front mean a refit or an import: nothing is measured, and following ends
    // when they have. Otherwise a reference or scan is being measured.
    let measuring = fits_pending.is_empty();
    let mut follower = Follower {
        client,
        followed,
        progress,
        readings,
        fit_bars: HashMap::new(),
        fits_pending,
        measuring,
    };
    for raw in events {
        let event = Event::deserialize(&raw).unwrap_or(Event::Unknown);
        if json && (follower.concerns(&event) || event == Event::ShuttingDown) {
            println!("{raw}");
        }
        match follower.on_event(&event) {
            Step::Continue => {}
            Step::Finished => return Ok(()),
            Step::Failed(reason) => bail!(reason),
            Step::DaemonStopping => return Err(follower.daemon_gone(true).into()),
        }
    }
    // An event stream that closes before the end is a lost daemon (restarted, killed, or the
    // connection cut), not a success.
    Err(follower.daemon_gone(false).into())
}

/// The fits of scan `scan` still queued or running, from its detail.
pub(super) fn pending_fits(client: &Client, scan: ScanId) -> anyhow::Result<Vec<FitRunId>> {
    Ok(client.scan(scan)?.pending_fits())
}

/// The end of a followed scan: its fits as a table, or `{"type":"result","scan":…}`.
pub(super) fn print_scan_result(detail: &ScanView, json: bool) -> anyhow::Result<()> {
    if json {
        #[derive(serde::Serialize)]
        struct Outcome<'a> {
            #[serde(rename = "type")]
            kind: &'static str,
            scan: &'a ScanView,
        }
        println!(
            "{}",
            json_line(&Outcome {
                kind: "result",
                scan: detail
            })?
        );
    } else {
        super::show::print_fits(detail);
    }
    Ok(())
}
