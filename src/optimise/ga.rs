//! The paper's method: a plain, bounded, real-coded, elitist genetic algorithm over all 34
//! parameters (31 kd, ks, α, μ), as the paper describes its optimiser (SCIENCE.md §6).
//!
//! - Initial population uniform within the bounds.
//! - Parents by tournament selection (with replacement).
//! - Simulated binary crossover, SBX: K. Deb & R. B. Agrawal, "Simulated binary crossover for
//!   continuous search space", Complex Systems 9(2), 1995 — each gene crossed with
//!   probability ½, children clamped to the bounds.
//! - Polynomial mutation: K. Deb & M. Goyal, "A combined genetic adaptive search (GeneAS) for
//!   engineering design", Computer Science and Informatics 26(4), 1996 — perturbation scaled
//!   by the gene's bound width, clamped.
//! - Elitism: the best `elite` individuals pass unchanged to the next generation.
//! - Stops after `generations`, or earlier when the best cost has improved by less than
//!   `stall_tolerance` (relative) over the last `stall_generations` generations.
//!
//! Every random choice comes from one `ChaCha8Rng::seed_from_u64(seed)`, in a fixed order, so
//! a run is bit-for-bit repeatable. The two population buffers are allocated once.

use std::ops::ControlFlow;

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use super::problem::Problem;
use super::{FitError, GaSettings, Progress, Run, Tracker};
use crate::model::Params;
use crate::spectral::BANDS;

/// Genes: kd for the 31 bands, then ks, α, μ.
const GENES: usize = BANDS + 3;
type Genome = [f64; GENES];

#[derive(Clone, Copy)]
struct Individual {
    genes: Genome,
    cost: f64,
}

fn to_params(g: &Genome) -> Params {
    Params {
        kd: std::array::from_fn(|b| g[b]),
        ks: g[BANDS],
        alpha: g[BANDS + 1],
        ior: g[BANDS + 2],
        extra: [0.0; crate::model::EXTRA],
    }
}

fn evaluate(problem: &Problem, g: &Genome) -> f64 {
    let kd = std::array::from_fn(|b| g[b]);
    problem.full_cost(&kd, g[BANDS], g[BANDS + 1], g[BANDS + 2])
}

/// Runs the GA. Cost evaluations: population × (generations run + 1) less the elite copies.
pub(super) fn run(
    problem: &Problem,
    s: &GaSettings,
    seed: u64,
    observer: &mut dyn FnMut(&Progress) -> ControlFlow<()>,
) -> Result<Run, FitError> {
    let b = problem.bounds;
    let lo: Genome = std::array::from_fn(|i| {
        if i < BANDS {
            b.kd.0
        } else {
            [b.ks.0, b.alpha.0, b.ior.0][i - BANDS]
        }
    });
    let hi: Genome = std::array::from_fn(|i| {
        if i < BANDS {
            b.kd.1
        } else {
            [b.ks.1, b.alpha.1, b.ior.1][i - BANDS]
        }
    });
    let n = s.population as usize;
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut tracker = Tracker::new(s.generations);

    let mut pop: Vec<Individual> = Vec::with_capacity(n);
    for _ in 0..n {
        let genes: Genome = std::array::from_fn(|i| lo[i] + (hi[i] - lo[i]) * rng.random::<f64>());
        pop.push(Individual {
            genes,
            cost: evaluate(problem, &genes),
        });
    }
    tracker.evaluations += n as u64;
    let mut next: Vec<Individual> = Vec::with_capacity(n);

    for _ in 0..s.generations {
        // Best first; the stable sort keeps ties in population order (deterministic).
        pop.sort_by(|a, b| a.cost.total_cmp(&b.cost));
        next.clear();
        next.extend_from_slice(&pop[..s.elite as usize]);
        while next.len() < n {
            let p1 = tournament(&pop, s.tournament, &mut rng);
            let p2 = tournament(&pop, s.tournament, &mut rng);
            let (mut c1, mut c2) = (pop[p1].genes, pop[p2].genes);
            if rng.random::<f64>() < s.crossover_probability {
                sbx(&mut c1, &mut c2, &lo, &hi, s.crossover_eta, &mut rng);
            }
            for child in [&mut c1, &mut c2] {
                mutate(
                    child,
                    &lo,
                    &hi,
                    s.mutation_probability,
                    s.mutation_eta,
                    &mut rng,
                );
            }
            for child in [c1, c2] {
                if next.len() < n {
                    next.push(Individual {
                        genes: child,
                        cost: evaluate(problem, &child),
                    });
                    tracker.evaluations += 1;
                }
            }
        }
        std::mem::swap(&mut pop, &mut next);
        let best = pop.iter().map(|i| i.cost).fold(f64::INFINITY, f64::min);
        tracker.generation_done(best, observer)?;
        let h = &tracker.history;
        let window = s.stall_generations as usize;
        if window > 0 && h.len() > window {
            let before = h[h.len() - 1 - window];
            if before - best <= s.stall_tolerance * before {
                break;
            }
        }
    }

    let best = pop
        .iter()
        .min_by(|a, b| a.cost.total_cmp(&b.cost))
        .expect("population >= 4");
    Ok(Run {
        params: to_params(&best.genes),
        tracker,
    })
}

/// Index of the best of `k` individuals drawn with replacement.
fn tournament(pop: &[Individual], k: u32, rng: &mut ChaCha8Rng) -> usize {
    let mut best = rng.random_range(0..pop.len());
    for _ in 1..k {
        let i = rng.random_range(0..pop.len());
        if pop[i].cost < pop[best].cost {
            best = i;
        }
    }
    best
}

/// SBX on each gene with probability ½: children spread around the parents with a spread
/// factor β whose density is polynomial with index η (η large → children near the parents).
fn sbx(a: &mut Genome, b: &mut Genome, lo: &Genome, hi: &Genome, eta: f64, rng: &mut ChaCha8Rng) {
    for i in 0..GENES {
        if rng.random::<f64>() >= 0.5 {
            continue;
        }
        let u: f64 = rng.random();
        let beta = if u <= 0.5 {
            (2.0 * u).powf(1.0 / (eta + 1.0))
        } else {
            (1.0 / (2.0 * (1.0 - u))).powf(1.0 / (eta + 1.0))
        };
        let (x1, x2) = (a[i], b[i]);
        a[i] = (0.5 * ((1.0 + beta) * x1 + (1.0 - beta) * x2)).clamp(lo[i], hi[i]);
        b[i] = (0.5 * ((1.0 - beta) * x1 + (1.0 + beta) * x2)).clamp(lo[i], hi[i]);
    }
}

/// Polynomial mutation of each gene with probability `p`: a perturbation δ ∈ (−1, 1) of the
/// bound width, concentrated near 0 with index η.
fn mutate(g: &mut Genome, lo: &Genome, hi: &Genome, p: f64, eta: f64, rng: &mut ChaCha8Rng) {
    for i in 0..GENES {
        if rng.random::<f64>() >= p {
            continue;
        }
        let u: f64 = rng.random();
        let delta = if u < 0.5 {
            (2.0 * u).powf(1.0 / (eta + 1.0)) - 1.0
        } else {
            1.0 - (2.0 * (1.0 - u)).powf(1.0 / (eta + 1.0))
        };
        g[i] = (g[i] + delta * (hi[i] - lo[i])).clamp(lo[i], hi[i]);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn unit() -> (Genome, Genome) {
        ([0.0; GENES], [1.0; GENES])
    }

    #[test]
    fn sbx_keeps_the_parents_mean_and_the_bounds() {
        let (lo, hi) = unit();
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        for _ in 0..200 {
            let mut a: Genome = std::array::from_fn(|i| (i as f64 * 0.37).fract());
            let mut b: Genome = std::array::from_fn(|i| (i as f64 * 0.61).fract());
            let mean: Genome = std::array::from_fn(|i| 0.5 * (a[i] + b[i]));
            sbx(&mut a, &mut b, &lo, &hi, 15.0, &mut rng);
            for i in 0..GENES {
                assert!((0.0..=1.0).contains(&a[i]) && (0.0..=1.0).contains(&b[i]));
                // SBX is symmetric about the parents' mean unless a child was clamped.
                if a[i] > 0.0 && a[i] < 1.0 && b[i] > 0.0 && b[i] < 1.0 {
                    assert!((0.5 * (a[i] + b[i]) - mean[i]).abs() < 1e-12);
                }
            }
        }
    }

    #[test]
    fn mutation_stays_in_bounds_and_touches_about_p_of_the_genes() {
        let (lo, hi) = unit();
        let mut rng = ChaCha8Rng::seed_from_u64(9);
        let mut changed = 0;
        let trials = 2000;
        for _ in 0..trials {
            let mut g = [0.5; GENES];
            mutate(&mut g, &lo, &hi, 0.1, 20.0, &mut rng);
            assert!(g.iter().all(|x| (0.0..=1.0).contains(x)));
            changed += g.iter().filter(|&&x| x != 0.5).count();
        }
        let rate = changed as f64 / (trials * GENES) as f64;
        assert!((rate - 0.1).abs() < 0.01, "rate {rate}");
    }

    #[test]
    fn tournament_prefers_the_better() {
        let pop: Vec<Individual> = (0..10)
            .map(|i| Individual {
                genes: [0.0; GENES],
                cost: i as f64,
            })
            .collect();
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        let picks: Vec<usize> = (0..1000).map(|_| tournament(&pop, 3, &mut rng)).collect();
        let mean = picks.iter().sum::<usize>() as f64 / picks.len() as f64;
        // The minimum of 3 uniform draws from 0..10 has mean 2.025; 4.5 for k = 1.
        assert!((mean - 2.025).abs() < 0.3, "mean {mean}");
    }
}
