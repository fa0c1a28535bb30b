//! The paper's figures 4–12 (SCIENCE.md §9), drawn with plotters into PNG (bitmap backend)
//! and SVG from one drawing routine per figure.
//!
//! Text is rendered with the embedded DejaVu Sans (`fonts/`), registered with plotters'
//! `ab_glyph` renderer, so no installed font is needed. Colours: black for measured data, and
//! the Okabe–Ito colour-blind-safe palette for cost functions and samples. Every figure's title
//! names the method and cost function(s); axes say their quantity and unit.

use std::path::{Path, PathBuf};
use std::sync::Once;

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
use super::study::{SampleStudy, Study};

static FONT: &[u8] = include_bytes!("fonts/DejaVuSans.ttf");
const FAMILY: &str = "sans-serif";

pub(crate) fn register_font() {
    static ONCE: Once = Once::new();
    ONCE.call_once(|| {
        if plotters::style::register_font(FAMILY, FontStyle::Normal, FONT).is_err() {
            panic!("the embedded DejaVu Sans does not load");
        }
    });
}

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

/// Colour of a cost function's estimates.
fn cost_colour(c: CostFunction) -> RGBColor {
    match c {
        CostFunction::Cf1 => PALETTE[5],
        CostFunction::Cf2 => PALETTE[6],
        CostFunction::M2 => PALETTE[3],
    }
}

/// Colour of the i-th sample: the palette without yellow (unreadable on white), then grey.
fn sample_colour(i: usize) -> RGBColor {
    const ORDER: [RGBColor; 8] = [
        PALETTE[5],
        PALETTE[6],
        PALETTE[3],
        PALETTE[7],
        PALETTE[2],
        PALETTE[1],
        PALETTE[0],
        RGBColor(150, 150, 150),
    ];
    ORDER[i % ORDER.len()]
}

type DrawResult<DB> = Result<(), DrawingAreaErrorKind<<DB as DrawingBackend>::ErrorType>>;

pub(crate) fn font(size: u32) -> TextStyle<'static> {
    (FAMILY, size).into_font().color(&BLACK)
}

/// One figure of the report.
#[derive(Debug, Clone, PartialEq)]
pub struct Figure {
    /// File stem: `<stem>.png` and `<stem>.svg`.
    pub stem: String,
    /// The caption the summary prints under it.
    pub caption: String,
    kind: Kind,
    size: (u32, u32),
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
    let mut out = vec![
        Figure {
            stem: "fig04-measured-swatches".into(),
            caption: format!(
                "Fig. 4. Measured colour of each sample at the 12 diffuse (MA-T12) and 2 specular (SRA) geometries, as sRGB swatches (CIE D65, 2° observer). Swatches marked with a white triangle are clipped: outside the sRGB gamut, typically brighter than white at the specular geometries. SRA readings processed with the {strat} strategy. Measured data: no fit, no cost function."
            ),
            kind: Kind::MeasuredSwatches,
            size: (1280, swatch_h),
        },
        Figure {
            stem: "fig05-lightness-diffuse".into(),
            caption: "Fig. 5. CIELAB lightness L* of the measured diffuse readings (MA-T12) per geometry and sample (D65, 2°). Measured data: no fit, no cost function.".into(),
            kind: Kind::LightnessDiffuse,
            size: (1200, 720),
        },
        Figure {
            stem: "fig06-lightness-specular".into(),
            caption: format!("Fig. 6. CIELAB lightness L* of the measured specular readings (SRA, spread flat over the bands, {strat} strategy) per sample; L* above 100 is brighter than the reference white. Measured data: no fit, no cost function."),
            kind: Kind::LightnessSpecular,
            size: (1000, 720),
        },
        Figure {
            stem: "fig06b-luminance-specular".into(),
            caption: format!("Fig. 6b (luminance view of Fig. 6). CIELAB L* of the luminance at the two SRA geometries, measured (the reading) against estimated (the fitted model's luminance), per sample and cost function ({cost_list}), method {method}; luminance under {}. On the diagonal the fit reproduces what the SRA reads; this is the luminance metric, not the paper's ΔE00 against the grey spectrum.", instrument(study)),
            kind: Kind::LuminanceSpecular,
            size: (1000, 760),
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
        });
    }
    for (i, s) in study.samples.iter().enumerate() {
        out.push(Figure {
            stem: format!("fig08-spectra-{}", crate::synth::slug(&s.name)),
            caption: format!(
                "Fig. 8 ({}). Measured (black) and estimated reflectance factor R = π·f against wavelength at each of the 14 geometries for sample \"{}\"; estimates per cost function ({cost_list}), method {method}.",
                s.name, s.name
            ),
            kind: Kind::Spectra(i),
            size: (1400, 1100),
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
        });
    }
    out.push(Figure {
        stem: "fig11-delta-e-boxplots".into(),
        caption: format!(
            "Fig. 11. ΔE00 between measured and estimated colour over the 14 geometries, per sample and cost function ({cost_list}), method {method}: box from first to third quartile, line at the median, whiskers to the smallest and largest value. At the 2 SRA geometries this is the paper's metric, ΔE00 against the grey spectrum the reading is spread into; Fig. 11b shows the luminance metric."
        ),
        kind: Kind::BoxPlots,
        size: (1300, 700),
    });
    out.push(Figure {
        stem: "fig11b-specular-delta-l".into(),
        caption: format!(
            "Fig. 11b (luminance view of Fig. 11). Specular |ΔL*| between the model's and the measured luminance at sra-20 (filled) and sra-60 (open), per sample and cost function ({cost_list}), method {method}; luminance under {}. The luminance metric, not the paper's ΔE00 against the grey spectrum that Fig. 11 includes at the SRA geometries.",
            instrument(study)
        ),
        kind: Kind::SpecularDeltaL,
        size: (1300, 700),
    });
    out.push(Figure {
        stem: "fig12-mean-delta-e".into(),
        caption: format!(
            "Fig. 12. Mean ΔE00 over the samples that take part in the comparison, per cost function ({cost_list}), method {method}, over all 14 geometries and split into diffuse and specular (the paper's specular metric, ΔE00 against the grey spectrum; Fig. 12b shows the luminance metric); error bars are 95 % confidence intervals (Student t)."
        ),
        kind: Kind::MeanCi,
        size: (1000, 700),
    });
    out.push(Figure {
        stem: "fig12b-mean-specular-delta-l".into(),
        caption: format!(
            "Fig. 12b (luminance view of Fig. 12). Mean over the samples that take part of each sample's mean specular |ΔL*| (model vs measured luminance at the SRA geometries, under {}), per cost function ({cost_list}), method {method}; error bars are 95 % confidence intervals (Student t). Fig. 12's specular group is the paper's ΔE00 against the grey spectrum.",
            instrument(study)
        ),
        kind: Kind::MeanDeltaL,
        size: (1000, 700),
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
        Kind::MeanDeltaL => mean_ci_groups(
            root,
            study,
            analysis,
            "Fig. 12b  Mean specular |ΔL*| per cost function, luminance metric, 95 % CI",
            "mean specular |ΔL*| over samples",
            &[("specular |ΔL*| (SRA)", |s| s.specular_delta_l, PALETTE[6])],
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
    let mut chart = ChartBuilder::on(root)
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
    for (i, (s, lab)) in study.samples.iter().zip(&labs).enumerate() {
        let c = sample_colour(i);
        let pts: Vec<(SegmentValue<usize>, f64)> = geos
            .iter()
            .enumerate()
            .map(|(k, g)| (SegmentValue::CenterOf(k), lab[g.index].l))
            .collect();
        chart
            .draw_series(LineSeries::new(pts.clone(), c.stroke_width(2)))?
            .label(s.name.clone())
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], c.stroke_width(2)));
        chart.draw_series(pts.into_iter().map(|p| Circle::new(p, 4, c.filled())))?;
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

fn legend_costs<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    study: &Study,
    x: i32,
    y: i32,
) -> DrawResult<DB> {
    area.draw(&PathElement::new(
        vec![(x, y), (x + 28, y)],
        BLACK.stroke_width(3),
    ))?;
    area.draw(&Text::new(
        "measured",
        (x + 36, y),
        font(16).pos(Pos::new(HPos::Left, VPos::Center)),
    ))?;
    for (k, c) in study.cost_functions().into_iter().enumerate() {
        let yy = y + 26 * (k as i32 + 1);
        let col = cost_colour(c);
        area.draw(&PathElement::new(
            vec![(x, yy), (x + 28, yy)],
            col.stroke_width(2),
        ))?;
        area.draw(&Text::new(
            format!("estimated, {c} ({})", study.method_of(c)),
            (x + 36, yy),
            font(16).pos(Pos::new(HPos::Left, VPos::Center)),
        ))?;
    }
    Ok(())
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
        chart.draw_series(LineSeries::new(
            nm.iter().zip(&measured).map(|(&w, &v)| (f64::from(w), v)),
            BLACK.stroke_width(3),
        ))?;
        for (c, e) in &estimates {
            chart.draw_series(LineSeries::new(
                nm.iter().zip(e).map(|(&w, &v)| (f64::from(w), v)),
                cost_colour(*c).stroke_width(2),
            ))?;
        }
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
    legend_costs(legend, study, 20, 60)?;
    let (missing, note): (Vec<String>, &str) =
        (s.fits.iter().filter_map(|f| f.problem()).collect(), "");
    for (k, m) in missing.iter().enumerate() {
        legend.draw(&Text::new(
            format!("{m}{note}"),
            (20, 170 + 22 * k as i32),
            font(14),
        ))?;
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
        chart.draw_series(LineSeries::new(line(&m), BLACK.stroke_width(3)))?;
        chart.draw_series(
            line(&m)
                .into_iter()
                .map(|p| Circle::new(p, 4, BLACK.filled())),
        )?;
        for (c, l) in &ests {
            let col = cost_colour(*c);
            chart.draw_series(LineSeries::new(line(l), col.stroke_width(2)))?;
            chart.draw_series(
                line(l)
                    .into_iter()
                    .map(|p| TriangleMarker::new(p, 5, col.filled())),
            )?;
        }
    }
    // One legend row for every panel.
    let mut x = 20;
    legend.draw(&PathElement::new(
        vec![(x, 30), (x + 28, 30)],
        BLACK.stroke_width(3),
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
            col.stroke_width(2),
        ))?;
        let label = format!("estimated, {c} ({})", study.method_of(c));
        legend.draw(&Text::new(
            label.clone(),
            (x + 36, 30),
            font(16).pos(Pos::new(HPos::Left, VPos::Center)),
        ))?;
        x += 60 + 9 * label.len() as i32;
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

/// The axes of Fig. 11 and 11b: one column per sample (named on the x axis), y from 0 to 1.3 ×
/// the largest of `values` (1 when none is above 0), caption and y label as given.
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
    let mut chart = ChartBuilder::on(root)
        .caption(caption, font(24))
        .margin(20)
        .x_label_area_size(60)
        .y_label_area_size(70)
        .build_cartesian_2d(-0.5f64..(n as f64 - 0.5), 0f64..hi)?;
    chart
        .configure_mesh()
        .disable_x_mesh()
        .x_labels(n.max(1))
        .x_label_formatter(&|x| {
            let i = x.round();
            if (x - i).abs() < 1e-6 && i >= 0.0 {
                names.get(i as usize).cloned().unwrap_or_default()
            } else {
                String::new()
            }
        })
        .x_desc("sample")
        .y_desc(y_desc)
        .label_style(font(14))
        .axis_desc_style(font(17))
        .draw()?;
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
            let (x0, x1) = (x - width * 0.4, x + width * 0.4);
            let series = chart.draw_series(std::iter::once(Rectangle::new(
                [(x0, q1), (x1, q3)],
                col.mix(0.35).filled(),
            )))?;
            if first {
                series
                    .label(format!("{c} ({})", study.method_of(c)))
                    .legend(move |(x, y)| {
                        Rectangle::new([(x, y - 6), (x + 16, y + 6)], col.mix(0.6).filled())
                    });
                first = false;
            }
            chart.draw_series(std::iter::once(Rectangle::new(
                [(x0, q1), (x1, q3)],
                col.stroke_width(2),
            )))?;
            chart.draw_series(std::iter::once(PathElement::new(
                vec![(x0, med), (x1, med)],
                col.stroke_width(3),
            )))?;
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
            ("all 14 geometries", |s| s.all, PALETTE[0]),
            ("diffuse (MA-T12)", |s| s.diffuse, PALETTE[5]),
            ("specular (SRA)", |s| s.specular, PALETTE[6]),
        ],
    )
}

/// Means with their 95 % CI per cost function, one coloured group per `groups` entry.
fn mean_ci_groups<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    study: &Study,
    analysis: &Analysis,
    title: &str,
    y_desc: &str,
    groups: &[(&str, Pick, RGBColor)],
) -> DrawResult<DB> {
    let costs = &analysis.cost_functions;
    let hi = analysis
        .per_cost
        .iter()
        .flat_map(|s| groups.iter().filter_map(|g| (g.1)(s)).map(|ci| ci.hi))
        .fold(0.0f64, f64::max)
        * 1.35;
    let hi = if hi > 0.0 { hi } else { 1.0 };
    let names: Vec<String> = costs
        .iter()
        .map(|c| format!("{c} ({})", study.method_of(*c)))
        .collect();
    let mut chart = ChartBuilder::on(root)
        .caption(title, font(24))
        .margin(20)
        .x_label_area_size(60)
        .y_label_area_size(70)
        .build_cartesian_2d(-0.5f64..(costs.len() as f64 - 0.5), 0f64..hi)?;
    chart
        .configure_mesh()
        .disable_x_mesh()
        .x_labels(costs.len().max(1))
        .x_label_formatter(&|x| {
            let i = x.round();
            if (x - i).abs() < 1e-6 && i >= 0.0 {
                names.get(i as usize).cloned().unwrap_or_default()
            } else {
                String::new()
            }
        })
        .x_desc("cost function (method)")
        .y_desc(y_desc)
        .label_style(font(15))
        .axis_desc_style(font(17))
        .draw()?;
    let centre = (groups.len() as f64 - 1.0) / 2.0;
    for (k, (label, pick, col)) in groups.iter().enumerate() {
        let offset = (k as f64 - centre) * 0.2;
        let pts: Vec<(f64, crate::stats::MeanCi)> = analysis
            .per_cost
            .iter()
            .enumerate()
            .filter_map(|(i, s)| pick(s).map(|ci| (i as f64 + offset, ci)))
            .collect();
        let col = *col;
        chart
            .draw_series(pts.iter().map(|(x, ci)| {
                ErrorBar::new_vertical(*x, ci.lo, ci.mean, ci.hi, col.stroke_width(2), 14)
            }))?
            .label(*label)
            .legend(move |(x, y)| Circle::new((x + 8, y), 5, col.filled()));
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
                    .map(|p| Circle::new((p.1, p.2), 5, col.filled())),
            )?
            .label(format!("{c} ({})", study.method_of(c)))
            .legend(move |(x, y)| Circle::new((x + 8, y), 5, col.filled()));
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
