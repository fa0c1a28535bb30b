//! The statistics figures: ΔE00 box plots per sample (Fig. 11), specular |ΔL*| per sample
//! (Fig. 11b) and the means with their confidence intervals (Fig. 12, 12b), with the quartiles
//! and box drawing they share with Fig. 13.

use plotters::coord::Shift;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};

use plotters::coord::types::RangedCoordf64;

use crate::cost::CostFunction;
use crate::fonts::font;
use crate::report::analysis::Analysis;
use crate::study::Study;

use super::style::{cost_colour, draw_legend};
use super::{DrawResult, methods};

/// A chart with a linear x and y axis.
pub(super) type Chart<'a, DB> = ChartContext<'a, DB, Cartesian2d<RangedCoordf64, RangedCoordf64>>;

/// Quartiles by linear interpolation between order statistics (R's type 7).
pub fn quartiles(xs: &[f64]) -> Option<[f64; 5]> {
    if xs.is_empty() {
        return None;
    }
    let mut v = xs.to_vec();
    v.sort_by(f64::total_cmp);
    let q = |p: f64| {
        let h = (v.len() - 1) as f64 * p;
        let (lo, frac) = (h.floor() as usize, h.fract());
        let hi = (lo + 1).min(v.len() - 1);
        v[lo] + frac * (v[hi] - v[lo])
    };
    Some([v[0], q(0.25), q(0.5), q(0.75), v[v.len() - 1]])
}

/// Size of the sample-name labels under Fig. 11 and 11b.
const SAMPLE_LABEL_PX: u32 = 14;

/// Width and height of the per-sample charts (Fig. 11, 11b) of `names`: 1300 × 700, wider
/// with many samples so that each name keeps room for its label (at least 24 px a sample,
/// the height of a label turned upright), and taller by the length of the longest name when
/// the labels are turned (an estimate: 8.5 px a character at 14 px).
pub(super) fn per_sample_size(names: &[&str]) -> (u32, u32) {
    let n = names.len().max(1) as u32;
    let width = 1300.max(200 + 24 * n);
    let plot = f64::from(width - 110);
    let longest = names.iter().map(|s| s.chars().count()).max().unwrap_or(0) as f64 * 8.5;
    let turned = longest + 8.0 > plot / f64::from(n);
    let height = if turned {
        700 + longest.round() as u32
    } else {
        700
    };
    (width, height)
}

/// One box of a box plot at `x` (`width` the group's slot): the quartile box filled at
/// `fill` opacity and outlined, the median line, and, for the first box of a series, its legend
/// entry `label`. Whiskers and points are the caller's.
pub(super) fn draw_box<DB: DrawingBackend>(
    chart: &mut Chart<'_, DB>,
    x: f64,
    width: f64,
    [q1, med, q3]: [f64; 3],
    col: RGBColor,
    fill: f64,
    label: Option<String>,
) -> DrawResult<DB> {
    let (x0, x1) = (x - width * 0.4, x + width * 0.4);
    let series = chart.draw_series(std::iter::once(Rectangle::new(
        [(x0, q1), (x1, q3)],
        col.mix(fill).filled(),
    )))?;
    if let Some(label) = label {
        series.label(label).legend(move |(x, y)| {
            Rectangle::new([(x, y - 6), (x + 16, y + 6)], col.mix(0.6).filled())
        });
    }
    chart.draw_series(std::iter::once(Rectangle::new(
        [(x0, q1), (x1, q3)],
        col.stroke_width(2),
    )))?;
    chart.draw_series(std::iter::once(PathElement::new(
        vec![(x0, med), (x1, med)],
        col.stroke_width(3),
    )))?;
    Ok(())
}

/// The axes of Fig. 11 and 11b: one column per sample (named on the x axis), y from 0 to 1.3 ×
/// the largest of `values` (1 when none is above 0), caption and y label as given. The names
/// are written under their columns, turned upright when they do not fit side by side.
fn per_sample_chart<'a, DB: DrawingBackend>(
    root: &'a DrawingArea<DB, Shift>,
    study: &Study,
    caption: String,
    y_desc: &str,
    values: &[f64],
) -> Result<Chart<'a, DB>, DrawingAreaErrorKind<DB::ErrorType>> {
    let n = study.samples.len();
    let hi = values.iter().copied().fold(0.0f64, f64::max) * 1.3;
    let hi = if hi > 0.0 { hi } else { 1.0 };
    let names: Vec<String> = study.samples.iter().map(|s| s.name.clone()).collect();
    let label = font(SAMPLE_LABEL_PX);
    let widths: Vec<i32> = names
        .iter()
        .map(|t| root.estimate_text_size(t, &label).map_or(0, |s| s.0 as i32))
        .collect();
    let widest = widths.iter().copied().max().unwrap_or(0);
    let (margin, y_area) = (20, 70);
    let spacing = (root.dim_in_pixel().0 as i32 - 2 * margin - y_area) / n.max(1) as i32;
    // Side by side when every name fits its column with a gap; else upright.
    let turned = widest + 8 > spacing;
    let label_h = if turned { widest + 14 } else { 26 };
    let mut chart = ChartBuilder::on(root)
        .caption(caption, font(24))
        .margin(margin)
        .x_label_area_size(label_h + 36)
        .y_label_area_size(y_area)
        .build_cartesian_2d(-0.5f64..(n as f64 - 0.5), 0f64..hi)?;
    chart
        .configure_mesh()
        .disable_x_mesh()
        .x_labels(n.max(1))
        .x_label_formatter(&|_| String::new())
        .x_desc("sample")
        .y_desc(y_desc)
        .label_style(font(14))
        .axis_desc_style(font(17))
        .draw()?;
    let base = root.get_base_pixel();
    for (i, name) in names.iter().enumerate() {
        let (x, y) = chart.backend_coord(&(i as f64, 0.0));
        let (x, y) = (x - base.0, y - base.1 + 8);
        let style = if turned {
            label
                .transform(FontTransform::Rotate270)
                .pos(Pos::new(HPos::Right, VPos::Center))
        } else {
            label.pos(Pos::new(HPos::Center, VPos::Top))
        };
        root.draw(&Text::new(name.clone(), (x, y), style))?;
    }
    Ok(chart)
}

/// Fig. 11 and 11b: [`per_sample_chart`] of `values` titled `what` "per sample and cost
/// function" with the methods, then per cost function `draw(chart, cost, colour, offset,
/// width)` with its column's offset from each sample's position and the columns' width, then
/// the legend.
fn per_sample_figure<'a, DB: DrawingBackend>(
    root: &'a DrawingArea<DB, Shift>,
    study: &Study,
    what: &str,
    y_desc: &str,
    values: &[f64],
    mut draw: impl FnMut(&mut Chart<'a, DB>, CostFunction, RGBColor, f64, f64) -> DrawResult<DB>,
) -> DrawResult<DB> {
    let costs = study.cost_functions();
    let mut chart = per_sample_chart(
        root,
        study,
        format!(
            "{what} per sample and cost function (method {})",
            methods(study)
        ),
        y_desc,
        values,
    )?;
    let m = costs.len().max(1) as f64;
    let width = 0.7 / m;
    for (k, &c) in costs.iter().enumerate() {
        let offset = (k as f64 - (m - 1.0) / 2.0) * width;
        draw(&mut chart, c, cost_colour(c), offset, width)?;
    }
    draw_legend(&mut chart, SeriesLabelPosition::UpperRight, 0.85)
}

pub(super) fn box_plots<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    study: &Study,
    _analysis: &Analysis,
) -> DrawResult<DB> {
    let values: Vec<f64> = study
        .done_fits()
        .flat_map(|d| d.evaluation.evaluated())
        .collect();
    per_sample_figure(
        root,
        study,
        "Fig. 11  ΔE00 over the 14 geometries",
        "ΔE00 (CIEDE2000)",
        &values,
        |chart, c, col, offset, width| {
            let mut first = true;
            for (i, s) in study.samples.iter().enumerate() {
                let Some(d) = s.done(c) else { continue };
                let Some([min, q1, med, q3, max]) = quartiles(&d.evaluation.evaluated()) else {
                    continue;
                };
                let x = i as f64 + offset;
                let label = first.then(|| format!("{c} ({})", study.method_of(c)));
                first = false;
                draw_box(chart, x, width, [q1, med, q3], col, 0.35, label)?;
                for (a, b) in [(min, q1), (q3, max)] {
                    chart.draw_series(std::iter::once(PathElement::new(
                        vec![(x, a), (x, b)],
                        col.stroke_width(1),
                    )))?;
                }
                for v in [min, max] {
                    chart.draw_series(std::iter::once(PathElement::new(
                        vec![(x - width * 0.2, v), (x + width * 0.2, v)],
                        col.stroke_width(1),
                    )))?;
                }
            }
            Ok(())
        },
    )
}

pub(super) type Pick = fn(&crate::report::analysis::CostSummary) -> Option<crate::stats::MeanCi>;

pub(super) fn mean_ci<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    study: &Study,
    analysis: &Analysis,
) -> DrawResult<DB> {
    let n_in = analysis.included.len();
    mean_ci_groups(
        root,
        study,
        analysis,
        &format!("Fig. 12  Mean ΔE00 per cost function, 95 % CI (n = {n_in} samples)"),
        "mean ΔE00 over samples",
        &[
            ("all 14 geometries", |s| s.all),
            ("diffuse (MA-T12)", |s| s.diffuse),
            ("specular (SRA)", |s| s.specular),
        ],
    )
}

/// Means with their 95 % CI: one group per `groups` entry on the x axis, in each one error bar
/// per cost function in its colour (as in every figure), named in the legend.
pub(super) fn mean_ci_groups<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    study: &Study,
    analysis: &Analysis,
    title: &str,
    y_desc: &str,
    groups: &[(&str, Pick)],
) -> DrawResult<DB> {
    let costs = &analysis.cost_functions;
    let hi = analysis
        .per_cost
        .iter()
        .flat_map(|s| groups.iter().filter_map(|g| (g.1)(s)).map(|ci| ci.hi))
        .fold(0.0f64, f64::max)
        * 1.35;
    let hi = if hi > 0.0 { hi } else { 1.0 };
    let names: Vec<&str> = groups.iter().map(|g| g.0).collect();
    let mut chart = ChartBuilder::on(root)
        .caption(title, font(24))
        .margin(20)
        .x_label_area_size(60)
        .y_label_area_size(70)
        .build_cartesian_2d(-0.5f64..(groups.len() as f64 - 0.5), 0f64..hi)?;
    chart
        .configure_mesh()
        .disable_x_mesh()
        .x_labels(groups.len().max(1))
        .x_label_formatter(&|x| {
            let i = x.round();
            if (x - i).abs() < 1e-6 && i >= 0.0 {
                names
                    .get(i as usize)
                    .copied()
                    .unwrap_or_default()
                    .to_string()
            } else {
                String::new()
            }
        })
        .x_desc("geometries the mean is over")
        .y_desc(y_desc)
        .label_style(font(15))
        .axis_desc_style(font(17))
        .draw()?;
    let m = costs.len().max(1) as f64;
    let step = (0.6 / m).min(0.2);
    for (j, summary) in analysis.per_cost.iter().enumerate() {
        let col = cost_colour(summary.cost);
        let offset = (j as f64 - (m - 1.0) / 2.0) * step;
        let pts: Vec<(f64, crate::stats::MeanCi)> = groups
            .iter()
            .enumerate()
            .filter_map(|(k, (_, pick))| pick(summary).map(|ci| (k as f64 + offset, ci)))
            .collect();
        chart
            .draw_series(pts.iter().map(|(x, ci)| {
                ErrorBar::new_vertical(*x, ci.lo, ci.mean, ci.hi, col.stroke_width(2), 14)
            }))?
            .label(format!(
                "{} ({})",
                summary.cost,
                study.method_of(summary.cost)
            ))
            .legend(move |(x, y)| Circle::new((x + 8, y), 6, col.filled()));
        chart.draw_series(
            pts.iter()
                .map(|(x, ci)| Circle::new((*x, ci.mean), 6, col.filled())),
        )?;
    }
    draw_legend(&mut chart, SeriesLabelPosition::UpperRight, 0.85)
}

/// Fig. 11b: specular |ΔL*| at sra-20 (filled) and sra-60 (open) per sample and cost function.
pub(super) fn specular_delta_l_points<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    study: &Study,
) -> DrawResult<DB> {
    let values: Vec<f64> = study
        .done_fits()
        .flat_map(|d| d.specular_delta_l.map(|l| l.per_geometry))
        .flatten()
        .collect();
    per_sample_figure(
        root,
        study,
        "Fig. 11b  Specular |ΔL*| (luminance)",
        "|ΔL*| at the SRA geometries",
        &values,
        |chart, c, col, offset, width| {
            let done: Vec<(f64, [f64; 2])> = study
                .samples
                .iter()
                .enumerate()
                .filter_map(|(i, s)| {
                    s.done(c)
                        .and_then(|d| d.specular_delta_l)
                        .map(|l| (i as f64 + offset, l.per_geometry))
                })
                .collect();
            chart
                .draw_series(
                    done.iter()
                        .map(|(x, v)| Circle::new((*x - width * 0.15, v[0]), 5, col.filled())),
                )?
                .label(format!("{c} ({})", study.method_of(c)))
                .legend(move |(x, y)| Circle::new((x + 8, y), 5, col.filled()));
            chart
                .draw_series(done.iter().map(|(x, v)| {
                    Circle::new((*x + width * 0.15, v[1]), 5, col.stroke_width(2))
                }))?;
            Ok(())
        },
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fonts::FONT;
    use crate::report::figures::tests::{El, svg_elements};
    use crate::report::figures::{Kind, figures, render};
    use crate::study::tests::study_from_truth;

    /// Fig. 11's sample names stay readable with 30+ samples: no two labels overlap (their
    /// extents measured with the report's font, turned as drawn), each lies inside the figure,
    /// and none is smaller than 12 px. They were written side by side however many there were.
    #[test]
    fn sample_labels_do_not_overlap_with_many_samples() {
        use ab_glyph::{Font, FontRef, ScaleFont};
        let base = study_from_truth(8, None);
        let mut study = Study::default();
        for k in 0..4 {
            for s in &base.samples {
                let mut s = s.clone();
                s.name = format!("{} (scan {})", s.name, 100 + k * 8 + study.samples.len());
                study.samples.push(s);
            }
        }
        let n = study.samples.len();
        assert!(n >= 30);
        let analysis = Analysis::of(&study);
        let dir = tempfile::tempdir().unwrap();
        let face = FontRef::try_from_slice(FONT).unwrap();
        for fig in figures(&study)
            .into_iter()
            .filter(|f| matches!(f.kind, Kind::BoxPlots | Kind::SpecularDeltaL))
        {
            let [_, svg] = render(&fig, &study, &analysis, dir.path()).unwrap();
            let (w, h) = (f64::from(fig.size.0), f64::from(fig.size.1));
            let names: Vec<&str> = study.samples.iter().map(|s| s.name.as_str()).collect();
            let labels: Vec<El> = svg_elements(&svg)
                .into_iter()
                .filter(|e| e.tag == "text" && names.contains(&e.text.as_str()))
                .collect();
            assert_eq!(labels.len(), n, "{}", fig.stem);
            // Each label's box: (x0, y0, x1, y1) in pixels.
            let boxes: Vec<[f64; 4]> = labels
                .iter()
                .map(|e| {
                    let px = e.num("font-size") * 1.24;
                    assert!(px >= 12.0 - 1e-6, "{}: {px} px", e.text);
                    let scaled = face.as_scaled(px as f32);
                    let mut len = 0.0f64;
                    let mut prev = None;
                    for c in e.text.chars() {
                        let id = face.glyph_id(c);
                        if let Some(p) = prev {
                            len += f64::from(scaled.kern(p, id));
                        }
                        len += f64::from(scaled.h_advance(id));
                        prev = Some(id);
                    }
                    let (x, y) = (e.num("x"), e.num("y"));
                    let along = match e.get("text-anchor") {
                        "end" => [-len, 0.0],
                        "middle" => [-len / 2.0, len / 2.0],
                        _ => [0.0, len],
                    };
                    if e.get("transform").starts_with("rotate(270") {
                        // Turned upright, reading upwards: along the text is up the page.
                        [x - px / 2.0, y - along[1], x + px / 2.0, y - along[0]]
                    } else {
                        assert_eq!(e.get("transform"), "", "{}", e.text);
                        [x + along[0], y - px / 2.0, x + along[1], y + px]
                    }
                })
                .collect();
            for (i, a) in boxes.iter().enumerate() {
                assert!(
                    a[0] >= 0.0 && a[1] >= 0.0 && a[2] <= w && a[3] <= h,
                    "{}: {} outside the figure: {a:?}",
                    fig.stem,
                    labels[i].text
                );
                for (j, b) in boxes.iter().enumerate().skip(i + 1) {
                    let overlap = a[0] < b[2] && b[0] < a[2] && a[1] < b[3] && b[1] < a[3];
                    assert!(
                        !overlap,
                        "{}: {} {a:?} overlaps {} {b:?}",
                        fig.stem, labels[i].text, labels[j].text
                    );
                }
            }
        }
    }

    #[test]
    fn quartiles_interpolate_like_r_type_7() {
        assert_eq!(quartiles(&[]), None);
        assert_eq!(quartiles(&[3.0]), Some([3.0; 5]));
        // R: quantile(c(1,2,3,4), c(0, .25, .5, .75, 1)) = 1, 1.75, 2.5, 3.25, 4
        assert_eq!(
            quartiles(&[4.0, 1.0, 3.0, 2.0]),
            Some([1.0, 1.75, 2.5, 3.25, 4.0])
        );
    }
}
