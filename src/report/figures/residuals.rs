//! Fig. 13: where the model misses, measured minus estimated L* per diffuse geometry.

use plotters::coord::Shift;
use plotters::prelude::*;

use crate::fonts::font;
use crate::geometry::{Device, GEOMETRIES};
use crate::study::Study;

use super::statistics::{draw_box, quartiles};
use super::style::{cost_colour, draw_legend, sample_styles};
use super::{DrawResult, lab_of, methods, padded};

/// Fig. 13: measured minus estimated L* per diffuse geometry, a box over the samples per cost
/// function and a dot per sample.
pub(super) fn residual_lightness<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    study: &Study,
) -> DrawResult<DB> {
    let geos: Vec<_> = GEOMETRIES
        .iter()
        .filter(|g| g.device == Device::MaT12)
        .collect();
    let costs = study.cost_functions();
    let styles = sample_styles(study);
    // ΔL* per cost function, sample and geometry (None where the fit is not done).
    let residuals: Vec<Vec<Option<Vec<f64>>>> = costs
        .iter()
        .map(|&c| {
            study
                .samples
                .iter()
                .map(|s| {
                    let d = s.done(c)?;
                    let (m, e) = (lab_of(&s.measured.values), lab_of(&d.estimated));
                    Some(geos.iter().map(|g| m[g.index].l - e[g.index].l).collect())
                })
                .collect()
        })
        .collect();
    let (lo, hi) = padded(
        residuals
            .iter()
            .flatten()
            .flatten()
            .flatten()
            .copied()
            .chain([0.0]),
    );
    let names: Vec<&str> = geos.iter().map(|g| g.name).collect();
    let n = geos.len();
    let mut chart = ChartBuilder::on(root)
        .caption(
            format!(
                "Fig. 13  Where the model misses: measured − estimated L* per geometry (method {})",
                methods(study)
            ),
            font(24),
        )
        .margin(20)
        .x_label_area_size(60)
        .y_label_area_size(70)
        .build_cartesian_2d(-0.5f64..n as f64 - 0.5, lo..hi)?;
    chart
        .configure_mesh()
        .x_desc("geometry (device name; detector° as aspecular°)")
        .y_desc("ΔL* measured − estimated")
        .x_labels(n)
        .x_label_formatter(&|x| {
            let i = x.round();
            if (x - i).abs() < 1e-6 && i >= 0.0 {
                names.get(i as usize).copied().unwrap_or("").to_string()
            } else {
                String::new()
            }
        })
        .label_style(font(15))
        .axis_desc_style(font(17))
        .draw()?;
    chart.draw_series(std::iter::once(PathElement::new(
        vec![(-0.5, 0.0), (n as f64 - 0.5, 0.0)],
        BLACK.stroke_width(1),
    )))?;
    let m = costs.len().max(1) as f64;
    let width = 0.8 / m;
    for (k, (&c, per_sample)) in costs.iter().zip(&residuals).enumerate() {
        let col = cost_colour(c);
        let offset = (k as f64 - (m - 1.0) / 2.0) * width;
        let mut first = true;
        for gi in 0..n {
            let values: Vec<f64> = per_sample.iter().flatten().map(|r| r[gi]).collect();
            let Some([_, q1, med, q3, _]) = quartiles(&values) else {
                continue;
            };
            let x = gi as f64 + offset;
            let label = first.then(|| format!("{c} ({})", study.method_of(c)));
            first = false;
            draw_box(&mut chart, x, width, [q1, med, q3], col, 0.25, label)?;
            for (r, (_, style)) in per_sample.iter().zip(&styles) {
                if let Some(r) = r {
                    chart.draw_series(std::iter::once(Circle::new(
                        (x, r[gi]),
                        3,
                        style.colour.filled(),
                    )))?;
                }
            }
        }
    }
    draw_legend(&mut chart, SeriesLabelPosition::UpperRight, 0.9)
}
