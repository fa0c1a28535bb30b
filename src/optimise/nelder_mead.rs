//! The Nelder–Mead simplex method on the unit cube: the separable method's 3-D search, and the
//! oracle's polish in `brdfd validate` (up to [`MAX_DIMENSION`] coordinates).
//!
//! J. A. Nelder & R. Mead, "A simplex method for function minimization", The Computer Journal
//! 7(4), 1965, with the standard coefficients (reflection 1, expansion 2, contraction ½,
//! shrink ½) and the accept/contract rules as stated by Lagarias, Reeds, Wright & Wright,
//! "Convergence properties of the Nelder–Mead simplex method in low dimensions", SIAM J.
//! Optim. 9(1), 1998. Bounds are kept by clamping every trial point into [0, 1]^D; a simplex
//! that collapses onto a face is why the caller restarts the method (polishing).
//!
//! Derivative-free on purpose: the cf2 profile cost has kinks wherever a band's best kd
//! switches from one geometry to another, so gradients are not to be trusted.

// Numeric loops index parallel per-geometry and per-band arrays; `for g in 0..G` reads
// closest to the equations.
#![allow(clippy::needless_range_loop)]

/// When to stop one run.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Options {
    /// Edge length of the starting simplex, in unit-cube coordinates.
    pub initial_step: f64,
    /// Most objective evaluations in this run (the starting point's included if not given).
    pub max_evaluations: u32,
    /// Stop when every vertex lies within this distance (∞-norm) of the best one...
    pub x_tolerance: f64,
    /// ...and the costs across the simplex differ by at most this fraction of the best cost.
    pub f_tolerance: f64,
}

/// The best vertex at the end of a run.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Outcome<const D: usize> {
    pub x: [f64; D],
    pub f: f64,
}

/// The most coordinates [`minimise`] takes.
pub(crate) const MAX_DIMENSION: usize = 8;

/// Vertices of the largest simplex.
const VERTICES: usize = MAX_DIMENSION + 1;

fn clamp_unit<const D: usize>(x: [f64; D]) -> [f64; D] {
    x.map(|v| v.clamp(0.0, 1.0))
}

/// `a + t (b − a)`, clamped to the unit cube.
fn along<const D: usize>(a: &[f64; D], b: &[f64; D], t: f64) -> [f64; D] {
    clamp_unit(std::array::from_fn(|i| a[i] + t * (b[i] - a[i])))
}

/// Minimises `f` over [0, 1]^D from `start` (whose cost `f_start` is already known).
pub(crate) fn minimise<const D: usize>(
    f: &mut impl FnMut(&[f64; D]) -> f64,
    start: [f64; D],
    f_start: f64,
    opts: &Options,
) -> Outcome<D> {
    // D + 1 vertices in fixed arrays on the stack: no allocation.
    const {
        assert!(
            D >= 1 && D <= MAX_DIMENSION,
            "nelder_mead: dimension must be 1..=MAX_DIMENSION"
        )
    };
    let mut x = simplex::<D>(start, opts.initial_step);
    let mut fx = [0.0f64; VERTICES];
    fx[0] = f_start;
    let mut evals = 0u32;
    for i in 1..=D {
        fx[i] = f(&x[i]);
        evals += 1;
    }
    let n = D + 1;
    let mut order = [0usize; VERTICES];
    loop {
        // Sort vertex indices by cost; ties keep the lower index (deterministic).
        for (i, o) in order.iter_mut().enumerate().take(n) {
            *o = i;
        }
        order[..n].sort_by(|&a, &b| fx[a].total_cmp(&fx[b]).then(a.cmp(&b)));
        let (best, second_worst, worst) = (order[0], order[n - 2], order[n - 1]);

        let spread_x = (0..n)
            .flat_map(|v| (0..D).map(move |i| (v, i)))
            .map(|(v, i)| (x[v][i] - x[best][i]).abs())
            .fold(0.0, f64::max);
        let spread_f = fx[worst] - fx[best];
        let converged =
            spread_x <= opts.x_tolerance && spread_f <= opts.f_tolerance * fx[best].abs();
        if converged || evals >= opts.max_evaluations {
            return Outcome {
                x: x[best],
                f: fx[best],
            };
        }

        // Centroid of every vertex but the worst.
        let mut c = [0.0; D];
        for &v in order[..n - 1].iter() {
            for i in 0..D {
                c[i] += x[v][i] / D as f64;
            }
        }
        let xr = along(&c, &x[worst], -1.0);
        let fr = f(&xr);
        evals += 1;
        if fr < fx[best] {
            let xe = along(&c, &x[worst], -2.0);
            let fe = f(&xe);
            evals += 1;
            if fe < fr {
                (x[worst], fx[worst]) = (xe, fe);
            } else {
                (x[worst], fx[worst]) = (xr, fr);
            }
            continue;
        }
        if fr < fx[second_worst] {
            (x[worst], fx[worst]) = (xr, fr);
            continue;
        }
        if fr < fx[worst] {
            // Outside contraction, toward the reflected point.
            let xc = along(&c, &xr, 0.5);
            let fc = f(&xc);
            evals += 1;
            if fc <= fr {
                (x[worst], fx[worst]) = (xc, fc);
                continue;
            }
        } else {
            // Inside contraction, toward the worst vertex.
            let xc = along(&c, &x[worst], 0.5);
            let fc = f(&xc);
            evals += 1;
            if fc < fx[worst] {
                (x[worst], fx[worst]) = (xc, fc);
                continue;
            }
        }
        // Shrink every vertex toward the best.
        for &v in order[1..n].iter() {
            x[v] = along(&x[best], &x[v], 0.5);
            fx[v] = f(&x[v]);
            evals += 1;
        }
    }
}

/// The starting simplex: `start` and one vertex a step away along each axis, stepping
/// inward when the outward step would leave the cube.
fn simplex<const D: usize>(start: [f64; D], step: f64) -> [[f64; D]; VERTICES] {
    let mut x = [start; VERTICES];
    for i in 0..D {
        let up = start[i] + step;
        x[i + 1][i] = if up <= 1.0 { up } else { start[i] - step };
    }
    x
}

#[cfg(test)]
mod tests {
    use super::*;

    fn opts() -> Options {
        Options {
            initial_step: 0.1,
            max_evaluations: 2000,
            x_tolerance: 1e-10,
            f_tolerance: 1e-12,
        }
    }

    #[test]
    fn finds_the_minimum_of_a_rotated_quadratic() {
        let target = [0.3, 0.7, 0.45];
        let mut count = 0;
        let mut f = |x: &[f64; 3]| {
            count += 1;
            let d = [x[0] - target[0], x[1] - target[1], x[2] - target[2]];
            // A correlated valley, as (ks, μ) give through f0.
            (d[0] + d[1]).powi(2) + 10.0 * (d[0] - d[1]).powi(2) + 3.0 * d[2] * d[2] + 1.0
        };
        let start = [0.9, 0.1, 0.9];
        let f0 = f(&start);
        let out = minimise(&mut f, start, f0, &opts());
        for i in 0..3 {
            assert!((out.x[i] - target[i]).abs() < 1e-6, "{:?}", out.x);
        }
        assert!((out.f - 1.0).abs() < 1e-11);
        assert!(count < 2000, "{count} evaluations");
    }

    #[test]
    fn stays_in_the_cube_and_finds_a_minimum_on_its_face() {
        // Unconstrained minimum at x0 = −0.5: the constrained one is on the face x0 = 0.
        let mut f = |x: &[f64; 2]| {
            assert!(x.iter().all(|v| (0.0..=1.0).contains(v)));
            (x[0] + 0.5).powi(2) + (x[1] - 0.25).powi(2)
        };
        let out = minimise(&mut f, [0.8, 0.8], 1.3 * 1.3 + 0.55 * 0.55, &opts());
        assert!(
            out.x[0].abs() < 1e-8 && (out.x[1] - 0.25).abs() < 1e-6,
            "{:?}",
            out.x
        );
    }

    #[test]
    fn finds_the_minimum_in_seven_dimensions() {
        // The oracle's polish: 7 coordinates (kd's XYZ, ks, α, μ, σ).
        let target: [f64; 7] = std::array::from_fn(|i| 0.2 + 0.09 * i as f64);
        let mut f = |x: &[f64; 7]| {
            (0..7)
                .map(|i| (1.0 + i as f64) * (x[i] - target[i]).powi(2))
                .sum::<f64>()
                + (x[0] - target[0]) * (x[1] - target[1])
        };
        let start = [0.5; 7];
        let f0 = f(&start);
        let o = Options {
            max_evaluations: 20_000,
            ..opts()
        };
        let mut best = minimise(&mut f, start, f0, &o);
        // Restarts from the best, as the polish does: a simplex may stall in 7-D.
        for _ in 0..3 {
            best = minimise(&mut f, best.x, best.f, &o);
        }
        for i in 0..7 {
            assert!((best.x[i] - target[i]).abs() < 1e-4, "{:?}", best.x);
        }
    }

    #[test]
    fn honours_the_evaluation_cap() {
        let mut count = 0u32;
        let mut f = |x: &[f64; 3]| {
            count += 1;
            x.iter().map(|v| (v - 0.5).powi(2)).sum::<f64>()
        };
        let o = Options {
            max_evaluations: 20,
            ..opts()
        };
        minimise(&mut f, [0.0; 3], 0.75, &o);
        // The cap is checked once per iteration, and one iteration costs at most D + 1.
        assert!((20..=24).contains(&count), "{count}");
    }
}
