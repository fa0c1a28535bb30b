//! `brdfd fit`: fit one scan file and print the fit (ARCHITECTURE.md contract 3).

use std::fmt::Write as _;
use std::path::PathBuf;

use anyhow::Context;

use crate::colour::{Colorimetry, Observer, Weighting};
use crate::cost::CostFunction;
use crate::crossval::{fit_holding_out, parse_hold_out};
use crate::fit::{FitReport, FitRequest, fit_scan};
use crate::geometry::GEOMETRIES;
use crate::model::{FresnelCosine, ModelKind};
use crate::optimise::{Method, Preset, Settings};
use crate::processing::{self, ProcessingOptions, SpecularStrategy};
use crate::scan::Scan;
use crate::spectral::wavelengths_nm;
use crate::sra_reading::{SraIlluminant, SraModel, SraReading, SraWeight};
use crate::uncertainty::BootstrapOptions;
use std::sync::atomic::AtomicBool;

#[derive(Debug, clap::Args)]
pub struct FitArgs {
    /// Scan file to fit: a `brdfd.scan/1` JSON document (sample and Munsell N9 reference
    /// readings at all 14 geometries), or an X-Rite `.xlsx` export of one sample (fitted over
    /// its 12 MA-T12 geometries, as `brdfd import-format` reads it).
    #[arg(long, value_name = "SCAN.json")]
    pub input: PathBuf,

    /// Cost function to minimise: `cf1` cosine-weighted RMSE (paper Eq. 6), `cf2` cube-root
    /// cosine-weighted RMSE (Eq. 7, Forés et al. 2012), `m2` logarithmic error (Eq. 8, Löw et
    /// al. 2012).
    #[arg(long, value_name = "cf1|cf2|m2")]
    pub cost: CostFunction,

    /// Optimiser: `paper` is the paper's genetic algorithm over all 34 parameters; the default
    /// method exploits the model's structure and is never worse than `paper`.
    #[arg(long, value_name = "NAME", default_value_t = Method::default())]
    pub method: Method,

    /// Seed of the optimiser's random stream: same scan, settings and seed give the same fit,
    /// bit for bit.
    #[arg(long, value_name = "N", default_value_t = Settings::default().seed)]
    pub seed: u64,

    /// How the Canon SRA's single intensity becomes a flat spectrum: `ratio` (relative to the
    /// N9 reference, on the MA-T12's scale) or `paper-eq9` (the paper's Eq. 9, R = q·π/300 nm).
    #[arg(long, value_name = "ratio|paper-eq9", default_value_t = SpecularStrategy::Ratio)]
    pub specular: SpecularStrategy,

    #[command(flatten)]
    pub science: ScienceArgs,

    /// Standard observer for L*a*b* and ΔE00: `2` (CIE 1931, the paper's) or `10` (CIE 1964,
    /// what instrument software often uses). Illuminant is always D65.
    #[arg(long, value_name = "2|10", default_value_t = Observer::default())]
    pub observer: Observer,

    /// How the 31 bands are weighted into XYZ: `summation` (CIE 15 at the band centres, the
    /// paper's) or `astm-e308` (ASTM E308 / E2022 weighting factors, as instrument software
    /// computes L*a*b* from 10 nm data).
    #[arg(long, value_name = "summation|astm-e308", default_value_t = Weighting::default())]
    pub weighting: Weighting,

    /// Illuminant of the SRA's luminance (the `luminance` model's cost and the specular |ΔL*|
    /// of every fit): `C` (ISO 2813) or `D65`.
    #[arg(long, value_name = "C|D65", default_value_t = SraIlluminant::default())]
    pub sra_illuminant: SraIlluminant,

    /// Observer whose ȳ is the SRA's luminous efficiency function: `2` (V(λ), ISO 2813) or `10`.
    #[arg(long, value_name = "2|10", default_value_t = Observer::default())]
    pub sra_observer: Observer,

    /// Bootstrap resamples for 95 % intervals of ks, alpha, ior and kd per band (and the spread
    /// of the ΔE00 summaries): each resample perturbs the measured BRDF with the noise the scan
    /// itself shows and refits from this fit (SCIENCE.md §10). 200 is a good number; 0 (the
    /// default) skips it. Adds an `uncertainty` object to `--json` and intervals to the table.
    #[arg(long, value_name = "N", default_value_t = 0)]
    pub bootstrap: u32,

    /// MA-T12 geometries to leave out of the fit (comma-separated names, e.g. `45as-15` or
    /// `15as-45,45as110`): the fit is made to the other readings and predicts these; the
    /// prediction (ΔE00, measured and predicted L*a*b*) is printed after the fit, and is
    /// `held_out` in `--json`. `brdfd crossval` holds out each geometry in turn.
    #[arg(long, value_name = "GEOMETRY[,…]", value_delimiter = ',')]
    pub hold_out: Vec<String>,

    /// Print one JSON object on stdout (sample, cost_function, method, seed, params, cost,
    /// evaluations, generations, wall_ms, delta_e00 per geometry, delta_e00_mean, …) instead
    /// of a table.
    #[arg(long)]
    pub json: bool,
}

/// The science choices of a fit (`brdfd fit`, `brdfd crossval`): a preset and the three
/// choices it sets, each of which may be given on its own ([`Preset`]).
#[derive(Debug, Clone, Default, clap::Args)]
pub struct ScienceArgs {
    /// The science defaults: `measured` (the paper's model form with the exact dielectric
    /// Fresnel and the SRA read as luminance: what predicts real materials best off the measured
    /// angles, SCIENCE.md §4.1) or `paper` (the paper's configuration: Schlick on cos θi, the
    /// flat grey SRA reading; what `brdfd demo` and the study report use). `--model`,
    /// `--fresnel` and `--sra` given beside it win.
    #[arg(long, value_name = "measured|paper", default_value_t = Preset::default())]
    pub preset: Preset,

    /// The model's form (SCIENCE.md §4.1): `paper` (the paper's Eq. 1, Lambertian diffuse),
    /// `oren-nayar` (Oren–Nayar's rough diffuse term, one more parameter σ) or `two-lobe` (a
    /// second GGX lobe, two more parameters). Needs the default method for the options.
    /// Default: the preset's (`paper`).
    #[arg(long, value_name = "paper|oren-nayar|two-lobe")]
    pub model: Option<ModelKind>,

    /// The lobe's Fresnel factor: `exact` (the exact dielectric Fresnel on l·h, what renderers
    /// evaluate; exports to Mitsuba without approximation), Schlick on `incidence` (cos θi, as
    /// the paper writes Eq. 2) or on `light-half` (l·h, textbook Schlick). Default: the
    /// preset's (`exact` for `measured`, `incidence` for `paper`).
    #[arg(long, value_name = "exact|incidence|light-half")]
    pub fresnel: Option<FresnelCosine>,

    /// How the SRA's one achromatic reading per geometry enters the cost: `luminance` (the
    /// sample's luminous reflectance Y under CIE illuminant C and the 2° V(λ), as ISO 2813
    /// specifies; compared with the model's Y) or `flat` (the paper's: a grey spectrum,
    /// compared band by band). SCIENCE.md §5.1, §10. Default: the preset's (`luminance` for
    /// `measured`, `flat` for `paper`).
    #[arg(long, value_name = "luminance|flat")]
    pub sra: Option<SraModel>,

    /// How much the SRA readings weigh in the cost beside the MA-T12's (SCIENCE.md §5.2):
    /// `balanced` (when a glossy sample's specular readings are above its diffuse ones, their
    /// weights are scaled down to the diffuse level, so that bright readings the model cannot
    /// follow do not pull the diffuse colour away) or `paper` (every geometry by cos θi).
    /// Default: the preset's (`balanced` for cf1 and m2 and `paper` for cf2 under `measured`;
    /// `paper` under `paper`).
    #[arg(long, value_name = "balanced|paper")]
    pub sra_weight: Option<SraWeight>,
}

impl ScienceArgs {
    /// The model form in force: `--model`, else the preset's.
    pub fn model(&self) -> ModelKind {
        self.model.unwrap_or(self.preset.model())
    }

    /// The Fresnel factor in force: `--fresnel`, else the preset's.
    pub fn fresnel(&self) -> FresnelCosine {
        self.fresnel.unwrap_or(self.preset.fresnel())
    }

    /// The SRA reading model in force: `--sra`, else the preset's.
    pub fn sra(&self) -> SraModel {
        self.sra.unwrap_or(self.preset.sra())
    }

    /// The SRA readings' weight in cost function `cost`: `--sra-weight`, else the preset's.
    pub fn sra_weight(&self, cost: CostFunction) -> SraWeight {
        self.sra_weight.unwrap_or(self.preset.sra_weight(cost))
    }
}

impl FitArgs {
    /// The fit request these options describe; every other setting keeps its default.
    pub fn request(&self) -> FitRequest {
        FitRequest {
            processing: ProcessingOptions {
                specular: self.specular,
                ..Default::default()
            },
            settings: Settings {
                method: self.method,
                cost: self.cost,
                seed: self.seed,
                fresnel: self.science.fresnel(),
                model: self.science.model(),
                sra: SraReading {
                    model: self.science.sra(),
                    illuminant: self.sra_illuminant,
                    observer: self.sra_observer,
                    weight: self.science.sra_weight(self.cost),
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

/// The fit document `brdfd fit --json` prints (and the Python package's `FitReport.to_json`):
/// the report with its reach verdict after its keys.
pub fn fit_document_json(report: &FitReport) -> serde_json::Result<String> {
    #[derive(serde::Serialize)]
    struct WithReach<'a> {
        #[serde(flatten)]
        fit: &'a FitReport,
        #[serde(skip_serializing_if = "Option::is_none")]
        reach: Option<crate::reach::Reach>,
    }
    serde_json::to_string(&WithReach {
        fit: report,
        reach: crate::reach::of_report(report),
    })
}

pub fn run(args: &FitArgs) -> anyhow::Result<()> {
    let scan = super::scan_file::read_scan_input(&args.input)?;
    let report = fit_with(&scan, args)?;
    if args.json {
        println!("{}", fit_document_json(&report)?);
    } else {
        print!("{}", table(&report));
        if let Some(reach) = &crate::reach::of_report(&report) {
            println!("reach            {}", reach_line(reach));
        }
    }
    Ok(())
}

/// A reach verdict in one line: the verdict, the ΔE00 to expect over the hemisphere and why
/// (SCIENCE.md §12.7).
pub fn reach_line(reach: &crate::reach::Reach) -> String {
    let [lo, hi] = reach.expected_delta_e00;
    let [nlo, nhi] = reach.expected_near_specular_delta_e00;
    format!(
        "{}: expect ΔE00 {lo:.1}–{hi:.1} over the hemisphere, {nlo:.1}–{nhi:.1} near the mirror \
         direction; {} (calibrated on {})",
        reach.verdict,
        reach.reasons.join("; "),
        reach.calibration
    )
}

/// The fit `brdfd fit` makes of `scan` with these options (`args.input` names it in errors),
/// bootstrap included; what the Python package's `brdfd.fit` calls too, so both give the same
/// numbers to the last bit.
pub fn fit_with(scan: &Scan, args: &FitArgs) -> anyhow::Result<FitReport> {
    let request = args.request();
    let mut report = if args.hold_out.is_empty() {
        fit_scan(scan, &request)
    } else {
        let measured = processing::process(scan, &request.processing)?;
        let held = parse_hold_out(&args.hold_out, measured.geometries)
            .with_context(|| format!("--hold-out for {}", args.input.display()))?;
        fit_holding_out(
            &scan.sample,
            scan.reference_label(),
            &measured,
            &request,
            &held,
        )
    }
    .with_context(|| format!("fitting {}", args.input.display()))?;
    if args.bootstrap > 0 {
        let opts = BootstrapOptions {
            resamples: args.bootstrap,
            seed: args.seed,
            threads: std::thread::available_parallelism().map_or(1, |n| n.get()),
            noise: None,
            ..Default::default()
        };
        report = report
            .with_uncertainty(&opts, &AtomicBool::new(false))
            .with_context(|| format!("bootstrapping the fit of {}", args.input.display()))?;
    }
    Ok(report)
}

/// The human-readable form of a fit.
pub fn table(r: &FitReport) -> String {
    let o = &r.outcome;
    let s = &r.request.settings;
    let e = &r.evaluation;
    let mut t = String::new();
    let _ = writeln!(t, "sample           {}", r.sample);
    let _ = writeln!(
        t,
        "reference        {}{}",
        r.reference,
        if r.measured.geometries.has_sra() {
            ""
        } else {
            "; no specular readings (fitted over the 12 MA-T12 geometries)"
        }
    );
    let _ = writeln!(
        t,
        "fit              cost function {}, method {}, seed {}, specular {}, fresnel {}, sra {}",
        s.cost,
        o.method,
        o.seed,
        r.request.processing.specular,
        parse_name(s.fresnel),
        s.sra
    );
    if s.model != ModelKind::Paper {
        let names = s.model.extra_names();
        let values: Vec<String> = names
            .iter()
            .zip(o.params.extra.iter())
            .map(|(n, v)| format!("{n} {v:.5}"))
            .collect();
        let _ = writeln!(t, "model            {}: {}", s.model, values.join("  "));
    }
    let _ = writeln!(
        t,
        "cost             {:.6e}  ({} evaluations, {} generations, {:.1} ms)",
        o.cost, o.evaluations, o.generations, o.wall_ms
    );
    let p = &o.params;
    let _ = writeln!(
        t,
        "specular lobe    ks {:.5}  alpha {:.5}  ior {:.5}",
        p.ks, p.alpha, p.ior
    );
    let bound = crate::uncertainty::jackknife::at_bound(p, &s.bounds);
    if !bound.is_empty() {
        let _ = writeln!(
            t,
            "at a bound       {} (the fit is not identified there: an interval on the bound is not calibrated)",
            bound.join(", ")
        );
    }
    if let Some(u) = &r.uncertainty {
        let _ = writeln!(
            t,
            "{}ks [{:.5}, {:.5}]  alpha [{:.5}, {:.5}]  ior [{:.5}, {:.5}]",
            if u.calibrated {
                "95 % intervals   "
            } else {
                "intervals (not calibrated 95 %)  "
            },
            u.ks[0],
            u.ks[1],
            u.alpha[0],
            u.alpha[1],
            u.ior[0],
            u.ior[1]
        );
        let _ = writeln!(
            t,
            "                 ({}, {} resamples, noise σ {:.4} per value; ΔE00 mean [{:.4}, {:.4}])",
            u.method, u.resamples, u.noise, u.delta_e00_mean[0], u.delta_e00_mean[1]
        );
        match &u.note {
            Some(note) if !u.calibrated => {
                let _ = writeln!(t, "                 NOT calibrated: {note}");
            }
            _ => {
                let _ = writeln!(
                    t,
                    "                 calibrated: coverage measured ≥ 90 % for this cost function and SRA model, and on held-out real geometries"
                );
            }
        }
    }
    let _ = writeln!(t, "kd (sr⁻¹)");
    if let Some(u) = &r.uncertainty {
        for (nm, (k, iv)) in wavelengths_nm().iter().zip(p.kd.iter().zip(&u.kd)) {
            let _ = writeln!(t, "  {nm} {k:.5}  [{:.5}, {:.5}]", iv[0], iv[1]);
        }
    }
    for (chunk_nm, chunk_kd) in wavelengths_nm()
        .chunks(8)
        .zip(p.kd.chunks(8))
        .filter(|_| r.uncertainty.is_none())
    {
        let cells: Vec<String> = chunk_nm
            .iter()
            .zip(chunk_kd)
            .map(|(nm, k)| format!("{nm} {k:.5}"))
            .collect();
        let _ = writeln!(t, "  {}", cells.join("  "));
    }
    let _ = writeln!(
        t,
        "ΔE00 per geometry ({}), L*a*b* measured → fitted",
        r.request.colorimetry
    );
    for (pair, (name, de)) in r.lab().0.iter().zip(e.per_geometry_named()) {
        let geo = GEOMETRIES
            .iter()
            .find(|g| g.name == name)
            .expect("table geometry");
        let [lm, am, bm] = pair.measured;
        let [lf, af, bf] = pair.fitted;
        let _ = writeln!(
            t,
            "  {:<8} {:>6}  {de:8.4}   ({lm:6.2} {am:6.2} {bm:6.2}) → ({lf:6.2} {af:6.2} {bf:6.2})",
            geo.name,
            geo.device.key()
        );
    }
    let _ = writeln!(
        t,
        "ΔE00 mean        {:.4}  (median {:.4}, max {:.4})",
        e.all.mean, e.all.median, e.all.max
    );
    let _ = writeln!(
        t,
        "  diffuse  (12)  {:.4}  (median {:.4}, max {:.4})",
        e.diffuse.mean, e.diffuse.median, e.diffuse.max
    );
    match (&e.specular, &r.specular_delta_l) {
        (Some(spec), Some(d)) => {
            let _ = writeln!(
                t,
                "  specular (2)   {:.4}  (max {:.4})  the paper's: against the grey spectrum",
                spec.mean, spec.max
            );
            let _ = writeln!(
                t,
                "specular |ΔL*|   {:.4}  (sra-20 {:.4}, sra-60 {:.4}; luminance under {}/{}°)",
                d.mean, d.per_geometry[0], d.per_geometry[1], s.sra.illuminant, s.sra.observer
            );
        }
        _ => {
            let _ = writeln!(t, "  specular       no specular readings");
        }
    }
    if let Some(held) = &r.held_out {
        let _ = writeln!(
            t,
            "held out         not fitted, predicted: ΔE00, L*a*b* measured → predicted"
        );
        for h in held {
            let [lm, am, bm] = h.measured_lab;
            let [lp, ap, bp] = h.predicted_lab;
            let _ = writeln!(
                t,
                "  {:<8} {:>6}  {:8.4}   ({lm:6.2} {am:6.2} {bm:6.2}) → ({lp:6.2} {ap:6.2} {bp:6.2})",
                h.geometry, "ma_t12", h.delta_e00
            );
        }
        let mean = held.iter().map(|h| h.delta_e00).sum::<f64>() / held.len() as f64;
        let _ = writeln!(t, "held-out mean    {mean:.4}");
    }
    t
}

fn parse_name(f: FresnelCosine) -> &'static str {
    f.name()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fresnel_names_round_trip() {
        for f in FresnelCosine::ALL {
            assert_eq!(parse_name(f).parse::<FresnelCosine>().unwrap(), f);
            // Same spelling as the settings' serde form.
            assert_eq!(
                serde_json::to_string(&f).unwrap(),
                format!("\"{}\"", parse_name(f))
            );
        }
        let e = "half".parse::<FresnelCosine>().unwrap_err();
        assert!(e.contains("incidence") && e.contains("exact"), "{e}");
    }

    /// `--preset` sets the three choices; each given beside it wins.
    #[test]
    fn the_preset_gives_defaults_and_explicit_choices_win() {
        use clap::Parser;
        #[derive(clap::Parser)]
        struct Cli {
            #[command(flatten)]
            science: ScienceArgs,
        }
        let parse = |args: &[&str]| {
            let s = Cli::try_parse_from(std::iter::once("t").chain(args.iter().copied()))
                .unwrap()
                .science;
            (s.model(), s.fresnel(), s.sra())
        };
        assert_eq!(
            parse(&[]),
            (ModelKind::Paper, FresnelCosine::Exact, SraModel::Luminance)
        );
        assert_eq!(
            parse(&["--preset", "paper"]),
            (ModelKind::Paper, FresnelCosine::Incidence, SraModel::Flat)
        );
        assert_eq!(
            parse(&[
                "--preset",
                "paper",
                "--fresnel",
                "exact",
                "--sra",
                "luminance"
            ]),
            (ModelKind::Paper, FresnelCosine::Exact, SraModel::Luminance)
        );
        assert_eq!(
            parse(&["--model", "oren-nayar", "--fresnel", "light-half"]),
            (
                ModelKind::OrenNayar,
                FresnelCosine::LightHalf,
                SraModel::Luminance
            )
        );
        assert!(Cli::try_parse_from(["t", "--preset", "gloss"]).is_err());
    }
}
