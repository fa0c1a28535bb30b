//! The paper's figures 4–12 and Fig. 13, where the model misses (SCIENCE.md §9), drawn with plotters into PNG (bitmap backend)
//! and SVG from one drawing routine per figure.
//!
//! Text is rendered with the embedded DejaVu Sans (`fonts/`), registered with plotters'
//! `ab_glyph` renderer, so no installed font is needed. Colours: black for measured data, and
//! the Okabe–Ito colour-blind-safe palette for cost functions and samples. Every figure's title
//! names the method and cost function(s); axes say their quantity and unit.

use std::path::{Path, PathBuf};

use plotters::coord::Shift;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};

use crate::colour::{Lab, brdf_to_reflectance, reflectance_to_xyz, xyz_to_srgb8};
use crate::cost::CostFunction;
use crate::evaluation::lab_per_geometry;
use crate::geometry::{Device, GEOMETRIES, GEOMETRY_COUNT, MA_T12_COUNT};
use crate::spectral::{Spectrum, wavelengths_nm};

use super::ReportError;
use super::analysis::Analysis;
use crate::fonts::{font, register_font};
use crate::study::{SampleStudy, Study, simulated_statement};

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
fn cost_colour(c: CostFunction) -> RGBColor {
    match c {
        CostFunction::Cf1 => PALETTE[5],
        CostFunction::Cf2 => PALETTE[6],
        CostFunction::M2 => PALETTE[3],
    }
}

/// Line width of a cost function's estimates. Cost functions are drawn in
/// [`CostFunction::ALL`] order, widest first, so estimates that coincide show as nested
/// lines (a cf1 line under an identical m2 line stays visible around it).
fn cost_width(c: CostFunction) -> u32 {
    match c {
        CostFunction::Cf1 => 7,
        CostFunction::Cf2 => 5,
        CostFunction::M2 => 3,
    }
}

/// Radius of a cost function's point markers: largest first, as [`cost_width`].
fn cost_radius(c: CostFunction) -> i32 {
    match c {
        CostFunction::Cf1 => 8,
        CostFunction::Cf2 => 6,
        CostFunction::M2 => 4,
    }
}

/// The shapes that tell samples of similar colour apart.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Marker {
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
fn marker_at<DB: DrawingBackend>(
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
struct SampleStyle {
    colour: RGBColor,
    marker: Marker,
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
fn sample_styles(study: &Study) -> Vec<(String, SampleStyle)> {
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

type DrawResult<DB> = Result<(), DrawingAreaErrorKind<<DB as DrawingBackend>::ErrorType>>;

/// One figure of the report.
#[derive(Debug, Clone, PartialEq)]
pub struct Figure {
    /// File stem: `<stem>.png` and `<stem>.svg`.
    pub stem: String,
    /// The caption the summary prints under it.
    pub caption: String,
    kind: Kind,
    size: (u32, u32),
    /// What the figure itself says under its drawing when it shows simulated scans ("simulated
    /// — replayed from …"), and a short form for when that does not fit its width.
    note: Option<[String; 2]>,
}

impl Figure {
    /// Whether the figure is drawn from the study's samples one by one (swatches, spectra,
    /// lightness panels, box plots), as opposed to its summary statistics (Fig. 12).
    pub fn per_sample(&self) -> bool {
        !matches!(self.kind, Kind::MeanCi | Kind::MeanDeltaL)
    }
}

#[derive(Debug, Clone, PartialEq)]
enum Kind {
    MeasuredSwatches,
    LightnessDiffuse,
    LightnessSpecular,
    EstimatedSwatches(CostFunction),
    Spectra(usize),
    LightnessPerDetector(f64),
    BoxPlots,
    MeanCi,
    LuminanceSpecular,
    SpecularDeltaL,
    MeanDeltaL,
    ResidualLightness,
}

fn methods(study: &Study) -> String {
    let m = study.methods();
    if m.is_empty() {
        "none".into()
    } else {
        m.join(" + ")
    }
}

fn strategy(study: &Study) -> String {
    study
        .specular_strategies()
        .iter()
        .map(|s| s.name())
        .collect::<Vec<_>>()
        .join(" + ")
}

/// The figures of a study, in the paper's order.
pub fn figures(study: &Study) -> Vec<Figure> {
    figures_for(study, study)
}

/// Height of the strip under a figure that says its scans are simulated.
const NOTE_STRIP: u32 = 30;

/// What a caption and a figure say of the simulated scans among `samples`: the sentence for the
/// caption, and the figure's own note (long and short forms). `None` when none is simulated.
fn simulated_texts(samples: &[SampleStudy]) -> Option<(String, [String; 2])> {
    let (said, all) = simulated_statement(samples)?;
    let sims: Vec<&SampleStudy> = samples
        .iter()
        .filter(|s| s.simulated_note().is_some())
        .collect();
    let recordings = {
        let mut r: Vec<String> = sims.iter().filter_map(|s| s.recording()).collect();
        r.dedup();
        r.len()
    };
    let caption = if all && samples.len() == 1 {
        format!(" This scan is {said}, not a measurement.")
    } else if all {
        format!(" Every scan shown is {said}, not a measurement.")
    } else {
        format!(
            " Of the scans shown, {} {} {said}, not measurements.",
            sims.iter()
                .map(|s| s.name.as_str())
                .collect::<Vec<_>>()
                .join(", "),
            if sims.len() == 1 { "is" } else { "are" }
        )
    };
    let long = if all {
        said.clone()
    } else {
        format!(
            "{} of the {} scans shown: {said}",
            sims.len(),
            samples.len()
        )
    };
    let short = format!(
        "{}simulated — replayed from {recordings} recording{} (named in the report's caption and Table 5)",
        if all {
            String::new()
        } else {
            format!("{} of the {} scans shown: ", sims.len(), samples.len())
        },
        if recordings == 1 { "" } else { "s" }
    );
    Some((caption, [long, short]))
}

/// [`figures`] of `drawn` (the samples the per-sample figures show) for a report whose
/// statistics (Fig. 12, 12b) cover `all`.
pub(crate) fn figures_for(drawn: &Study, all: &Study) -> Vec<Figure> {
    let mut out = figure_list(drawn);
    let on_drawn = simulated_texts(&drawn.samples);
    let on_all = simulated_texts(&all.samples);
    for f in &mut out {
        let texts = match f.kind {
            Kind::Spectra(i) => simulated_texts(std::slice::from_ref(&drawn.samples[i])),
            Kind::MeanCi | Kind::MeanDeltaL => on_all.clone(),
            _ => on_drawn.clone(),
        };
        if let Some((caption, note)) = texts {
            f.caption.push_str(&caption);
            f.note = Some(note);
            f.size.1 += NOTE_STRIP;
        }
    }
    out
}

fn figure_list(study: &Study) -> Vec<Figure> {
    let n = study.samples.len().max(1) as u32;
    let costs = study.cost_functions();
    let cost_list = costs
        .iter()
        .map(|c| c.name())
        .collect::<Vec<_>>()
        .join(", ");
    let method = methods(study);
    let strat = strategy(study);
    let swatch_h = 140 + 46 * n;
    // Fig. 5 and 6: a legend row of 22 px per sample beside the plot.
    let lines_h = 720.max(110 + 22 * n);
    let names: Vec<&str> = study.samples.iter().map(|s| s.name.as_str()).collect();
    let mut out = vec![
        Figure {
            stem: "fig04-measured-swatches".into(),
            caption: format!(
                "Fig. 4. Measured colour of each sample at the 12 diffuse (MA-T12) and 2 specular (SRA) geometries, as sRGB swatches (CIE D65, 2° observer). Swatches marked with a white triangle are clipped: outside the sRGB gamut, typically brighter than white at the specular geometries. SRA readings processed with the {strat} strategy. Measured data: no fit, no cost function."
            ),
            kind: Kind::MeasuredSwatches,
            size: (1280, swatch_h),
            note: None,
        },
        Figure {
            stem: "fig05-lightness-diffuse".into(),
            caption: "Fig. 5. CIELAB lightness L* of the measured diffuse readings (MA-T12) per geometry and sample (D65, 2°). Measured data: no fit, no cost function.".into(),
            kind: Kind::LightnessDiffuse,
            size: (1440, lines_h),
            note: None,
        },
        Figure {
            stem: "fig06-lightness-specular".into(),
            caption: format!("Fig. 6. CIELAB lightness L* of the measured specular readings (SRA, spread flat over the bands, {strat} strategy) per sample; L* above 100 is brighter than the reference white. Measured data: no fit, no cost function."),
            kind: Kind::LightnessSpecular,
            size: (1240, lines_h),
            note: None,
        },
        Figure {
            stem: "fig06b-luminance-specular".into(),
            caption: format!("Fig. 6b (luminance view of Fig. 6). CIELAB L* of the luminance at the two SRA geometries, measured (the reading) against estimated (the fitted model's luminance), per sample and cost function ({cost_list}), method {method}; luminance under {}. On the diagonal the fit reproduces what the SRA reads; this is the luminance metric, not the paper's ΔE00 against the grey spectrum.", instrument(study)),
            kind: Kind::LuminanceSpecular,
            size: (1000, 760),
            note: None,
        },
    ];
    for &c in &costs {
        out.push(Figure {
            stem: format!("fig07-swatches-{c}"),
            caption: format!(
                "Fig. 7 ({c}). Measured (upper half) vs estimated (lower half) colour per sample and geometry, sRGB swatches (D65, 2°); estimates of the model fitted with cost function {c}, method {}. White triangles mark clipped swatches.",
                study.method_of(c)
            ),
            kind: Kind::EstimatedSwatches(c),
            size: (1280, swatch_h),
            note: None,
        });
    }
    for (i, s) in study.samples.iter().enumerate() {
        let done = s.fits.iter().filter_map(|f| f.done()).count();
        let with = s
            .fits
            .iter()
            .filter(|f| f.done().is_some_and(|d| d.uncertainty.is_some()))
            .count();
        let bars = if with == 0 {
            " No error bars: none of this sample's fits has bootstrap intervals (the summary says why)."
                .to_string()
        } else if with < done {
            format!(
                " Error bars: the 95 % bootstrap intervals of the estimates, for the {with} of its {done} fits that have them."
            )
        } else {
            " Error bars: the 95 % bootstrap intervals of the estimates.".to_string()
        };
        out.push(Figure {
            stem: format!("fig08-spectra-{}", crate::names::slug(&s.name)),
            caption: format!(
                "Fig. 8 ({}). Measured (black) and estimated reflectance factor R = π·f against wavelength at each of the 14 geometries for sample \"{}\"; estimates per cost function ({cost_list}), method {method}, drawn widest first so that estimates which coincide show as nested lines.{bars}",
                s.name, s.name
            ),
            kind: Kind::Spectra(i),
            size: (1400, 1100),
            note: None,
        });
    }
    let cols = n.min(4);
    let rows = n.div_ceil(cols);
    for (fig, detector) in [(9, 15.0), (10, 45.0)] {
        out.push(Figure {
            stem: format!("fig{fig:02}-lightness-{detector}deg"),
            caption: format!(
                "Fig. {fig}. CIELAB lightness L* per aspecular angle at the MA-T12's {detector}° detector, measured (black) vs estimated per cost function ({cost_list}), method {method}, one panel per sample."
            ),
            kind: Kind::LightnessPerDetector(detector),
            size: (340 * cols + 60, 300 * rows + 120),
            note: None,
        });
    }
    out.push(Figure {
        stem: "fig11-delta-e-boxplots".into(),
        caption: format!(
            "Fig. 11. ΔE00 between measured and estimated colour over the 14 geometries, per sample and cost function ({cost_list}), method {method}: box from first to third quartile, line at the median, whiskers to the smallest and largest value. At the 2 SRA geometries this is the paper's metric, ΔE00 against the grey spectrum the reading is spread into; Fig. 11b shows the luminance metric."
        ),
        kind: Kind::BoxPlots,
        size: per_sample_size(&names),
        note: None,
    });
    out.push(Figure {
        stem: "fig11b-specular-delta-l".into(),
        caption: format!(
            "Fig. 11b (luminance view of Fig. 11). Specular |ΔL*| between the model's and the measured luminance at sra-20 (filled) and sra-60 (open), per sample and cost function ({cost_list}), method {method}; luminance under {}. The luminance metric, not the paper's ΔE00 against the grey spectrum that Fig. 11 includes at the SRA geometries.",
            instrument(study)
        ),
        kind: Kind::SpecularDeltaL,
        size: per_sample_size(&names),
        note: None,
    });
    out.push(Figure {
        stem: "fig12-mean-delta-e".into(),
        caption: format!(
            "Fig. 12. Mean ΔE00 over the samples that take part in the comparison, per cost function ({cost_list}), method {method}, over all 14 geometries and split into diffuse and specular (the paper's specular metric, ΔE00 against the grey spectrum; Fig. 12b shows the luminance metric); error bars are 95 % confidence intervals (Student t)."
        ),
        kind: Kind::MeanCi,
        size: (1000, 700),
        note: None,
    });
    out.push(Figure {
        stem: "fig12b-mean-specular-delta-l".into(),
        caption: format!(
            "Fig. 12b (luminance view of Fig. 12). Mean over the samples that take part of each sample's mean specular |ΔL*| (model vs measured luminance at the SRA geometries, under {}), per cost function ({cost_list}), method {method}; error bars are 95 % confidence intervals (Student t). Fig. 12's specular group is the paper's ΔE00 against the grey spectrum.",
            instrument(study)
        ),
        kind: Kind::MeanDeltaL,
        size: (1000, 700),
        note: None,
    });
    out.push(Figure {
        stem: "fig13-residual-lightness".into(),
        caption: format!(
            "Fig. 13. Where the model misses: measured minus estimated CIELAB lightness ΔL* (D65, 2°) at each of the 12 diffuse (MA-T12) geometries, per cost function ({cost_list}), method {method}; each dot one sample (in its colour, as in Fig. 5), the box from first to third quartile over the samples with a line at the median. Above zero the fit is too dark at that geometry, below zero too bright; a pattern shared by the samples is a shape the model cannot take, not noise."
        ),
        kind: Kind::ResidualLightness,
        size: (1440, 720),
        note: None,
    });
    // A study whose scans have no specular readings (MA-T12-only instrument exports) has
    // nothing to draw in the SRA figures: they are left out, not drawn empty.
    if !study
        .samples
        .iter()
        .any(|s| s.measured.geometries.has_sra())
    {
        out.retain(|f| {
            !matches!(
                f.kind,
                Kind::LightnessSpecular
                    | Kind::LuminanceSpecular
                    | Kind::SpecularDeltaL
                    | Kind::MeanDeltaL
            )
        });
    }
    out
}

/// The SRA instrument of the study's luminance figures, e.g. "CIE illuminant C, 2° observer".
fn instrument(study: &Study) -> String {
    let d = study.done_fits().map(|d| d.sra).next().unwrap_or_default();
    format!("CIE illuminant {}, {}° observer", d.illuminant, d.observer)
}

/// Draws `fig` as `<dir>/<stem>.png` and `.svg`; returns both paths.
pub fn render(
    fig: &Figure,
    study: &Study,
    analysis: &Analysis,
    dir: &Path,
) -> Result<[PathBuf; 2], ReportError> {
    register_font();
    let png = dir.join(format!("{}.png", fig.stem));
    let svg = dir.join(format!("{}.svg", fig.stem));
    let fail = |path: &Path, e: String| ReportError::Figure {
        path: path.to_path_buf(),
        message: e,
    };
    {
        let root = BitMapBackend::new(&png, fig.size).into_drawing_area();
        draw(fig, study, analysis, &root).map_err(|e| fail(&png, e.to_string()))?;
        root.present().map_err(|e| fail(&png, e.to_string()))?;
    }
    {
        let root = SVGBackend::new(&svg, fig.size).into_drawing_area();
        draw(fig, study, analysis, &root).map_err(|e| fail(&svg, e.to_string()))?;
        root.present().map_err(|e| fail(&svg, e.to_string()))?;
    }
    Ok([png, svg])
}

fn draw<DB: DrawingBackend>(
    fig: &Figure,
    study: &Study,
    analysis: &Analysis,
    root: &DrawingArea<DB, Shift>,
) -> DrawResult<DB> {
    root.fill(&WHITE)?;
    let strip;
    let root = match &fig.note {
        None => root,
        Some([long, short]) => {
            let (w, h) = root.dim_in_pixel();
            let (main, bottom) = root.split_vertically(h as i32 - NOTE_STRIP as i32);
            let style = font(15)
                .color(&RGBColor(150, 0, 0))
                .pos(Pos::new(HPos::Left, VPos::Center));
            let fits = bottom
                .estimate_text_size(long, &style)
                .is_ok_and(|(tw, _)| tw + 24 <= w);
            bottom.draw(&Text::new(
                if fits { long.clone() } else { short.clone() },
                (12, NOTE_STRIP as i32 / 2),
                style,
            ))?;
            strip = main;
            &strip
        }
    };
    match &fig.kind {
        Kind::MeasuredSwatches => swatches(root, study, None),
        Kind::EstimatedSwatches(c) => swatches(root, study, Some(*c)),
        Kind::LightnessDiffuse => lightness_lines(root, study, Device::MaT12),
        Kind::LightnessSpecular => lightness_lines(root, study, Device::Sra),
        Kind::Spectra(i) => spectra(root, study, *i),
        Kind::LightnessPerDetector(d) => lightness_per_detector(root, study, *d),
        Kind::BoxPlots => box_plots(root, study, analysis),
        Kind::MeanCi => mean_ci(root, study, analysis),
        Kind::LuminanceSpecular => luminance_specular(root, study),
        Kind::SpecularDeltaL => specular_delta_l_points(root, study),
        Kind::ResidualLightness => residual_lightness(root, study),
        Kind::MeanDeltaL => mean_ci_groups(
            root,
            study,
            analysis,
            "Fig. 12b  Mean specular |ΔL*| per cost function, luminance metric, 95 % CI",
            "mean specular |ΔL*| over samples",
            &[("specular |ΔL*| (SRA)", |s| s.specular_delta_l)],
        ),
    }
}

fn srgb(f: &Spectrum) -> (RGBColor, bool) {
    let c = xyz_to_srgb8(reflectance_to_xyz(&brdf_to_reflectance(f)));
    (RGBColor(c.rgb[0], c.rgb[1], c.rgb[2]), c.clipped)
}

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

fn swatches<DB: DrawingBackend>(
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
    root.draw(&Text::new(
        "specular: SRA",
        (x_of(MA_T12_COUNT), 52),
        font(15),
    ))?;
    for g in &GEOMETRIES {
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
        for g in &GEOMETRIES {
            let x0 = x_of(g.index);
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

fn lab_of(f: &[Spectrum; GEOMETRY_COUNT]) -> [Lab; GEOMETRY_COUNT] {
    lab_per_geometry(f)
}

/// (lo, hi) of the values, padded by 5 % (at least 1).
fn padded(values: impl Iterator<Item = f64>) -> (f64, f64) {
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for v in values.filter(|v| v.is_finite()) {
        lo = lo.min(v);
        hi = hi.max(v);
    }
    if !lo.is_finite() {
        return (0.0, 1.0);
    }
    let pad = ((hi - lo) * 0.05).max(1.0);
    (lo - pad, hi + pad)
}

fn lightness_lines<DB: DrawingBackend>(
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

/// Fig. 13: measured minus estimated L* per diffuse geometry, a box over the samples per cost
/// function and a dot per sample.
fn residual_lightness<DB: DrawingBackend>(
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
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::UpperRight)
        .background_style(WHITE.mix(0.9))
        .border_style(BLACK)
        .label_font(font(15))
        .draw()?;
    Ok(())
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

fn spectra<DB: DrawingBackend>(
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

fn lightness_per_detector<DB: DrawingBackend>(
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
fn per_sample_size(names: &[&str]) -> (u32, u32) {
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
fn draw_box<DB: DrawingBackend>(
    chart: &mut ChartContext<
        '_,
        DB,
        Cartesian2d<plotters::coord::types::RangedCoordf64, plotters::coord::types::RangedCoordf64>,
    >,
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
) -> Result<
    ChartContext<
        'a,
        DB,
        Cartesian2d<plotters::coord::types::RangedCoordf64, plotters::coord::types::RangedCoordf64>,
    >,
    DrawingAreaErrorKind<DB::ErrorType>,
> {
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

fn box_plots<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    study: &Study,
    _analysis: &Analysis,
) -> DrawResult<DB> {
    let costs = study.cost_functions();
    let values: Vec<f64> = study
        .done_fits()
        .flat_map(|d| d.evaluation.evaluated())
        .collect();
    let mut chart = per_sample_chart(
        root,
        study,
        format!(
            "Fig. 11  ΔE00 over the 14 geometries per sample and cost function (method {})",
            methods(study)
        ),
        "ΔE00 (CIEDE2000)",
        &values,
    )?;
    let m = costs.len().max(1) as f64;
    let width = 0.7 / m;
    for (k, &c) in costs.iter().enumerate() {
        let col = cost_colour(c);
        let offset = (k as f64 - (m - 1.0) / 2.0) * width;
        let mut first = true;
        for (i, s) in study.samples.iter().enumerate() {
            let Some(d) = s.done(c) else { continue };
            let Some([min, q1, med, q3, max]) = quartiles(&d.evaluation.evaluated()) else {
                continue;
            };
            let x = i as f64 + offset;
            let label = first.then(|| format!("{c} ({})", study.method_of(c)));
            first = false;
            draw_box(&mut chart, x, width, [q1, med, q3], col, 0.35, label)?;
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
    }
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::UpperRight)
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .label_font(font(15))
        .draw()?;
    Ok(())
}

type Pick = fn(&super::analysis::CostSummary) -> Option<crate::stats::MeanCi>;

fn mean_ci<DB: DrawingBackend>(
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
fn mean_ci_groups<DB: DrawingBackend>(
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
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::UpperRight)
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .label_font(font(15))
        .draw()?;
    Ok(())
}

/// Fig. 6b: L* of the luminance at the SRA geometries, measured against estimated.
fn luminance_specular<DB: DrawingBackend>(
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
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::UpperLeft)
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .label_font(font(15))
        .draw()?;
    Ok(())
}

/// Fig. 11b: specular |ΔL*| at sra-20 (filled) and sra-60 (open) per sample and cost function.
fn specular_delta_l_points<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    study: &Study,
) -> DrawResult<DB> {
    let costs = study.cost_functions();
    let values: Vec<f64> = study
        .done_fits()
        .flat_map(|d| d.specular_delta_l.map(|l| l.per_geometry))
        .flatten()
        .collect();
    let mut chart = per_sample_chart(
        root,
        study,
        format!(
            "Fig. 11b  Specular |ΔL*| (luminance) per sample and cost function (method {})",
            methods(study)
        ),
        "|ΔL*| at the SRA geometries",
        &values,
    )?;
    let m = costs.len().max(1) as f64;
    let width = 0.7 / m;
    for (k, &c) in costs.iter().enumerate() {
        let col = cost_colour(c);
        let offset = (k as f64 - (m - 1.0) / 2.0) * width;
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
        chart.draw_series(
            done.iter()
                .map(|(x, v)| Circle::new((*x + width * 0.15, v[1]), 5, col.stroke_width(2))),
        )?;
    }
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::UpperRight)
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .label_font(font(15))
        .draw()?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fonts::FONT;

    /// `text` drawn in the report's font at `size` px, black on white, as coverage (0–255 of
    /// ink) per pixel, `w` × `h`.
    fn rendered(text: &str, size: u32, w: u32, h: u32) -> Vec<Vec<u8>> {
        register_font();
        let mut buf = vec![255u8; (w * h * 3) as usize];
        {
            let root = BitMapBackend::with_buffer(&mut buf, (w, h)).into_drawing_area();
            root.draw(&Text::new(text.to_string(), (10, 10), font(size)))
                .unwrap();
            root.present().unwrap();
        }
        (0..h as usize)
            .map(|y| {
                (0..w as usize)
                    .map(|x| 255 - buf[(y * w as usize + x) * 3])
                    .collect()
            })
            .collect()
    }

    /// Ink per pixel column of `text` laid out by ab_glyph itself: each glyph at its pen
    /// position (advances and kerning), its coverage placed by its own pixel bounds.
    fn reference_columns(text: &str, size: f32, x0: f32, w: usize) -> Vec<f64> {
        use ab_glyph::{Font, FontRef, ScaleFont, point};
        let font = FontRef::try_from_slice(FONT).unwrap();
        let scaled = font.as_scaled(size);
        let mut cols = vec![0.0; w];
        let mut pen = x0;
        let mut prev = None;
        for c in text.chars() {
            let id = font.glyph_id(c);
            if let Some(p) = prev {
                pen += scaled.kern(p, id);
            }
            prev = Some(id);
            let glyph = id.with_scale_and_position(size, point(pen, 40.0));
            if let Some(q) = font.outline_glyph(glyph) {
                let b = q.px_bounds();
                q.draw(|x, _, v| {
                    let col = (b.min.x as i64 + x as i64) as usize;
                    if col < w {
                        cols[col] += f64::from(v);
                    }
                });
            }
            pen += scaled.h_advance(id);
        }
        cols
    }

    /// Every glyph of a figure's text sits where the font puts it: "T.Freesia pink" drawn as
    /// the figures draw it (16 px, the size of sample names) has its ink in the same columns as
    /// the font's own layout. Plotters' ab_glyph text placed each glyph without its side
    /// bearing ("T.Freesia" read "TFreesia", "M andarin"); see vendor/README.md.
    #[test]
    fn figure_text_is_placed_as_the_font_lays_it_out() {
        for text in ["T.Freesia pink", "T.Mandarin orange", "reflectance factor"] {
            let ink = rendered(text, 16, 300, 40);
            let drawn: Vec<f64> = (0..300)
                .map(|x| ink.iter().map(|r| f64::from(r[x]) / 255.0).sum())
                .collect();
            let reference = reference_columns(text, 16.0, 10.0, 300);
            let total: f64 = reference.iter().sum();
            let off: f64 = drawn
                .iter()
                .zip(&reference)
                .map(|(a, b)| (a - b).abs())
                .sum();
            assert!(
                off / total < 0.25,
                "{text}: {:.0} % of the ink is in other columns than the font's layout",
                100.0 * off / total
            );
        }
    }

    use crate::study::tests::study_from_truth;

    /// One element of an SVG figure: its tag and attributes, and its text for `<text>`.
    #[derive(Debug)]
    struct El {
        tag: String,
        attrs: Vec<(String, String)>,
        text: String,
    }

    impl El {
        fn get(&self, k: &str) -> &str {
            self.attrs
                .iter()
                .find(|(a, _)| a == k)
                .map_or("", |(_, v)| v.as_str())
        }
        fn num(&self, k: &str) -> f64 {
            self.get(k).parse().unwrap_or(f64::NAN)
        }
    }

    fn svg_elements(path: &Path) -> Vec<El> {
        let svg = std::fs::read_to_string(path).unwrap();
        let mut out = Vec::new();
        for chunk in svg.split('<').skip(1) {
            let Some(end) = chunk.find('>') else { continue };
            let head = &chunk[..end];
            if head.starts_with('/') || head.starts_with('?') || head.starts_with('!') {
                continue;
            }
            let tag: String = head.chars().take_while(|c| c.is_alphanumeric()).collect();
            let mut attrs = Vec::new();
            for part in head[tag.len()..].split('"').collect::<Vec<_>>().chunks(2) {
                if let [k, v] = part {
                    attrs.push((k.trim().trim_end_matches('=').to_string(), v.to_string()));
                }
            }
            let text = chunk[end + 1..]
                .trim()
                .replace("&quot;", "\"")
                .replace("&amp;", "&");
            out.push(El { tag, attrs, text });
        }
        out
    }

    /// The legend entries of an SVG figure: every left-anchored text with a small coloured
    /// key (line, circle, square, polygon) just left of it on its line, as (text, colour).
    fn legend_entries(els: &[El]) -> Vec<(String, String)> {
        let mut out = Vec::new();
        for t in els
            .iter()
            .filter(|e| e.tag == "text" && e.get("text-anchor") == "start")
        {
            let (tx, ty) = (t.num("x"), t.num("y"));
            let ty = if t.get("dy") == "0.76em" {
                ty + 0.4 * t.num("font-size") * 1.24
            } else {
                ty
            };
            let key = els.iter().find_map(|e| {
                let (x0, x1, y, colour) = match e.tag.as_str() {
                    "circle" => {
                        let (cx, r) = (e.num("cx"), e.num("r"));
                        (cx - r, cx + r, e.num("cy"), e.get("fill"))
                    }
                    "rect" if e.num("width") < 30.0 && e.get("fill") != "none" => (
                        e.num("x"),
                        e.num("x") + e.num("width"),
                        e.num("y") + e.num("height") / 2.0,
                        e.get("fill"),
                    ),
                    "polyline" => {
                        let pts: Vec<f64> = e
                            .get("points")
                            .split([' ', ','])
                            .filter_map(|v| v.parse().ok())
                            .collect();
                        if pts.len() != 4 || pts[1] != pts[3] || pts[2] - pts[0] > 40.0 {
                            return None;
                        }
                        (pts[0], pts[2], pts[1], e.get("stroke"))
                    }
                    _ => return None,
                };
                (x1 <= tx && x1 >= tx - 45.0 && (y - ty).abs() <= 8.0 && x0 < x1)
                    .then(|| colour.to_string())
            });
            if let Some(c) = key {
                out.push((t.text.clone(), c));
            }
        }
        out
    }

    fn hex(c: RGBColor) -> String {
        format!("#{:02X}{:02X}{:02X}", c.0, c.1, c.2)
    }

    /// Colours are matched to names, one colour map for the whole report: every name a legend
    /// gives (a sample, a cost function, "measured") has one colour in every figure, no colour
    /// stands for two names, and a sample's colour is its own colour (the line of "T.Sky blue"
    /// is blue). Fig. 5 drew the samples in palette order — "T.Sky blue" black, "T.Freesia
    /// pink" in cf1's blue — and Fig. 12 drew its diffuse and specular groups in cf1's and
    /// cf2's colours.
    #[test]
    fn colours_are_matched_to_names_across_the_figures() {
        let study = study_from_truth(8, None);
        let analysis = Analysis::of(&study);
        let dir = tempfile::tempdir().unwrap();
        let mut by_name: std::collections::BTreeMap<String, (String, String)> = Default::default();
        let mut by_colour: std::collections::BTreeMap<String, (String, String)> =
            Default::default();
        for fig in figures(&study) {
            let [_, svg] = render(&fig, &study, &analysis, dir.path()).unwrap();
            let els = svg_elements(&svg);
            let entries = legend_entries(&els);
            if matches!(
                fig.kind,
                Kind::LightnessDiffuse | Kind::MeanCi | Kind::Spectra(0)
            ) {
                assert!(
                    entries.len() >= 3,
                    "{}: legend not found: {entries:?}",
                    fig.stem
                );
            }
            for (label, colour) in entries {
                let name = label
                    .strip_prefix("estimated, ")
                    .unwrap_or(&label)
                    .split(' ')
                    .next()
                    .filter(|w| ["cf1", "cf2", "m2"].contains(w))
                    .map_or(label.clone(), str::to_string);
                if let Some((c, at)) = by_name.get(&name) {
                    assert_eq!(c, &colour, "{name}: {colour} in {}, {c} in {at}", fig.stem);
                }
                by_name.insert(name.clone(), (colour.clone(), fig.stem.clone()));
                if let Some((n, at)) = by_colour.get(&colour) {
                    assert_eq!(n, &name, "{colour} is {name} in {}, {n} in {at}", fig.stem);
                }
                by_colour.insert(colour, (name, fig.stem.clone()));
            }
        }
        // Each sample's colour has its own hue, and its line is drawn in it.
        let fig5 = figures(&study)
            .into_iter()
            .find(|f| f.kind == Kind::LightnessDiffuse)
            .unwrap();
        let els = svg_elements(&dir.path().join(format!("{}.svg", fig5.stem)));
        for s in &study.samples {
            let (colour, _) = by_name.get(&s.name).unwrap_or_else(|| panic!("{}", s.name));
            let rgb = |h: &str| -> [f64; 3] {
                [1, 3, 5].map(|i| f64::from(u8::from_str_radix(&h[i..i + 2], 16).unwrap()))
            };
            let [r, g, b] = rgb(colour);
            let own = srgb(&{
                let mut m = [0.0; crate::spectral::BANDS];
                for gm in GEOMETRIES.iter().filter(|g| g.device == Device::MaT12) {
                    for (k, v) in s.measured.values[gm.index].iter().enumerate() {
                        m[k] += v / 12.0;
                    }
                }
                m
            })
            .0;
            let [r0, g0, b0] = [own.0, own.1, own.2].map(f64::from);
            // Same chromaticity: the drawn colour is the sample's own, darkened.
            let (sum, sum0) = (r + g + b, r0 + g0 + b0);
            assert!(sum > 0.0 && sum0 > 0.0, "{}", s.name);
            for (a, b) in [
                (r / sum, r0 / sum0),
                (g / sum, g0 / sum0),
                (b / sum, b0 / sum0),
            ] {
                assert!(
                    (a - b).abs() < 0.06,
                    "{} drawn {colour}, its colour is {}",
                    s.name,
                    hex(own)
                );
            }
            let lines = els
                .iter()
                .filter(|e| e.tag == "polyline" && e.get("stroke") == colour)
                .filter(|e| e.get("points").split(' ').filter(|p| !p.is_empty()).count() == 12)
                .count();
            assert_eq!(lines, 1, "{}: no line of 12 geometries in {colour}", s.name);
        }
        let blue = by_name.get("T.Sky blue").unwrap().0.clone();
        let [r, _, b] = [1, 3, 5].map(|i| u8::from_str_radix(&blue[i..i + 2], 16).unwrap());
        assert!(b > r + 40, "T.Sky blue is drawn {blue}");
    }

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
