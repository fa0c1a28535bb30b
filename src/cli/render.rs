//! `brdfd render`: the spectral sphere preview of a sample's fits ([`crate::render`]) as PNG,
//! from a stored scan (its fits as the store holds them) or from a scan file (fitted here,
//! with each cost function asked for, as `brdfd fit` would).

use std::path::PathBuf;

use anyhow::{Context, bail};

use crate::config::Config;
use crate::cost::CostFunction;
use crate::fit::{FitRequest, fit_scan};
use crate::optimise::{Method, Settings};
use crate::processing::ProcessingOptions;
use crate::report::Study;
use crate::report::load::Selection;
use crate::store::ScanId;

use super::report::{StoreSelection, load_study};

#[derive(Debug, clap::Args)]
#[command(after_help = "Examples:\n  \
    brdfd render 12 --out sphere.png                     # stored scan 12, its cf1/cf2/m2 fits\n  \
    brdfd render --input t-freesia-pink.scan.json --cost cf2 --out cf2.png\n\n\
    The picture: one 256 × 256 sphere per cost function, computed over the 31 bands under a \
    directional D65 light from the upper left (45° from the view) and a weak uniform ambient, \
    in sRGB as the report's swatches, on an 18 % grey background; clipped pixels are hatched in \
    magenta; the 14 measured swatches below; and whether the scale is absolute (calibrated \
    reference tile, [reference] reflectance) or relative to the tile.")]
pub struct RenderArgs {
    /// The stored scan to render (see `brdfd scans`).
    #[arg(
        value_name = "SCAN",
        conflicts_with = "input",
        required_unless_present = "input"
    )]
    pub scan: Option<i64>,

    /// A `brdfd.scan/1` file (or an X-Rite `.xlsx` export of one sample) to fit and render
    /// instead of a stored scan.
    #[arg(long, value_name = "SCAN.json")]
    pub input: Option<PathBuf>,

    /// Cost functions to show, one sphere each, comma-separated; default all three.
    #[arg(long, value_name = "cf1,cf2,m2", value_delimiter = ',')]
    pub cost: Vec<CostFunction>,

    /// PNG file to write.
    #[arg(long, value_name = "FILE.png")]
    pub out: PathBuf,

    /// With --input: optimiser method (as `brdfd fit --method`).
    #[arg(long, value_name = "NAME", default_value_t = Method::default())]
    pub method: Method,

    /// The SQLite store to read a SCAN from (default as `brdfd report`).
    #[arg(long, value_name = "PATH")]
    pub db: Option<PathBuf>,

    /// Configuration file: its store (for SCAN), and, with --input, its `[reference]
    /// reflectance` (a scan file does not carry the tile's calibration).
    #[arg(long, value_name = "brdfd.toml")]
    pub config: Option<PathBuf>,

    /// Print `{"sample", "costs", "scale", "file"}` instead of the sentence.
    #[arg(long)]
    pub json: bool,
}

pub fn run(args: &RenderArgs) -> anyhow::Result<()> {
    let costs = if args.cost.is_empty() {
        CostFunction::ALL.to_vec()
    } else {
        args.cost.clone()
    };
    let study = match (&args.input, args.scan) {
        (Some(path), _) => {
            let config = Config::load_or_default(args.config.as_deref())?;
            let scan = super::scan_file::read_scan_input(path)?;
            let mut reports = Vec::new();
            for &cost in &costs {
                let request = FitRequest {
                    processing: ProcessingOptions {
                        specular: config.fit.specular,
                        reference_reflectance: config.reference.reflectance,
                    },
                    settings: Settings {
                        method: args.method,
                        cost,
                        ..Settings::default()
                    },
                    colorimetry: config.colour,
                };
                reports.push(
                    fit_scan(&scan, &request)
                        .with_context(|| format!("fitting {} with {cost}", path.display()))?,
                );
            }
            Study::from_fit_reports(std::slice::from_ref(&scan), &[reports])
        }
        (None, Some(id)) => {
            let select = StoreSelection {
                all: false,
                scans: vec![id],
                db: args.db.clone(),
                config: args.config.clone(),
                station: None,
                include_simulated: true,
            };
            load_study(&select.db_path()?, &Selection::Scans(vec![ScanId(id)]))?
        }
        (None, None) => bail!("name a stored SCAN or give --input FILE"),
    };
    let sample = &study.samples[0];
    crate::render::write_preview(sample, &costs, &args.out)?;
    if args.json {
        println!(
            "{}",
            serde_json::json!({
                "sample": sample.name,
                "costs": costs,
                "scale": sample.scale().name(),
                "file": args.out,
            })
        );
        return Ok(());
    }
    println!(
        "{}: {} sphere(s) ({}), {}, in {}",
        sample.name,
        costs.len(),
        costs
            .iter()
            .map(|c| c.name())
            .collect::<Vec<_>>()
            .join(", "),
        sample.scale().name(),
        args.out.display()
    );
    Ok(())
}
