//! `brdfd scans`: the scans in the daemon's store, newest first, a page at a time.

use super::operator::{DaemonArgs, json_pretty, local_time, terminal_safe};
use crate::wire::{Provenance, ScanQuery};

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
pub fn scans(args: &ScansArgs) -> anyhow::Result<()> {
    let client = args.daemon.client()?;
    let rows = client.scans(&ScanQuery {
        state: args.state.clone(),
        sample: args.sample.clone(),
        sample_contains: None,
        limit: Some(args.limit),
        before: args.before,
    })?;
    if args.json {
        println!("{}", json_pretty(&rows)?);
        return Ok(());
    }
    if rows.is_empty() {
        println!("no scans");
        return Ok(());
    }
    println!(
        "{:>5}  {:<22} {:<9} {:>8}  {:<26}  {:<9} reason; source of a simulated scan",
        "id", "sample", "state", "readings", "requested (local time)", "origin"
    );
    let mut last = None;
    for r in &rows {
        println!(
            "{:>5}  {:<22} {:<9} {:>8}  {:<26}  {:<9} {}",
            r.id,
            terminal_safe(&r.sample),
            terminal_safe(&r.state.to_string()),
            r.reading_count,
            local_time(r.requested_at_ms),
            origin_mark(&r.provenance),
            [
                r.reason.as_deref().map(terminal_safe),
                super::show::simulated_note(&r.provenance),
            ]
            .into_iter()
            .flatten()
            .collect::<Vec<_>>()
            .join("; ")
        );
        last = Some(r.id);
    }
    if let Some(last) = last
        && rows.len() as u32 == args.limit
    {
        eprintln!("(more may follow: `brdfd scans --before {last}`)");
    }
    Ok(())
}
/// "simulated" when either instrument was, else the MA-T12's origin ("measured",
/// "imported").
fn origin_mark(provenance: &Provenance) -> &'static str {
    if provenance.simulated() {
        "simulated"
    } else {
        provenance.ma_t12.origin.as_str()
    }
}
