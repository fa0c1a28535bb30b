//! Fitting the 34 model parameters to one measured BRDF (SCIENCE.md §6).
//!
//! Two methods, chosen by [`Settings::method`] and recorded in every [`FitOutcome`]:
//! - [`Method::Paper`] (`paper`): what the paper did — a plain, bounded, real-coded, elitist
//!   genetic algorithm over all 34 parameters. Kept to reproduce the paper and as the yardstick.
//! - [`Method::Separable`] (`separable`, the default): uses the model's structure. With
//!   (ks, α, μ) fixed the specular term is one number per geometry, and kd(λ) enters only its
//!   own band's residuals, so the best kd is solved exactly band by band (`problem`). What is
//!   left is a 3-D search over (ks, α, μ): a seeded space-filling design, Nelder–Mead from its
//!   best distinct points, and Nelder–Mead restarts at the best point to polish (`separable`).
//!   For cf2 and m2 the same search first runs on smoother criteria (cf1, then for cf2 the
//!   weighted L1 error), whose optima are extra starting points: cf2's landscape has many
//!   local minima, and this continuation is what makes its fits agree across seeds.
//!   The reliability harness (`tools/src/bin/reliability.rs`) checks that it ends within 1 % of the
//!   best cost either method ever finds, on every scan, cost function and seed.
//!
//! Both are deterministic: the same measured BRDF, settings and seed give the same parameters
//! bit for bit. Progress is reported once per generation through [`fit_with_observer`], which
//! can also cancel the fit.

// Numeric loops index parallel per-geometry and per-band arrays; `for g in 0..G` reads
// closest to the equations.
#![allow(clippy::needless_range_loop)]

mod ga;
pub(crate) mod nelder_mead;
mod options;
mod preset;
mod problem;
mod separable;
pub mod synthetic;

pub use preset::Preset;

use std::fmt;
use std::ops::ControlFlow;
use std::str::FromStr;
use std::time::Instant;

use serde::{Deserialize, Serialize};

use crate::cost::{CostFunction, cost_with};
use crate::geometry::{GEOMETRIES, GEOMETRY_COUNT};
use crate::model::{Bounds, FresnelCosine, ModelKind, Params, SpecularGeometry, evaluate_model};
use crate::processing::MeasuredBrdf;
use crate::spectral::{BANDS, wavelengths_nm};
use crate::sra_reading::{SraModel, SraReading};

use problem::Problem;

/// How the parameters are searched for.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Method {
    /// The paper's genetic algorithm over all 34 parameters.
    Paper,
    /// kd solved exactly per band, a multi-start Nelder–Mead search over (ks, α, μ).
    #[default]
    Separable,
}

impl Method {
    /// Both methods, the default last.
    pub const ALL: [Method; 2] = [Method::Paper, Method::Separable];

    /// The name used on the command line, in settings and in reports.
    pub const fn name(self) -> &'static str {
        match self {
            Method::Paper => "paper",
            Method::Separable => "separable",
        }
    }
}

impl fmt::Display for Method {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// A method name that is not one of `paper`, `separable`.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("unknown fit method \"{name}\": expected one of paper, separable")]
pub struct ParseMethodError {
    /// The name as given.
    pub name: String,
}

impl FromStr for Method {
    type Err = ParseMethodError;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        Method::ALL
            .into_iter()
            .find(|m| m.name().eq_ignore_ascii_case(s.trim()))
            .ok_or_else(|| ParseMethodError {
                name: s.to_string(),
            })
    }
}

/// Settings of the paper's genetic algorithm ([`Method::Paper`]).
///
/// A genome is the 34 parameters in their own units; every gene starts uniform within its
/// bounds and is clamped back into them after crossover and mutation.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct GaSettings {
    /// Individuals per generation. Default 100.
    pub population: u32,
    /// Most generations after the initial population. Default 1000.
    pub generations: u32,
    /// Stop early when the best cost improved by less than `stall_tolerance` (relative) over
    /// this many generations, as MATLAB's `ga` does by default; 0 runs every generation.
    /// Default 50.
    pub stall_generations: u32,
    /// Relative improvement that counts as progress for `stall_generations`. Default 1e-6.
    pub stall_tolerance: f64,
    /// Tournament size for parent selection (with replacement). Default 3.
    pub tournament: u32,
    /// Best individuals copied unchanged into the next generation (elitism). Default 2.
    pub elite: u32,
    /// Probability that a pair of parents is recombined by simulated binary crossover
    /// (Deb & Agrawal 1995) rather than copied. Default 0.9.
    pub crossover_probability: f64,
    /// SBX distribution index η_c: larger keeps children closer to their parents. Default 15.
    pub crossover_eta: f64,
    /// Per-gene probability of polynomial mutation (Deb & Goyal 1996). Default 1/34, one gene
    /// per child on average.
    pub mutation_probability: f64,
    /// Polynomial-mutation distribution index η_m. Default 20.
    pub mutation_eta: f64,
}

impl Default for GaSettings {
    fn default() -> Self {
        GaSettings {
            population: 100,
            generations: 1000,
            stall_generations: 50,
            stall_tolerance: 1e-6,
            tournament: 3,
            elite: 2,
            crossover_probability: 0.9,
            crossover_eta: 15.0,
            mutation_probability: 1.0 / 34.0,
            mutation_eta: 20.0,
        }
    }
}

/// Settings of the default method ([`Method::Separable`]).
///
/// The search runs in unit-cube coordinates t ∈ [0, 1]³ mapped onto the bounds as
/// ks = lo + (hi − lo)·t², α log-uniform (lo·(hi/lo)^t) and μ linear: matt samples have
/// small ks and α, where the cost changes fastest, and these maps give those regions room.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SeparableSettings {
    /// Points of the seeded Latin-hypercube design that surveys (ks, α, μ). Default 64.
    pub samples: u32,
    /// Nelder–Mead searches per stage from the design, started from the best design points
    /// that lie at least `start_separation` apart (and that far from the warm starts, which
    /// are searched as well). Default 4.
    pub starts: u32,
    /// Least ∞-norm distance (unit cube) between two starting points, so that the searches
    /// explore different basins. Default 0.15.
    pub start_separation: f64,
    /// A search stops when its simplex is this small (unit-cube ∞-norm) and its costs agree
    /// to this relative tolerance. Loose on purpose: it only has to tell basins apart (near a
    /// smooth minimum a 1e-3 step moves the cost by ~1e-6 relative); polishing takes the best
    /// one the rest of the way. Default 1e-3.
    pub search_tolerance: f64,
    /// Most cost evaluations of one search. Default 150.
    pub max_evaluations_per_search: u32,
    /// Nelder–Mead restarts at the best point, each with a fresh simplex a quarter the size of
    /// the last (the first 0.05), to polish it and to undo a simplex that collapsed early.
    /// Default 3; stops early when a restart improves the cost by no more than
    /// `search_tolerance` (relative): only a simplex that stalled gains that much.
    pub polish_restarts: u32,
    /// Most cost evaluations of one polishing restart. Default 300.
    pub max_evaluations_per_polish: u32,
    /// Polishing stops when the simplex is this small (unit-cube ∞-norm)... Default 1e-7,
    /// which pins ks, α and μ to better than 1e-5 relative.
    pub x_tolerance: f64,
    /// ...and its costs agree to this relative tolerance. Default 1e-8: cf2's |r|^(2/3)
    /// turns parameter rounding into cost differences of that order near an exact fit, so a
    /// tighter value only burns evaluations.
    pub f_tolerance: f64,
    /// Continuation: before the fit's own cost, run the same survey–search–polish on the same
    /// design for smoother criteria — cf2: cf1, then the weighted L1 error; m2: cf1; cf1:
    /// none — and search from their optima too. Default true; false gives the plain
    /// multi-start search (fits then miss cf2's best basin for some seeds).
    pub continuation: bool,
}

impl Default for SeparableSettings {
    fn default() -> Self {
        SeparableSettings {
            samples: 64,
            starts: 4,
            start_separation: 0.15,
            search_tolerance: 1e-3,
            max_evaluations_per_search: 150,
            polish_restarts: 3,
            max_evaluations_per_polish: 300,
            x_tolerance: 1e-7,
            f_tolerance: 1e-8,
            continuation: true,
        }
    }
}

/// Every setting of a fit; recorded with the fit so that it can be repeated bit for bit.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Settings {
    /// Search method. Default [`Method::Separable`].
    pub method: Method,
    /// Cost function minimised. Default [`CostFunction::Cf2`].
    pub cost: CostFunction,
    /// Parameter bounds. Default SCIENCE.md §4: kd ∈ [0, 1], ks ∈ [0, 10], α ∈ [0.01, 1],
    /// μ ∈ [1, 3].
    pub bounds: Bounds,
    /// Which cosine the Fresnel term uses. Default: cos θi, as the paper.
    pub fresnel: FresnelCosine,
    /// Seed of the ChaCha8 generator behind every random choice. Default 1; fixed so that two
    /// runs with default settings agree, change it to probe the optimiser.
    pub seed: u64,
    /// The paper GA's settings (used when `method` is `paper`).
    pub paper: GaSettings,
    /// The separable method's settings (used when `method` is `separable`).
    pub separable: SeparableSettings,
    /// How the SRA readings enter the cost (SCIENCE.md §5.1). Default: the paper's flat model,
    /// left out of the serialised settings so that they read as before the option existed.
    #[serde(skip_serializing_if = "SraReading::is_default")]
    pub sra: SraReading,
    /// The model's form (SCIENCE.md §4.1). Default: the paper's, left out of the serialised
    /// settings so that they read as before the option existed.
    #[serde(skip_serializing_if = "is_paper_model")]
    pub model: ModelKind,
}

fn is_paper_model(m: &ModelKind) -> bool {
    *m == ModelKind::Paper
}

impl Default for Settings {
    fn default() -> Self {
        Settings {
            method: Method::default(),
            cost: CostFunction::default(),
            bounds: Bounds::default(),
            fresnel: FresnelCosine::default(),
            seed: 1,
            paper: GaSettings::default(),
            separable: SeparableSettings::default(),
            sra: SraReading::default(),
            model: ModelKind::default(),
        }
    }
}

/// A setting that cannot be used; the message names the setting and the accepted values.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{0}")]
pub struct SettingsError(pub String);

fn check(ok: bool, message: impl FnOnce() -> String) -> Result<(), SettingsError> {
    if ok {
        Ok(())
    } else {
        Err(SettingsError(message()))
    }
}

fn unit_interval(x: f64) -> bool {
    (0.0..=1.0).contains(&x)
}

impl Settings {
    /// Checks every setting, both methods' included (a settings file is checked whole).
    pub fn validate(&self) -> Result<(), SettingsError> {
        self.bounds.validate().map_err(SettingsError)?;
        let b = &self.bounds;
        check(b.kd.0 >= 0.0, || {
            format!(
                "bounds: kd lower bound {} must be >= 0 (a BRDF is not negative)",
                b.kd.0
            )
        })?;
        check(b.ks.0 >= 0.0, || {
            format!(
                "bounds: ks lower bound {} must be >= 0 (a BRDF is not negative)",
                b.ks.0
            )
        })?;

        check(
            self.model == ModelKind::Paper || self.method == Method::Separable,
            || {
                format!(
                    "model {} needs the separable method: the paper's GA fits the paper's \
                     model only",
                    self.model.name()
                )
            },
        )?;

        let p = &self.paper;
        check(p.population >= 4, || {
            format!("paper GA: population must be >= 4, got {}", p.population)
        })?;
        check(p.generations >= 1, || {
            "paper GA: generations must be >= 1, got 0".to_string()
        })?;
        check(p.tournament >= 1 && p.tournament <= p.population, || {
            format!(
                "paper GA: tournament must be between 1 and the population ({}), got {}",
                p.population, p.tournament
            )
        })?;
        check(p.elite < p.population, || {
            format!(
                "paper GA: elite must be below the population ({}), got {}",
                p.population, p.elite
            )
        })?;
        check(unit_interval(p.crossover_probability), || {
            format!(
                "paper GA: crossover_probability must be in [0, 1], got {}",
                p.crossover_probability
            )
        })?;
        check(unit_interval(p.mutation_probability), || {
            format!(
                "paper GA: mutation_probability must be in [0, 1], got {}",
                p.mutation_probability
            )
        })?;
        check(
            p.crossover_eta.is_finite() && p.crossover_eta >= 0.0,
            || {
                format!(
                    "paper GA: crossover_eta must be finite and >= 0, got {}",
                    p.crossover_eta
                )
            },
        )?;
        check(p.mutation_eta.is_finite() && p.mutation_eta >= 0.0, || {
            format!(
                "paper GA: mutation_eta must be finite and >= 0, got {}",
                p.mutation_eta
            )
        })?;

        let s = &self.separable;
        check(s.starts >= 1, || {
            "separable: starts must be >= 1, got 0".to_string()
        })?;
        check(s.samples >= s.starts, || {
            format!(
                "separable: samples must be >= starts ({}), got {}",
                s.starts, s.samples
            )
        })?;
        check(
            s.start_separation.is_finite() && s.start_separation >= 0.0,
            || {
                format!(
                    "separable: start_separation must be finite and >= 0, got {}",
                    s.start_separation
                )
            },
        )?;
        for (name, value) in [
            ("max_evaluations_per_search", s.max_evaluations_per_search),
            ("max_evaluations_per_polish", s.max_evaluations_per_polish),
        ] {
            check(value >= 8, || {
                format!("separable: {name} must be >= 8 (a 3-D simplex needs 4), got {value}")
            })?;
        }
        check(s.search_tolerance > 0.0 && s.search_tolerance < 1.0, || {
            format!(
                "separable: search_tolerance must be in (0, 1), got {}",
                s.search_tolerance
            )
        })?;
        check(s.x_tolerance > 0.0 && s.x_tolerance < 1.0, || {
            format!(
                "separable: x_tolerance must be in (0, 1), got {}",
                s.x_tolerance
            )
        })?;
        check(s.f_tolerance.is_finite() && s.f_tolerance >= 0.0, || {
            format!(
                "separable: f_tolerance must be finite and >= 0, got {}",
                s.f_tolerance
            )
        })?;
        Ok(())
    }
}

/// Reported once per generation.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Progress {
    /// Generations finished so far, from 1.
    pub generation: u32,
    /// Generations the fit will run at most (the separable method may stop polishing early).
    pub generations_total: u32,
    /// Best cost found so far.
    pub best_cost: f64,
    /// Cost evaluations so far.
    pub evaluations: u64,
}

/// The result of one fit, with what is needed to repeat and to judge it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FitOutcome {
    /// The fitted parameters, within the bounds.
    pub params: Params,
    /// Their cost, as [`crate::cost::cost_with`] computes it.
    pub cost: f64,
    /// Cost evaluations. For the paper GA one evaluation is a full 34-parameter model; for the
    /// separable method it is one (ks, α, μ) point with its exact per-band kd solve, for the
    /// fit's own cost or (continuation) a surrogate criterion — cf1's and L1's are 10–20 times
    /// cheaper than cf2's.
    pub evaluations: u64,
    /// Generations run. The paper GA: one per GA generation (fewer than the maximum when it
    /// stalls). The separable method: each continuation stage, the design survey, each
    /// Nelder–Mead search and each polishing restart.
    pub generations: u32,
    /// Wall-clock time of the fit, ms.
    pub wall_ms: f64,
    /// Best cost after each generation (non-increasing).
    pub best_cost_per_generation: Vec<f64>,
    /// The method that produced the fit.
    pub method: Method,
    /// The seed it ran with.
    pub seed: u64,
}

/// Why a fit did not produce parameters.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum FitError {
    /// A setting is out of range; fix the settings (the message names the setting).
    #[error("invalid fit settings: {0}")]
    InvalidSettings(#[from] SettingsError),
    /// The measured BRDF holds a NaN or infinity; the scan or its processing is broken.
    #[error(
        "measured BRDF at geometry {geometry}, band {band} ({nm} nm) is not finite; \
         check the scan's readings and its N9 reference",
        nm = wavelengths_nm()[*band]
    )]
    NonFiniteInput {
        /// The geometry's device name.
        geometry: &'static str,
        /// Band index, 0 = 400 nm.
        band: usize,
    },
    /// m2 takes ln(1 + cosθi·M); a measured value at or below −1/cosθi sr⁻¹ has no logarithm.
    #[error(
        "measured BRDF {value} sr⁻¹ at geometry {geometry}, band {band} ({nm} nm) is out of \
         m2's domain (needs 1 + cosθi·M > 0); check the scan or fit with cf1 or cf2",
        nm = wavelengths_nm()[*band]
    )]
    OutOfDomain {
        /// The geometry's device name.
        geometry: &'static str,
        /// Band index, 0 = 400 nm.
        band: usize,
        /// The measured value, sr⁻¹.
        value: f64,
    },
    /// The observer asked to stop.
    #[error("fit cancelled")]
    Cancelled,
}

/// Fits `measured` with `settings`.
pub fn fit(measured: &MeasuredBrdf, settings: &Settings) -> Result<FitOutcome, FitError> {
    fit_with_observer(measured, settings, &mut |_| ControlFlow::Continue(()))
}

/// Fits `measured` with `settings`, calling `observer` after every generation; returning
/// `ControlFlow::Break(())` from it cancels the fit with [`FitError::Cancelled`].
pub fn fit_with_observer(
    measured: &MeasuredBrdf,
    settings: &Settings,
    observer: &mut dyn FnMut(&Progress) -> ControlFlow<()>,
) -> Result<FitOutcome, FitError> {
    let started = Instant::now();
    settings.validate()?;
    check_input(measured, settings.cost)?;
    let run = if settings.model == ModelKind::Paper {
        // The flat SRA terms under the fit's weights: the L1 stepping stone's problem.
        let flat = Problem::new(measured, settings.cost, settings.fresnel, settings.bounds)
            .with_sra(measured, settings.sra.with_model(SraModel::Flat));
        let problem = flat.clone().with_sra(measured, settings.sra);
        match settings.method {
            Method::Paper => ga::run(&problem, &settings.paper, settings.seed, observer)?,
            Method::Separable => separable::run(
                &problem,
                &flat,
                &settings.separable,
                settings.seed,
                observer,
            )?,
        }
    } else {
        options::run(measured, settings, observer)?
    };
    Ok(outcome(measured, settings, run, settings.method, started))
}

/// A local refit of `measured` warm-started at `start`: the separable method's search and
/// polish from that one point (no survey, no continuation), whatever `settings.method` is.
/// The bootstrap ([`crate::uncertainty`]) refits each resample this way from the point fit.
pub fn refit_local(
    measured: &MeasuredBrdf,
    settings: &Settings,
    start: &Params,
) -> Result<FitOutcome, FitError> {
    let started = Instant::now();
    settings.validate()?;
    check_input(measured, settings.cost)?;
    let problem = options::problem(measured, settings, &start.extra);
    let mut run = separable::run_local(&problem, &settings.separable, start);
    run.params.extra = start.extra;
    Ok(outcome(measured, settings, run, Method::Separable, started))
}

fn check_input(measured: &MeasuredBrdf, cf: CostFunction) -> Result<(), FitError> {
    for g in 0..GEOMETRY_COUNT {
        let w = GEOMETRIES[g].cos_theta_i();
        for b in 0..BANDS {
            let value = measured.values[g][b];
            let geometry = GEOMETRIES[g].name;
            if !value.is_finite() {
                return Err(FitError::NonFiniteInput { geometry, band: b });
            }
            if cf == CostFunction::M2 && 1.0 + w * value <= 0.0 {
                return Err(FitError::OutOfDomain {
                    geometry,
                    band: b,
                    value,
                });
            }
        }
    }
    Ok(())
}

/// The outcome of `run` by `method`: its parameters, their cost under `settings` against
/// `measured`, its trace, and the time since `started`.
fn outcome(
    measured: &MeasuredBrdf,
    settings: &Settings,
    run: Run,
    method: Method,
    started: Instant,
) -> FitOutcome {
    let model = evaluate_model(
        &run.params,
        settings.model,
        settings.fresnel,
        &SpecularGeometry::all(),
    );
    FitOutcome {
        params: run.params,
        cost: cost_with(settings.cost, settings.sra, measured, &model),
        evaluations: run.tracker.evaluations,
        generations: run.tracker.history.len() as u32,
        wall_ms: started.elapsed().as_secs_f64() * 1e3,
        best_cost_per_generation: run.tracker.history,
        method,
        seed: settings.seed,
    }
}

/// What a method hands back: the parameters and its bookkeeping.
struct Run {
    params: Params,
    tracker: Tracker,
}

/// Counts evaluations, records the best cost per generation and talks to the observer.
struct Tracker {
    generations_total: u32,
    evaluations: u64,
    history: Vec<f64>,
}

impl Tracker {
    fn new(generations_total: u32) -> Self {
        Tracker {
            generations_total,
            evaluations: 0,
            history: Vec::new(),
        }
    }

    /// Closes a generation whose best cost so far is `best_cost`.
    fn generation_done(
        &mut self,
        best_cost: f64,
        observer: &mut dyn FnMut(&Progress) -> ControlFlow<()>,
    ) -> Result<(), FitError> {
        self.history.push(best_cost);
        let progress = Progress {
            generation: self.history.len() as u32,
            generations_total: self.generations_total,
            best_cost,
            evaluations: self.evaluations,
        };
        match observer(&progress) {
            ControlFlow::Continue(()) => Ok(()),
            ControlFlow::Break(()) => Err(FitError::Cancelled),
        }
    }
}

#[cfg(test)]
mod tests;
