//! `brdfd show`: one scan with its provenance, reference, readings and fits, and the fits'
//! sphere previews on request. The fits table is also what a followed scan ends with.

use serde_json::Value;

use super::operator::{DaemonArgs, f, id, local_time, s, terminal_safe};

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
    let v = client.get(&format!("/scans/{}", args.scan))?;
    if args.json {
        println!("{}", serde_json::to_string_pretty(&v)?);
        return Ok(());
    }
    let scan = &v["scan"];
    println!(
        "scan {}: sample \"{}\", {}{}",
        id(scan, "id"),
        s(scan, "sample"),
        s(scan, "state"),
        scan["reason"]
            .as_str()
            .map(|r| format!(" ({r})"))
            .unwrap_or_default()
    );
    println!(
        "requested {}, {} of 14 readings",
        local_time(scan["requested_at_ms"].as_i64().unwrap_or(0)),
        scan["reading_count"]
    );
    let provenance = &scan["provenance"];
    println!(
        "measured by: {}; {}",
        instrument_line(&provenance["ma_t12"], "MA-T12"),
        instrument_line(&provenance["sra"], "RA-532H")
    );
    if let Some(note) = simulated_note(provenance) {
        println!("{note}");
    }
    println!(
        "source: {}{}",
        s(provenance, "source"),
        provenance["source_detail"]
            .as_str()
            .map(|d| format!(" ({})", terminal_safe(d)))
            .unwrap_or_default()
    );
    let reference = &v["reference"]["reference"];
    let no_sra = v["scan"]["specular_readings"].as_bool() == Some(false);
    if reference["instrument_calibration"].as_bool() == Some(true) {
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
            id(reference, "id"),
            s(reference, "name"),
            f(&v, "reference_age_hours"),
            if v["reference_stale"].as_bool() == Some(true) {
                " — older than the configured limit: not fitted automatically"
            } else {
                ""
            }
        );
    }
    for r in v["readings"].as_array().into_iter().flatten() {
        let values = &r["values"];
        let text = match values.as_array() {
            Some(a) => format!(
                "reflectance 400 nm {:.4}, 550 nm {:.4}, 700 nm {:.4}",
                a.first().and_then(Value::as_f64).unwrap_or(f64::NAN),
                a.get(15).and_then(Value::as_f64).unwrap_or(f64::NAN),
                a.get(30).and_then(Value::as_f64).unwrap_or(f64::NAN)
            ),
            None => format!("intensity {:.4}", values.as_f64().unwrap_or(f64::NAN)),
        };
        println!("  {:<7} {:<9} {text}", s(r, "device"), s(r, "geometry"));
    }
    print_fits(&v);
    if let Some(dir) = &args.preview {
        let out = super::out_dir(dir)?;
        for fit in v["fits"].as_array().into_iter().flatten() {
            let run = &fit["run"];
            if run["status"] != "done" {
                continue;
            }
            let name = format!("fit-{}-{}.png", id(run, "id"), s(run, "cost_function"));
            let png = client.get_bytes(&format!("/fits/{}/preview.png", id(run, "id")))?;
            // A preview of the same fit is the same picture: replaced, but only if it is a
            // plain file (never a link, the store or the token).
            let path = out.write(&name, &png, crate::safe_fs::Replace::OwnKind)?;
            println!("preview {}", path.display());
        }
    }
    Ok(())
}
/// One instrument's provenance as `show` prints it: its model (`kind` when it never said),
/// serial and firmware.
fn instrument_line(p: &Value, kind: &str) -> String {
    let simulated = match p["simulated"].as_bool() {
        Some(true) => " — SIMULATED",
        Some(false) => "",
        None => " — simulated or real: not recorded",
    };
    let model = match p["model"].as_str() {
        Some(m) if !m.is_empty() && m != "unknown" => terminal_safe(m),
        _ => format!("{kind} (model not recorded)"),
    };
    format!(
        "{model} serial {} firmware {}{simulated}",
        s(p, "serial"),
        s(p, "firmware")
    )
}

/// "simulated — replayed from …" for a scan an instrument of which was simulated.
pub(super) fn simulated_note(provenance: &Value) -> Option<String> {
    let simulated = ["ma_t12", "sra"]
        .iter()
        .any(|k| provenance[k]["simulated"].as_bool() == Some(true));
    if !simulated {
        return None;
    }
    Some(match provenance["source_detail"].as_str() {
        Some(d) if d.starts_with("simulated") => terminal_safe(d),
        Some(d) => format!("simulated — {}", terminal_safe(d)),
        None => "simulated — which recording answered was not recorded".into(),
    })
}
pub(super) fn print_fits(detail: &Value) {
    let fits = detail["fits"].as_array().cloned().unwrap_or_default();
    if fits.is_empty() {
        println!("no fits");
        return;
    }
    println!(
        "{:>5}  {:<4} {:<9} {:<9} {:>11} {:>8} {:>8} {:>8} {:>9}",
        "fit", "cost", "method", "status", "cost value", "ΔE00", "diffuse", "specular", "wall ms"
    );
    for fit in fits {
        let run = &fit["run"];
        let e = &fit["evaluation"];
        let result = &run["result"];
        println!(
            "{:>5}  {:<4} {:<9} {:<9} {:>11.4e} {:>8.3} {:>8.3} {:>8} {:>9.1}{}",
            id(run, "id"),
            s(run, "cost_function"),
            s(run, "method"),
            s(run, "status"),
            f(result, "cost"),
            f(&e["all"], "mean"),
            f(&e["diffuse"], "mean"),
            // No specular readings: no specular mean.
            if e["specular"].is_null() && !e.is_null() {
                "none".to_string()
            } else {
                format!("{:.3}", f(&e["specular"], "mean"))
            },
            f(result, "wall_ms"),
            run["error"]
                .as_str()
                .map(|e| format!("  {e}"))
                .unwrap_or_default()
        );
        print_fit_extras(&fit);
    }
}
/// Under a fit's row: the colorimetry of its ΔE00 and, once the bootstrap has run, the 95 %
/// intervals of the lobe parameters (SCIENCE.md §7.1, §10).
fn print_fit_extras(fit: &Value) {
    // Where the model misses: measured minus fitted L* at each geometry.
    if let Some(lab) = fit["lab"].as_object().filter(|l| !l.is_empty()) {
        // In the geometry table's order (a JSON object's keys come sorted).
        let dl: Vec<String> = crate::geometry::GEOMETRIES
            .iter()
            .filter_map(|g| {
                let p = lab.get(g.name)?;
                Some(format!(
                    "{} {:+.2}",
                    g.name,
                    p["residual"]["dL"].as_f64().unwrap_or(f64::NAN)
                ))
            })
            .collect();
        println!("       ΔL* measured − fitted: {}", dl.join("  "));
    }
    let c = &fit["colorimetry"];
    if c.is_object() {
        println!(
            "       ΔE00 under D65/{}° {}",
            s(c, "observer"),
            s(c, "weighting")
        );
    }
    let sra = &fit["sra"];
    if sra.is_object() {
        let dl = &fit["specular_delta_l"];
        let delta_l = if dl.is_object() {
            format!(
                "; specular |ΔL*| {:.3} (sra-20 {:.3}, sra-60 {:.3})",
                dl["mean"].as_f64().unwrap_or(f64::NAN),
                dl["per_geometry"][0].as_f64().unwrap_or(f64::NAN),
                dl["per_geometry"][1].as_f64().unwrap_or(f64::NAN)
            )
        } else {
            String::new()
        };
        println!(
            "       SRA reading model {} (illuminant {}, {}° observer){delta_l}",
            s(sra, "model"),
            s(sra, "illuminant"),
            s(sra, "observer")
        );
    }
    let u = &fit["uncertainty"];
    if u.is_object() {
        let iv = |k: &str| {
            format!(
                "[{:.4}, {:.4}]",
                u[k][0].as_f64().unwrap_or(f64::NAN),
                u[k][1].as_f64().unwrap_or(f64::NAN)
            )
        };
        let calibrated = u["calibrated"].as_bool() == Some(true);
        println!(
            "       {} ({} resamples): ks {}  alpha {}  ior {}  ΔE00 mean {}",
            if calibrated {
                "95 % intervals"
            } else {
                "intervals, not calibrated 95 %"
            },
            u["resamples"],
            iv("ks"),
            iv("alpha"),
            iv("ior"),
            iv("delta_e00_mean")
        );
        if !calibrated {
            println!(
                "       ({})",
                u["note"].as_str().unwrap_or("no calibration recorded")
            );
        }
    }
}
