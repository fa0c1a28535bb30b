//! The study's statistics (SCIENCE.md §8): which samples take part, the mean ΔE00 per cost
//! function with its 95 % Student-t interval, and the pairwise sign tests.
//!
//! - A sample whose fit failed (or did not finish) under any of the study's cost functions is
//!   left out of every comparison, as the paper did, and named with the reason.
//! - The mean is over samples of each sample's mean ΔE00 (over its 14 geometries, and split
//!   into diffuse and specular); n is the number of samples that take part.
//! - The sign test pairs the ΔE00 of two cost functions per (sample, geometry): 14 pairs per
//!   sample, ties dropped. `plus` counts pairs where the first cost function has the larger
//!   ΔE00 (fits worse).
//! - A recording replayed more than once (the demo run twice: the same sample's recording
//!   through the simulated instruments again) is one sample, not several: its scans hold the
//!   same readings, so counting each would count one measurement as many. Scans of one sample
//!   that replay the same recording, or hold bit-identical readings (one file imported twice),
//!   count once, as the last of them in report order whose fits all finished (else the last);
//!   the others are listed ([`Repeat`]). Scans of one sample with different readings (measured
//!   again) each count, and the report says so ([`Rescan`]).
//! - The specular luminance metric (SCIENCE.md §7.2) gets its own mean per cost function and
//!   its own sign tests, on the paired |ΔL*| per (sample, SRA geometry): 2 pairs per sample.

use crate::cost::CostFunction;
use crate::evaluation::Evaluation;
use crate::stats::{MeanCi, SignTest, mean_ci95, sign_test};

use crate::study::{DoneFit, SampleStudy, Study};

/// A sample left out of the comparison, and why.
#[derive(Debug, Clone, PartialEq)]
pub struct Exclusion {
    pub sample: String,
    /// One entry per cost function whose fit is missing, failed or unfinished.
    pub reasons: Vec<String>,
}

/// A scan counted once with another: it replays the same recording (or holds the same
/// readings) as the scan that counts.
#[derive(Debug, Clone, PartialEq)]
pub struct Repeat {
    /// The scan left out, by its name in the study.
    pub sample: String,
    /// The scan that counts for both.
    pub counted_as: String,
    /// What they share: "the recording synthetic-t-sky-blue (T.Sky blue)" or "the same
    /// readings".
    pub shared: String,
}

/// A sample measured in more than one scan with different readings: each scan counts.
#[derive(Debug, Clone, PartialEq)]
pub struct Rescan {
    /// The sample's name as scanned.
    pub sample: String,
    /// The scans' names in the study.
    pub scans: Vec<String>,
}

/// Mean ΔE00 over samples under one cost function.
#[derive(Debug, Clone, PartialEq)]
pub struct CostSummary {
    pub cost: CostFunction,
    /// The method(s) that produced the fits.
    pub method: String,
    /// Over all 14 geometries; `None` with fewer than two samples.
    pub all: Option<MeanCi>,
    pub diffuse: Option<MeanCi>,
    /// The paper's specular metric: ΔE00 against the grey spectrum the SRA reading is spread
    /// into.
    pub specular: Option<MeanCi>,
    /// Each sample's mean specular |ΔL*| between model and measured luminance (SCIENCE.md §7.2).
    pub specular_delta_l: Option<MeanCi>,
}

/// A sign test between two cost functions.
#[derive(Debug, Clone, PartialEq)]
pub struct SignRow {
    pub a: CostFunction,
    pub b: CostFunction,
    pub test: SignTest,
}

/// Everything the summary tables show.
#[derive(Debug, Clone, PartialEq)]
pub struct Analysis {
    pub cost_functions: Vec<CostFunction>,
    /// Indices into `study.samples` of the samples that take part.
    pub included: Vec<usize>,
    pub excluded: Vec<Exclusion>,
    /// Scans counted once with another scan of the same recording: in neither `included` nor
    /// `excluded`.
    pub repeats: Vec<Repeat>,
    /// Samples with several counted scans of different readings: each scan counts.
    pub rescanned: Vec<Rescan>,
    pub per_cost: Vec<CostSummary>,
    pub sign_tests: Vec<SignRow>,
    /// Sign tests on the paired specular |ΔL*| per (sample, SRA geometry): 2 pairs a sample.
    pub luminance_sign_tests: Vec<SignRow>,
}

impl Analysis {
    pub fn of(study: &Study) -> Analysis {
        let cost_functions = study.cost_functions();
        let (repeats, rescanned, counted) = replays(study, &cost_functions);
        let mut included = Vec::new();
        let mut excluded = Vec::new();
        for (i, s) in study.samples.iter().enumerate() {
            if !counted[i] {
                continue;
            }
            let reasons: Vec<String> = cost_functions
                .iter()
                .filter_map(|&c| match s.fit(c) {
                    None => Some(format!("no {c} fit")),
                    Some(f) => f.problem(),
                })
                .collect();
            if reasons.is_empty() {
                included.push(i);
            } else {
                excluded.push(Exclusion {
                    sample: s.name.clone(),
                    reasons,
                });
            }
        }
        let done = |i: usize, c: CostFunction| -> &DoneFit {
            study.samples[i]
                .done(c)
                .expect("included samples have every fit done")
        };
        let evaluation = |i: usize, c: CostFunction| -> &Evaluation { &done(i, c).evaluation };
        let per_cost = cost_functions
            .iter()
            .map(|&c| {
                let ci = |pick: fn(&Evaluation) -> f64| {
                    // NaN: no such geometries (a scan without SRA readings has no specular mean).
                    let xs: Vec<f64> = included
                        .iter()
                        .map(|&i| pick(evaluation(i, c)))
                        .filter(|v| !v.is_nan())
                        .collect();
                    mean_ci95(&xs)
                };
                CostSummary {
                    cost: c,
                    method: study.method_of(c),
                    all: ci(|e| e.all.mean),
                    diffuse: ci(|e| e.diffuse.mean),
                    specular: ci(|e| e.specular.map_or(f64::NAN, |s| s.mean)),
                    specular_delta_l: mean_ci95(
                        &included
                            .iter()
                            .filter_map(|&i| done(i, c).specular_delta_l.map(|d| d.mean))
                            .collect::<Vec<_>>(),
                    ),
                }
            })
            .collect();
        let mut sign_tests = Vec::new();
        let mut luminance_sign_tests = Vec::new();
        for (k, &a) in cost_functions.iter().enumerate() {
            for &b in &cost_functions[k + 1..] {
                let paired = |c: CostFunction| -> Vec<f64> {
                    included
                        .iter()
                        .flat_map(|&i| evaluation(i, c).evaluated())
                        .collect()
                };
                sign_tests.push(SignRow {
                    a,
                    b,
                    test: sign_test(&paired(a), &paired(b)),
                });
                let paired_l = |c: CostFunction| -> Vec<f64> {
                    included
                        .iter()
                        .flat_map(|&i| done(i, c).specular_delta_l.map(|d| d.per_geometry))
                        .flatten()
                        .collect()
                };
                luminance_sign_tests.push(SignRow {
                    a,
                    b,
                    test: sign_test(&paired_l(a), &paired_l(b)),
                });
            }
        }
        Analysis {
            cost_functions,
            included,
            excluded,
            repeats,
            rescanned,
            per_cost,
            sign_tests,
            luminance_sign_tests,
        }
    }
}

/// Who a sample is: its scanned name and station.
fn identity(s: &SampleStudy) -> (&str, Option<&str>) {
    (
        s.scan.sample.as_str(),
        s.origin.as_ref().and_then(|o| o.station.as_deref()),
    )
}

/// What two scans of one sample share that makes them one measurement: the same replayed
/// recording, or bit-identical readings.
fn shared(a: &SampleStudy, b: &SampleStudy) -> Option<String> {
    match (a.recording(), b.recording()) {
        (Some(x), Some(y)) if x == y => return Some(format!("the recording {x}")),
        _ => {}
    }
    (a.scan.readings == b.scan.readings && a.scan.reference == b.scan.reference)
        .then(|| "the same readings".to_string())
}

/// The scans counted once with another ([`Repeat`]), the samples counted per scan
/// ([`Rescan`]), and per sample whether it counts.
fn replays(study: &Study, costs: &[CostFunction]) -> (Vec<Repeat>, Vec<Rescan>, Vec<bool>) {
    let n = study.samples.len();
    let complete = |i: usize| costs.iter().all(|&c| study.samples[i].done(c).is_some());
    // Groups of one measurement: scans of one sample that share a recording or readings.
    let mut group: Vec<usize> = (0..n).collect();
    for i in 0..n {
        for j in 0..i {
            if group[j] == j
                && identity(&study.samples[i]) == identity(&study.samples[j])
                && shared(&study.samples[i], &study.samples[j]).is_some()
            {
                group[i] = j;
                break;
            }
        }
    }
    let mut counted = vec![false; n];
    let mut repeats = Vec::new();
    for head in (0..n).filter(|&i| group[i] == i) {
        let members: Vec<usize> = (0..n).filter(|&i| group[i] == head).collect();
        let keep = members
            .iter()
            .rev()
            .copied()
            .find(|&i| complete(i))
            .unwrap_or(members[members.len() - 1]);
        counted[keep] = true;
        for &i in members.iter().filter(|&&i| i != keep) {
            repeats.push(Repeat {
                sample: study.samples[i].name.clone(),
                counted_as: study.samples[keep].name.clone(),
                shared: shared(&study.samples[i], &study.samples[keep])
                    .unwrap_or_else(|| "the same readings".into()),
            });
        }
    }
    let mut rescanned: Vec<Rescan> = Vec::new();
    for i in (0..n).filter(|&i| counted[i]) {
        let (name, _) = identity(&study.samples[i]);
        let same: Vec<String> = (0..n)
            .filter(|&j| counted[j] && identity(&study.samples[j]) == identity(&study.samples[i]))
            .map(|j| study.samples[j].name.clone())
            .collect();
        if same.len() > 1 && !rescanned.iter().any(|r| r.scans == same) {
            rescanned.push(Rescan {
                sample: name.to_string(),
                scans: same,
            });
        }
    }
    (repeats, rescanned, counted)
}

/// A p-value readably: four decimals, or scientific notation below 0.0001.
pub fn format_p(p: f64) -> String {
    if p < 1e-4 {
        format!("{p:.2e}")
    } else {
        format!("{p:.4}")
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::study::tests::study_from_truth;

    #[test]
    fn a_sample_failed_under_one_cost_function_is_left_out_of_all() {
        let study = study_from_truth(5, Some(3));
        let a = Analysis::of(&study);
        assert_eq!(a.included, vec![0, 1, 2, 4]);
        assert_eq!(a.excluded.len(), 1);
        assert_eq!(a.excluded[0].sample, study.samples[3].name);
        assert_eq!(
            a.excluded[0].reasons,
            vec!["m2 fit failed: cancelled by the operator".to_string()]
        );
        // cf1 is left out for the failed sample too, though it finished.
        assert_eq!(a.per_cost[0].all.unwrap().n, 4);
        assert_eq!(a.sign_tests.len(), 3);
        let t = a.sign_tests[0].test;
        assert_eq!(t.n + t.ties, 4 * 14);
        // The luminance sign tests pair the 2 SRA geometries of each sample that takes part.
        assert_eq!(a.luminance_sign_tests.len(), 3);
        let t = a.luminance_sign_tests[0].test;
        assert_eq!(t.n + t.ties, 4 * 2);
        assert_eq!(a.per_cost[0].specular_delta_l.unwrap().n, 4);
    }

    /// The demo run twice: 8 recordings replayed twice each make 16 scans of 8 samples. Each
    /// recording counts once (the later replay), so n is 8, not 16, and the sign tests pair 8
    /// samples' geometries.
    #[test]
    fn a_recording_replayed_twice_counts_once() {
        let study = crate::study::tests::replayed_twice(8);
        assert_eq!(study.samples.len(), 16);
        let a = Analysis::of(&study);
        assert_eq!(a.included, (8..16).collect::<Vec<_>>());
        assert!(a.excluded.is_empty());
        assert_eq!(a.repeats.len(), 8);
        assert_eq!(a.repeats[0].sample, "T.Freesia pink (scan 1)");
        assert_eq!(a.repeats[0].counted_as, "T.Freesia pink (scan 9)");
        assert_eq!(
            a.repeats[0].shared,
            "the recording synthetic-t-freesia-pink (T.Freesia pink)"
        );
        assert_eq!(a.per_cost[0].all.unwrap().n, 8);
        let t = a.sign_tests[0].test;
        assert_eq!(t.n + t.ties, 8 * 14);
        // The same as the study of one run.
        let once = Analysis::of(&study_from_truth(8, None));
        assert_eq!(a.per_cost, once.per_cost);
        assert!(a.rescanned.is_empty());
    }

    /// A sample measured twice with different readings is two measurements: both count, and the
    /// analysis names it so the report can say that n counts scans.
    #[test]
    fn a_sample_scanned_again_counts_per_scan_and_is_named() {
        let mut study = study_from_truth(3, None);
        let mut again = study.samples[0].clone();
        again.scan.readings.ma_t12[0][0] *= 1.01;
        study.samples[0].name = "T.Freesia pink (scan 1)".into();
        again.name = "T.Freesia pink (scan 4)".into();
        study.samples.push(again);
        let a = Analysis::of(&study);
        assert_eq!(a.included.len(), 4);
        assert!(a.repeats.is_empty());
        assert_eq!(
            a.rescanned,
            vec![Rescan {
                sample: "T.Freesia pink".into(),
                scans: vec![
                    "T.Freesia pink (scan 1)".into(),
                    "T.Freesia pink (scan 4)".into()
                ],
            }]
        );
    }

    #[test]
    fn p_values_print_readably() {
        assert_eq!(format_p(0.0703125), "0.0703");
        assert_eq!(format_p(1.0), "1.0000");
        assert_eq!(format_p(3.2e-6), "3.20e-6");
    }
}
