//! Following a reference, a scan or a scan's fits on the daemon's event stream (`GET /events`)
//! until everything has ended: progress per reading and per fit (`indicatif` bars on a
//! terminal, one line per step otherwise), or the events themselves as NDJSON with `--json`.
//! Used by `reference`, `scan`, `refit` and `import`.

use std::io::IsTerminal;

use anyhow::bail;
use indicatif::{MultiProgress, ProgressBar, ProgressDrawTarget, ProgressStyle};
use serde_json::{Value, json};

use super::operator::{f, id, s};
use crate::client::Client;

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
pub(super) fn follow(
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
/// The end of a followed scan: its fits as a table, or `{"type":"result","scan":…}`.
pub(super) fn print_scan_result(detail: &Value, json: bool) {
    if json {
        println!("{}", json!({ "type": "result", "scan": detail }));
    } else {
        super::show::print_fits(detail);
    }
}
