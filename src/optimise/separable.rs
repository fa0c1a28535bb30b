//! The default method: kd solved exactly per band, a global-then-local search over
//! (ks, α, μ) (SCIENCE.md §6: "structure helps ... and so do restarts and local polishing").
//!
//! 1. Survey: a seeded Latin-hypercube design of `samples` points over the unit cube
//!    (M. D. McKay, R. J. Beckman & W. J. Conover, Technometrics 21(2), 1979), each costed by
//!    its profile — the cost with the best kd for that (ks, α, μ).
//! 2. Search: Nelder–Mead (1965) from the best design points that lie at least
//!    `start_separation` apart, so that different basins are each followed to their bottom.
//! 3. Polish: Nelder–Mead restarted at the best point with fresh, shrinking simplices until a
//!    restart no longer improves the cost; a restart undoes a simplex that collapsed early,
//!    the known failure of Nelder–Mead.
//!
//! The kd solve being exact, a local minimum could only hide in the 3-D (ks, α, μ) space,
//! which the survey covers and the separated starts explore.

use std::cell::Cell;
use std::ops::ControlFlow;

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use super::nelder_mead::{self, Options};
use super::problem::Problem;
use super::{FitError, Progress, Run, SeparableSettings, Tracker};
use crate::model::{Bounds, Params};
use crate::spectral::BANDS;

/// Unit-cube coordinates → (ks, α, μ); see [`SeparableSettings`] for why these maps.
#[derive(Debug, Clone, Copy)]
struct Map {
    bounds: Bounds,
}

impl Map {
    fn params(&self, t: &[f64; 3]) -> (f64, f64, f64) {
        let b = &self.bounds;
        let ks = b.ks.0 + (b.ks.1 - b.ks.0) * t[0] * t[0];
        // α's lower bound is > 0 (Bounds::validate), so the log map is defined.
        let alpha = (b.alpha.0 * (b.alpha.1 / b.alpha.0).powf(t[1])).clamp(b.alpha.0, b.alpha.1);
        let ior = b.ior.0 + (b.ior.1 - b.ior.0) * t[2];
        (ks, alpha, ior)
    }
}

fn distance_inf(a: &[f64; 3], b: &[f64; 3]) -> f64 {
    (0..3).map(|i| (a[i] - b[i]).abs()).fold(0.0, f64::max)
}

/// A Latin-hypercube design: each axis cut into `n` strata, one point per stratum per axis,
/// strata paired across axes by seeded shuffles, jittered within their stratum.
fn latin_hypercube(n: usize, rng: &mut ChaCha8Rng) -> Vec<[f64; 3]> {
    let mut points = vec![[0.0; 3]; n];
    let mut perm: Vec<usize> = (0..n).collect();
    for d in 0..3 {
        // Fisher–Yates, written out so the draw order is fixed by this code alone.
        for i in (1..n).rev() {
            let j = rng.random_range(0..=i);
            perm.swap(i, j);
        }
        for (p, &stratum) in points.iter_mut().zip(perm.iter()) {
            p[d] = (stratum as f64 + rng.random::<f64>()) / n as f64;
        }
    }
    points
}

/// Picks up to `k` design points, best first, each at least `sep` from those already picked;
/// if too few are that far apart, the best of the rest fill up.
fn pick_starts(points: &[[f64; 3]], costs: &[f64], k: usize, sep: f64) -> Vec<usize> {
    let mut order: Vec<usize> = (0..points.len()).collect();
    order.sort_by(|&a, &b| costs[a].total_cmp(&costs[b]));
    let mut chosen: Vec<usize> = Vec::with_capacity(k);
    for &i in &order {
        if chosen.len() == k {
            break;
        }
        if chosen
            .iter()
            .all(|&c| distance_inf(&points[i], &points[c]) >= sep)
        {
            chosen.push(i);
        }
    }
    for &i in &order {
        if chosen.len() == k {
            break;
        }
        if !chosen.contains(&i) {
            chosen.push(i);
        }
    }
    chosen
}

pub(super) fn run(
    problem: &Problem,
    s: &SeparableSettings,
    seed: u64,
    observer: &mut dyn FnMut(&Progress) -> ControlFlow<()>,
) -> Result<Run, FitError> {
    let map = Map {
        bounds: problem.bounds,
    };
    let mut tracker = Tracker::new(1 + s.starts + s.polish_restarts);
    let count = Cell::new(0u64);
    let mut kd = [0.0; BANDS];
    let mut cost_at = |t: &[f64; 3]| {
        count.set(count.get() + 1);
        let (ks, alpha, ior) = map.params(t);
        problem.profile(ks, alpha, ior, &mut kd)
    };

    // 1. Survey.
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let points = latin_hypercube(s.samples as usize, &mut rng);
    let costs: Vec<f64> = points.iter().map(&mut cost_at).collect();
    let first = (0..points.len())
        .min_by(|&a, &b| costs[a].total_cmp(&costs[b]))
        .expect("samples >= 1");
    let (mut best_t, mut best_f) = (points[first], costs[first]);
    tracker.evaluations = count.get();
    tracker.generation_done(best_f, observer)?;

    // 2. Searches from separated starts, to the loose search tolerance.
    let search = Options {
        initial_step: 0.1,
        max_evaluations: s.max_evaluations_per_search,
        x_tolerance: s.search_tolerance,
        f_tolerance: s.search_tolerance,
    };
    for start in pick_starts(&points, &costs, s.starts as usize, s.start_separation) {
        let out = nelder_mead::minimise(&mut cost_at, points[start], costs[start], &search);
        if out.f < best_f {
            (best_t, best_f) = (out.x, out.f);
        }
        tracker.evaluations = count.get();
        tracker.generation_done(best_f, observer)?;
    }

    // 3. Polish the best to the tight tolerances.
    let mut polish = Options {
        initial_step: 0.05,
        max_evaluations: s.max_evaluations_per_polish,
        x_tolerance: s.x_tolerance,
        f_tolerance: s.f_tolerance,
    };
    for _ in 0..s.polish_restarts {
        let out = nelder_mead::minimise(&mut cost_at, best_t, best_f, &polish);
        let improved = best_f - out.f > s.f_tolerance * best_f;
        if out.f < best_f {
            (best_t, best_f) = (out.x, out.f);
        }
        tracker.evaluations = count.get();
        tracker.generation_done(best_f, observer)?;
        if !improved {
            break;
        }
        polish.initial_step *= 0.25;
    }

    // The kd of the best point: one more profile, which writes it.
    cost_at(&best_t);
    tracker.evaluations = count.get();
    let (ks, alpha, ior) = map.params(&best_t);
    Ok(Run {
        params: Params { kd, ks, alpha, ior },
        tracker,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn latin_hypercube_has_one_point_per_stratum_on_every_axis() {
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let n = 37;
        let pts = latin_hypercube(n, &mut rng);
        for d in 0..3 {
            let mut strata: Vec<usize> = pts.iter().map(|p| (p[d] * n as f64) as usize).collect();
            strata.sort();
            assert_eq!(strata, (0..n).collect::<Vec<_>>());
        }
    }

    #[test]
    fn starts_are_separated_when_possible() {
        let pts = [
            [0.1, 0.1, 0.1],
            [0.12, 0.1, 0.1],
            [0.9, 0.9, 0.9],
            [0.5, 0.5, 0.5],
        ];
        let costs = [1.0, 2.0, 3.0, 4.0];
        assert_eq!(pick_starts(&pts, &costs, 3, 0.15), vec![0, 2, 3]);
        // Asking for all four: the close one fills up last.
        assert_eq!(pick_starts(&pts, &costs, 4, 0.15), vec![0, 2, 3, 1]);
    }

    #[test]
    fn map_reaches_the_bounds_at_the_cube_corners() {
        let map = Map {
            bounds: Bounds::default(),
        };
        assert_eq!(map.params(&[0.0; 3]), (0.0, 0.01, 1.0));
        let (ks, alpha, ior) = map.params(&[1.0; 3]);
        assert_eq!((ks, ior), (10.0, 3.0));
        assert!((alpha - 1.0).abs() < 1e-15);
        // Log-uniform α: the middle of the cube is the geometric mean of the bounds.
        assert!((map.params(&[0.5; 3]).1 - 0.1).abs() < 1e-15);
    }
}
