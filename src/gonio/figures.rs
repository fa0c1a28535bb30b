//! The figures of `brdfd validate --figures DIR` (SCIENCE.md §12.6): where over the hemisphere
//! the default configuration's fit (the paper's model with exact Fresnel on all 14 readings;
//! cf2's when cf2 was run) misses a measured BRDF, and its measured against predicted
//! lightness in the plane of incidence. Drawn from [`Report::directions_of_default`], as SVG.
//!
//! - `<material>-hemisphere.svg`: one panel per incidence angle (up to six, spread over those
//!   measured); each predicted direction is a dot at the view's projected position on the
//!   upper half of the hemisphere (x = −sin θr cos φ, y = sin θr sin φ; the mirror direction
//!   on the right, at x = sin θi, marked ×), coloured by its ΔE00 from 0 (blue) to 10 or more
//!   (red). An isotropic BRDF is symmetric about the plane, so the half is the whole.
//! - `<material>-in-plane.svg`: the directions within 7.5° of the plane of incidence, L* against
//!   the signed view angle (positive on the mirror side), measured as dots and predicted as a
//!   line, one colour per incidence (up to four).

use std::path::{Path, PathBuf};

use plotters::prelude::*;

use super::validate::{DirectionError, Report};
use crate::fonts::{font, register_font};

/// ΔE00 at which the hemisphere's colour scale saturates.
const SCALE_MAX: f64 = 10.0;
/// How far from the plane of incidence a direction still counts as in-plane, degrees.
const IN_PLANE_DEG: f64 = 7.5;

/// Colour of a ΔE00 on the hemisphere's scale: blue at 0, through yellow, to red at
/// [`SCALE_MAX`] and above.
fn scale(de: f64) -> RGBColor {
    let t = (de / SCALE_MAX).clamp(0.0, 1.0);
    let stops = [
        (49.0, 54.0, 149.0),
        (254.0, 224.0, 144.0),
        (165.0, 0.0, 38.0),
    ];
    let (a, b, u) = if t < 0.5 {
        (stops[0], stops[1], t / 0.5)
    } else {
        (stops[1], stops[2], (t - 0.5) / 0.5)
    };
    let mix = |x: f64, y: f64| (x + (y - x) * u).round() as u8;
    RGBColor(mix(a.0, b.0), mix(a.1, b.1), mix(a.2, b.2))
}

/// The incidence angles measured, rounded to the degree, at most `n` of them spread evenly.
fn incidences(points: &[DirectionError], n: usize) -> Vec<f64> {
    let mut all: Vec<f64> = points.iter().map(|p| p.theta_i_deg.round()).collect();
    all.sort_by(f64::total_cmp);
    all.dedup();
    if all.len() <= n {
        return all;
    }
    (0..n).map(|k| all[k * (all.len() - 1) / (n - 1)]).collect()
}

fn at(points: &[DirectionError], theta_i: f64) -> impl Iterator<Item = &DirectionError> {
    points
        .iter()
        .filter(move |p| (p.theta_i_deg.round() - theta_i).abs() < 0.5)
}

fn cost_name(report: &Report) -> &'static str {
    report.figures_cost.map_or("default", |c| c.name())
}

/// A file name of the material: letters and digits kept, the rest `-`.
fn slug(material: &str) -> String {
    let s: String = material
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() {
                c.to_ascii_lowercase()
            } else {
                '-'
            }
        })
        .collect();
    let s = s.trim_matches('-').to_string();
    if s.is_empty() { "material".into() } else { s }
}

/// Draws both figures of `report` into `dir` (created if missing); returns their paths.
pub fn write(report: &Report, dir: &Path) -> Result<[PathBuf; 2], String> {
    if report.directions_of_default.is_empty() {
        return Err("no default fit among the variants run: nothing to draw".into());
    }
    std::fs::create_dir_all(dir).map_err(|e| format!("creating {}: {e}", dir.display()))?;
    register_font();
    let stem = slug(&report.material);
    let hemisphere = dir.join(format!("{stem}-hemisphere.svg"));
    let in_plane = dir.join(format!("{stem}-in-plane.svg"));
    let fail = |p: &Path, e: String| format!("drawing {}: {e}", p.display());
    draw_hemisphere(report, &hemisphere).map_err(|e| fail(&hemisphere, e.to_string()))?;
    draw_in_plane(report, &in_plane).map_err(|e| fail(&in_plane, e.to_string()))?;
    Ok([hemisphere, in_plane])
}

type DrawError = Box<dyn std::error::Error>;

fn draw_hemisphere(report: &Report, path: &Path) -> Result<(), DrawError> {
    let points = &report.directions_of_default;
    let angles = incidences(points, 6);
    let panel = 260u32;
    let width = panel * angles.len() as u32;
    let root = SVGBackend::new(path, (width, panel / 2 + 150)).into_drawing_area();
    root.fill(&WHITE)?;
    let (top, rest) = root.split_vertically(60);
    top.draw(&Text::new(
        format!(
            "{}: prediction ΔE00 of the {} fit (exact Fresnel, 14 readings) over the \
             hemisphere, per incidence",
            report.material,
            cost_name(report)
        ),
        (10, 8),
        font(16),
    ))?;
    top.draw(&Text::new(
        format!(
            "dot colour: ΔE00 0 (blue) – {SCALE_MAX:.0} or more (red); × the mirror direction; \
             {} directions",
            points.len()
        ),
        (10, 32),
        font(13),
    ))?;
    let (panels, legend) = rest.split_vertically(panel / 2 + 50);
    for (area, &ti) in panels.split_evenly((1, angles.len())).iter().zip(&angles) {
        let mine: Vec<&DirectionError> = at(points, ti).collect();
        let mean = mine.iter().map(|p| p.delta_e00).sum::<f64>() / mine.len().max(1) as f64;
        let mut chart = ChartBuilder::on(area)
            .caption(format!("θi = {ti:.0}°: mean ΔE00 {mean:.2}"), font(13))
            .margin(8)
            .build_cartesian_2d(-1.05f64..1.05f64, 0f64..1.05f64)?;
        // The horizon (θr = 90°) and θr = 30°, 60°.
        for r in [0.5f64, 3f64.sqrt() / 2.0, 1.0] {
            chart.draw_series(LineSeries::new(
                (0..=60).map(|k| {
                    let a = std::f64::consts::PI * f64::from(k) / 60.0;
                    (r * a.cos(), r * a.sin())
                }),
                RGBColor(200, 200, 200),
            ))?;
        }
        chart.draw_series(mine.iter().map(|p| {
            let s = p.theta_r_deg.to_radians().sin();
            let phi = p.phi_deg.to_radians();
            Circle::new(
                (-s * phi.cos(), s * phi.sin()),
                3,
                scale(p.delta_e00).filled(),
            )
        }))?;
        chart.draw_series(std::iter::once(Cross::new(
            (ti.to_radians().sin(), 0.02),
            6,
            BLACK.stroke_width(2),
        )))?;
    }
    // The colour scale.
    let steps = 40;
    for k in 0..steps {
        let x0 = 20 + k * 6;
        legend.draw(&Rectangle::new(
            [(x0, 10), (x0 + 6, 24)],
            scale(SCALE_MAX * f64::from(k) / f64::from(steps - 1)).filled(),
        ))?;
    }
    legend.draw(&Text::new("0", (16, 28), font(12)))?;
    legend.draw(&Text::new(
        format!("{SCALE_MAX:.0}+ ΔE00"),
        (20 + steps * 6 - 6, 28),
        font(12),
    ))?;
    root.present()?;
    Ok(())
}

fn draw_in_plane(report: &Report, path: &Path) -> Result<(), DrawError> {
    const COLOURS: [RGBColor; 4] = [
        RGBColor(0, 114, 178),
        RGBColor(213, 94, 0),
        RGBColor(0, 158, 115),
        RGBColor(204, 121, 167),
    ];
    let points = &report.directions_of_default;
    let signed = |p: &DirectionError| {
        if p.phi_deg > 90.0 {
            p.theta_r_deg
        } else {
            -p.theta_r_deg
        }
    };
    let in_plane: Vec<&DirectionError> = points
        .iter()
        .filter(|p| p.phi_deg <= IN_PLANE_DEG || p.phi_deg >= 180.0 - IN_PLANE_DEG)
        .collect();
    let owned: Vec<DirectionError> = in_plane.iter().map(|p| **p).collect();
    let angles = incidences(&owned, 4);
    let (lo, hi) = in_plane
        .iter()
        .flat_map(|p| [p.measured_l, p.predicted_l])
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| {
            (a.min(v), b.max(v))
        });
    let (lo, hi) = if lo.is_finite() {
        (lo.min(0.0), hi.max(1.0) * 1.05)
    } else {
        (0.0, 100.0)
    };
    let root = SVGBackend::new(path, (760, 480)).into_drawing_area();
    root.fill(&WHITE)?;
    let mut chart = ChartBuilder::on(&root)
        .caption(
            format!(
                "{}: L* in the plane of incidence, measured (dots) and predicted by the {} fit \
                 (lines)",
                report.material,
                cost_name(report)
            ),
            font(14),
        )
        .margin(12)
        .x_label_area_size(40)
        .y_label_area_size(50)
        .build_cartesian_2d(-90f64..90f64, lo..hi)?;
    chart
        .configure_mesh()
        .x_desc("view angle θr, degrees (positive: the mirror side)")
        .y_desc("L*")
        .label_style(font(12))
        .draw()?;
    for (k, &ti) in angles.iter().enumerate() {
        let colour = COLOURS[k % COLOURS.len()];
        let mut mine: Vec<&DirectionError> = in_plane
            .iter()
            .copied()
            .filter(|p| (p.theta_i_deg.round() - ti).abs() < 0.5)
            .collect();
        mine.sort_by(|a, b| signed(a).total_cmp(&signed(b)));
        chart
            .draw_series(LineSeries::new(
                mine.iter().map(|p| (signed(p), p.predicted_l)),
                colour.stroke_width(2),
            ))?
            .label(format!("θi = {ti:.0}°"))
            .legend(move |(x, y)| PathElement::new([(x, y), (x + 16, y)], colour.stroke_width(2)));
        chart.draw_series(
            mine.iter()
                .map(|p| Circle::new((signed(p), p.measured_l), 3, colour.filled())),
        )?;
    }
    chart
        .configure_series_labels()
        .background_style(WHITE.mix(0.8))
        .border_style(BLACK)
        .label_font(font(12))
        .draw()?;
    root.present()?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_scale_runs_from_blue_to_red_and_saturates() {
        assert_eq!(scale(0.0), RGBColor(49, 54, 149));
        assert_eq!(scale(SCALE_MAX), RGBColor(165, 0, 38));
        assert_eq!(scale(5.0 * SCALE_MAX), scale(SCALE_MAX));
    }

    #[test]
    fn incidences_are_spread_over_those_measured() {
        let p = |ti: f64| DirectionError {
            theta_i_deg: ti,
            theta_r_deg: 10.0,
            phi_deg: 180.0,
            delta_e00: 1.0,
            measured_l: 50.0,
            predicted_l: 50.0,
        };
        let points: Vec<_> = (0..=15).map(|k| p(5.0 * f64::from(k))).collect();
        assert_eq!(incidences(&points, 4), [0.0, 25.0, 50.0, 75.0]);
        assert_eq!(incidences(&points[..3], 4), [0.0, 5.0, 10.0]);
        assert_eq!(slug("Krylon blue (gloss) #2"), "krylon-blue--gloss---2");
    }
}
