//! `brdfd refit`: fit a stored scan again, then follow the new fits.

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
    /// How the SRA's readings enter the fit: `flat` (the paper's grey spectrum) or `luminance`
    /// (the model's luminous reflectance; SCIENCE.md §5.1); default: the configured one.
    #[arg(long, value_name = "flat|luminance")]
    pub sra: Option<crate::sra_reading::SraModel>,
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
pub fn refit(args: &RefitArgs) -> anyhow::Result<()> {
    let client = args.daemon.client()?;
    let events = (!args.detach).then(|| client.events()).transpose()?;
    let request = RefitRequest {
        cost_functions: args.cost.clone(),
        method: args.method,
        seed: args.seed,
        sra: args.sra,
        allow_stale_reference: args.allow_stale_reference,
    };
    let scan = ScanId(args.scan);
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
