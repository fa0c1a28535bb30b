//! `brdfd show`: one scan with its provenance, reference, readings and fits, and the fits'
//! sphere previews on request. The fits table is also what a followed scan ends with.

use super::operator::{DaemonArgs, json_pretty, local_time, terminal_safe};
use crate::store::ScanId;
use crate::wire::{
    FitDetail, FitStatus, InstrumentOrigin, InstrumentProvenance, Provenance, ReadingValues,
    ScanView,
};

#[derive(Debug, clap::Args)]
pub struct ShowArgs {
    #[command(flatten)]
    pub daemon: DaemonArgs,
    /// The scan's id (see `brdfd scans`).
    #[arg(value_name = "SCAN")]
    pub scan: i64,
    /// Print the daemon's JSON (every reading, raw frames in hex, every fit).
    #[arg(long)]
    pub json: bool,
    /// Also write each finished fit's sphere preview (`GET /fits/{id}/preview.png`) into DIR
    /// as `fit-<id>-<cost>.png` (see `brdfd render --help` for what the picture shows).
    #[arg(long, value_name = "DIR")]
    pub preview: Option<std::path::PathBuf>,
}
pub fn show(args: &ShowArgs) -> anyhow::Result<()> {
    let client = args.daemon.client()?;
    let v = client.scan(ScanId(args.scan))?;
    if args.json {
        println!("{}", json_pretty(&v)?);
        return Ok(());
    }
    let scan = &v.scan;
    println!(
        "scan {}: sample \"{}\", {}{}",
        scan.id,
        terminal_safe(&scan.sample),
        terminal_safe(&scan.state.to_string()),
        scan.reason
            .as_deref()
            .map(|r| format!(" ({r})"))
            .unwrap_or_default()
    );
    println!(
        "requested {}, {} of {} readings",
        local_time(scan.requested_at_ms),
        scan.reading_count,
        if scan.specular_readings { 14 } else { 12 }
    );
    let provenance = &scan.provenance;
    println!(
        "measured by: {}; {}",
        instrument_line(&provenance.ma_t12, "MA-T12"),
        instrument_line(&provenance.sra, "RA-532H")
    );
    if let Some(note) = simulated_note(provenance) {
        println!("{note}");
    }
    println!(
        "source: {}{}",
        terminal_safe(&provenance.source.to_string()),
        provenance
            .source_detail
            .as_deref()
            .map(|d| format!(" ({})", terminal_safe(d)))
            .unwrap_or_default()
    );
    let reference = &v.reference.reference;
    let no_sra = !v.scan.specular_readings;
    if reference.instrument_calibration {
        println!(
            "reference: instrument calibration (the MA-T12's reflectance factor as exported, \
             relative to its calibrated white standard){}",
            if no_sra {
                "; no specular readings (fitted over the 12 MA-T12 geometries)"
            } else {
                ""
            }
        );
    } else {
        if no_sra {
            println!("no specular readings (fitted over the 12 MA-T12 geometries)");
        }
        println!(
            "reference {} ({}), measured {:.1} h before the scan{}",
            reference.id,
            terminal_safe(&reference.name),
            v.reference_age_hours,
            if v.reference_stale {
                " — older than the configured limit: not fitted automatically"
            } else {
                ""
            }
        );
    }
    for r in &v.readings {
        let text = match &r.values {
            ReadingValues::Spectrum(a) => format!(
                "reflectance 400 nm {:.4}, 550 nm {:.4}, 700 nm {:.4}",
                a[0], a[15], a[30]
            ),
            ReadingValues::Intensity(i) => format!("intensity {i:.4}"),
        };
        println!(
            "  {:<7} {:<9} {text}",
            terminal_safe(r.device.key()),
            terminal_safe(&r.geometry)
        );
    }
    print_fits(&v);
    if let Some(dir) = &args.preview {
        let out = super::out_dir(dir)?;
        for fit in &v.fits {
            let run = &fit.run;
            if !run.status.is(FitStatus::Done) {
                continue;
            }
            let name = format!(
                "fit-{}-{}.png",
                run.id,
                terminal_safe(&run.cost_function.to_string())
            );
            let png = client.fit_preview(run.id)?;
            // A preview of the same fit is the same picture: replaced, but only if it is a
            // plain file (never a link, the store or the token).
            let path = out.write(&name, &png, crate::safe_fs::Replace::OwnKind)?;
            println!("preview {}", path.display());
        }
    }
    Ok(())
}
/// One instrument's provenance as `show` prints it: its model (`kind` when it never said),
/// serial and firmware, and its origin (measured, imported, simulated; absent when the scan
/// has no readings of it).
fn instrument_line(p: &InstrumentProvenance, kind: &str) -> String {
    let simulated = match (p.origin, p.simulated) {
        (InstrumentOrigin::Absent, _) => return format!("{kind} absent (no readings of it)"),
        (InstrumentOrigin::Simulated, _) => " — SIMULATED",
        (InstrumentOrigin::Imported, _) => " — imported (real readings from a file)",
        (InstrumentOrigin::Measured, Some(_)) => " — measured",
        (InstrumentOrigin::Measured, None) => " — simulated or real: not recorded",
    };
    let model = match p.model.as_str() {
        m if !m.is_empty() && m != "unknown" => terminal_safe(m),
        _ => format!("{kind} (model not recorded)"),
    };
    format!(
        "{model} serial {} firmware {}{simulated}",
        terminal_safe(&p.serial),
        terminal_safe(&p.firmware)
    )
}

/// "simulated — replayed from …" for a scan an instrument of which was simulated.
pub(super) fn simulated_note(provenance: &Provenance) -> Option<String> {
    if !provenance.simulated() {
        return None;
    }
    Some(match provenance.source_detail.as_deref() {
        Some(d) if d.starts_with("simulated") => terminal_safe(d),
        Some(d) => format!("simulated — {}", terminal_safe(d)),
        None => "simulated — which recording answered was not recorded".into(),
    })
}
pub(super) fn print_fits(detail: &ScanView) {
    if detail.fits.is_empty() {
        println!("no fits");
        return;
    }
    println!(
        "{:>5}  {:<4} {:<9} {:<9} {:>11} {:>8} {:>8} {:>8} {:>9}",
        "fit", "cost", "method", "status", "cost value", "ΔE00", "diffuse", "specular", "wall ms"
    );
    // A fit that has not finished has no result or evaluation yet: NaN in its columns.
    let or_nan = |v: Option<f64>| v.unwrap_or(f64::NAN);
    for fit in &detail.fits {
        let run = &fit.run;
        let e = fit.evaluation.as_ref();
        let result = run.result.as_ref();
        println!(
            "{:>5}  {:<4} {:<9} {:<9} {:>11.4e} {:>8.3} {:>8.3} {:>8} {:>9.1}{}",
            run.id,
            terminal_safe(&run.cost_function.to_string()),
            terminal_safe(&run.method),
            terminal_safe(&run.status.to_string()),
            or_nan(result.map(|r| r.cost)),
            or_nan(e.map(|e| e.all.mean)),
            or_nan(e.map(|e| e.diffuse.mean)),
            // No specular readings: no specular mean.
            match e {
                Some(e) if e.specular.is_none() => "none".to_string(),
                _ => format!("{:.3}", or_nan(e.and_then(|e| e.specular).map(|s| s.mean))),
            },
            or_nan(result.map(|r| r.wall_ms)),
            run.error
                .as_deref()
                .map(|e| format!("  {e}"))
                .unwrap_or_default()
        );
        print_fit_extras(fit, detail.scan.specular_readings);
    }
    if detail.scan.specular_readings {
        println!(
            "specular: ΔE00 at sra-20 and sra-60 against the grey spectrum the SRA reading is \
             spread into (the paper's metric, not a colour measured there); the |ΔL*| under each \
             fit's SRA reading model is the luminance check"
        );
    }
    print_lobe_identified(detail);
}

/// A fit's held-out ΔE00 beside its fitted one, over the MA-T12 geometries, and the geometry
/// predicted worst (SCIENCE.md §12.5).
pub(super) fn held_out_line(cv: &crate::crossval::CrossValidation) -> String {
    let worst = cv
        .held_out
        .iter()
        .max_by(|a, b| a.delta_e00.total_cmp(&b.delta_e00))
        .map(|h| format!(", worst {} {:.2}", h.geometry, h.delta_e00))
        .unwrap_or_default();
    format!(
        "held-out ΔE00 {:.3} (fitted {:.3}; each MA-T12 geometry predicted by a fit without \
         it{worst}): how far to trust the estimate off the measured angles",
        cv.held_out_mean, cv.fitted_mean
    )
}

/// Where the latest cf1 and cf2 intervals of the scan do not overlap, says that the lobe is
/// not identified (SCIENCE.md §10): neither fit's narrow interval is the parameter's.
fn print_lobe_identified(detail: &ScanView) {
    use crate::cost::CostFunction;
    let latest = |cost: CostFunction| {
        detail
            .fits
            .iter()
            .rev()
            .filter(|f| f.run.cost_function.known() == Some(&cost))
            .find_map(|f| f.uncertainty.as_ref())
    };
    if let (Some(a), Some(b)) = (latest(CostFunction::Cf1), latest(CostFunction::Cf2)) {
        let apart = crate::uncertainty::jackknife::disjoint(a, b);
        if !apart.is_empty() {
            println!(
                "lobe not identified: cf1 and cf2 disagree beyond their intervals on {} (the \
                 readings do not fix the lobe; read neither interval as the parameter's)",
                apart.join(", ")
            );
        }
    }
}

/// The done fit's parameters at a bound of the range it was fitted within (its stored settings'
/// bounds), as the intervals record them or else from its parameters; empty when none or not
/// done.
fn at_bound(fit: &FitDetail) -> Vec<String> {
    if !fit.at_bound.is_empty() {
        return fit.at_bound.clone();
    }
    if let Some(u) = fit.uncertainty.as_ref().filter(|u| u.misfit.is_some()) {
        return u.at_bound.clone();
    }
    let params = fit
        .run
        .result
        .as_ref()
        .and_then(|r| serde_json::from_value::<crate::model::Params>(r.params.clone()).ok());
    let settings = serde_json::from_value::<crate::optimise::Settings>(fit.run.settings.clone());
    match (params, settings) {
        (Some(p), Ok(s)) => crate::uncertainty::jackknife::at_bound(&p, &s.bounds),
        _ => Vec::new(),
    }
}

/// Under a fit's row: the colorimetry of its ΔE00, once computed the held-out ΔE00 of its
/// cross-validation, and once the bootstrap has run the 95 % intervals of the lobe parameters
/// (SCIENCE.md §7.1, §10, §12.5). The SRA reading model only for a scan with SRA readings
/// (`specular`): without them it played no part in the fit.
fn print_fit_extras(fit: &FitDetail, specular: bool) {
    // Where the model misses: measured minus fitted L* at each geometry, in table order.
    if let Some(lab) = fit.lab.as_ref().filter(|l| !l.0.is_empty()) {
        let dl: Vec<String> = lab
            .0
            .iter()
            .map(|p| {
                format!(
                    "{} {:+.2}",
                    p.geometry,
                    p.residual.map_or(f64::NAN, |r| r.dl)
                )
            })
            .collect();
        println!("       ΔL* measured − fitted: {}", dl.join("  "));
    }
    if let Some(c) = &fit.colorimetry {
        println!("       ΔE00 under D65/{}° {}", c.observer, c.weighting);
    }
    if let Some(cv) = &fit.crossval {
        println!("       {}", held_out_line(cv));
    }
    // The science choices the fit was made with (settings stored without them: the paper's).
    let choice = |key: &str, default: &str| {
        fit.run
            .settings
            .get(key)
            .and_then(|v| v.as_str())
            .unwrap_or(default)
            .to_string()
    };
    println!(
        "       model {}, Fresnel {}",
        choice("model", crate::model::ModelKind::default().name()),
        choice("fresnel", crate::model::FresnelCosine::default().name())
    );
    if let Some(reach) = &fit.reach {
        println!("       reach: {}", super::fit::reach_line(reach));
    }
    let sra = &fit.sra;
    let delta_l = match &fit.specular_delta_l {
        Some(dl) => format!(
            "; specular |ΔL*| {:.3} (sra-20 {:.3}, sra-60 {:.3})",
            dl.mean, dl.per_geometry[0], dl.per_geometry[1]
        ),
        None => String::new(),
    };
    if specular {
        // The SRA readings' weight in the cost, where it is not the paper's (SCIENCE.md §5.2).
        let weight = if sra.weight.is_paper() {
            String::new()
        } else {
            format!(", {} weight", sra.weight)
        };
        println!(
            "       SRA reading model {} (illuminant {}, {}° observer{weight}){delta_l}",
            sra.model, sra.illuminant, sra.observer
        );
    }
    let bound = at_bound(fit);
    if !bound.is_empty() {
        println!(
            "       at a bound: {} (not identified there; an interval on the bound is not calibrated)",
            bound.join(", ")
        );
    }
    if let Some(u) = &fit.uncertainty {
        let iv = |i: &[f64; 2]| format!("[{:.4}, {:.4}]", i[0], i[1]);
        println!(
            "       {} ({} resamples): ks {}  alpha {}  ior {}  ΔE00 mean {}",
            if u.calibrated {
                "95 % intervals"
            } else {
                "intervals, not calibrated 95 %"
            },
            u.resamples,
            iv(&u.ks),
            iv(&u.alpha),
            iv(&u.ior),
            iv(&u.delta_e00_mean)
        );
        if !u.calibrated {
            println!(
                "       ({})",
                u.note.as_deref().unwrap_or("no calibration recorded")
            );
        }
    }
}
