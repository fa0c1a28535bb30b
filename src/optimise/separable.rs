//! The default method: kd solved exactly per band, a global-then-local search over
//! (ks, α, μ) (SCIENCE.md §6: "structure helps ... and so do restarts and local polishing").
//!
//! 0. Continuation (cf2 and m2 only): the same search, steps 1–3, is first run on smoother
//!    criteria, and their optima become extra starting points ("warm starts") of the search
//!    on the fit's own cost; see below.
//! 1. Survey: a seeded Latin-hypercube design of `samples` points over the unit cube
//!    (M. D. McKay, R. J. Beckman & W. J. Conover, Technometrics 21(2), 1979), each costed by
//!    its profile — the cost with the best kd for that (ks, α, μ). One design serves every
//!    stage.
//! 2. Search: Nelder–Mead (1965) from the warm starts and from the best design points that lie
//!    at least `start_separation` apart (from each other and from the warm starts), so that
//!    different basins are each followed to their bottom.
//! 3. Polish: Nelder–Mead restarted at the best point with fresh, shrinking simplices until a
//!    restart gains no more than the search tolerance; a restart undoes a simplex that
//!    collapsed early, the known failure of Nelder–Mead, and only a stalled simplex leaves
//!    that much to gain (smaller gains are the polish converging: on the example scans, restarts on gains above
//!    `f_tolerance` gained at most ~1e-7 of the cost).
//! 4. Lobe-width moves (the fit's own cost only): α × 1.25 and × 0.8 with the lobe's peak
//!    ks·F0/α² kept, by F0 or by ks; the best move is searched when it comes within
//!    `JUMP_MARGIN` of the best, and polished if the search beats it. On real paint the best
//!    fit often lies in a narrow valley along that peak on a bound face, whose floor holds
//!    several minima that no local search crosses (SCIENCE.md §12.5).
//!
//! cf1's stages survey the design together with its projections onto the three upper-bound
//! faces and search from three times the starts (cf1 profiles are cheap, and real paint's cf1
//! optima often lie on a face); each surrogate stage passes on `TRACKS` warm starts, its
//! optimum and another distinct search end near it, so that a second basin is followed too.
//!
//! # Why the continuation
//!
//! The kd solve being exact, a local minimum can only hide in the 3-D (ks, α, μ) space — and
//! for cf2 it does, often. Each band's best kd sits on a kink of `|r|^(2/3)` (one residual
//! exactly zero, `problem`), so moving (ks, α, μ) switches kinks and the profile is a patchwork
//! of concave pieces with many local minima. On a noise-free scan the best fit is a narrow
//! cusp (residuals near zero, where `|r|^(2/3)` has unbounded slope) that 64 design points
//! rarely land near; on "T.Freesia pink" with 1 % noise there are two long, curved valleys
//! 1.7 % apart, and a Nelder–Mead search and polish from a uniformly random start reaches the
//! better one in only about a quarter of the starts. The reliability harness
//! (`tools/src/bin/reliability.rs`) found fits ending up to 8.7 % above the best. cf1's optimum as
//! one extra start cured the noise-free scans but not T.Freesia pink 1 % (13 of 50 seeds
//! missed), and neither 8 design starts on top (still 7 misses in 1 400 cf2 fits, at 17 ms a
//! fit) nor big-simplex restarts from the best point (no change) closed the gap.
//!
//! Continuation, or graduated non-convexity (A. Blake & A. Zisserman, *Visual Reconstruction*,
//! MIT Press 1987), does: minimise a sequence of criteria, from a smooth one to the target,
//! each started from the last one's optimum. The sequence is the family `Σ |M·w − A·w|^p` that
//! cf1 (p = 2) and cf2 (p = 2/3) belong to, with the weighted L1 error (p = 1) between them:
//! - cf1 is a quadratic in kd, solved in closed form (0.6 µs a profile against cf2's 11 µs
//!   when this was designed; cf2's solve now runs in SIMD lanes, and cf1 is still the cheaper);
//!   its landscape is smooth and its optimum is the exact fit of a noise-free scan, i.e. the
//!   bottom of cf2's cusp.
//! - L1 is still convex in kd (its minimiser is the weighted median, found among the kinks as
//!   cf2's is, in the same SIMD loop without the cube roots) but, like
//!   cf2, it lets a few large residuals stand rather than spreading them: on T.Freesia pink
//!   1 %, L1 started from cf1's optimum (which lies in cf2's worse valley) ends in cf2's better
//!   one, 0.09 % above cf2's best before any cf2 search.
//! - Under the luminance SRA model the L1 stage runs on the paper's flat SRA terms instead
//!   (each band's SRA readings taken as that band's): there its band-by-band solve is exact,
//!   while with the luminance terms it would only be an upper bound (`problem`). It is a
//!   stepping stone either way; on the example scans, whose SRA reads the band mean, cf2
//!   fits more than 1 % above the best under `--sra luminance` fell from 39 to 25 of 320
//!   (the harness's luminance scans: 0 of 320 either way).
//! - m2 is smooth and was reliable without a warm start; it takes cf1's optimum as one more
//!   start all the same, which costs next to nothing (its fit time stayed at 8 ms).
//!
//! The warm starts come on top of the design starts, so a misleading surrogate costs one
//! search and nothing else; with [`SeparableSettings::continuation`] off the method is the
//! plain multi-start search (bit for bit what it was before the continuation). Measured with
//! the harness over its 28 scans × 50 seeds, cf2 fits more than 1 % above the best fell from
//! 38 of 1 400 to 0 (the worst now 0.024 % above); over 40 fresh noise draws (1–5 %) of the
//! eight example samples × cf2 and m2 × 10 seeds, misses fell from 14 of 800 to 0.

use std::cell::Cell;
use std::ops::ControlFlow;

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use super::nelder_mead::{self, Options};
use super::problem::{Criterion, Problem};
use super::{FitError, Progress, Run, SeparableSettings, Tracker};
use crate::cost::CostFunction;
use crate::model::{Bounds, Params};
use crate::spectral::{BANDS, Spectrum};

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

impl Map {
    /// The inverse of [`Map::params`]: (ks, α, μ) → unit cube, clamped into it.
    fn unit(&self, ks: f64, alpha: f64, ior: f64) -> [f64; 3] {
        let b = &self.bounds;
        let t0 = ((ks - b.ks.0) / (b.ks.1 - b.ks.0)).max(0.0).sqrt();
        let t1 = (alpha / b.alpha.0).ln() / (b.alpha.1 / b.alpha.0).ln();
        let t2 = (ior - b.ior.0) / (b.ior.1 - b.ior.0);
        [t0, t1, t2].map(|t| {
            if t.is_finite() {
                t.clamp(0.0, 1.0)
            } else {
                0.0
            }
        })
    }
}

/// What a search ends with: the lobe at the unit point `t`, the `kd` profiled there, and
/// the search's trace.
fn answer(map: &Map, t: &[f64; 3], kd: [f64; BANDS], tracker: Tracker) -> Run {
    let (ks, alpha, ior) = map.params(t);
    Run {
        params: Params {
            kd,
            ks,
            alpha,
            ior,
            extra: [0.0; crate::model::EXTRA],
        },
        tracker,
    }
}

/// A local refit warm-started at `start` (the bootstrap's refits, `crate::uncertainty`): one
/// Nelder–Mead search from `start`, then the usual polishing — no survey, no continuation.
/// A resample moves the optimum by about the noise, so the search only has to follow it
/// within its basin; the point fit's global search has already chosen the basin.
pub(super) fn run_local(problem: &Problem, s: &SeparableSettings, start: &Params) -> Run {
    let map = Map {
        bounds: problem.bounds,
    };
    let mut tracker = Tracker::new(1 + s.polish_restarts);
    let count = Cell::new(0u64);
    let mut kd = [0.0; BANDS];
    let objective = Criterion::from(problem.cf);
    let mut cost_at = |t: &[f64; 3]| {
        count.set(count.get() + 1);
        let (ks, alpha, ior) = map.params(t);
        problem.profile(objective, ks, alpha, ior, &mut kd)
    };
    let t0 = map.unit(start.ks, start.alpha, start.ior);
    let f0 = cost_at(&t0);
    let (best_t, _) = descend(
        &mut cost_at,
        &[t0],
        &[f0],
        &[],
        &SeparableSettings { starts: 1, ..*s },
        &mut |f| {
            tracker.history.push(f);
            Ok(())
        },
        &mut Vec::new(),
        None,
    )
    .unwrap_or((t0, f0));
    cost_at(&best_t);
    tracker.evaluations = count.get();
    answer(&map, &best_t, kd, tracker)
}

/// Moves along the lobe's peak/width trade-off from `t`: α scaled by 1.25 and by 0.8, the
/// peak ks·F0/α² kept by scaling F0 = ((μ − 1)/(μ + 1))² (first two) or ks (last two) by the
/// square of the same factor, within the bounds.
fn lobe_width_moves(map: &Map, t: &[f64; 3]) -> [[f64; 3]; 4] {
    let b = &map.bounds;
    let (ks, alpha, ior) = map.params(t);
    let r = (ior - 1.0) / (ior + 1.0);
    let mv = |c: f64, by_ior: bool| {
        let a = (alpha * c).clamp(b.alpha.0, b.alpha.1);
        let c = a / alpha;
        if by_ior {
            let r2 = r * c;
            let mu = ((1.0 + r2) / (1.0 - r2)).clamp(b.ior.0, b.ior.1);
            let r3 = (mu - 1.0) / (mu + 1.0);
            // what F0 could not take, ks does
            let rest = if r3 > 0.0 { (r2 / r3).powi(2) } else { 1.0 };
            map.unit((ks * rest).clamp(b.ks.0, b.ks.1), a, mu)
        } else {
            map.unit((ks * c * c).clamp(b.ks.0, b.ks.1), a, ior)
        }
    };
    [
        mv(1.25, true),
        mv(0.8, true),
        mv(1.25, false),
        mv(0.8, false),
    ]
}

/// Surrogate stages pass on their best optimum and up to `TRACKS − 1` more distinct search
/// ends within `TRACK_MARGIN` of it (other basins the later stages search too).
const TRACKS: usize = 2;
const TRACK_MARGIN: f64 = 0.05;
/// Lobe-width moves (`lobe_width_moves`) after the polish: a move is searched when its cost is
/// within `JUMP_MARGIN` of the best, at most `JUMP_ROUNDS` times; its polish restarts while
/// they gain more than `JUMP_POLISH_GAIN` of the cost.
const JUMP_MARGIN: f64 = 0.01;
const JUMP_ROUNDS: u32 = 2;
const JUMP_POLISH_GAIN: f64 = 1e-6;

/// A stage's tracks: its optimum `best` (cost `best_f`), then, best first, the search `ends`
/// within `TRACK_MARGIN` of it that lie at least `sep` from the tracks already taken, up to
/// `TRACKS` in all.
fn tracks(best: [f64; 3], best_f: f64, mut ends: Vec<([f64; 3], f64)>, sep: f64) -> Vec<[f64; 3]> {
    ends.sort_by(|a, b| a.1.total_cmp(&b.1));
    let mut kept = vec![best];
    for (u, fu) in ends {
        if kept.len() == TRACKS {
            break;
        }
        if fu <= best_f * (1.0 + TRACK_MARGIN) && kept.iter().all(|k| distance_inf(k, &u) >= sep) {
            kept.push(u);
        }
    }
    kept
}

/// cf1's survey: the design and its projections onto the three upper-bound faces (real
/// paint's cf1 optima often lie on a face: α = 1, ks = 10, μ = 3).
fn with_faces(points: &[[f64; 3]]) -> Vec<[f64; 3]> {
    let mut v = points.to_vec();
    {
        for d in 0..3 {
            v.extend(points.iter().map(|p| {
                let mut q = *p;
                q[d] = 1.0;
                q
            }));
        }
    }
    v
}

/// cf1 profiles are cheap: its stages search from three times the design starts.
fn cf1_settings(c: Criterion, s: &SeparableSettings) -> SeparableSettings {
    let n: u32 = 3 * s.starts;
    if c == Criterion::Cf1 {
        SeparableSettings { starts: n, ..*s }
    } else {
        *s
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

/// Picks up to `k` design points, best first, each at least `sep` from those already picked
/// and from the `taken` starting points (the warm starts); if too few are that far apart, the
/// best of the rest fill up.
fn pick_starts(
    points: &[[f64; 3]],
    costs: &[f64],
    taken: &[[f64; 3]],
    k: usize,
    sep: f64,
) -> Vec<usize> {
    let mut order: Vec<usize> = (0..points.len()).collect();
    order.sort_by(|&a, &b| costs[a].total_cmp(&costs[b]));
    let mut chosen: Vec<usize> = Vec::with_capacity(k);
    for &i in &order {
        if chosen.len() == k {
            break;
        }
        let far = |q: &[f64; 3]| distance_inf(&points[i], q) >= sep;
        if chosen.iter().all(|&c| far(&points[c])) && taken.iter().all(far) {
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

/// The surrogate criteria whose optima warm-start a fit with `cf`, in the order they run:
/// each stage starts from the optima of those before it (see the module doc).
fn surrogate_chain(cf: CostFunction) -> &'static [Criterion] {
    match cf {
        CostFunction::Cf1 => &[],
        CostFunction::Cf2 => &[Criterion::Cf1, Criterion::L1],
        CostFunction::M2 => &[Criterion::Cf1],
    }
}

/// The separable method on `problem`. `flat` is the same scan under the flat SRA terms, with
/// the same weights (`problem` itself when that is its model): the weighted L1 stage of cf2's
/// continuation runs on it (see the module doc).
pub(super) fn run(
    problem: &Problem,
    flat: &Problem,
    s: &SeparableSettings,
    seed: u64,
    observer: &mut dyn FnMut(&Progress) -> ControlFlow<()>,
) -> Result<Run, FitError> {
    let map = Map {
        bounds: problem.bounds,
    };
    let chain = if s.continuation {
        surrogate_chain(problem.cf)
    } else {
        &[]
    };
    let stages = chain.len() as u32;
    // A generation per surrogate stage, then the survey, one per search (the warm starts
    // and the design's), one per polishing restart.
    let own_starts = cf1_settings(Criterion::from(problem.cf), s).starts;
    let mut tracker = Tracker::new(
        stages + 1 + stages * TRACKS as u32 + own_starts + s.polish_restarts + JUMP_ROUNDS,
    );
    let count = Cell::new(0u64);
    let mut kd = [0.0; BANDS];
    let profile = |criterion: Criterion, t: &[f64; 3], kd: &mut Spectrum| {
        count.set(count.get() + 1);
        let (ks, alpha, ior) = map.params(t);
        // The L1 stepping stone on the flat SRA terms, where its band-by-band solve is exact.
        let p = if criterion == Criterion::L1 {
            flat
        } else {
            problem
        };
        p.profile(criterion, ks, alpha, ior, kd)
    };
    let objective = Criterion::from(problem.cf);

    // One design for every stage: the surrogates survey the same points.
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let points = latin_hypercube(s.samples as usize, &mut rng);

    // 0. The surrogate chain, each stage a full search of its own, warm-started from the
    //    stages before. `warm` holds their optima (unit cube) with the fit's own cost there.
    let mut warm: Vec<([f64; 3], f64)> = Vec::with_capacity(chain.len());
    let mut best_f = f64::INFINITY;
    let faced = with_faces(&points);
    for &criterion in chain {
        let mut cost_at = |t: &[f64; 3]| profile(criterion, t, &mut kd);
        let points: &[[f64; 3]] = if criterion == Criterion::Cf1 {
            &faced
        } else {
            &points
        };
        let costs: Vec<f64> = points.iter().map(&mut cost_at).collect();
        let starts: Vec<([f64; 3], f64)> = warm.iter().map(|(t, _)| (*t, cost_at(t))).collect();
        let mut ends = Vec::new();
        let s1 = cf1_settings(criterion, s);
        let (t, fs) = descend(
            &mut cost_at,
            points,
            &costs,
            &starts,
            &s1,
            &mut |_| Ok(()),
            &mut ends,
            None,
        )?;
        // The stage's tracks go on as warm starts, costed in the fit's own cost (which is
        // also what progress reports).
        for u in tracks(t, fs, ends, s.start_separation) {
            let f = profile(objective, &u, &mut kd);
            warm.push((u, f));
            best_f = best_f.min(f);
        }
        tracker.evaluations = count.get();
        tracker.generation_done(best_f, observer)?;
    }

    // 1–3. The fit's own cost: survey, searches from the warm starts and the design, polish.
    let mut cost_at = |t: &[f64; 3]| profile(objective, t, &mut kd);
    let points: &[[f64; 3]] = if objective == Criterion::Cf1 {
        &faced
    } else {
        &points
    };
    let costs: Vec<f64> = points.iter().map(&mut cost_at).collect();
    best_f = costs.iter().copied().fold(best_f, f64::min);
    tracker.evaluations = count.get();
    tracker.generation_done(best_f, observer)?;
    let jumps = |t: &[f64; 3]| lobe_width_moves(&map, t);
    let s1 = cf1_settings(objective, s);
    let (best_t, _) = descend(
        &mut cost_at,
        points,
        &costs,
        &warm,
        &s1,
        &mut |f| {
            tracker.evaluations = count.get();
            tracker.generation_done(f, observer)
        },
        &mut Vec::new(),
        Some(&jumps),
    )?;

    // The kd of the best point: one more profile, which writes it.
    cost_at(&best_t);
    tracker.evaluations = count.get();
    Ok(answer(&map, &best_t, kd, tracker))
}

/// Steps 2 and 3 for one criterion whose design costs are `costs`: Nelder–Mead searches from
/// the warm starts (point, cost) and from the best separated design points, then polishing of
/// the best point found, then (with `jumps`) the lobe-width moves from it. Calls
/// `generation_done` with the best cost so far after each search, each polishing restart and
/// each move taken; returns the best point and its cost, and pushes every search's end onto
/// `ends`.
#[allow(clippy::too_many_arguments)]
fn descend(
    cost_at: &mut impl FnMut(&[f64; 3]) -> f64,
    points: &[[f64; 3]],
    costs: &[f64],
    warm: &[([f64; 3], f64)],
    s: &SeparableSettings,
    generation_done: &mut dyn FnMut(f64) -> Result<(), FitError>,
    ends: &mut Vec<([f64; 3], f64)>,
    jumps: Option<&dyn Fn(&[f64; 3]) -> [[f64; 3]; 4]>,
) -> Result<([f64; 3], f64), FitError> {
    // Warm starts that coincide (cf1 and L1 both find an exact fit) are searched once.
    let mut starts: Vec<([f64; 3], f64)> = Vec::with_capacity(warm.len() + s.starts as usize);
    for &(t, f) in warm {
        if starts
            .iter()
            .all(|(u, _)| distance_inf(&t, u) > s.search_tolerance)
        {
            starts.push((t, f));
        }
    }
    let taken: Vec<[f64; 3]> = starts.iter().map(|(t, _)| *t).collect();
    let design = pick_starts(points, costs, &taken, s.starts as usize, s.start_separation);
    starts.extend(design.into_iter().map(|i| (points[i], costs[i])));
    // The best point so far: a warm start or the best design point.
    let (mut best_t, mut best_f) = (0..points.len())
        .map(|i| (points[i], costs[i]))
        .chain(warm.iter().copied())
        .min_by(|a, b| a.1.total_cmp(&b.1))
        .expect("samples >= 1");

    // 2. Searches, to the loose search tolerance.
    let search = Options {
        initial_step: 0.1,
        max_evaluations: s.max_evaluations_per_search,
        x_tolerance: s.search_tolerance,
        f_tolerance: s.search_tolerance,
    };
    for (t, f) in starts {
        let out = nelder_mead::minimise(cost_at, t, f, &search);
        ends.push((out.x, out.f));
        if out.f < best_f {
            (best_t, best_f) = (out.x, out.f);
        }
        generation_done(best_f)?;
    }

    // 3. Polish the best to the tight tolerances. Another restart follows only while a
    //    restart gains more than the search tolerance (relative): a gain that large means the
    //    last simplex had stalled short of the minimum; a smaller one is the polish itself
    //    closing in, which a further restart only refines (on the example scans and the
    //    reliability harness by at most ~1e-7 of the cost, for 150–300 more evaluations).
    let polish_options = Options {
        initial_step: 0.05,
        max_evaluations: s.max_evaluations_per_polish,
        x_tolerance: s.x_tolerance,
        f_tolerance: s.f_tolerance,
    };
    (best_t, best_f) = polish(
        cost_at,
        (best_t, best_f),
        polish_options,
        s.polish_restarts,
        s.search_tolerance,
        generation_done,
    )?;

    // 4. Lobe-width moves: a move close enough to the best is searched, and polished (to a
    //    finer gain: the valleys the moves reach are narrow) if the search beats the best.
    if let Some(jumps) = jumps {
        for _ in 0..JUMP_ROUNDS {
            let (jt, jf) = jumps(&best_t)
                .into_iter()
                .map(|t| (t, cost_at(&t)))
                .min_by(|a, b| a.1.total_cmp(&b.1))
                .expect("four moves");
            if jf > best_f * (1.0 + JUMP_MARGIN) {
                break;
            }
            let out = nelder_mead::minimise(cost_at, jt, jf, &search);
            if out.f >= best_f {
                break;
            }
            (best_t, best_f) = polish(
                cost_at,
                (out.x, out.f),
                polish_options,
                2 * s.polish_restarts,
                JUMP_POLISH_GAIN,
                &mut |_| Ok(()),
            )?;
            generation_done(best_f)?;
        }
    }
    Ok((best_t, best_f))
}

/// Nelder–Mead restarted at `best` with simplices a quarter the size of the last (the first
/// `options.initial_step`), at most `restarts` times, while a restart gains more than `gain`
/// of the cost; calls `on_restart` with the best cost after each. Returns the best point.
fn polish(
    cost_at: &mut impl FnMut(&[f64; 3]) -> f64,
    best: ([f64; 3], f64),
    mut options: Options,
    restarts: u32,
    gain: f64,
    on_restart: &mut dyn FnMut(f64) -> Result<(), FitError>,
) -> Result<([f64; 3], f64), FitError> {
    let (mut best_t, mut best_f) = best;
    for _ in 0..restarts {
        let out = nelder_mead::minimise(cost_at, best_t, best_f, &options);
        let improved = best_f - out.f > gain * best_f;
        if out.f < best_f {
            (best_t, best_f) = (out.x, out.f);
        }
        on_restart(best_f)?;
        if !improved {
            break;
        }
        options.initial_step *= 0.25;
    }
    Ok((best_t, best_f))
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
        assert_eq!(pick_starts(&pts, &costs, &[], 3, 0.15), vec![0, 2, 3]);
        // Asking for all four: the close one fills up last.
        assert_eq!(pick_starts(&pts, &costs, &[], 4, 0.15), vec![0, 2, 3, 1]);
        // A warm start near the best design point pushes it back: the others come first.
        assert_eq!(
            pick_starts(&pts, &costs, &[[0.05, 0.1, 0.1]], 3, 0.15),
            vec![2, 3, 0]
        );
    }

    #[test]
    fn unit_inverts_the_map() {
        let map = Map {
            bounds: Bounds::default(),
        };
        for t in [[0.0, 0.0, 0.0], [0.3, 0.7, 0.2], [1.0, 1.0, 1.0]] {
            let (ks, a, i) = map.params(&t);
            let u = map.unit(ks, a, i);
            for d in 0..3 {
                assert!((u[d] - t[d]).abs() < 1e-12, "{t:?} → {u:?}");
            }
        }
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
