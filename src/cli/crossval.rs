//! `brdfd crossval`: leave-one-geometry-out cross-validation of one scan file, per cost
//! function ([`crate::crossval`]): how well a fit predicts readings it has not seen.

use std::fmt::Write as _;
use std::path::PathBuf;

use anyhow::Context;
use serde::Serialize;

use crate::colour::{Colorimetry, Observer, Weighting};
use crate::cost::CostFunction;
use crate::crossval::{CrossValidation, crossval_measured};
use crate::fit::FitRequest;
use crate::optimise::{Method, Settings};
use crate::processing::{self, ProcessingOptions, SpecularStrategy};
use crate::scan::Scan;
use crate::sra_reading::SraReading;

use super::fit::ScienceArgs;

#[derive(Debug, Clone, clap::Args)]
pub struct CrossvalArgs {
    /// Scan file: a `brdfd.scan/1` JSON document (`brdfd import-format` makes one of an
    /// instrument's export), or an X-Rite `.xlsx` export of one sample.
    #[arg(value_name = "SCAN.json")]
    pub input: PathBuf,

    /// Cost functions to cross-validate (comma-separated): by default all three.
    #[arg(long, value_name = "cf1,cf2,m2", value_delimiter = ',')]
    pub cost: Vec<CostFunction>,

    #[command(flatten)]
    pub science: ScienceArgs,

    /// Optimiser (as `brdfd fit --method`).
    #[arg(long, value_name = "NAME", default_value_t = Method::default())]
    pub method: Method,

    /// Seed of the optimiser's random stream (every fit of the run uses it).
    #[arg(long, value_name = "N", default_value_t = Settings::default().seed)]
    pub seed: u64,

    /// Standard observer for L*a*b* and ΔE00: `2` or `10` (`10` with `--weighting astm-e308`
    /// is how X-Rite's software computes an export's L*a*b*).
    #[arg(long, value_name = "2|10", default_value_t = Observer::default())]
    pub observer: Observer,

    /// How the 31 bands are weighted into XYZ: `summation` or `astm-e308`.
    #[arg(long, value_name = "summation|astm-e308", default_value_t = Weighting::default())]
    pub weighting: Weighting,

    /// Print one JSON object on stdout: `{"sample", "reference", "fits": [{"cost", "model",
    /// "fresnel", "fitted_mean", "held_out_mean", "held_out": [{"geometry", "delta_e00",
    /// "measured_lab", "predicted_lab"}, …]}, …]}`.
    #[arg(long)]
    pub json: bool,
}

/// What `brdfd crossval --json` prints.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct CrossvalDocument {
    pub sample: String,
    pub reference: String,
    /// One cross-validation per cost function, in the order asked.
    pub fits: Vec<CrossValidation>,
}

impl CrossvalArgs {
    /// The cost functions to run: those given, or all three.
    pub fn costs(&self) -> Vec<CostFunction> {
        if self.cost.is_empty() {
            CostFunction::ALL.to_vec()
        } else {
            self.cost.clone()
        }
    }

    /// The fit request of one cost function.
    pub fn request(&self, cost: CostFunction) -> FitRequest {
        FitRequest {
            processing: ProcessingOptions {
                specular: SpecularStrategy::Ratio,
                ..Default::default()
            },
            settings: Settings {
                method: self.method,
                cost,
                seed: self.seed,
                fresnel: self.science.fresnel(),
                model: self.science.model(),
                sra: SraReading {
                    model: self.science.sra(),
                    weight: self.science.sra_weight(cost),
                    ..SraReading::default()
                },
                ..Settings::default()
            },
            colorimetry: Colorimetry {
                observer: self.observer,
                weighting: self.weighting,
            },
        }
    }
}

/// The cross-validation `brdfd crossval` makes of `scan` (`args.input` names it in errors);
/// what the Python package's `brdfd.crossval` calls too.
pub fn crossval_with(scan: &Scan, args: &CrossvalArgs) -> anyhow::Result<CrossvalDocument> {
    let mut fits = Vec::new();
    for cost in args.costs() {
        let request = args.request(cost);
        let measured = processing::process(scan, &request.processing)
            .with_context(|| format!("processing {}", args.input.display()))?;
        let cv = crossval_measured(&scan.sample, scan.reference_label(), &measured, &request)
            .with_context(|| format!("cross-validating {} with {cost}", args.input.display()))?;
        fits.push(cv);
    }
    Ok(CrossvalDocument {
        sample: scan.sample.clone(),
        reference: scan.reference_label().to_string(),
        fits,
    })
}

pub fn run(args: &CrossvalArgs) -> anyhow::Result<()> {
    let scan = super::scan_file::read_scan_input(&args.input)?;
    let doc = crossval_with(&scan, args)?;
    if args.json {
        println!("{}", serde_json::to_string(&doc)?);
    } else {
        print!("{}", table(&doc, args));
    }
    Ok(())
}

/// The human-readable form.
pub fn table(doc: &CrossvalDocument, args: &CrossvalArgs) -> String {
    let mut t = String::new();
    let _ = writeln!(t, "sample           {}", doc.sample);
    let _ = writeln!(t, "reference        {}", doc.reference);
    let _ = writeln!(
        t,
        "leave one MA-T12 geometry out: fit the others, predict it ({})",
        Colorimetry {
            observer: args.observer,
            weighting: args.weighting
        }
    );
    for cv in &doc.fits {
        let _ = writeln!(
            t,
            "{}, model {}, fresnel {}: held-out ΔE00 mean {:.4} (fitted to every reading {:.4})",
            cv.cost,
            cv.model,
            cv.fresnel.name(),
            cv.held_out_mean,
            cv.fitted_mean
        );
        for h in &cv.held_out {
            let [lm, am, bm] = h.measured_lab;
            let [lp, ap, bp] = h.predicted_lab;
            let _ = writeln!(
                t,
                "  {:<8} {:8.4}   ({lm:6.2} {am:6.2} {bm:6.2}) → ({lp:6.2} {ap:6.2} {bp:6.2})",
                h.geometry, h.delta_e00
            );
        }
    }
    t
}
