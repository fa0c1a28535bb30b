//! Fig. 4 and 7: measured (and estimated) colour per sample and geometry as sRGB swatches. A
//! geometry a sample's scan did not measure (the SRA's, for a scan without SRA readings) is a
//! hatched "not measured" cell, never a swatch; the SRA columns are left out when no sample
//! has them.

use plotters::coord::Shift;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};

use crate::cost::CostFunction;
use crate::fonts::font;
use crate::geometry::{GeometrySet, MA_T12_COUNT};
use crate::study::Study;

use super::style::srgb;
use super::{DrawResult, strategy};

/// A white triangle with a black edge in the top-right corner of a swatch: "clipped".
fn clip_mark<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    x1: i32,
    y0: i32,
) -> DrawResult<DB> {
    let tri = vec![(x1 - 14, y0), (x1, y0), (x1, y0 + 14)];
    root.draw(&Polygon::new(tri.clone(), WHITE.filled()))?;
    root.draw(&PathElement::new(
        vec![tri[0], tri[1], tri[2], tri[0]],
        BLACK.stroke_width(1),
    ))
}

/// A cell of a geometry the sample's scan did not measure: pale grey, hatched, labelled.
fn not_measured<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    x0: i32,
    y0: i32,
    w: i32,
    h: i32,
) -> DrawResult<DB> {
    let grey = RGBColor(150, 150, 150);
    root.draw(&Rectangle::new(
        [(x0, y0), (x0 + w, y0 + h)],
        NOT_MEASURED.filled(),
    ))?;
    // Diagonal hatching, clipped to the cell.
    let mut k = -h;
    while k < w {
        let (a, b) = (
            (x0 + k.max(0), y0 + (k.max(0) - k)),
            (x0 + (k + h).min(w), y0 + ((k + h).min(w) - k)),
        );
        root.draw(&PathElement::new(vec![a, b], grey.stroke_width(1)))?;
        k += 8;
    }
    // One label, on two lines so that it fits the cell.
    for (line, dy) in [("not", -7), ("measured", 7)] {
        root.draw(&Text::new(
            line,
            (x0 + w / 2, y0 + h / 2 + dy),
            font(12).pos(Pos::new(HPos::Center, VPos::Center)),
        ))?;
    }
    root.draw(&Rectangle::new(
        [(x0, y0), (x0 + w, y0 + h)],
        RGBColor(120, 120, 120).stroke_width(1),
    ))
}

/// The fill of a "not measured" cell.
pub(super) const NOT_MEASURED: RGBColor = RGBColor(236, 236, 236);

pub(super) fn swatches<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    study: &Study,
    cost: Option<CostFunction>,
) -> DrawResult<DB> {
    let title = match cost {
        None => format!(
            "Fig. 4  Measured colour per geometry (sRGB, D65, 2°) — SRA: {} strategy",
            strategy(study)
        ),
        Some(c) => format!(
            "Fig. 7  Measured (top) vs estimated (bottom) colour — cost function {c}, method {}",
            study.method_of(c)
        ),
    };
    root.draw(&Text::new(title, (20, 14), font(22)))?;
    let (left, top, w, h, gap) = (230, 110, 64, 40, 24);
    let x_of = |g: usize| left + (g as i32) * (w + 4) + if g >= MA_T12_COUNT { gap } else { 0 };
    root.draw(&Text::new(
        "diffuse: X-Rite MA-T12 (detector°as aspecular°)",
        (left, 52),
        font(15),
    ))?;
    // The SRA columns only when some sample has SRA readings; a sample without them shows
    // "not measured" there, never a swatch.
    let columns = if study
        .samples
        .iter()
        .any(|s| s.measured.geometries.has_sra())
    {
        root.draw(&Text::new(
            "specular: SRA",
            (x_of(MA_T12_COUNT), 52),
            font(15),
        ))?;
        GeometrySet::ALL
    } else {
        GeometrySet::MA_T12
    };
    for g in columns.iter() {
        root.draw(&Text::new(
            g.name,
            (x_of(g.index) + w / 2, top - 14),
            font(14).pos(Pos::new(HPos::Center, VPos::Center)),
        ))?;
    }
    for (i, s) in study.samples.iter().enumerate() {
        let y0 = top + (i as i32) * (h + 6);
        root.draw(&Text::new(
            s.name.clone(),
            (left - 12, y0 + h / 2),
            font(16).pos(Pos::new(HPos::Right, VPos::Center)),
        ))?;
        let estimated = cost.map(|c| s.done(c).map(|d| d.estimated));
        for g in columns.iter() {
            let x0 = x_of(g.index);
            if !s.measured.geometries.contains(g.index) {
                not_measured(root, x0, y0, w, h)?;
                continue;
            }
            let (m, m_clip) = srgb(&s.measured.values[g.index]);
            match estimated {
                None => {
                    root.draw(&Rectangle::new([(x0, y0), (x0 + w, y0 + h)], m.filled()))?;
                    if m_clip {
                        clip_mark(root, x0 + w, y0)?;
                    }
                }
                Some(est) => {
                    root.draw(&Rectangle::new(
                        [(x0, y0), (x0 + w, y0 + h / 2)],
                        m.filled(),
                    ))?;
                    if m_clip {
                        clip_mark(root, x0 + w, y0)?;
                    }
                    match est {
                        Some(e) => {
                            let (c, c_clip) = srgb(&e[g.index]);
                            root.draw(&Rectangle::new(
                                [(x0, y0 + h / 2), (x0 + w, y0 + h)],
                                c.filled(),
                            ))?;
                            if c_clip {
                                let tri = vec![
                                    (x0 + w - 12, y0 + h),
                                    (x0 + w, y0 + h),
                                    (x0 + w, y0 + h - 12),
                                ];
                                root.draw(&Polygon::new(tri.clone(), WHITE.filled()))?;
                                root.draw(&PathElement::new(
                                    vec![tri[0], tri[1], tri[2], tri[0]],
                                    BLACK.stroke_width(1),
                                ))?;
                            }
                        }
                        None => {
                            root.draw(&Text::new(
                                "no fit",
                                (x0 + w / 2, y0 + 3 * h / 4),
                                font(12).pos(Pos::new(HPos::Center, VPos::Center)),
                            ))?;
                        }
                    }
                }
            }
            root.draw(&Rectangle::new(
                [(x0, y0), (x0 + w, y0 + h)],
                RGBColor(120, 120, 120).stroke_width(1),
            ))?;
        }
    }
    let y = top + (study.samples.len() as i32) * (h + 6) + 14;
    clip_mark(root, left + 14, y)?;
    root.draw(&Text::new(
        "clipped: outside the sRGB gamut (e.g. brighter than white at a specular geometry); the swatch shows the nearest displayable colour",
        (left + 24, y + 7),
        font(14).pos(Pos::new(HPos::Left, VPos::Center)),
    ))?;
    Ok(())
}
