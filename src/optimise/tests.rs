//! Tests of the public fitting API on synthetic scans built from known parameters.
//! The full reliability study is `tools/src/bin/reliability.rs`; `small_reliability_study` below
//! is its always-run miniature.

use super::*;
use crate::cost::cost;
use crate::geometry::by_name;
use crate::model::evaluate;
use crate::optimise::synthetic::{self, SyntheticCase};

fn settings(cf: CostFunction, method: Method, seed: u64) -> Settings {
    Settings {
        cost: cf,
        method,
        seed,
        ..Settings::default()
    }
}

/// A GA small enough for debug builds (2 320 evaluations instead of up to 100 000), run to
/// its last generation.
fn small_paper(cf: CostFunction, seed: u64) -> Settings {
    Settings {
        paper: GaSettings {
            population: 40,
            generations: 60,
            stall_generations: 0,
            ..GaSettings::default()
        },
        ..settings(cf, Method::Paper, seed)
    }
}

fn case(i: usize) -> SyntheticCase {
    synthetic::cases()[i]
}

fn cost_of(cf: CostFunction, m: &MeasuredBrdf, p: &Params) -> f64 {
    cost(
        cf,
        m,
        &evaluate(p, FresnelCosine::Incidence, &SpecularGeometry::all()),
    )
}

fn rel(a: f64, b: f64) -> f64 {
    ((a - b) / b).abs()
}

#[test]
fn same_seed_gives_bit_identical_fits() {
    let m = synthetic::with_noise(
        &synthetic::measured(&case(0).truth, Default::default()),
        0.01,
        4,
    );
    for s in [
        settings(CostFunction::Cf2, Method::Separable, 11),
        small_paper(CostFunction::M2, 11),
    ] {
        let (a, b) = (fit(&m, &s).unwrap(), fit(&m, &s).unwrap());
        let bits = |p: &Params| {
            let mut v: Vec<u64> = p.kd.iter().map(|x| x.to_bits()).collect();
            v.extend([p.ks.to_bits(), p.alpha.to_bits(), p.ior.to_bits()]);
            v
        };
        assert_eq!(bits(&a.params), bits(&b.params), "{}", s.method);
        assert_eq!(a.cost.to_bits(), b.cost.to_bits());
        assert_eq!(a.best_cost_per_generation, b.best_cost_per_generation);
        assert_eq!(
            (a.evaluations, a.generations),
            (b.evaluations, b.generations)
        );
        assert_eq!((a.method, a.seed), (s.method, 11));
    }
    // A different seed draws a different GA population.
    let c = fit(&m, &small_paper(CostFunction::M2, 12)).unwrap();
    assert_ne!(
        c.params,
        fit(&m, &small_paper(CostFunction::M2, 11)).unwrap().params
    );
}

/// A scan the model can reproduce exactly (spectral SRA readings): every cost function
/// brings the parameters back.
#[test]
fn recovers_the_truth_from_a_model_consistent_scan() {
    for (i, cf) in [
        (1, CostFunction::Cf1),
        (3, CostFunction::Cf2),
        (4, CostFunction::M2),
    ] {
        let truth = case(i).truth;
        let m = synthetic::consistent(&truth, FresnelCosine::Incidence);
        let out = fit(&m, &settings(cf, Method::Separable, 1)).unwrap();
        let p = out.params;
        assert!(
            out.cost
                < 1e-4
                    * cost_of(
                        cf,
                        &m,
                        &Params {
                            kd: [0.0; BANDS],
                            ..truth
                        }
                    )
        );
        for (name, got, want) in [
            ("ks", p.ks, truth.ks),
            ("alpha", p.alpha, truth.alpha),
            ("ior", p.ior, truth.ior),
        ] {
            assert!(rel(got, want) < 1e-4, "{cf} {name}: {got} vs {want}");
        }
        for b in 0..BANDS {
            assert!((p.kd[b] - truth.kd[b]).abs() < 1e-5, "{cf} kd[{b}]");
        }
    }
}

/// The instruments' scan (flat SRA readings): the truth is no longer a zero of the cost, but
/// the fit must cost no more than the truth does and land near it.
#[test]
fn fits_an_instrument_like_scan_at_least_as_well_as_the_truth() {
    for (i, cf) in [
        (0, CostFunction::Cf1),
        (2, CostFunction::Cf2),
        (5, CostFunction::M2),
    ] {
        let truth = case(i).truth;
        let m = synthetic::measured(&truth, FresnelCosine::Incidence);
        let out = fit(&m, &settings(cf, Method::Separable, 1)).unwrap();
        let at_truth = cost_of(cf, &m, &truth);
        let p = out.params;
        let mean_kd = truth.kd.iter().sum::<f64>() / BANDS as f64;
        let mean_kd_err = (0..BANDS)
            .map(|b| (p.kd[b] - truth.kd[b]).abs())
            .sum::<f64>()
            / BANDS as f64;
        eprintln!(
            "{cf}: fit {:e} truth {at_truth:e} ks {} {} alpha {} {} ior {} {} kd err {:.4}",
            out.cost,
            p.ks,
            truth.ks,
            p.alpha,
            truth.alpha,
            p.ior,
            truth.ior,
            mean_kd_err / mean_kd
        );
        // cf2's |r|^(2/3) turns parameter rounding of 1e-13 into cost changes near 1e-8
        // relative where the fit is exact (its slope is unbounded at r = 0): allow 1e-6.
        assert!(
            out.cost <= at_truth * (1.0 + 1e-6),
            "{cf}: fit {} vs truth {at_truth}",
            out.cost
        );
        assert!(
            rel(p.alpha, truth.alpha) < 0.1,
            "{cf} alpha {} vs {}",
            p.alpha,
            truth.alpha
        );
        assert!(
            rel(p.ks, truth.ks) < 0.5,
            "{cf} ks {} vs {}",
            p.ks,
            truth.ks
        );
        assert!(mean_kd_err < 0.1 * mean_kd, "{cf}");
    }
}

#[test]
fn separable_is_never_worse_than_paper() {
    for (i, cf) in [
        (0, CostFunction::Cf2),
        (3, CostFunction::Cf1),
        (4, CostFunction::M2),
    ] {
        let m = synthetic::with_noise(
            &synthetic::measured(&case(i).truth, Default::default()),
            0.01,
            1,
        );
        let ours = fit(&m, &settings(cf, Method::Separable, 3)).unwrap();
        let paper = fit(&m, &small_paper(cf, 3)).unwrap();
        assert!(
            ours.cost <= paper.cost,
            "{cf}: separable {} vs paper {}",
            ours.cost,
            paper.cost
        );
        assert_eq!(
            (ours.method, paper.method),
            (Method::Separable, Method::Paper)
        );
    }
}

#[test]
fn observer_sees_every_generation_and_outcome_records_them() {
    let m = synthetic::measured(&case(1).truth, Default::default());
    for s in [
        settings(CostFunction::Cf1, Method::Separable, 2),
        small_paper(CostFunction::Cf1, 2),
    ] {
        let mut seen: Vec<Progress> = Vec::new();
        let out = fit_with_observer(&m, &s, &mut |p| {
            seen.push(*p);
            ControlFlow::Continue(())
        })
        .unwrap();
        assert_eq!(seen.len() as u32, out.generations, "{}", s.method);
        assert_eq!(out.best_cost_per_generation.len() as u32, out.generations);
        for (i, p) in seen.iter().enumerate() {
            assert_eq!(p.generation, i as u32 + 1);
            assert!(p.generation <= p.generations_total);
            assert_eq!(p.best_cost, out.best_cost_per_generation[i]);
        }
        assert!(seen.windows(2).all(|w| w[1].best_cost <= w[0].best_cost));
        assert!(seen.windows(2).all(|w| w[1].evaluations > w[0].evaluations));
        assert!(out.evaluations >= seen.last().unwrap().evaluations);
        // The reported cost is the reference cost of the reported parameters.
        assert_eq!(out.cost, cost_of(CostFunction::Cf1, &m, &out.params));
        assert!(out.wall_ms > 0.0);
    }
    let paper = small_paper(CostFunction::Cf1, 2);
    let out = fit(&m, &paper).unwrap();
    assert_eq!(out.generations, 60);
    // 40 initial, then 38 children in each of 60 generations (2 elite copies are not costed).
    assert_eq!(out.evaluations, 40 + 60 * 38);
}

#[test]
fn paper_ga_stops_when_it_stalls() {
    let m = synthetic::measured(&case(1).truth, Default::default());
    let mut s = small_paper(CostFunction::Cf1, 4);
    // Any improvement under 100 % counts as a stall: the GA stops as soon as it has a
    // 5-generation window to judge, after generation 6.
    s.paper.stall_generations = 5;
    s.paper.stall_tolerance = 1.0;
    let out = fit(&m, &s).unwrap();
    assert_eq!(out.generations, 6);
    assert_eq!(out.evaluations, 40 + 6 * 38);
    // With a zero tolerance only a generation with no improvement at all ends it early.
    s.paper.stall_tolerance = 0.0;
    let out = fit(&m, &s).unwrap();
    let h = &out.best_cost_per_generation;
    assert_eq!(h.len(), out.generations as usize);
    // The rule, checked whichever way this run went: after `g` generations it has stalled iff
    // the best cost did not move over the last 5; it never went on past a stall, and it stopped
    // before the 60-generation limit exactly when the last window stalled.
    let stalled = |g: usize| g > 5 && h[g - 1] >= h[g - 6];
    for g in 1..h.len() {
        assert!(
            !stalled(g),
            "went on after stalling at generation {g}: {h:?}"
        );
    }
    assert_eq!(stalled(h.len()), out.generations < 60, "{h:?}");
}

#[test]
fn observer_can_cancel() {
    let m = synthetic::measured(&case(2).truth, Default::default());
    for s in [
        settings(CostFunction::Cf2, Method::Separable, 1),
        small_paper(CostFunction::Cf2, 1),
    ] {
        let mut calls = 0;
        let err = fit_with_observer(&m, &s, &mut |p| {
            calls += 1;
            if p.generation == 2 {
                ControlFlow::Break(())
            } else {
                ControlFlow::Continue(())
            }
        })
        .unwrap_err();
        assert_eq!(err, FitError::Cancelled);
        assert_eq!(calls, 2, "{}", s.method);
    }
}

#[test]
fn bad_settings_are_rejected_naming_the_setting() {
    let m = synthetic::measured(&case(0).truth, Default::default());
    let cases: Vec<(Settings, &str)> = vec![
        (
            Settings {
                paper: GaSettings {
                    population: 2,
                    ..Default::default()
                },
                ..Default::default()
            },
            "paper GA: population must be >= 4, got 2",
        ),
        (
            Settings {
                paper: GaSettings {
                    generations: 0,
                    ..Default::default()
                },
                ..Default::default()
            },
            "paper GA: generations must be >= 1, got 0",
        ),
        (
            Settings {
                paper: GaSettings {
                    elite: 100,
                    ..Default::default()
                },
                ..Default::default()
            },
            "paper GA: elite must be below the population (100), got 100",
        ),
        (
            Settings {
                paper: GaSettings {
                    mutation_probability: 1.5,
                    ..Default::default()
                },
                ..Default::default()
            },
            "paper GA: mutation_probability must be in [0, 1], got 1.5",
        ),
        (
            Settings {
                separable: SeparableSettings {
                    starts: 0,
                    ..Default::default()
                },
                ..Default::default()
            },
            "separable: starts must be >= 1, got 0",
        ),
        (
            Settings {
                separable: SeparableSettings {
                    x_tolerance: 0.0,
                    ..Default::default()
                },
                ..Default::default()
            },
            "separable: x_tolerance must be in (0, 1), got 0",
        ),
        (
            Settings {
                bounds: Bounds {
                    alpha: (0.0, 1.0),
                    ..Bounds::default()
                },
                ..Default::default()
            },
            "bounds: alpha lower bound 0 must be > 0",
        ),
        (
            Settings {
                bounds: Bounds {
                    kd: (-0.1, 1.0),
                    ..Bounds::default()
                },
                ..Default::default()
            },
            "bounds: kd lower bound -0.1 must be >= 0 (a BRDF is not negative)",
        ),
    ];
    for (s, msg) in cases {
        assert_eq!(s.validate().unwrap_err().to_string(), msg);
        let err = fit(&m, &s).unwrap_err();
        assert_eq!(err.to_string(), format!("invalid fit settings: {msg}"));
    }
    Settings::default().validate().unwrap();
}

#[test]
fn bad_measurements_are_rejected_naming_geometry_and_band() {
    let mut m = synthetic::measured(&case(0).truth, Default::default());
    let g = by_name("45as25").unwrap().index;
    m.values[g][3] = f64::NAN;
    let err = fit(&m, &Settings::default()).unwrap_err();
    assert_eq!(
        err,
        FitError::NonFiniteInput {
            geometry: "45as25",
            band: 3
        }
    );
    assert!(err.to_string().contains("45as25, band 3 (430 nm)"), "{err}");

    let mut m = synthetic::measured(&case(0).truth, Default::default());
    let g = by_name("15as15").unwrap().index; // θi = 0: w = 1
    m.values[g][0] = -1.0;
    let s = settings(CostFunction::M2, Method::Separable, 1);
    assert!(matches!(
        fit(&m, &s),
        Err(FitError::OutOfDomain {
            geometry: "15as15",
            band: 0,
            ..
        })
    ));
    // cf1 and cf2 have no such domain: a negative reading (noise) is fitted.
    assert!(fit(&m, &settings(CostFunction::Cf1, Method::Separable, 1)).is_ok());
}

#[test]
fn names_and_settings_serialise() {
    for m in Method::ALL {
        assert_eq!(m.to_string().parse::<Method>().unwrap(), m);
        assert_eq!(serde_json::to_string(&m).unwrap(), format!("\"{m}\""));
    }
    assert_eq!(Method::default(), Method::Separable);
    assert_eq!(
        "ga".parse::<Method>().unwrap_err().to_string(),
        "unknown fit method \"ga\": expected one of paper, separable"
    );
    let s = Settings {
        seed: 99,
        cost: CostFunction::M2,
        ..Settings::default()
    };
    let json = serde_json::to_string(&s).unwrap();
    assert_eq!(serde_json::from_str::<Settings>(&json).unwrap(), s);
    // A partial settings object takes the defaults for the rest; unknown keys are refused.
    let partial: Settings =
        serde_json::from_str(r#"{"method": "paper", "paper": {"generations": 5}}"#).unwrap();
    assert_eq!(partial.method, Method::Paper);
    assert_eq!(partial.paper.generations, 5);
    assert_eq!(partial.paper.population, 100);
    assert!(serde_json::from_str::<Settings>(r#"{"sead": 1}"#).is_err());
}

/// The always-run miniature of `tools/src/bin/reliability.rs`: over two noisy scans × 3 cost
/// functions × 3 seeds, every separable fit ends within 1 % of the best cost any run found.
#[test]
fn small_reliability_study() {
    for i in [2, 4] {
        let m = synthetic::with_noise(
            &synthetic::measured(&case(i).truth, Default::default()),
            0.01,
            i as u64,
        );
        for cf in CostFunction::ALL {
            let ours: Vec<f64> = (0..3)
                .map(|seed| {
                    fit(&m, &settings(cf, Method::Separable, seed))
                        .unwrap()
                        .cost
                })
                .collect();
            let paper = fit(&m, &small_paper(cf, 0)).unwrap().cost;
            let best = ours.iter().copied().fold(paper, f64::min);
            for (seed, c) in ours.iter().enumerate() {
                assert!(
                    *c <= best * 1.01,
                    "{} {cf} seed {seed}: {c} vs best {best}",
                    case(i).patch
                );
            }
        }
    }
}

/// Regression (reliability harness): on the processed noise-free T.Manzana green example scan,
/// cf2 fits used to end in another basin for some seeds (seed 4: 8.7 % above the best, at
/// ks 0.027, α 0.14 instead of the truth's 0.1, 0.45). Every seed must now end within 1 % of
/// the best of them, and no higher than the parameters the scan was made from cost (not zero:
/// the SRA reports one achromatic value per geometry, which the model cannot match exactly).
#[test]
fn cf2_fits_of_manzana_green_agree_across_seeds_and_reach_the_truth() {
    use crate::processing::{ProcessingOptions, process};
    use crate::scan::Scan;

    #[derive(serde::Deserialize)]
    struct Truth {
        params: Params,
    }
    let scan = Scan::from_json(include_bytes!("../../tests/data/t-manzana-green.scan.json"))
        .expect("the example scan is valid");
    let m = process(&scan, &ProcessingOptions::default()).expect("the example scan processes");
    let truth: Truth =
        serde_json::from_str(include_str!("../../tests/data/t-manzana-green.truth.json"))
            .expect("the truth file is valid");
    let at_truth = cost_of(CostFunction::Cf2, &m, &truth.params);

    let costs: Vec<f64> = (0..6)
        .map(|seed| {
            fit(&m, &settings(CostFunction::Cf2, Method::Separable, seed))
                .unwrap()
                .cost
        })
        .collect();
    let best = costs.iter().copied().fold(f64::INFINITY, f64::min);
    for (seed, c) in costs.iter().enumerate() {
        assert!(
            *c <= best * 1.01,
            "seed {seed}: {c} is {:.4} × the best {best}",
            c / best
        );
        // The fit lands on the truth's (ks, α, μ) to ~1e-7, and cf2's |r|^(2/3) turns that
        // into cost differences far below 1e-6 relative (as in the instrument-like test).
        assert!(
            *c <= at_truth * (1.0 + 1e-6),
            "seed {seed}: {c} vs the truth's {at_truth}"
        );
    }
}
