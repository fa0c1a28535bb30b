//! The paper's figures 4–12 and Fig. 13, where the model misses (SCIENCE.md §9), drawn with plotters into PNG (bitmap backend)
//! and SVG from one drawing routine per figure.
//!
//! Text is rendered with the embedded DejaVu Sans (`fonts/`), registered with plotters'
//! `ab_glyph` renderer, so no installed font is needed. Colours: black for measured data, and
//! the Okabe–Ito colour-blind-safe palette for cost functions and samples. Every figure's title
//! names the method and cost function(s); axes say their quantity and unit.

mod lightness;
mod residuals;
mod spectra;
mod statistics;
mod style;
mod swatches;

use std::path::{Path, PathBuf};

use plotters::coord::Shift;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};

use crate::colour::Lab;
use crate::cost::CostFunction;
use crate::evaluation::lab_per_geometry;
use crate::geometry::{Device, GEOMETRY_COUNT};
use crate::spectral::Spectrum;

use super::ReportError;
use super::analysis::Analysis;
use crate::fonts::{font, register_font};
use crate::study::{SampleStudy, Study, simulated_statement};

use lightness::{lightness_lines, lightness_per_detector, luminance_specular};
use residuals::residual_lightness;
use spectra::spectra;
pub use statistics::quartiles;
use statistics::{box_plots, mean_ci, mean_ci_groups, per_sample_size, specular_delta_l_points};
use swatches::swatches;

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
    // Scans without SRA readings: their SRA cells say "not measured".
    let no_sra: Vec<&str> = study
        .samples
        .iter()
        .filter(|s| !s.measured.geometries.has_sra())
        .map(|s| s.name.as_str())
        .collect();
    let unmeasured = if no_sra.is_empty() {
        String::new()
    } else if no_sra.len() == study.samples.len() {
        " No scan has SRA readings: the 12 MA-T12 geometries only.".to_string()
    } else {
        format!(
            " Hatched cells marked \"not measured\": the SRA geometries of scans without SRA readings ({}).",
            no_sra.join(", ")
        )
    };
    let mut out = vec![
        Figure {
            stem: "fig04-measured-swatches".into(),
            caption: format!(
                "Fig. 4. Measured colour of each sample at the 12 diffuse (MA-T12) and 2 specular (SRA) geometries, as sRGB swatches (CIE D65, 2° observer). Swatches marked with a white triangle are clipped: outside the sRGB gamut, typically brighter than white at the specular geometries. SRA readings processed with the {strat} strategy.{unmeasured} Measured data: no fit, no cost function."
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
                "Fig. 7 ({c}). Measured (upper half) vs estimated (lower half) colour per sample and geometry, sRGB swatches (D65, 2°); estimates of the model fitted with cost function {c}, method {}. White triangles mark clipped swatches.{unmeasured}",
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

#[cfg(test)]
mod tests {
    use super::style::srgb;
    use super::*;
    use crate::fonts::FONT;
    use crate::geometry::GEOMETRIES;

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
    pub(super) struct El {
        pub(super) tag: String,
        pub(super) attrs: Vec<(String, String)>,
        pub(super) text: String,
    }

    impl El {
        pub(super) fn get(&self, k: &str) -> &str {
            self.attrs
                .iter()
                .find(|(a, _)| a == k)
                .map_or("", |(_, v)| v.as_str())
        }
        pub(super) fn num(&self, k: &str) -> f64 {
            self.get(k).parse().unwrap_or(f64::NAN)
        }
    }

    pub(super) fn svg_elements(path: &Path) -> Vec<El> {
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

    /// A scan without SRA readings (an instrument export) has its SRA cells drawn as "not
    /// measured" in Fig. 4 and every Fig. 7, never as the black of a zero reading; the other
    /// samples keep their SRA swatches.
    #[test]
    fn swatch_figures_mark_unmeasured_geometries_instead_of_drawing_black() {
        let mut study = study_from_truth(3, None);
        let s = &mut study.samples[0];
        s.scan.readings.sra = None;
        s.scan.reference = None;
        s.measured = crate::processing::process(&s.scan, &Default::default()).unwrap();
        assert!(!s.measured.geometries.has_sra());
        let analysis = Analysis::of(&study);
        let dir = tempfile::tempdir().unwrap();
        let mut drawn = 0;
        for fig in figures(&study) {
            if !matches!(
                fig.kind,
                Kind::MeasuredSwatches | Kind::EstimatedSwatches(_)
            ) {
                continue;
            }
            drawn += 1;
            let [_, svg] = render(&fig, &study, &analysis, dir.path()).unwrap();
            let els = svg_elements(&svg);
            let black = els
                .iter()
                .filter(|e| e.tag == "rect" && e.get("fill") == "#000000")
                .count();
            assert_eq!(black, 0, "{}: black swatches drawn", fig.stem);
            let marked = els
                .iter()
                .filter(|e| e.tag == "text" && e.text == "measured")
                .count();
            assert_eq!(marked, 2, "{}: the two SRA cells of one sample", fig.stem);
            let filled = els
                .iter()
                .filter(|e| e.tag == "rect" && e.get("fill") == hex(swatches_not_measured()))
                .count();
            assert_eq!(filled, 2, "{}", fig.stem);
        }
        assert!(drawn >= 2, "Fig. 4 and Fig. 7 drawn: {drawn}");
    }

    fn swatches_not_measured() -> RGBColor {
        super::swatches::NOT_MEASURED
    }
}
