//! How figures tell things apart: the cost functions' colours, line widths and marker sizes,
//! and each sample's own colour and marker shape.

use plotters::coord::{CoordTranslate, Shift};
use plotters::prelude::*;

use crate::colour::{brdf_to_reflectance, reflectance_to_xyz, xyz_to_srgb8};
use crate::cost::CostFunction;
use crate::fonts::font;
use crate::geometry::{Device, GEOMETRIES};
use crate::spectral::Spectrum;
use crate::study::{SampleStudy, Study};

use super::DrawResult;

/// Okabe & Ito (2008) colour-blind-safe palette, black first.
const PALETTE: [RGBColor; 8] = [
    RGBColor(0, 0, 0),
    RGBColor(230, 159, 0),
    RGBColor(86, 180, 233),
    RGBColor(0, 158, 115),
    RGBColor(240, 228, 66),
    RGBColor(0, 114, 178),
    RGBColor(213, 94, 0),
    RGBColor(204, 121, 167),
];

/// Colour of a cost function's estimates, in every figure. No other name is drawn in these
/// colours: the samples of Fig. 5 and 6 are drawn in their own colour, and Fig. 12's groups
/// stand on the x axis, coloured by cost function.
pub(super) fn cost_colour(c: CostFunction) -> RGBColor {
    match c {
        CostFunction::Cf1 => PALETTE[5],
        CostFunction::Cf2 => PALETTE[6],
        CostFunction::M2 => PALETTE[3],
    }
}

/// Line width of a cost function's estimates. Cost functions are drawn in
/// [`CostFunction::ALL`] order, widest first, so estimates that coincide show as nested
/// lines (a cf1 line under an identical m2 line stays visible around it).
pub(super) fn cost_width(c: CostFunction) -> u32 {
    match c {
        CostFunction::Cf1 => 7,
        CostFunction::Cf2 => 5,
        CostFunction::M2 => 3,
    }
}

/// Radius of a cost function's point markers: largest first, as [`cost_width`].
pub(super) fn cost_radius(c: CostFunction) -> i32 {
    match c {
        CostFunction::Cf1 => 8,
        CostFunction::Cf2 => 6,
        CostFunction::M2 => 4,
    }
}

/// Draws the chart's legend of its labelled series at `position`, on white at `opacity`,
/// framed in black.
pub(super) fn draw_legend<'a, DB: DrawingBackend + 'a, CT: CoordTranslate>(
    chart: &mut ChartContext<'a, DB, CT>,
    position: SeriesLabelPosition,
    opacity: f64,
) -> DrawResult<DB> {
    chart
        .configure_series_labels()
        .position(position)
        .background_style(WHITE.mix(opacity))
        .border_style(BLACK)
        .label_font(font(15))
        .draw()
}

/// The shapes that tell samples of similar colour apart.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Marker {
    Circle,
    Square,
    Triangle,
    Diamond,
    Cross,
}

const MARKERS: [Marker; 5] = [
    Marker::Circle,
    Marker::Square,
    Marker::Triangle,
    Marker::Diamond,
    Marker::Cross,
];

/// Draws `m` centred on pixel `at` of `area`, radius `r`.
pub(super) fn marker_at<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    m: Marker,
    at: (i32, i32),
    r: i32,
    col: RGBColor,
) -> DrawResult<DB> {
    let (x, y) = at;
    match m {
        Marker::Circle => area.draw(&Circle::new(at, r, col.filled())),
        Marker::Square => area.draw(&Rectangle::new(
            [(x - r + 1, y - r + 1), (x + r - 1, y + r - 1)],
            col.filled(),
        )),
        Marker::Triangle => area.draw(&Polygon::new(
            vec![(x, y - r - 1), (x - r, y + r - 1), (x + r, y + r - 1)],
            col.filled(),
        )),
        Marker::Diamond => area.draw(&Polygon::new(
            vec![
                (x, y - r - 1),
                (x + r + 1, y),
                (x, y + r + 1),
                (x - r - 1, y),
            ],
            col.filled(),
        )),
        Marker::Cross => {
            area.draw(&PathElement::new(
                vec![(x - r, y - r), (x + r, y + r)],
                col.stroke_width(3),
            ))?;
            area.draw(&PathElement::new(
                vec![(x - r, y + r), (x + r, y - r)],
                col.stroke_width(3),
            ))
        }
    }
}

/// How a sample is drawn where samples are told apart by colour (Fig. 5 and 6).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct SampleStyle {
    pub(super) colour: RGBColor,
    pub(super) marker: Marker,
}

/// The colour of a sample: its own measured colour (the mean of its diffuse readings as
/// sRGB, D65), darkened where needed to stand out on white, so that the line of "T.Sky blue"
/// is blue and that of "T.Mandarin orange" orange. A function of the sample's data, not of
/// its place in the study: the same sample has the same colour in every figure and report.
fn sample_colour(s: &SampleStudy) -> RGBColor {
    let diffuse: Vec<&Spectrum> = GEOMETRIES
        .iter()
        .filter(|g| g.device == Device::MaT12 && s.measured.geometries.contains(g.index))
        .map(|g| &s.measured.values[g.index])
        .collect();
    if diffuse.is_empty() {
        return RGBColor(90, 90, 90);
    }
    let mut mean: Spectrum = [0.0; crate::spectral::BANDS];
    for f in &diffuse {
        for (m, v) in mean.iter_mut().zip(f.iter()) {
            *m += v / diffuse.len() as f64;
        }
    }
    let (c, _) = srgb(&mean);
    readable_on_white(c)
}

/// `c` with its linear RGB scaled down (hue and saturation kept) until its luminance gives a
/// contrast of at least 4.5 : 1 against white (WCAG 2), so thin lines and markers read.
fn readable_on_white(c: RGBColor) -> RGBColor {
    let lin = |v: u8| {
        let v = f64::from(v) / 255.0;
        if v <= 0.04045 {
            v / 12.92
        } else {
            ((v + 0.055) / 1.055).powf(2.4)
        }
    };
    let enc = |v: f64| {
        let v = if v <= 0.003_130_8 {
            12.92 * v
        } else {
            1.055 * v.powf(1.0 / 2.4) - 0.055
        };
        (v.clamp(0.0, 1.0) * 255.0).round() as u8
    };
    let (r, g, b) = (lin(c.0), lin(c.1), lin(c.2));
    let y = 0.2126 * r + 0.7152 * g + 0.0722 * b;
    // (1 + 0.05) / (Y + 0.05) ≥ 4.5  ⇔  Y ≤ 0.1833; a little below for rounding.
    const MAX_Y: f64 = 0.18;
    let k = if y > MAX_Y { MAX_Y / y } else { 1.0 };
    RGBColor(enc(r * k), enc(g * k), enc(b * k))
}

/// Every sample's style, keyed by its name: its own colour, and a marker shape taken in turn
/// so that samples of similar colour are still told apart.
pub(super) fn sample_styles(study: &Study) -> Vec<(String, SampleStyle)> {
    study
        .samples
        .iter()
        .enumerate()
        .map(|(i, s)| {
            (
                s.name.clone(),
                SampleStyle {
                    colour: sample_colour(s),
                    marker: MARKERS[i % MARKERS.len()],
                },
            )
        })
        .collect()
}

pub(super) fn srgb(f: &Spectrum) -> (RGBColor, bool) {
    let c = xyz_to_srgb8(reflectance_to_xyz(&brdf_to_reflectance(f)));
    (RGBColor(c.rgb[0], c.rgb[1], c.rgb[2]), c.clipped)
}
