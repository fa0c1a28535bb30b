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
    /// The science defaults for `--model`, `--fresnel` and `--sra`: `measured` (exact Fresnel,
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
        preset: args.preset,
        sra: args.sra,
        model: args.model,
        fresnel: args.fresnel,
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
