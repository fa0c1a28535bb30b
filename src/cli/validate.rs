//! `brdfd validate`: the handheld estimate against measured goniometric BRDFs
//! ([`crate::gonio::validate`], SCIENCE.md §12.6).

use std::fmt::Write as _;
use std::path::PathBuf;

use anyhow::Context;

use crate::cost::CostFunction;
use crate::gonio::Measurement;
use crate::gonio::validate::{Options, Prediction, Report, validate_with, variants_of};

#[derive(Debug, clap::Args)]
#[command(after_help = "\
What it does, per file:
  1. Reads the measured BRDF: an ASTM E1392 text file (spectral or R,G,B columns) or an
     RGL-EPFL tensor file (.bsdf, spectral or RGB).
  2. Derives the 14 readings the instruments would give on that material: the MA-T12's
     reflectance factor π·f at its 12 geometries, the SRA's luminance Y at sra-20 and sra-60
     (illuminant C, 2°). ASTM directions are scattered: the instrument geometries are
     interpolated between them, and the interpolation's own leave-one-out error is reported.
  3. Fits the readings under cf1, cf2 and m2, each with the paper's model under the paper's
     Schlick Fresnel and under the exact Fresnel (the default of measured scans), and with
     Oren–Nayar, and with the paper's model from the 12 MA-T12 readings alone under either
     Fresnel factor.
  4. Predicts every measured direction (ASTM) or a grid (RGL: θi 0–75°, θr 5–80°, φ 0–180°,
     every 5°/5°/15°) and reports ΔE00 (D65/10°, ASTM E308): mean, median, p95, near-specular
     (half vector within 10° of the normal) and the rest; beside the oracle (the same model
     form fitted to every direction: the best the model can do) and the Lambert baseline
     (the 45as45 reading everywhere). RGB files go through one spectral upsampling, measured
     and predicted alike.

With --intervals each default fit (exact Fresnel, all 14 readings) is also cross-validated
(each MA-T12 reading predicted by a fit without it), and the 95 % prediction interval this gives
a direction's L*a*b* (the one `brdfd crossval` gives a held-out geometry) is held against every
predicted direction: `intervals` says how often it holds the measured colour.

The oracle of each form minimises the mean ΔE00 over every direction, starting from the best
of the fits of that form, a least-squares fit and Lambert: no prediction of its form does
better. `reach` is the verdict a scan of the material would be given from its readings alone
(SCIENCE.md §12.7), to hold against the prediction.

A prediction close to the oracle means the 14 readings pin down what the model can hold; an
oracle far above 1 means the material is out of the model's reach, however it is measured.

Examples:
  brdfd validate krylon_blue.astm
  brdfd validate --json *.astm *.bsdf > validation.jsonl
  brdfd validate --cost cf2 --figures figures/ krylon_blue.astm
  brdfd validate --intervals krylon_blue.astm")]
pub struct ValidateArgs {
    /// Measured BRDF files: ASTM E1392 (.astm) or RGL tensor files (.bsdf).
    #[arg(value_name = "FILE", required = true)]
    pub files: Vec<PathBuf>,

    /// The cost functions to fit with (repeat the option for several); all three by default.
    #[arg(long, value_name = "cf1|cf2|m2")]
    pub cost: Vec<crate::cost::CostFunction>,

    /// Print one JSON object per file, one per line (material, format, readings with the
    /// file's raw values, fits with their predictions and reach verdicts, oracle, lambert,
    /// reach, …) instead of tables.
    #[arg(long)]
    pub json: bool,

    /// Also draw, per file, the prediction error of the default configuration's fit (exact
    /// Fresnel, all 14 readings; cf2's, or the first cost function's without cf2) over the
    /// hemisphere per incidence (`MATERIAL-hemisphere.svg`) and its measured against predicted L* in the
    /// plane of incidence (`MATERIAL-in-plane.svg`) into DIR (created if missing).
    #[arg(long, value_name = "DIR")]
    pub figures: Option<PathBuf>,

    /// Also cross-validate each default fit (each MA-T12 reading predicted by a fit without
    /// it) and say how often the 95 % prediction interval this gives holds the measured
    /// L*a*b* over every direction (`intervals` line; `interval_coverage` in `--json`). About
    /// doubles the run: 12 more fits per cost function.
    #[arg(long)]
    pub intervals: bool,
}

pub fn run(args: &ValidateArgs) -> anyhow::Result<()> {
    for path in &args.files {
        let file =
            std::fs::File::open(path).with_context(|| format!("opening {}", path.display()))?;
        let m = Measurement::read(file).with_context(|| format!("reading {}", path.display()))?;
        let costs = if args.cost.is_empty() {
            CostFunction::ALL.to_vec()
        } else {
            args.cost.clone()
        };
        let opts = Options {
            intervals: args.intervals,
            ..Options::default()
        };
        let mut report = validate_with(&m, &opts, &variants_of(&costs))
            .with_context(|| format!("validating {}", path.display()))?;
        report.file = Some(path.display().to_string());
        if args.json {
            println!("{}", serde_json::to_string(&report)?);
        } else {
            print!("{}", table(&report));
        }
        if let Some(dir) = &args.figures {
            let drawn = crate::gonio::figures::write(&report, dir)
                .map_err(anyhow::Error::msg)
                .with_context(|| format!("drawing the figures of {}", path.display()))?;
            for p in drawn {
                eprintln!("wrote {}", p.display());
            }
        }
    }
    Ok(())
}

fn cells(p: &Prediction) -> String {
    let opt = |x: Option<f64>| x.map_or("—".to_string(), |v| format!("{v:.2}"));
    format!(
        "{:6.2} {:6.2} {:6.2} {:>6} {:>6}",
        p.mean,
        p.median,
        p.p95,
        opt(p.near_specular_mean),
        opt(p.rest_mean)
    )
}

/// The human-readable form of a validation.
pub fn table(r: &Report) -> String {
    let mut t = String::new();
    let _ = writeln!(t, "material         {}", r.material);
    if let Some(f) = &r.file {
        let _ = writeln!(t, "file             {f} ({}, {})", r.format, r.channels);
    }
    if let Some(u) = r.rgb_upsampling {
        let _ = writeln!(t, "RGB upsampling   {u}");
    }
    let _ = writeln!(
        t,
        "predicted        {} directions ({}; {} near-specular), ΔE00 {}",
        r.directions, r.prediction_set, r.near_specular_directions, r.colorimetry
    );
    if let Some(i) = &r.interpolation {
        let _ = writeln!(
            t,
            "interpolation    {}: leave-one-out ΔE00 mean {:.2}, p95 {:.2}",
            i.method, i.leave_one_out.mean, i.leave_one_out.p95
        );
    }
    let _ = writeln!(
        t,
        "\n{:<4} {:<10} {:<10} {:<19} {:>8} | prediction ΔE00:  mean median    p95  n-spec   rest",
        "cost", "model", "fresnel", "readings", "fit ΔE00"
    );
    for f in &r.fits {
        // The SRA readings' weight, where it is not the paper's (SCIENCE.md §5.2).
        let readings = if f.sra_weight.is_paper() {
            f.readings.to_string()
        } else {
            format!("{} {}", f.readings, f.sra_weight)
        };
        let _ = writeln!(
            t,
            "{:<4} {:<10} {:<10} {:<19} {:8.2} | {:>17}{}{}",
            f.cost.name(),
            f.model.name(),
            f.fresnel.name(),
            readings,
            f.fit_delta_e00_mean,
            "",
            cells(&f.prediction),
            if f.default { "  (default)" } else { "" }
        );
    }
    for o in &r.oracles {
        let _ = writeln!(
            t,
            "{:<4} {:<10} {:<10} {:<19} {:>8} | {:>17}{}  (from {}: {:.2})",
            "orcl",
            o.model.name(),
            o.fresnel.name(),
            "all dirs",
            "",
            "",
            cells(&o.prediction),
            o.start,
            o.start_mean
        );
    }
    let _ = writeln!(
        t,
        "{:<4} {:<10} {:<10} {:<19} {:>8} | {:>17}{}",
        "lamb",
        "lambert",
        "",
        r.lambert.geometry,
        "",
        "",
        cells(&r.lambert.prediction)
    );
    for f in &r.fits {
        if let Some(c) = &f.interval_coverage {
            let pct = |x: f64| format!("{:.0} %", 100.0 * x);
            let _ = writeln!(
                t,
                "intervals        {} default: the 95 % prediction interval (± {:.2} L*, {:.2} a*, {:.2} b*, from the held-out ΔE00 {:.2}) holds L* at {} of the directions, a* {}, b* {}, all three {}{}",
                f.cost.name(),
                c.half_width[0],
                c.half_width[1],
                c.half_width[2],
                c.held_out_mean,
                pct(c.l),
                pct(c.a),
                pct(c.b),
                pct(c.all),
                c.near_specular_l
                    .map(|n| format!("; near-specular L* {}", pct(n)))
                    .unwrap_or_default()
            );
        }
    }
    if let Some(reach) = &r.reach {
        let _ = writeln!(t, "reach            {}", super::fit::reach_line(reach));
    }
    let _ = writeln!(t, "({:.0} ms)\n", r.wall_ms);
    t
}
