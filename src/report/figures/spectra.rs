//! Fig. 8: measured and estimated reflectance factor against wavelength per geometry for one
//! sample, with the estimates' 95 % bands and notes on estimates that coincide.

use plotters::coord::Shift;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};

use crate::colour::brdf_to_reflectance;
use crate::cost::CostFunction;
use crate::fonts::font;
use crate::geometry::{GEOMETRIES, GEOMETRY_COUNT};
use crate::spectral::{Spectrum, wavelengths_nm};
use crate::study::{SampleStudy, Study};

use super::DrawResult;
use super::style::{cost_colour, cost_width};

/// `text` broken at spaces into lines no wider than `width` pixels in `style`.
fn wrap<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    text: &str,
    style: TextStyle<'static>,
    width: i32,
) -> Vec<String> {
    let fits = |t: &str| {
        area.estimate_text_size(t, &style)
            .map_or(true, |(w, _)| w as i32 <= width)
    };
    let mut lines: Vec<String> = Vec::new();
    let mut line = String::new();
    for word in text.split(' ') {
        let next = if line.is_empty() {
            word.to_string()
        } else {
            format!("{line} {word}")
        };
        if fits(&next) || line.is_empty() {
            line = next;
        } else {
            lines.push(std::mem::take(&mut line));
            line = word.to_string();
        }
    }
    if !line.is_empty() {
        lines.push(line);
    }
    lines
}

fn legend_costs<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    study: &Study,
    x: i32,
    y: i32,
) -> DrawResult<DB> {
    for (k, c) in study.cost_functions().into_iter().enumerate() {
        let yy = y + 26 * (k as i32 + 1);
        area.draw(&PathElement::new(
            vec![(x, yy), (x + 28, yy)],
            cost_colour(c).stroke_width(cost_width(c)),
        ))?;
        area.draw(&Text::new(
            format!("estimated, {c} ({})", study.method_of(c)),
            (x + 36, yy),
            font(16).pos(Pos::new(HPos::Left, VPos::Center)),
        ))?;
    }
    area.draw(&PathElement::new(
        vec![(x, y), (x + 28, y)],
        BLACK.stroke_width(2),
    ))?;
    area.draw(&Text::new(
        "measured",
        (x + 36, y),
        font(16).pos(Pos::new(HPos::Left, VPos::Center)),
    ))?;
    Ok(())
}

/// The pairs of cost functions whose estimates of `s` lie so close at every geometry and band
/// (within 1 % of the largest reflectance factor drawn) that their lines coincide in Fig. 8,
/// with the largest difference.
fn coinciding_estimates(s: &SampleStudy) -> Vec<(CostFunction, CostFunction, f64)> {
    let est: Vec<(CostFunction, &[Spectrum; GEOMETRY_COUNT])> = s
        .fits
        .iter()
        .filter_map(|f| f.done().map(|d| (f.cost, &d.estimated)))
        .collect();
    let shown = |g: &&crate::geometry::Geometry| s.measured.geometries.contains(g.index);
    let scale = GEOMETRIES
        .iter()
        .filter(shown)
        .flat_map(|g| {
            brdf_to_reflectance(&s.measured.values[g.index])
                .into_iter()
                .chain(
                    est.iter()
                        .flat_map(|(_, e)| brdf_to_reflectance(&e[g.index])),
                )
        })
        .fold(0.0f64, f64::max);
    let mut out = Vec::new();
    for (k, (a, ea)) in est.iter().enumerate() {
        for (b, eb) in &est[k + 1..] {
            let diff = GEOMETRIES
                .iter()
                .filter(shown)
                .flat_map(|g| {
                    let (ra, rb) = (
                        brdf_to_reflectance(&ea[g.index]),
                        brdf_to_reflectance(&eb[g.index]),
                    );
                    (0..ra.len()).map(move |i| (ra[i] - rb[i]).abs())
                })
                .fold(0.0f64, f64::max);
            if diff <= 0.01 * scale {
                out.push((*a, *b, diff));
            }
        }
    }
    out
}

pub(super) fn spectra<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    study: &Study,
    index: usize,
) -> DrawResult<DB> {
    let s: &SampleStudy = &study.samples[index];
    let titled = root.titled(
        &format!(
            "Fig. 8  Measured vs estimated reflectance factor per geometry — sample \"{}\"",
            s.name
        ),
        font(24),
    )?;
    let panels = titled.split_evenly((4, 4));
    let nm = wavelengths_nm();
    // A scan without specular readings gets no SRA panels (nothing was measured there).
    for (g, panel) in GEOMETRIES
        .iter()
        .filter(|g| s.measured.geometries.contains(g.index))
        .zip(&panels)
    {
        let measured = brdf_to_reflectance(&s.measured.values[g.index]);
        let estimates: Vec<(CostFunction, Spectrum)> = s
            .fits
            .iter()
            .filter_map(|f| {
                f.done()
                    .map(|d| (f.cost, brdf_to_reflectance(&d.estimated[g.index])))
            })
            .collect();
        // 95 % bands of the fits that have bootstrap intervals (SCIENCE.md §10), drawn as
        // error bars at each band centre.
        let bands: Vec<(CostFunction, [Spectrum; 2])> = s
            .fits
            .iter()
            .filter_map(|f| {
                let [lo, hi] = crate::formats::estimate_band(f.done()?)?;
                Some((f.cost, [lo[g.index], hi[g.index]]))
            })
            .collect();
        let all = measured
            .iter()
            .chain(estimates.iter().flat_map(|(_, e)| e.iter()))
            .chain(bands.iter().flat_map(|(_, [_, hi])| hi.iter()));
        let hi = all.fold(0.0f64, |m, v| m.max(*v)) * 1.08;
        let hi = if hi > 0.0 { hi } else { 1.0 };
        let mut chart = ChartBuilder::on(panel)
            .caption(format!("{} ({})", g.name, g.device), font(16))
            .margin(8)
            .margin_right(18)
            .x_label_area_size(36)
            .y_label_area_size(54)
            .build_cartesian_2d(400f64..700f64, 0f64..hi)?;
        chart
            .configure_mesh()
            .x_labels(4)
            .y_labels(5)
            .x_label_formatter(&|x| format!("{x:.0}"))
            .x_desc("wavelength (nm)")
            .y_desc("reflectance factor")
            .label_style(font(12))
            .axis_desc_style(font(13))
            .draw()?;
        // Estimates widest first (cf1, cf2, m2), then the measurement on top: lines that
        // coincide stay visible as nested lines.
        for (c, e) in &estimates {
            chart.draw_series(LineSeries::new(
                nm.iter().zip(e).map(|(&w, &v)| (f64::from(w), v)),
                cost_colour(*c).stroke_width(cost_width(*c)),
            ))?;
        }
        chart.draw_series(LineSeries::new(
            nm.iter().zip(&measured).map(|(&w, &v)| (f64::from(w), v)),
            BLACK.stroke_width(2),
        ))?;
        for (c, [lo, hi]) in &bands {
            for (k, &w) in nm.iter().enumerate() {
                chart.draw_series(LineSeries::new(
                    [(f64::from(w), lo[k]), (f64::from(w), hi[k])],
                    cost_colour(*c).stroke_width(1),
                ))?;
            }
        }
    }
    let legend = &panels[GEOMETRY_COUNT];
    legend_costs(legend, study, 20, 40)?;
    let mut notes: Vec<String> = s.fits.iter().filter_map(|f| f.problem()).collect();
    for (a, b, diff) in coinciding_estimates(s) {
        notes.push(format!(
            "{a} and {b} coincide (within {diff:.4} in R): the {a} line is the wider one beneath"
        ));
    }
    let done = s.fits.iter().filter(|f| f.done().is_some()).count();
    if done > 0
        && !s
            .fits
            .iter()
            .any(|f| f.done().is_some_and(|d| d.uncertainty.is_some()))
    {
        notes.push("no error bars: these fits have no bootstrap intervals".into());
    }
    let (w, _) = legend.dim_in_pixel();
    let mut y = 40 + 26 * (study.cost_functions().len() as i32 + 1);
    for m in notes {
        for line in wrap(legend, &m, font(14), w as i32 - 30) {
            legend.draw(&Text::new(line, (20, y), font(14)))?;
            y += 19;
        }
        y += 4;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fonts::register_font;
    use crate::report::analysis::Analysis;
    use crate::report::figures::tests::svg_elements;
    use crate::report::figures::{Kind, draw, figures, render};
    use crate::study::tests::study_from_truth;

    /// Estimates that coincide are all visible: with cf1 and m2 fitted to the same parameters
    /// (the same estimate to the last bit), the cf1 line still shows in every panel of Fig. 8,
    /// and the figure says that the two coincide. m2 was drawn over cf1, hiding it.
    #[test]
    fn coinciding_estimates_stay_visible_in_fig_8() {
        let mut study = study_from_truth(1, None);
        let cf1 = study.samples[0].fits[0].clone();
        study.samples[0].fits[2].state = cf1.state.clone();
        assert_eq!(
            study.samples[0].done(CostFunction::Cf1).unwrap().estimated,
            study.samples[0].done(CostFunction::M2).unwrap().estimated
        );
        register_font();
        let analysis = Analysis::of(&study);
        let fig = figures(&study)
            .into_iter()
            .find(|f| f.kind == Kind::Spectra(0))
            .unwrap();
        let (w, h) = fig.size;
        let mut buf = vec![255u8; (w * h * 3) as usize];
        {
            let root = BitMapBackend::with_buffer(&mut buf, (w, h)).into_drawing_area();
            draw(&fig, &study, &analysis, &root).unwrap();
            root.present().unwrap();
        }
        let colour = |c: RGBColor, x0: u32, y0: u32, x1: u32, y1: u32| -> usize {
            let mut n = 0;
            for y in y0..y1 {
                for x in x0..x1 {
                    let i = ((y * w + x) * 3) as usize;
                    if buf[i..i + 3] == [c.0, c.1, c.2] {
                        n += 1;
                    }
                }
            }
            n
        };
        // The 14 panels in a 4 × 4 grid under the title; the legend is the 15th.
        let top = 40;
        let (pw, ph) = (w / 4, (h - top) / 4);
        for k in 0..GEOMETRY_COUNT as u32 {
            let (x0, y0) = ((k % 4) * pw, top + (k / 4) * ph);
            for c in CostFunction::ALL {
                let n = colour(cost_colour(c), x0, y0, x0 + pw, y0 + ph);
                assert!(n > 150, "panel {k}: {n} pixels of the {c} line");
            }
        }
        let dir = tempfile::tempdir().unwrap();
        let [_, svg] = render(&fig, &study, &analysis, dir.path()).unwrap();
        let texts: String = svg_elements(&svg)
            .iter()
            .filter(|e| e.tag == "text")
            .map(|e| e.text.clone() + " ")
            .collect();
        assert!(
            texts.contains(
                "cf1 and m2 coincide (within 0.0000 in R): the cf1 line is the wider one beneath"
            ),
            "{texts}"
        );
    }
}
