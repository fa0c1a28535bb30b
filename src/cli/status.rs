//! `brdfd status` and `brdfd abort`: what the daemon is doing, and stopping it.

use super::operator::{DaemonArgs, json_line, json_pretty, terminal_safe};
use crate::wire::Operation;

/// `brdfd status` and `brdfd abort`.
#[derive(Debug, clap::Args)]
pub struct StatusArgs {
    #[command(flatten)]
    pub daemon: DaemonArgs,
    /// Print the daemon's JSON answer.
    #[arg(long)]
    pub json: bool,
}
pub fn status(args: &StatusArgs) -> anyhow::Result<()> {
    let v = args.daemon.client()?.status()?;
    if args.json {
        println!("{}", json_pretty(&v)?);
        return Ok(());
    }
    println!(
        "brdfd {} on {}",
        terminal_safe(&v.version),
        args.daemon.addr()?
    );
    match &v.busy {
        Some(b) => println!("measuring: {} for {:.0} s", b.operation, b.seconds),
        None => println!("instruments idle"),
    }
    match &v.reference {
        Some(r) => println!(
            "reference in force: {} ({}), {:.1} h old{}",
            r.id,
            r.name,
            r.age_hours,
            if r.stale {
                " — too old: measure a new one with `brdfd reference`"
            } else {
                ""
            }
        ),
        None => println!("no reference measured yet: run `brdfd reference`"),
    }
    println!(
        "fits: {} queued, {} running{}; instruments: {}",
        v.fits_queued,
        v.fits_running,
        match v.crossvals_pending {
            0 => String::new(),
            n => format!(", {n} being cross-validated"),
        },
        instruments_line(&v)
    );
    if let Some(sync) = &v.sync {
        println!(
            "forwarding as station {} to {}: {} entries waiting, {} rows forwarded since start{}",
            sync.station,
            sync.central,
            sync.backlog,
            sync.rows_forwarded,
            match &sync.last_error {
                Some(e) if sync.refused => {
                    format!(
                        "; REFUSED, nothing of this store is forwarded: {}",
                        terminal_safe(e)
                    )
                }
                Some(e) => format!("; last error: {}", terminal_safe(e)),
                None => String::new(),
            }
        );
        if let Some(lag) = &sync.lag {
            println!(
                "lag local commit → central commit over the last {} entries: p50 {:.0} ms, \
                 p99 {:.0} ms, max {:.0} ms",
                lag.entries, lag.p50_ms, lag.p99_ms, lag.max_ms
            );
        }
        if let Some(v) = &sync.last_verify {
            println!("last comparison with the central database: {v}");
        }
    }
    if let Some(ingest) = &v.ingest {
        println!(
            "watch folder {}: {} imported, {} rejected since start{}, {} waiting{}",
            terminal_safe(&ingest.dir),
            ingest.imported,
            ingest.rejected,
            match ingest.already_imported {
                0 => String::new(),
                n => format!(", {n} imported before (moved to done/ with a note)"),
            },
            ingest.waiting,
            // The last error names a file of the folder, whatever characters its name holds.
            match &ingest.last_error {
                Some(e) => format!("; last error: {}", terminal_safe(e)),
                None => String::new(),
            }
        );
        if !ingest.interrupted.is_empty() {
            println!(
                "the daemon stopped while importing {}: moved to {}/failed/ with a note, not read \
                 again (drop a file again to import it)",
                terminal_safe(&ingest.interrupted.join(", ")),
                terminal_safe(&ingest.dir)
            );
        }
    }
    Ok(())
}
/// Each instrument as simulated or real, the SRA "off" when turned off (its 12-geometry
/// references and scans): "MA-T12 simulated, SRA off".
pub(super) fn instruments_line(v: &crate::wire::Status) -> String {
    let kind = |simulated: bool| if simulated { "simulated" } else { "real" };
    format!(
        "MA-T12 {}, SRA {}",
        kind(v.simulated.ma_t12),
        if v.sra_off() {
            "off (12 MA-T12 geometries only)"
        } else {
            kind(v.simulated.sra)
        }
    )
}

pub fn abort(args: &StatusArgs) -> anyhow::Result<()> {
    let v = args.daemon.client()?.abort()?;
    if args.json {
        println!("{}", json_line(&v)?);
        return Ok(());
    }
    match v.aborted {
        Operation::Scan { scan } => {
            println!("scan {scan} aborting; its readings so far are kept")
        }
        op => println!("{op} aborting"),
    }
    Ok(())
}
