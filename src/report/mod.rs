//! Study reports: the paper's figures 4–12, Fig. 13 (where the model misses) and the statistics (SCIENCE.md §8–9), built from an
//! in-memory [`Study`] so that everything is testable without a database.
//!
//! - [`analysis`]: which samples take part, mean ΔE00 with 95 % CI, sign tests.
//! - [`figures`]: figures 4–13 as PNG and SVG (plotters, embedded DejaVu Sans).
//! - [`summary`]: the summary page in Markdown and HTML.
//!
//! The study model and its loader live in [`crate::study`] (the exports and previews use them
//! too); they are re-exported here as `report::study` and `report::load`.
//!
//! [`write_report`] writes all of it into one directory, showing progress on stderr.

pub mod analysis;
pub mod figures;
pub mod summary;

pub use crate::study::{self, load};

use std::path::{Path, PathBuf};

use crate::cost::CostFunction;

pub use crate::study::{DoneFit, FitState, FitStudy, Origin, SampleStudy, Study};
pub use analysis::Analysis;

/// Why a report could not be written.
#[derive(Debug, thiserror::Error)]
pub enum ReportError {
    /// Nothing to report: no sample was selected, or none has a processed scan.
    #[error("the study has no samples; scan and fit some first, or check the scan ids given")]
    Empty,
    #[error("cannot write {}: {source}", path.display())]
    Write {
        path: PathBuf,
        source: std::io::Error,
    },
    /// The directory or a file in it refused ([`crate::safe_fs`]): a link, the store, a name
    /// that exists.
    #[error("{0}")]
    File(#[from] crate::safe_fs::FsError),
    /// A figure could not be drawn or saved (the message is plotters').
    #[error("cannot draw {}: {message}", path.display())]
    Figure { path: PathBuf, message: String },
}

/// What a report wrote.
#[derive(Debug, Clone, PartialEq)]
pub struct ReportFiles {
    /// Every figure: PNG and SVG paths.
    pub figures: Vec<[PathBuf; 2]>,
    pub markdown: PathBuf,
    pub html: PathBuf,
    /// One sphere preview per sample with a finished fit ([`crate::render`]), PNG.
    pub previews: Vec<PathBuf>,
}

/// How a report is drawn.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ReportOptions {
    /// The figures that show samples one by one (swatches, spectra, lightness panels, box
    /// plots, previews) show at most this many, the first in report order; the tables and the
    /// statistics (Fig. 12) always cover every sample. A lab-wide study of thousands of scans
    /// would otherwise draw a swatch chart tens of thousands of pixels high and thousands of
    /// spectra files; the summary says when figures show fewer samples than the tables.
    pub max_sample_figures: usize,
    /// Replace the files of an earlier report in the directory (`--force`); otherwise a name
    /// that exists is refused. Either way, nothing is written through a link or onto the
    /// store ([`crate::safe_fs`]).
    pub replace: bool,
}

impl ReportOptions {
    /// The default of [`ReportOptions::max_sample_figures`].
    pub const MAX_SAMPLE_FIGURES: usize = 100;
}

impl Default for ReportOptions {
    fn default() -> Self {
        ReportOptions {
            max_sample_figures: ReportOptions::MAX_SAMPLE_FIGURES,
            replace: false,
        }
    }
}

/// Writes every figure and the summary pages of `study` into `dir` (created if missing), with
/// the default [`ReportOptions`]. `progress` is told each step's name before it runs (a
/// progress bar, or nothing).
pub fn write_report(
    study: &Study,
    dir: &Path,
    progress: &mut dyn FnMut(&str, usize, usize),
) -> Result<ReportFiles, ReportError> {
    write_report_with(study, dir, &ReportOptions::default(), progress)
}

/// [`write_report`] with explicit options.
pub fn write_report_with(
    study: &Study,
    dir: &Path,
    opts: &ReportOptions,
    progress: &mut dyn FnMut(&str, usize, usize),
) -> Result<ReportFiles, ReportError> {
    if study.samples.is_empty() {
        return Err(ReportError::Empty);
    }
    // A recording replayed more than once counts once (analysis::Repeat): the report covers
    // the scans that count, and lists the others.
    let full = Analysis::of(study);
    let counted_study;
    let study: &Study = if full.repeats.is_empty() {
        study
    } else {
        let left_out: Vec<&str> = full.repeats.iter().map(|r| r.sample.as_str()).collect();
        counted_study = Study {
            samples: study
                .samples
                .iter()
                .filter(|s| !left_out.contains(&s.name.as_str()))
                .cloned()
                .collect(),
        };
        &counted_study
    };
    let repeats = full.repeats;
    // The samples the per-sample figures show.
    let shown = opts.max_sample_figures.max(1).min(study.samples.len());
    let subset;
    let drawn: &Study = if shown < study.samples.len() {
        subset = Study {
            samples: study.samples[..shown].to_vec(),
        };
        &subset
    } else {
        study
    };
    // Everything is drawn into a fresh private folder inside DIR (plotters and the PNG
    // encoder write to paths), then moved to its name in DIR under the rules of safe_fs: no
    // name in DIR is ever opened for writing, so a link planted there leads nowhere.
    let out = crate::safe_fs::Dir::create(dir)?;
    let staging = out.staging(".brdfd-report-")?;
    let staged = staging.path().to_path_buf();
    let result = draw_report(study, drawn, shown, repeats, &staging.held_path(), progress);
    let published = result.and_then(|files| publish(&out, &staging, files, opts.replace));
    let staging_name = staged
        .file_name()
        .and_then(|n| n.to_str())
        .unwrap_or_default()
        .to_string();
    drop(staging);
    if let Err(e) = out.remove_tree(&staging_name) {
        tracing::warn!(error = %e, "cannot remove the report's staging folder");
    }
    published
}

/// Moves every file of a report drawn in `staging` to its name in `out`.
fn publish(
    out: &crate::safe_fs::Dir,
    staging: &crate::safe_fs::Dir,
    files: ReportFiles,
    replace: bool,
) -> Result<ReportFiles, ReportError> {
    let replace = crate::safe_fs::Replace::force(replace);
    let all = files
        .figures
        .iter()
        .flatten()
        .chain(&files.previews)
        .chain([&files.markdown, &files.html]);
    if replace == crate::safe_fs::Replace::Never {
        // Refuse before moving anything: no half-replaced report.
        for p in all {
            if let Some(name) = p.file_name().and_then(|n| n.to_str())
                && let Some(e) = out.entry(name)?
            {
                let path = out.path().join(name);
                return Err(if e.kind == crate::safe_fs::EntryKind::Symlink {
                    crate::safe_fs::FsError::Symlink { path }
                } else {
                    crate::safe_fs::FsError::Exists { path }
                }
                .into());
            }
        }
    }
    let moved = |p: &Path| -> Result<PathBuf, ReportError> {
        let name = p
            .file_name()
            .and_then(|n| n.to_str())
            .expect("the report names its files");
        Ok(out.publish_from(staging, name, name, replace)?)
    };
    let mut figures = Vec::with_capacity(files.figures.len());
    for [png, svg] in &files.figures {
        figures.push([moved(png)?, moved(svg)?]);
    }
    let previews = files
        .previews
        .iter()
        .map(|p| moved(p))
        .collect::<Result<Vec<_>, _>>()?;
    let markdown = moved(&files.markdown)?;
    let html = moved(&files.html)?;
    Ok(ReportFiles {
        figures,
        markdown,
        html,
        previews,
    })
}

/// Draws the report's files into `dir` (the staging folder).
fn draw_report(
    study: &Study,
    drawn: &Study,
    shown: usize,
    repeats: Vec<analysis::Repeat>,
    dir: &Path,
    progress: &mut dyn FnMut(&str, usize, usize),
) -> Result<ReportFiles, ReportError> {
    let mut analysis = Analysis::of(study);
    analysis.repeats = repeats;
    let figs = figures::figures_for(drawn, study);
    let total = figs.len() + 1;
    let mut written = Vec::new();
    for (i, f) in figs.iter().enumerate() {
        progress(&f.stem, i, total);
        let from = if f.per_sample() { drawn } else { study };
        written.push(figures::render(f, from, &analysis, dir)?);
    }
    // One sphere preview per sample (PNG only: the spheres are pixels, not vector shapes).
    let mut previews = Vec::new();
    let (mut md_previews, mut html_previews) = (String::new(), String::new());
    for s in &drawn.samples {
        if !CostFunction::ALL.iter().any(|c| s.done(*c).is_some()) {
            continue;
        }
        let name = format!("preview-{}.png", crate::names::slug(&s.name));
        let path = dir.join(&name);
        progress(&name, figs.len(), total);
        crate::render::write_preview(s, &CostFunction::ALL, &path).map_err(|e| {
            ReportError::Figure {
                path: path.clone(),
                message: e.to_string(),
            }
        })?;
        let mut caption = format!(
            "{}: the fitted material per cost function on a sphere, 31 bands under a directional D65 light with a weak ambient (brdfd render); {}.",
            s.name,
            s.scale().describe()
        );
        if let Some(note) = s.simulated_note() {
            caption.push_str(&format!(" The scan is {note}, not a measurement."));
        }
        md_previews.push_str(&format!("![{name}]({name})\n\n{caption}\n\n"));
        html_previews.push_str(&format!(
            "<figure>\n<img src=\"{name}\" alt=\"preview of {0}\">\n<figcaption>{1}</figcaption>\n</figure>\n",
            html_escape(&s.name),
            html_escape(&caption)
        ));
        previews.push(path);
    }
    progress("summary", figs.len(), total);
    let write = |name: &str, text: String| -> Result<PathBuf, ReportError> {
        let path = dir.join(name);
        std::fs::write(&path, text).map_err(|source| ReportError::Write {
            path: path.clone(),
            source,
        })?;
        Ok(path)
    };
    let mut md = summary::markdown(study, &analysis, &figs);
    let mut html = summary::html(study, &analysis, &figs);
    if shown < study.samples.len() {
        let note = format!(
            "The figures that show samples one by one (Fig. 4–11 and the previews) show the \
             first {shown} of the {} samples; the tables and Fig. 12 cover all of them. Draw \
             others by naming their scans, or raise --max-sample-figures.",
            study.samples.len()
        );
        let at = md.find("\n## ").unwrap_or(md.len());
        md.insert_str(at, &format!("\n{note}\n"));
        let at = html.find("<h2>").unwrap_or(html.len());
        html.insert_str(at, &format!("<p>{}</p>\n", html_escape(&note)));
    }
    if !previews.is_empty() {
        md.push_str(&format!("\n## Previews\n\n{md_previews}"));
        let at = html.rfind("</body>").unwrap_or(html.len());
        html.insert_str(at, &format!("<h2>Previews</h2>\n{html_previews}"));
    }
    let markdown = write("summary.md", md)?;
    let html = write("index.html", html)?;
    progress("done", total, total);
    Ok(ReportFiles {
        figures: written,
        markdown,
        html,
        previews,
    })
}

fn html_escape(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::study::tests::study_from_truth;

    #[test]
    fn a_report_writes_every_figure_and_both_summaries() {
        let study = study_from_truth(3, Some(2));
        let dir = tempfile::tempdir().unwrap();
        let mut steps = Vec::new();
        let files =
            write_report(&study, dir.path(), &mut |s, _, _| steps.push(s.to_string())).unwrap();
        // 4, 5, 6, 6b, 7×3, 8×3, 9, 10, 11, 11b, 12, 12b, 13.
        assert_eq!(files.figures.len(), 4 + 3 + 3 + 7);
        for [png, svg] in &files.figures {
            let bytes = std::fs::read(png).unwrap();
            assert_eq!(&bytes[..8], b"\x89PNG\r\n\x1a\n", "{}", png.display());
            let text = std::fs::read_to_string(svg).unwrap();
            assert!(text.contains("<svg"), "{}", svg.display());
        }
        assert_eq!(steps.first().unwrap(), "fig04-measured-swatches");
        assert_eq!(steps.last().unwrap(), "done");
        let md = std::fs::read_to_string(&files.markdown).unwrap();
        assert!(
            md.contains("| cf1 vs cf2 | separable / separable |"),
            "{md}"
        );
        assert!(
            md.contains("- T.Manzana green: m2 fit failed: cancelled by the operator"),
            "{md}"
        );
        assert!(md.contains("![fig12-mean-delta-e](fig12-mean-delta-e.png)"));
        // The luminance views and tables, each saying which specular metric it shows.
        for stem in [
            "fig06b-luminance-specular",
            "fig11b-specular-delta-l",
            "fig12b-mean-specular-delta-l",
        ] {
            assert!(md.contains(&format!("![{stem}]({stem}.png)")), "{stem}");
        }
        assert!(md.contains("Table 6. Specular |ΔL*|"), "{md}");
        assert!(
            md.contains("| cf1 vs cf2 | separable / separable | 4 |"),
            "{md}"
        );
        assert!(md.contains(
            "ΔE00 against the grey spectrum the SRA reading is spread into (the paper's)"
        ));
        let html = std::fs::read_to_string(&files.html).unwrap();
        assert!(html.contains("<img src=\"fig04-measured-swatches.png\""));
        assert!(html.contains("<td>T.Manzana green</td>"));
        // One preview per sample with a finished fit, in both summaries.
        assert_eq!(files.previews.len(), study.samples.len());
        for p in &files.previews {
            assert_eq!(&std::fs::read(p).unwrap()[..4], b"\x89PNG");
            let name = p.file_name().unwrap().to_str().unwrap();
            assert!(md.contains(&format!("![{name}]({name})")), "{name}");
            assert!(html.contains(&format!("<img src=\"{name}\"")), "{name}");
        }
    }

    #[test]
    fn a_large_study_draws_its_first_samples_and_tabulates_all() {
        let study = study_from_truth(3, None);
        let dir = tempfile::tempdir().unwrap();
        let opts = ReportOptions {
            max_sample_figures: 2,
            ..ReportOptions::default()
        };
        let files = write_report_with(&study, dir.path(), &opts, &mut |_, _, _| {}).unwrap();
        // 4, 5, 6, 6b, 7×3, 8×2 (not 3), 9, 10, 11, 11b, 12, 12b, 13.
        assert_eq!(files.figures.len(), 4 + 3 + 2 + 7);
        assert_eq!(files.previews.len(), 2);
        let md = std::fs::read_to_string(&files.markdown).unwrap();
        assert!(md.contains("show the first 2 of the 3 samples"), "{md}");
        // Every sample is still in Table 1.
        for s in &study.samples {
            assert!(md.contains(&format!("| {} |", s.name)), "{}", s.name);
        }
        let spectra: Vec<_> = files
            .figures
            .iter()
            .filter(|[png, _]| png.to_string_lossy().contains("fig08-"))
            .collect();
        assert_eq!(spectra.len(), 2);
        assert!(
            !dir.path()
                .join(format!(
                    "fig08-spectra-{}.png",
                    crate::names::slug(&study.samples[2].name)
                ))
                .exists()
        );
    }

    /// The demo run twice into one store: the report counts each replayed recording once, says
    /// so, says in its header, every caption and every figure that the scans are simulated and
    /// replayed from which recordings, and says that the fits have no bootstrap intervals and
    /// why.
    #[test]
    fn a_report_of_replayed_scans_says_so_and_counts_each_recording_once() {
        let study = crate::study::tests::replayed_twice(3);
        let dir = tempfile::tempdir().unwrap();
        let files = write_report(&study, dir.path(), &mut |_, _, _| {}).unwrap();
        let md = std::fs::read_to_string(&files.markdown).unwrap();
        assert!(
            md.contains(
                "3 samples (6 scans, 3 of them a recording replayed again and counted once)"
            ),
            "{md}"
        );
        assert!(md.contains(
            "- T.Freesia pink (scan 1): the recording synthetic-t-freesia-pink (T.Freesia pink), counted as T.Freesia pink (scan 4)"
        ), "{md}");
        assert!(md.contains(
            "Every scan of this study is simulated — replayed from synthetic-t-freesia-pink (T.Freesia pink), synthetic-t-prairie-green (T.Prairie green), synthetic-t-manzana-green (T.Manzana green):"
        ), "{md}");
        // Only the scans that count are drawn: three spectra figures, three previews.
        let spectra = files
            .figures
            .iter()
            .filter(|[png, _]| png.to_string_lossy().contains("fig08-"))
            .count();
        assert_eq!(spectra, 3);
        assert_eq!(files.previews.len(), 3);
        assert!(md.contains("| T.Freesia pink (scan 4) |"), "{md}");
        assert!(!md.contains("| T.Freesia pink (scan 1) |"), "{md}");
        // Every figure's caption, and every preview's, says the scans are simulated.
        let captions: Vec<&str> = md
            .split("![")
            .skip(1)
            .map(|c| c.lines().nth(2).unwrap_or_default())
            .collect();
        assert_eq!(captions.len(), files.figures.len() + files.previews.len());
        for c in &captions {
            assert!(c.contains("simulated — replayed from"), "{c}");
        }
        assert!(md.contains(
            "for sample \"T.Freesia pink (scan 4)\"; estimates per cost function (cf1, cf2, m2), method separable, drawn widest first so that estimates which coincide show as nested lines. No error bars: none of this sample's fits has bootstrap intervals (the summary says why). This scan is simulated — replayed from synthetic-t-freesia-pink (T.Freesia pink), not a measurement."
        ), "{md}");
        // The figures themselves say it too.
        for [_, svg] in &files.figures {
            let text = std::fs::read_to_string(svg).unwrap();
            assert!(
                text.contains("simulated — replayed from"),
                "{}",
                svg.display()
            );
        }
        let fig8 =
            std::fs::read_to_string(dir.path().join("fig08-spectra-t-freesia-pink-scan-4.svg"))
                .unwrap();
        assert!(
            fig8.contains("simulated — replayed from synthetic-t-freesia-pink (T.Freesia pink)")
        );
        let fig12 = std::fs::read_to_string(dir.path().join("fig12-mean-delta-e.svg")).unwrap();
        assert!(fig12.contains("(n = 3 samples)"), "{fig12}");
        // No fit has intervals: the report says so and why, instead of leaving them out.
        assert!(md.contains(
            "No bootstrap intervals: none of the 9 finished fits has them, so there is no table of parameter intervals and Fig. 8 draws no error bars. The store keeps no intervals for them."
        ), "{md}");
        assert!(md.contains("[fit] bootstrap is above 0"), "{md}");
        // The advice names the commands that give a stored fit intervals.
        assert!(md.contains("brdfd demo --bootstrap 200"), "{md}");
        assert!(md.contains("brdfd refit SCAN"), "{md}");
        assert!(
            !md.contains("Report again once the bootstraps have run"),
            "{md}"
        );
    }

    /// Fits without bootstrap intervals beside fits with them are marked, counted and
    /// explained.
    #[test]
    fn fits_without_intervals_are_marked_and_explained() {
        let mut study = study_from_truth(2, None);
        let FitState::Done(d) = &mut study.samples[0].fits[0].state else {
            panic!("the first fit is done");
        };
        d.uncertainty = Some(crate::test_support::made_up_uncertainty(&d.params, false));
        let a = Analysis::of(&study);
        let md = summary::markdown(&study, &a, &figures::figures(&study));
        assert!(md.contains("| T.Freesia pink | cf1 | "), "{md}");
        assert!(md.contains("| T.Freesia pink | cf2 | "), "{md}");
        assert!(md.contains("(no interval)"), "{md}");
        assert!(md.contains(
            "5 of the 6 finished fits have no bootstrap intervals (\"no interval\" above; Fig. 8 draws no error bars for them). These fits were made in this process without a bootstrap: intervals are computed only when asked for (brdfd fit --bootstrap N)."
        ), "{md}");
        assert!(md.contains("Error bars: the 95 % bootstrap intervals of the estimates, for the 1 of its 3 fits that have them."), "{md}");
        // Not simulated as far as the study knows: nothing said of it.
        assert!(!md.contains("simulated —"), "{md}");
    }

    /// A fit's held-out ΔE00 stands beside its fitted one; a fit without it is marked and
    /// counted, and a study with none says why.
    #[test]
    fn held_out_delta_e_is_tabled_beside_the_fitted_one() {
        let mut study = study_from_truth(2, None);
        let md = summary::markdown(&study, &Analysis::of(&study), &[]);
        assert!(
            md.contains("No held-out ΔE00: none of the 6 finished fits has a cross-validation"),
            "{md}"
        );
        let FitState::Done(d) = &mut study.samples[0].fits[0].state else {
            panic!("the first fit is done");
        };
        let held = |geometry: &str, de: f64| crate::crossval::HeldOut {
            geometry: geometry.into(),
            delta_e00: de,
            measured_lab: [50.0, 1.0, 2.0],
            predicted_lab: [51.0, 1.0, 2.0],
            predicted_l_interval: None,
        };
        d.crossval = Some(crate::crossval::CrossValidation {
            cost: CostFunction::Cf1,
            model: crate::model::ModelKind::Paper,
            fresnel: d.fresnel,
            fitted_mean: 0.25,
            held_out_mean: 1.5,
            held_out: vec![held("15as-45", 1.0), held("45as-15", 2.0)],
        });
        let md = summary::markdown(&study, &Analysis::of(&study), &[]);
        assert!(
            md.contains("Held-out ΔE00: how far to trust each estimate off the measured angles"),
            "{md}"
        );
        // Every finished fit's reach verdict, with the held-out ΔE00 among its evidence.
        assert!(
            md.contains("| sample | cf1 reach | cf1 expected ΔE00 |"),
            "{md}"
        );
        let reach_rows = md
            .lines()
            .filter(|l| {
                l.contains("in reach |") || l.contains("marginal |") || l.contains("out of reach |")
            })
            .count();
        assert_eq!(reach_rows, 2, "{md}");
        assert!(
            md.contains("| sample | cf1 fitted (MA-T12) | cf1 held out | cf1 worst held out |"),
            "{md}"
        );
        assert!(
            md.contains("| T.Freesia pink | 0.250 | 1.500 | 45as-15 2.000 | not computed |"),
            "{md}"
        );
        assert!(
            md.contains("5 of the 6 finished fits have no held-out ΔE00"),
            "{md}"
        );
    }

    #[test]
    fn an_empty_study_is_refused() {
        let dir = tempfile::tempdir().unwrap();
        let e = write_report(&Study::default(), dir.path(), &mut |_, _, _| {}).unwrap_err();
        assert!(matches!(e, ReportError::Empty));
    }
}
