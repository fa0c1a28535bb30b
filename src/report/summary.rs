//! The report's summary page, in Markdown (`summary.md`) and HTML (`index.html`) from one
//! list of blocks: the study, per-sample ΔE00 per cost function, the means with 95 % CI, the
//! sign tests with n and p, the samples left out and why, and every figure with its caption.

use std::fmt::Write as _;

use crate::cost::CostFunction;
use crate::stats::MeanCi;

use super::analysis::{Analysis, CostSummary, SignRow, format_p};
use super::figures::Figure;
use crate::study::{DoneFit, FitState, FitStudy, SampleStudy, Study, simulated_statement};

/// The columns of the sign-test tables (Table 3 on ΔE00, Table 8 on |ΔL*|).
const SIGN_TEST_HEAD: [&str; 7] = ["A vs B", "method", "n", "A worse", "B worse", "ties", "p"];

/// The rows of a sign-test table: one per pair of cost functions.
fn sign_test_rows(study: &Study, tests: &[SignRow]) -> Vec<Vec<String>> {
    tests
        .iter()
        .map(|r| {
            vec![
                format!("{} vs {}", r.a, r.b),
                format!("{} / {}", study.method_of(r.a), study.method_of(r.b)),
                r.test.n.to_string(),
                r.test.plus.to_string(),
                r.test.minus.to_string(),
                r.test.ties.to_string(),
                format_p(r.test.p),
            ]
        })
        .collect()
}

/// A piece of the page.
enum Block {
    Heading(String),
    Para(String),
    Table {
        caption: String,
        head: Vec<String>,
        rows: Vec<Vec<String>>,
    },
    List(Vec<String>),
    Figure {
        stem: String,
        caption: String,
    },
}

/// A paragraph, then the list it introduces.
fn introduced_list(intro: String, items: impl Iterator<Item = String>) -> [Block; 2] {
    [Block::Para(intro), Block::List(items.collect())]
}

/// A table of one row per sample: its name, then per cost function of `costs` the cells
/// `cells(row, sample, cost)` appends, headed "<cost> <part>" for each of `parts`.
fn per_sample_table(
    study: &Study,
    costs: &[CostFunction],
    parts: &[&str],
    caption: String,
    cells: impl Fn(&mut Vec<String>, &SampleStudy, CostFunction),
) -> Block {
    let mut head = vec!["sample".to_string()];
    for c in costs {
        for part in parts {
            head.push(format!("{c} {part}"));
        }
    }
    let rows = study
        .samples
        .iter()
        .map(|s| {
            let mut row = vec![s.name.clone()];
            for &c in costs {
                cells(&mut row, s, c);
            }
            row
        })
        .collect();
    Block::Table {
        caption,
        head,
        rows,
    }
}

/// A table of one row per cost function of the analysis: its name and method, then the cells
/// `cells(summary)` gives under `head`.
fn per_cost_table(
    analysis: &Analysis,
    caption: String,
    head: &[&str],
    cells: impl Fn(&CostSummary) -> Vec<String>,
) -> Block {
    Block::Table {
        caption,
        head: ["cost function", "method"]
            .iter()
            .chain(head)
            .map(|h| h.to_string())
            .collect(),
        rows: analysis
            .per_cost
            .iter()
            .map(|s| {
                let mut row = vec![s.cost.to_string(), s.method.clone()];
                row.extend(cells(s));
                row
            })
            .collect(),
    }
}

fn ci(c: &Option<MeanCi>) -> String {
    match c {
        Some(c) => format!(
            "{:.3} ± {:.3} [{:.3}, {:.3}]",
            c.mean, c.half_width, c.lo, c.hi
        ),
        None => "n/a (fewer than 2 samples)".into(),
    }
}

/// Each fit's held-out ΔE00 beside its fitted ΔE00 over the MA-T12 geometries (its
/// leave-one-geometry-out cross-validation, SCIENCE.md §12.5), when any fit has one; else a
/// sentence saying why there is none.
fn held_out_blocks(study: &Study, costs: &[CostFunction]) -> Vec<Block> {
    let with = study
        .samples
        .iter()
        .flat_map(|s| s.fits.iter())
        .filter(|f| f.done().is_some_and(|d| d.crossval.is_some()))
        .count();
    let done = study
        .samples
        .iter()
        .flat_map(|s| s.fits.iter())
        .filter(|f| f.done().is_some())
        .count();
    if done == 0 {
        return Vec::new();
    }
    let mut b = vec![Block::Heading(
        "Held-out ΔE00: how far to trust each estimate off the measured angles".into(),
    )];
    if with == 0 {
        b.push(Block::Para(format!(
            "No held-out ΔE00: none of the {done} finished fits has a cross-validation (the daemon computes one after each fit unless `[fit] crossval = false`; `brdfd crossval SCAN.json` computes it for an exported scan)."
        )));
        return b;
    }
    b.push(per_sample_table(
        study,
        costs,
        &["fitted (MA-T12)", "held out", "worst held out"],
        "Held-out ΔE00 per sample: each MA-T12 geometry held out in turn, the others fitted under the fit's own configuration, the held-out reading predicted (leave-one-geometry-out, SCIENCE.md §12.5); mean ΔE00 of those predictions beside the mean ΔE00 of the fit to every reading at the same geometries, and the geometry predicted worst. The fitted figure says how well the model reproduces what it was fitted to; the held-out one how far to trust the estimate at angles that were not measured.".into(),
        |row, s, c| match s.fit(c).and_then(|f| f.done()).map(|d| &d.crossval) {
            Some(Some(cv)) => {
                let worst = cv
                    .held_out
                    .iter()
                    .max_by(|a, b| a.delta_e00.total_cmp(&b.delta_e00))
                    .map_or(String::new(), |h| format!("{} {:.3}", h.geometry, h.delta_e00));
                row.extend([
                    format!("{:.3}", cv.fitted_mean),
                    format!("{:.3}", cv.held_out_mean),
                    worst,
                ]);
            }
            Some(None) => row.extend(["not computed".into(), "".into(), "".into()]),
            None => row.extend(["no finished fit".into(), "".into(), "".into()]),
        },
    ));
    if with < done {
        b.push(Block::Para(format!(
            "{} of the {done} finished fits have no held-out ΔE00 (\"not computed\" above: `[fit] crossval = false`, computed before the daemon did it, or stopped by a shutdown).",
            done - with
        )));
    }
    b
}

/// The reach verdict of a sample's finished fit (SCIENCE.md §12.7): from its readings' L*, its
/// MA-T12 ΔE00 and its held-out ΔE00 once computed, as `brdfd show` derives it.
fn reach_of(s: &SampleStudy, d: &crate::study::DoneFit) -> Option<crate::reach::Reach> {
    let lab = crate::fit::LabPerGeometry::of(
        &s.measured,
        &d.estimated,
        d.colorimetry,
        &std::array::from_fn(|g| d.evaluation.at(g).unwrap_or(f64::NAN)),
    );
    let e = crate::reach::Evidence::of(
        &lab,
        d.evaluation.diffuse.mean,
        d.crossval.as_ref().map(|c| c.held_out_mean),
        d.fresnel,
    )?;
    Some(crate::reach::assess(&e))
}

/// Whether each sample is in the model's reach, per cost function (SCIENCE.md §12.7).
fn reach_blocks(study: &Study, costs: &[CostFunction]) -> Vec<Block> {
    let done = study
        .samples
        .iter()
        .flat_map(|s| s.fits.iter())
        .any(|f| f.done().is_some());
    if !done {
        return Vec::new();
    }
    vec![
        Block::Heading("In the model's reach? What to expect over the hemisphere".into()),
        per_sample_table(
            study,
            costs,
            &["reach", "expected ΔE00"],
            format!(
                "Reach verdict per sample and fit (SCIENCE.md §12.7): in reach (matt and medium-gloss materials), marginal, or out of reach (glossy: the model's one lobe cannot follow the specular peak), told from the readings alone (how far the brightest reading stands above the 45as45 one, the fit's ΔE00 at the MA-T12 geometries, its held-out ΔE00 once computed), with the prediction ΔE00 over the hemisphere to expect; calibrated on {}.",
                crate::reach::CALIBRATION.source
            ),
            |row, s, c| match s.fit(c).and_then(|f| f.done()) {
                Some(d) => match reach_of(s, d) {
                    Some(r) => row.extend([
                        r.verdict.to_string(),
                        format!(
                            "{:.1}–{:.1}",
                            r.expected_delta_e00[0], r.expected_delta_e00[1]
                        ),
                    ]),
                    None => row.extend(["no 45as45 reading".into(), "".into()]),
                },
                None => row.extend(["no finished fit".into(), "".into()]),
            },
        ),
    ]
}

fn blocks(study: &Study, analysis: &Analysis, figures: &[Figure]) -> Vec<Block> {
    let costs = &analysis.cost_functions;
    let cost_list = costs
        .iter()
        .map(|c| c.name())
        .collect::<Vec<_>>()
        .join(", ");
    let methods = study.methods().join(", ");
    let strategies = study
        .specular_strategies()
        .iter()
        .map(|s| s.name())
        .collect::<Vec<_>>()
        .join(", ");
    // The colorimetry of the fits' evaluations: the paper's unless configured otherwise.
    let mut colorimetries: Vec<crate::colour::Colorimetry> = study
        .samples
        .iter()
        .flat_map(|s| {
            s.fits
                .iter()
                .filter_map(|f| f.done().map(|d| d.colorimetry))
        })
        .collect();
    colorimetries.dedup();
    let colour = match colorimetries.as_slice() {
        [] => "CIE D65, 2° observer".to_string(),
        [c] if *c == crate::colour::Colorimetry::default() => "CIE D65, 2° observer".to_string(),
        cs => cs
            .iter()
            .map(|c| {
                format!(
                    "CIE D65, {}° observer, {} weighting",
                    c.observer, c.weighting
                )
            })
            .collect::<Vec<_>>()
            .join(" / "),
    };
    let samples = if analysis.repeats.is_empty() {
        format!("{} samples", study.samples.len())
    } else {
        // A repeat shares a replayed recording, or the readings themselves (the same file
        // imported again): each called what it is.
        let replayed = analysis
            .repeats
            .iter()
            .filter(|r| r.shared.starts_with("the recording"))
            .count();
        let what = if replayed == analysis.repeats.len() {
            "a recording replayed again"
        } else if replayed == 0 {
            "the same readings again (a file imported again)"
        } else {
            "a recording replayed again or the same readings again"
        };
        format!(
            "{} samples ({} scans, {} of them {what} and counted once)",
            study.samples.len(),
            study.samples.len() + analysis.repeats.len(),
            analysis.repeats.len()
        )
    };
    let mut b = vec![
        Block::Heading("brdfd study report".into()),
        Block::Para(format!(
            "{samples}; cost functions {cost_list}; fit method {methods}; SRA readings processed with the {strategies} strategy. Colour: {colour}, CIELAB, ΔE00 = CIEDE2000 between measured and estimated colour, per geometry (12 MA-T12 + 2 SRA). {} samples take part in the comparison, {} left out.",
            analysis.included.len(),
            analysis.excluded.len()
        )),
    ];
    if let Some((said, all)) = simulated_statement(&study.samples) {
        b.push(Block::Para(if all {
            format!(
                "Every scan of this study is {said}: readings recorded earlier, played back through simulated instruments, not measurements made for this report."
            )
        } else {
            let names: Vec<&str> = study
                .samples
                .iter()
                .filter(|s| s.simulated_note().is_some())
                .map(|s| s.name.as_str())
                .collect();
            format!(
                "{} of the {} scans are {said}: readings recorded earlier, played back through simulated instruments, not measurements ({}). The others were not measured on simulated instruments.",
                names.len(),
                study.samples.len(),
                names.join(", ")
            )
        }));
    }
    if let Some(pooled) = real_statement(&study.samples) {
        b.push(Block::Para(pooled));
    }
    if !analysis.repeats.is_empty() {
        b.extend(introduced_list(
            format!(
                "Counted once: {} scans repeat a measurement another scan of the study already holds (the same recording replayed again, or the same readings, as a file imported again holds). One measurement is one sample: each counts once, as the last of its scans whose fits all finished, in every table, figure and statistic below; the repeats are left out:",
                analysis.repeats.len()
            ),
            analysis
                .repeats
                .iter()
                .map(|r| format!("{}: {}, counted as {}", r.sample, r.shared, r.counted_as)),
        ));
    }
    if !analysis.rescanned.is_empty() {
        b.extend(introduced_list(
            "Counted per scan: these samples were scanned more than once with different readings; every scan counts as one sample in the means, intervals and sign tests, so n counts scans, not distinct physical samples:".into(),
            analysis
                .rescanned
                .iter()
                .map(|r| format!("{}: {}", r.sample, r.scans.join(", "))),
        ));
    }
    b.push(Block::Heading(
        "Mean ΔE00 per sample and cost function".into(),
    ));
    b.push(per_sample_table(
        study,
        costs,
        &["all", "diffuse", "specular", "max"],
        format!(
            "Table 1. Mean ΔE00 between measured and estimated colour per sample: over all 14 geometries, the 12 diffuse (MA-T12) and the 2 specular (SRA) ones, and the maximum; per cost function ({cost_list}), method {methods}. Specular metric: ΔE00 against the grey spectrum the SRA reading is spread into (the paper's); Table 6 gives the luminance metric."
        ),
        |row, s, c| match s.fit(c).map(|f| &f.state) {
            Some(FitState::Done(d)) => {
                let e = &d.evaluation;
                row.extend(
                    [
                        Some(e.all.mean),
                        Some(e.diffuse.mean),
                        e.specular.map(|s| s.mean),
                        Some(e.all.max),
                    ]
                    .map(|v| v.map_or("no specular readings".into(), |v| format!("{v:.3}"))),
                );
            }
            Some(FitState::Failed { .. }) => {
                row.extend(["failed".into(), "".into(), "".into(), "".into()])
            }
            Some(FitState::Unfinished { status }) => {
                row.extend([status.clone(), "".into(), "".into(), "".into()])
            }
            None => row.extend(["no fit".into(), "".into(), "".into(), "".into()]),
        },
    ));
    b.extend(held_out_blocks(study, costs));
    b.extend(reach_blocks(study, costs));
    b.push(Block::Heading(
        "Mean ΔE00 per cost function, 95 % confidence interval".into(),
    ));
    b.push(per_cost_table(
        analysis,
        format!(
            "Table 2. Mean over the {} samples that take part of each sample's mean ΔE00, ± half-width [low, high] of the 95 % confidence interval (Student t, n − 1 degrees of freedom). Specular: the paper's ΔE00 against the grey spectrum; Table 7 gives the luminance metric.",
            analysis.included.len()
        ),
        &["n", "all geometries", "diffuse (MA-T12)", "specular (SRA)"],
        |s| {
            vec![
                s.all.map_or(analysis.included.len(), |c| c.n).to_string(),
                ci(&s.all),
                ci(&s.diffuse),
                ci(&s.specular),
            ]
        },
    ));
    b.push(Block::Heading("Sign tests between cost functions".into()));
    b.push(Block::Table {
        caption: "Table 3. Exact two-sided sign test on the paired ΔE00 of two cost functions per (sample, geometry) of the samples that take part (at the SRA geometries the paper's ΔE00 against the grey spectrum; Table 8 tests the luminance metric), ties dropped: n pairs, \"A worse\" where the first has the larger ΔE00, p = min(1, 2·P(X ≤ min(k, n − k))), X ~ Bin(n, ½).".into(),
        head: SIGN_TEST_HEAD.map(String::from).to_vec(),
        rows: sign_test_rows(study, &analysis.sign_tests),
    });
    // Parameters with their bootstrap intervals (SCIENCE.md §10); a fit without them says so.
    let done: Vec<(&str, &FitStudy, &DoneFit)> = study
        .samples
        .iter()
        .flat_map(|s| {
            s.fits
                .iter()
                .filter_map(move |f| f.done().map(|d| (s.name.as_str(), f, d)))
        })
        .collect();
    let with = done
        .iter()
        .filter(|(_, _, d)| d.uncertainty.is_some())
        .count();
    if !done.is_empty() {
        b.push(Block::Heading(
            "Fitted lobe parameters with bootstrap intervals".into(),
        ));
        let why = missing_intervals_reason(study);
        if with == 0 {
            b.push(Block::Para(format!(
                "No bootstrap intervals: none of the {} finished fits has them, so there is no table of parameter intervals and Fig. 8 draws no error bars. {why}",
                done.len()
            )));
            let bounded: Vec<String> = done
                .iter()
                .filter(|(_, _, d)| !d.at_bound.is_empty())
                .map(|(name, f, d)| format!("{name} {}: {}", f.cost, d.at_bound.join(", ")))
                .collect();
            if !bounded.is_empty() {
                b.push(Block::Para(format!(
                    "At a bound of the range searched, so not identified by the readings (an interval there would not be a 95 % interval either): {}.",
                    bounded.join("; ")
                )));
            }
        } else {
            let rows = done
                .iter()
                .map(|(name, f, d)| {
                    let p = &d.params;
                    let mut row = vec![name.to_string(), f.cost.to_string()];
                    // A parameter at a bound of its range is flagged whether or not it has an
                    // interval: there it is not identified.
                    let mut bound = d.at_bound.clone();
                    if let Some(u) = &d.uncertainty {
                        bound.extend(
                            u.at_bound
                                .iter()
                                .filter(|n| !d.at_bound.contains(n))
                                .cloned(),
                        );
                    }
                    let flag = |name: &str| {
                        if bound.iter().any(|b| b == name) {
                            " (at bound)"
                        } else {
                            ""
                        }
                    };
                    match &d.uncertainty {
                        Some(u) => {
                            let cell = |v: f64, iv: [f64; 2], name: &str| {
                                format!("{v:.4} [{:.4}, {:.4}]{}", iv[0], iv[1], flag(name))
                            };
                            row.extend([
                                cell(p.ks, u.ks, "ks"),
                                cell(p.alpha, u.alpha, "alpha"),
                                cell(p.ior, u.ior, "ior"),
                                cell(d.evaluation.all.mean, u.delta_e00_mean, ""),
                                u.resamples.to_string(),
                                match (u.calibrated && bound.is_empty(), bound.is_empty()) {
                                    (true, _) => "yes".to_string(),
                                    (false, true) => "no".to_string(),
                                    (false, false) => {
                                        format!("no ({} at a bound)", bound.join(", "))
                                    }
                                },
                            ]);
                        }
                        None => {
                            let cell =
                                |v: f64, name: &str| format!("{v:.4} (no interval){}", flag(name));
                            row.extend([
                                cell(p.ks, "ks"),
                                cell(p.alpha, "alpha"),
                                cell(p.ior, "ior"),
                                cell(d.evaluation.all.mean, ""),
                                "none".into(),
                                if bound.is_empty() {
                                    "—".into()
                                } else {
                                    format!("no ({} at a bound)", bound.join(", "))
                                },
                            ]);
                        }
                    }
                    row
                })
                .collect();
            b.push(Block::Table {
                caption: "Table 4. Fitted ks, α, μ (ior) and mean ΔE00, each with its 95 % bootstrap interval [low, high]: the measured BRDF perturbed with the noise the scan shows, refitted per resample (parametric bootstrap), widened to the spread of refits with each geometry left out (jackknife, SCIENCE.md §10). The ΔE00 interval is the spread of each resample's fit against its resample. Fig. 8 draws the kd intervals as error bars. Calibrated: whether intervals of that cost function and SRA model were measured to hold the truth in ≥ 90 % of synthetic trials and of held-out real geometries, with no parameter at a bound of its range (SCIENCE.md §10); where \"no\", they are not calibrated 95 % intervals. A fit without intervals is marked \"no interval\".".into(),
                head: ["sample", "cost", "ks", "α", "μ", "mean ΔE00", "resamples", "calibrated"]
                    .map(String::from)
                    .to_vec(),
                rows,
            });
            if with < done.len() {
                b.push(Block::Para(format!(
                    "{} of the {} finished fits have no bootstrap intervals (\"no interval\" above; Fig. 8 draws no error bars for them). {why}",
                    done.len() - with,
                    done.len()
                )));
            }
            let unidentified = lobe_not_identified(study);
            if !unidentified.is_empty() {
                b.push(Block::Para(format!(
                    "Lobe not identified: cf1's and cf2's intervals of the same scan do not overlap on {}. There the readings do not fix the lobe, and neither interval is the parameter's: read the held-out ΔE00 instead.",
                    unidentified.join("; ")
                )));
            }
        }
    }
    // Where, when and by which instruments each stored scan was measured.
    if study.samples.iter().any(|s| s.origin.is_some()) {
        let stations = study
            .samples
            .iter()
            .any(|s| s.origin.as_ref().is_some_and(|o| o.station.is_some()));
        let mut head = vec!["sample".to_string(), "scan".to_string()];
        if stations {
            head.push("station".into());
        }
        head.extend(["measured at (UTC)", "source", "MA-T12", "SRA"].map(String::from));
        let rows = study
            .samples
            .iter()
            .map(|s| {
                let mut row = vec![
                    s.name.clone(),
                    s.scan_id.map_or(String::new(), |id| id.to_string()),
                ];
                match &s.origin {
                    Some(o) => {
                        if stations {
                            row.push(o.station.clone().unwrap_or_default());
                        }
                        row.push(crate::formats::rfc3339_utc(
                            o.measured_at_ms.div_euclid(1000),
                        ));
                        row.push(o.provenance.source.to_string());
                        row.push(o.provenance.ma_t12.describe());
                        row.push(o.provenance.sra.describe());
                    }
                    None => row.resize(head.len(), "unknown".into()),
                }
                row
            })
            .collect();
        b.push(Block::Heading("Where the scans were measured".into()));
        b.push(Block::Table {
            caption: "Table 5. Provenance of each scan: the store's scan id, when it was measured, how its readings came in (measured by the daemon, imported from a file, replayed), and each instrument as it reported itself — model, serial, firmware — with its origin: measured on this bench, imported from a file, simulated, or absent (the scan has no readings of it). A report pools simulated with real scans only with --include-simulated.".into(),
            head,
            rows,
        });
    }
    // The specular geometries judged by luminance (SCIENCE.md §7.2), beside the paper's ΔE00.
    let mut sras: Vec<String> = Vec::new();
    for d in study.done_fits() {
        let text = d.sra.to_string();
        if !sras.contains(&text) {
            sras.push(text);
        }
    }
    let instrument = study
        .done_fits()
        .map(|d| {
            format!(
                "CIE illuminant {}, {}° observer",
                d.sra.illuminant, d.sra.observer
            )
        })
        .next()
        .unwrap_or_else(|| "CIE illuminant C, 2° observer".into());
    b.push(Block::Heading(
        "Specular geometries: luminance |ΔL*| (not the paper's metric)".into(),
    ));
    b.push(Block::Para(format!(
        "The SRA reads one achromatic number per geometry. The paper's specular metric, the \"specular\" columns of Tables 1 and 2 and the sign tests of Table 3, is ΔE00 against the grey spectrum that number is spread into; Tables 6–8 judge the same fits by |ΔL*| between the model's luminance and the measured one ({instrument}; SCIENCE.md §7.2). SRA reading model of the fits' cost: {} (SCIENCE.md §5.1).",
        if sras.is_empty() { "none".to_string() } else { sras.join(", ") }
    )));
    b.push(per_sample_table(
        study,
        costs,
        &["|ΔL*| sra-20", "|ΔL*| sra-60", "ΔE00 (paper)"],
        format!(
            "Table 6. Specular |ΔL*| between the model's and the measured luminance at sra-20 and sra-60 per sample and cost function ({cost_list}), method {methods}; beside it the paper's specular metric (mean ΔE00 against the grey spectrum, as in Table 1)."
        ),
        |row, s, c| match s.done(c) {
            Some(d) => match (&d.specular_delta_l, &d.evaluation.specular) {
                (Some(l), Some(e)) => {
                    row.push(format!("{:.3}", l.per_geometry[0]));
                    row.push(format!("{:.3}", l.per_geometry[1]));
                    row.push(format!("{:.3}", e.mean));
                }
                _ => row.extend(["no specular readings".into(), "".into(), "".into()]),
            },
            None => row.extend(["no result".into(), "".into(), "".into()]),
        },
    ));
    b.push(per_cost_table(
        analysis,
        format!(
            "Table 7. Mean over the {} samples that take part of each sample's mean specular |ΔL*| (luminance metric), ± half-width [low, high] of the 95 % confidence interval (Student t), beside the paper's specular ΔE00 of Table 2.",
            analysis.included.len()
        ),
        &["specular |ΔL*|", "specular ΔE00 (paper)"],
        |s| vec![ci(&s.specular_delta_l), ci(&s.specular)],
    ));
    b.push(Block::Table {
        caption: "Table 8. Exact two-sided sign test on the paired specular |ΔL*| (luminance metric) of two cost functions per (sample, SRA geometry) of the samples that take part, ties dropped: n pairs, \"A worse\" where the first has the larger |ΔL*|; p as in Table 3.".into(),
        head: SIGN_TEST_HEAD.map(String::from).to_vec(),
        rows: sign_test_rows(study, &analysis.luminance_sign_tests),
    });
    b.push(Block::Heading("Samples left out".into()));
    if analysis.excluded.is_empty() {
        b.push(Block::Para(
            "None: every sample's fit finished under every cost function.".into(),
        ));
    } else {
        b.extend(introduced_list(
            "A sample whose fit failed under any cost function is left out of the means, the confidence intervals and the sign tests for all cost functions (as the paper did); its finished fits still appear in Table 1 and the figures.".into(),
            analysis
                .excluded
                .iter()
                .map(|e| format!("{}: {}", e.sample, e.reasons.join("; "))),
        ));
    }
    b.push(Block::Heading("Figures".into()));
    for f in figures {
        b.push(Block::Figure {
            stem: f.stem.clone(),
            caption: f.caption.clone(),
        });
    }
    b
}

/// Which commands stop the daemon before the bootstraps end.
const STOPS_BEFORE_BOOTSTRAPS: &str =
    "brdfd replay does once the fits are done, and brdfd demo unless run with --bootstrap N";

/// The commands that give stored fits intervals, as the report advises them.
pub(crate) const HOW_TO_GET_INTERVALS: &str = "to get intervals, serve this store (brdfd serve --db DB) and refit each scan (brdfd refit SCAN), then report once brdfd status shows no bootstraps pending; for the demo, run brdfd demo --bootstrap 200 --dir NEW (it waits for every fit's intervals) and report on that new database.";

/// Why fits have no bootstrap intervals, as far as the study can tell.
/// The samples whose cf1 and cf2 intervals are disjoint on a lobe parameter, as
/// `NAME (ks, alpha)`: the lobe is not identified there (SCIENCE.md §10).
fn lobe_not_identified(study: &Study) -> Vec<String> {
    study
        .samples
        .iter()
        .filter_map(|s| {
            let of = |cost: CostFunction| {
                s.fits
                    .iter()
                    .filter(|f| f.cost == cost)
                    .find_map(|f| f.done().and_then(|d| d.uncertainty.as_ref()))
            };
            let apart = crate::uncertainty::jackknife::disjoint(
                of(CostFunction::Cf1)?,
                of(CostFunction::Cf2)?,
            );
            (!apart.is_empty()).then(|| format!("{} ({})", s.name, apart.join(", ")))
        })
        .collect()
}

fn missing_intervals_reason(study: &Study) -> String {
    if study.samples.iter().any(|s| s.origin.is_some()) {
        format!(
            "The store keeps no intervals for them. The daemon bootstraps each fit once, right after storing it, one fit at a time, when [fit] bootstrap is above 0 (200 resamples by default; 0 turns them off). A stored fit has none when that setting was 0, when the daemon stopped before its bootstrap ended ({STOPS_BEFORE_BOOTSTRAPS}), or when the report read the store too early (brdfd status counts the bootstraps pending). A stored fit is not bootstrapped later, a new fit is: {HOW_TO_GET_INTERVALS}"
        )
    } else {
        "These fits were made in this process without a bootstrap: intervals are computed only when asked for (brdfd fit --bootstrap N).".into()
    }
}

fn md_cell(s: &str) -> String {
    s.replace('|', "\\|")
}

/// The summary as Markdown.
pub fn markdown(study: &Study, analysis: &Analysis, figures: &[Figure]) -> String {
    let mut t = String::new();
    for block in blocks(study, analysis, figures) {
        match block {
            Block::Heading(h) if t.is_empty() => {
                let _ = writeln!(t, "# {h}\n");
            }
            Block::Heading(h) => {
                let _ = writeln!(t, "## {h}\n");
            }
            Block::Para(p) => {
                let _ = writeln!(t, "{p}\n");
            }
            Block::Table {
                caption,
                head,
                rows,
            } => {
                let _ = writeln!(t, "{caption}\n");
                let _ = writeln!(
                    t,
                    "| {} |",
                    head.iter()
                        .map(|h| md_cell(h))
                        .collect::<Vec<_>>()
                        .join(" | ")
                );
                let _ = writeln!(t, "|{}", "---|".repeat(head.len()));
                for r in rows {
                    let _ = writeln!(
                        t,
                        "| {} |",
                        r.iter().map(|c| md_cell(c)).collect::<Vec<_>>().join(" | ")
                    );
                }
                t.push('\n');
            }
            Block::List(items) => {
                for i in items {
                    let _ = writeln!(t, "- {i}");
                }
                t.push('\n');
            }
            Block::Figure { stem, caption } => {
                let _ = writeln!(
                    t,
                    "![{stem}]({stem}.png)\n\n{caption} ([SVG]({stem}.svg))\n"
                );
            }
        }
    }
    t
}

fn esc(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
}

/// The summary as a self-contained HTML page (figures linked beside it).
pub fn html(study: &Study, analysis: &Analysis, figures: &[Figure]) -> String {
    let mut t = String::from(
        "<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n<title>brdfd study report</title>\n<style>\nbody{font-family:sans-serif;max-width:1300px;margin:2em auto;padding:0 1em;line-height:1.4}\ntable{border-collapse:collapse;margin:.5em 0 1.5em}\nth,td{border:1px solid #aaa;padding:.25em .6em;text-align:right}\nth:first-child,td:first-child{text-align:left}\ncaption{caption-side:top;text-align:left;padding:.3em 0;max-width:1100px}\nfigure{margin:1.5em 0}\nimg{max-width:100%;border:1px solid #ddd}\n</style>\n</head>\n<body>\n",
    );
    let mut first = true;
    for block in blocks(study, analysis, figures) {
        match block {
            Block::Heading(h) => {
                let tag = if first { "h1" } else { "h2" };
                first = false;
                let _ = writeln!(t, "<{tag}>{}</{tag}>", esc(&h));
            }
            Block::Para(p) => {
                let _ = writeln!(t, "<p>{}</p>", esc(&p));
            }
            Block::Table {
                caption,
                head,
                rows,
            } => {
                let _ = writeln!(t, "<table>\n<caption>{}</caption>", esc(&caption));
                let _ = writeln!(
                    t,
                    "<tr>{}</tr>",
                    head.iter()
                        .map(|h| format!("<th>{}</th>", esc(h)))
                        .collect::<String>()
                );
                for r in rows {
                    let _ = writeln!(
                        t,
                        "<tr>{}</tr>",
                        r.iter()
                            .map(|c| format!("<td>{}</td>", esc(c)))
                            .collect::<String>()
                    );
                }
                let _ = writeln!(t, "</table>");
            }
            Block::List(items) => {
                let _ = writeln!(t, "<ul>");
                for i in items {
                    let _ = writeln!(t, "<li>{}</li>", esc(&i));
                }
                let _ = writeln!(t, "</ul>");
            }
            Block::Figure { stem, caption } => {
                let _ = writeln!(
                    t,
                    "<figure>\n<img src=\"{stem}.png\" alt=\"{}\">\n<figcaption>{} (<a href=\"{stem}.svg\">SVG</a>)</figcaption>\n</figure>",
                    esc(&caption),
                    esc(&caption)
                );
            }
        }
    }
    t.push_str("</body>\n</html>\n");
    t
}

/// "Pooled: the 3 scans of this study are real — 2 measured on this bench, 1 imported from a
/// file (…)", when every scan loaded from a store is real (no simulated instrument); `None`
/// for a study with simulated scans (said by [`simulated_statement`]) or made in memory.
fn real_statement(samples: &[SampleStudy]) -> Option<String> {
    use crate::store::InstrumentOrigin;
    let origins: Vec<_> = samples
        .iter()
        .map(|s| s.origin.as_ref().map(|o| &o.provenance))
        .collect::<Option<_>>()?;
    if origins.is_empty() || origins.iter().any(|p| p.simulated()) {
        return None;
    }
    let named = |origin: InstrumentOrigin| -> Vec<&str> {
        samples
            .iter()
            .zip(&origins)
            .filter(|(_, p)| p.ma_t12.origin == origin)
            .map(|(s, _)| s.name.as_str())
            .collect()
    };
    let parts: Vec<String> = [
        (InstrumentOrigin::Measured, "measured on this bench"),
        (
            InstrumentOrigin::Imported,
            "imported from instrument exports or scan files",
        ),
    ]
    .into_iter()
    .filter_map(|(o, said)| {
        let n = named(o);
        (!n.is_empty()).then(|| format!("{} {said} ({})", n.len(), n.join(", ")))
    })
    .collect();
    Some(format!(
        "Pooled: the {} scans of this study are real — {}. Scans from simulated instruments are left out unless the report is asked for them (--include-simulated).",
        samples.len(),
        parts.join("; ")
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The same file imported twice holds the same readings, not a replayed recording: the
    /// summary calls the repeat what it is.
    #[test]
    fn a_repeated_import_is_not_called_a_replayed_recording() {
        let mut study = crate::study::tests::study_from_truth(2, None);
        let mut again = study.samples[0].clone();
        again.name = format!("{} (again)", again.name);
        study.samples.push(again);
        let analysis = Analysis::of(&study);
        assert_eq!(analysis.repeats.len(), 1);
        let md = markdown(&study, &analysis, &[]);
        assert!(
            md.contains(
                "scans, 1 of them the same readings again (a file imported again) and counted \
                 once)"
            ),
            "{md}"
        );
        assert!(!md.contains("recording replayed again and"), "{md}");
    }

    /// A fit at a bound of its range (μ = 3, the top of the default range) is flagged with no
    /// intervals computed, and one inside its range is not.
    #[test]
    fn a_parameter_at_its_bound_is_flagged_without_intervals() {
        let study = crate::study::Study::from_truth(2, |i, _, mut p| {
            if i == 0 {
                p.ior = crate::model::Bounds::default().ior.1;
            } else {
                p.ior = 1.7;
            }
            Ok(p)
        });
        let first = &study.samples[0];
        let d = first.fits[0].done().unwrap();
        assert_eq!(d.at_bound, ["ior"], "{:?}", d.params);
        assert!(study.samples[1].fits[0].done().unwrap().at_bound.is_empty());
        let md = markdown(&study, &Analysis::of(&study), &[]);
        assert!(md.contains(&format!("{} cf1: ior", first.name)), "{md}");
        assert!(
            !md.contains(&format!("{} cf1: ior", study.samples[1].name)),
            "{md}"
        );
    }

    /// Where cf1's and cf2's intervals of a scan do not overlap, the report says the lobe is
    /// not identified, naming the sample and the parameters; where they overlap, it does not.
    #[test]
    fn disjoint_cf1_and_cf2_intervals_are_called_a_lobe_not_identified() {
        let mut study = crate::study::tests::study_from_truth(2, None);
        let interval = |ks: [f64; 2]| crate::uncertainty::Uncertainty {
            method: "test".into(),
            resamples: 200,
            noise: 0.01,
            seed: 1,
            percentile_level: 0.95,
            ks,
            alpha: [0.1, 0.3],
            ior: [1.4, 1.6],
            kd: vec![[0.0, 1.0]; crate::spectral::BANDS],
            delta_e00_mean: [0.5, 1.0],
            delta_e00_diffuse_mean: [0.5, 1.0],
            delta_e00_specular_mean: None,
            calibrated: true,
            note: None,
            at_bound: Vec::new(),
            misfit: None,
        };
        for (i, s) in study.samples.iter_mut().enumerate() {
            for f in &mut s.fits {
                let ks = match (f.cost, i) {
                    (CostFunction::Cf2, 0) => [0.5, 0.6],
                    _ => [0.1, 0.55],
                };
                if let FitState::Done(d) = &mut f.state {
                    d.uncertainty = Some(interval(if f.cost == CostFunction::Cf1 && i == 0 {
                        [0.1, 0.2]
                    } else {
                        ks
                    }));
                }
            }
        }
        let md = markdown(&study, &Analysis::of(&study), &[]);
        let first = &study.samples[0].name;
        assert!(
            md.contains(&format!("Lobe not identified: cf1's and cf2's intervals of the same scan do not overlap on {first} (ks).")),
            "{md}"
        );
        assert!(
            !md.contains(&format!("{} (ks)", study.samples[1].name)),
            "{md}"
        );
    }
}
