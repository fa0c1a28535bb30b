//! The lightness figures: measured L* per geometry (Fig. 5, 6), measured against estimated L*
//! per aspecular angle (Fig. 9, 10) and the specular luminance scatter (Fig. 6b).

use plotters::coord::Shift;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};

use crate::colour::Lab;
use crate::cost::CostFunction;
use crate::fonts::font;
use crate::geometry::{Device, GEOMETRIES, GEOMETRY_COUNT};
use crate::study::Study;

use super::style::{cost_colour, cost_radius, cost_width, draw_legend, marker_at, sample_styles};
use super::{DrawResult, lab_of, methods, padded};

pub(super) fn lightness_lines<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    study: &Study,
    device: Device,
) -> DrawResult<DB> {
    let geos: Vec<_> = GEOMETRIES.iter().filter(|g| g.device == device).collect();
    let labs: Vec<[Lab; GEOMETRY_COUNT]> = study
        .samples
        .iter()
        .map(|s| lab_of(&s.measured.values))
        .collect();
    let (lo, hi) = padded(
        labs.iter()
            .flat_map(|l| geos.iter().map(move |g| l[g.index].l)),
    );
    let (fig, what) = match device {
        Device::MaT12 => ("Fig. 5", "diffuse readings (MA-T12)"),
        Device::Sra => ("Fig. 6", "specular readings (SRA)"),
    };
    let n = geos.len();
    let names: Vec<&str> = geos.iter().map(|g| g.name).collect();
    // The legend has a column of its own, right of the plot, so it hides no line.
    let styles = sample_styles(study);
    let legend_font = font(15);
    let widest = styles
        .iter()
        .map(|(name, _)| {
            root.estimate_text_size(name, &legend_font)
                .map_or(0, |s| s.0)
        })
        .max()
        .unwrap_or(0) as i32;
    let legend_w = widest + 70;
    let (plot, legend) = root.split_horizontally(root.dim_in_pixel().0 as i32 - legend_w);
    let mut chart = ChartBuilder::on(&plot)
        .caption(
            format!("{fig}  Measured lightness L* of the {what}"),
            font(24),
        )
        .margin(20)
        .x_label_area_size(60)
        .y_label_area_size(70)
        .build_cartesian_2d((0..n - 1).into_segmented(), lo..hi)?;
    chart
        .configure_mesh()
        .x_desc("geometry (device name; detector° as aspecular°)")
        .y_desc("L* (CIELAB, D65, 2°)")
        .x_labels(n)
        .x_label_formatter(&|x| match x {
            SegmentValue::CenterOf(i) | SegmentValue::Exact(i) => {
                names.get(*i).copied().unwrap_or("").to_string()
            }
            SegmentValue::Last => String::new(),
        })
        .label_style(font(15))
        .axis_desc_style(font(17))
        .draw()?;
    let base = plot.get_base_pixel();
    for (lab, (_, style)) in labs.iter().zip(&styles) {
        let c = style.colour;
        let pts: Vec<(SegmentValue<usize>, f64)> = geos
            .iter()
            .enumerate()
            .map(|(k, g)| (SegmentValue::CenterOf(k), lab[g.index].l))
            .collect();
        chart.draw_series(LineSeries::new(pts.clone(), c.stroke_width(2)))?;
        for p in &pts {
            let (x, y) = chart.backend_coord(p);
            marker_at(&plot, style.marker, (x - base.0, y - base.1), 5, c)?;
        }
    }
    // The legend: one row per sample, its line and marker in its colour, then its name.
    legend.draw(&Text::new("sample", (10, 40), font(16)))?;
    for (k, (name, style)) in styles.iter().enumerate() {
        let y = 74 + 22 * k as i32;
        legend.draw(&PathElement::new(
            vec![(10, y), (40, y)],
            style.colour.stroke_width(2),
        ))?;
        marker_at(&legend, style.marker, (25, y), 5, style.colour)?;
        legend.draw(&Text::new(
            name.clone(),
            (50, y),
            legend_font.pos(Pos::new(HPos::Left, VPos::Center)),
        ))?;
    }
    Ok(())
}

pub(super) fn lightness_per_detector<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    study: &Study,
    detector: f64,
) -> DrawResult<DB> {
    let geos: Vec<_> = GEOMETRIES
        .iter()
        .filter(|g| g.device == Device::MaT12 && g.theta_r_deg == detector)
        .collect();
    let fig = if detector == 15.0 { 9 } else { 10 };
    let (title_area, rest) = root.split_vertically(50);
    title_area.draw(&Text::new(
        format!(
            "Fig. {fig}  L* per aspecular angle, {detector}° detector — measured vs estimated (method {})",
            methods(study)
        ),
        (20, 14),
        font(22),
    ))?;
    let (body, legend) = rest.split_vertically(rest.dim_in_pixel().1 as i32 - 60);
    let n = study.samples.len().max(1);
    let cols = n.min(4);
    let rows = n.div_ceil(cols);
    let panels = body.split_evenly((rows, cols));
    let costs = study.cost_functions();
    let (x_lo, x_hi) = padded(geos.iter().map(|g| g.aspecular_deg));
    for (s, panel) in study.samples.iter().zip(&panels) {
        let m = lab_of(&s.measured.values);
        let ests: Vec<(CostFunction, [Lab; GEOMETRY_COUNT])> = costs
            .iter()
            .filter_map(|&c| s.done(c).map(|d| (c, lab_of(&d.estimated))))
            .collect();
        let (lo, hi) = padded(
            geos.iter().map(|g| m[g.index].l).chain(
                ests.iter()
                    .flat_map(|(_, l)| geos.iter().map(|g| l[g.index].l)),
            ),
        );
        let mut chart = ChartBuilder::on(panel)
            .caption(s.name.clone(), font(16))
            .margin(8)
            .x_label_area_size(38)
            .y_label_area_size(48)
            .build_cartesian_2d(x_lo..x_hi, lo..hi)?;
        chart
            .configure_mesh()
            .x_labels(6)
            .y_labels(5)
            .x_label_formatter(&|x| format!("{x:.0}"))
            .x_desc("aspecular angle (°)")
            .y_desc("L*")
            .label_style(font(12))
            .axis_desc_style(font(13))
            .draw()?;
        let line = |l: &[Lab; GEOMETRY_COUNT]| -> Vec<(f64, f64)> {
            geos.iter()
                .map(|g| (g.aspecular_deg, l[g.index].l))
                .collect()
        };
        // Estimates widest first, the measurement on top: coinciding lines stay visible.
        for (c, l) in &ests {
            let col = cost_colour(*c);
            chart.draw_series(LineSeries::new(line(l), col.stroke_width(cost_width(*c))))?;
            chart.draw_series(
                line(l)
                    .into_iter()
                    .map(|p| TriangleMarker::new(p, cost_radius(*c), col.filled())),
            )?;
        }
        chart.draw_series(LineSeries::new(line(&m), BLACK.stroke_width(2)))?;
        chart.draw_series(
            line(&m)
                .into_iter()
                .map(|p| Circle::new(p, 3, BLACK.filled())),
        )?;
    }
    // One legend row for every panel.
    let mut x = 20;
    legend.draw(&PathElement::new(
        vec![(x, 30), (x + 28, 30)],
        BLACK.stroke_width(2),
    ))?;
    legend.draw(&Text::new(
        "measured",
        (x + 36, 30),
        font(16).pos(Pos::new(HPos::Left, VPos::Center)),
    ))?;
    x += 150;
    for c in costs {
        let col = cost_colour(c);
        legend.draw(&PathElement::new(
            vec![(x, 30), (x + 28, 30)],
            col.stroke_width(cost_width(c)),
        ))?;
        let label = format!("estimated, {c} ({})", study.method_of(c));
        let style = font(16).pos(Pos::new(HPos::Left, VPos::Center));
        let w = legend
            .estimate_text_size(&label, &style)
            .map_or(9 * label.len() as u32, |s| s.0) as i32;
        legend.draw(&Text::new(label, (x + 36, 30), style))?;
        x += 36 + w + 40;
    }
    Ok(())
}

/// Fig. 6b: L* of the luminance at the SRA geometries, measured against estimated.
pub(super) fn luminance_specular<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    study: &Study,
) -> DrawResult<DB> {
    let costs = study.cost_functions();
    // (cost, measured L*, estimated L*) at every SRA geometry of every finished fit.
    let mut pts: Vec<(CostFunction, f64, f64)> = Vec::new();
    for s in &study.samples {
        for &c in &costs {
            let Some(d) = s.done(c) else { continue };
            for g in GEOMETRIES.iter().filter(|g| g.device == Device::Sra) {
                pts.push((
                    c,
                    d.sra.lightness(&s.measured.values[g.index]),
                    d.sra.lightness(&d.estimated[g.index]),
                ));
            }
        }
    }
    let (lo, hi) = padded(pts.iter().flat_map(|p| [p.1, p.2]));
    let mut chart = ChartBuilder::on(root)
        .caption(
            "Fig. 6b  Specular luminance L*: measured (SRA reading) vs estimated",
            font(24),
        )
        .margin(20)
        .x_label_area_size(60)
        .y_label_area_size(70)
        .build_cartesian_2d(lo..hi, lo..hi)?;
    chart
        .configure_mesh()
        .x_desc("measured L* of the SRA reading")
        .y_desc("estimated L* of the model's luminance")
        .label_style(font(15))
        .axis_desc_style(font(17))
        .draw()?;
    chart.draw_series(std::iter::once(PathElement::new(
        vec![(lo, lo), (hi, hi)],
        BLACK.mix(0.5).stroke_width(1),
    )))?;
    for &c in &costs {
        let col = cost_colour(c);
        chart
            .draw_series(
                pts.iter()
                    .filter(|p| p.0 == c)
                    .map(|p| Circle::new((p.1, p.2), cost_radius(c), col.filled())),
            )?
            .label(format!("{c} ({})", study.method_of(c)))
            .legend(move |(x, y)| Circle::new((x + 8, y), cost_radius(c), col.filled()));
    }
    draw_legend(&mut chart, SeriesLabelPosition::UpperLeft, 0.85)
}
