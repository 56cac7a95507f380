//! The search: minimise an [`Objective`] within bounds. [`run`] is the one entry point; a [`Method`] says
//! which engine ([`rand1bin`], the paper's DE; [`lshade`], L-SHADE or jSO with a [`nelder_mead`] polish),
//! and every engine reports one [`SearchResult`] with one [`StopReason`].

pub mod lshade;
pub mod nelder_mead;
pub mod rand1bin;
pub mod rng;
pub mod select;

use rayon::prelude::*;

use crate::error::{Error, Result};
pub use lshade::{Init, LshadeConfig, LshadeResult, Variant};
pub use nelder_mead::{nelder_mead, NelderMeadResult};
pub use rand1bin::{DeConfig, DeResult};
pub use rng::Rng;
pub use select::{normalized_spread, normalized_spreads, replaces};

/// A function to minimise: one or more objectives of a parameter vector. Must be pure (and `Sync`).
pub trait Objective: Sync {
    fn n_objectives(&self) -> usize;
    /// Write the objective values of `x` into `out` (length `n_objectives`).
    fn evaluate(&self, x: &[f64], out: &mut [f64]);

    /// Like `evaluate` for a single objective, but the value only has to be exact when it is
    /// `<= bound`: an implementation may stop summing once it knows the value exceeds `bound` and
    /// return any value above it. DE uses this for trials, which only need to know whether they beat
    /// their target.
    fn evaluate_bounded(&self, x: &[f64], out: &mut [f64], bound: f64) {
        let _ = bound;
        self.evaluate(x, out);
    }

    /// Like `evaluate`, for a candidate evaluated alone (as a local search does, one point after the
    /// other): an implementation may spread the one evaluation over the current rayon pool. It must give
    /// exactly `evaluate`'s value, on any number of threads.
    fn evaluate_alone(&self, x: &[f64], out: &mut [f64]) {
        self.evaluate(x, out);
    }
}

impl<F: Fn(&[f64]) -> f64 + Sync> Objective for F {
    fn n_objectives(&self) -> usize {
        1
    }
    fn evaluate(&self, x: &[f64], out: &mut [f64]) {
        out[0] = self(x);
    }
}

/// What the per-generation callback sees.
pub struct GenerationReport<'a> {
    /// 0 for the initial population, then 1..=generations.
    pub generation: usize,
    pub best: &'a [f64],
    pub best_objectives: &'a [f64],
    pub evaluations: usize,
    pub population: &'a [Vec<f64>],
    pub objectives: &'a [Vec<f64>],
}

/// Why a search stopped.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum StopReason {
    /// The evaluation budget `max_evaluations` is spent.
    MaxEvaluations,
    /// `max_generations` generations were run.
    MaxGenerations,
    /// The population's spread in normalised parameter space fell below `x_tol`.
    Converged,
    /// The best value did not improve by more than `stall_tol` for `stall_generations` generations.
    Stalled,
    /// The callback returned `false`.
    Callback,
}

impl StopReason {
    /// `"max_evaluations"`, `"max_generations"`, `"converged"`, `"stalled"` or `"callback"`.
    pub fn as_str(self) -> &'static str {
        match self {
            StopReason::MaxEvaluations => "max_evaluations",
            StopReason::MaxGenerations => "max_generations",
            StopReason::Converged => "converged",
            StopReason::Stalled => "stalled",
            StopReason::Callback => "callback",
        }
    }
}

impl std::fmt::Display for StopReason {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.as_str())
    }
}

/// What the final Nelder–Mead polish did.
#[derive(Clone, Debug)]
pub struct PolishReport {
    pub evaluations: usize,
    /// Best value before and after the polish (`after <= before`: a worse point is never taken).
    pub f_before: f64,
    pub f_after: f64,
    /// `f_before − f_after` (0 when the polish found nothing better; `inf` when `f_before` was `inf`).
    pub improvement: f64,
    /// The simplex shrank below `polish_x_tol` before the budget was spent.
    pub converged: bool,
}

/// A search method and its settings.
#[derive(Clone, Debug)]
pub enum Method {
    /// The paper's DE/rand/1/bin ([`rand1bin::minimize`]).
    RandOneBin(DeConfig),
    /// L-SHADE or jSO ([`lshade::minimize`]), with the polish its config asks for.
    Lshade(LshadeConfig),
}

/// A search's budget as a fit protocol states it, for [`Method::named`].
#[derive(Clone, Debug)]
pub struct Budget {
    /// DE's population; L-SHADE's initial population.
    pub population: usize,
    /// DE's generations; L-SHADE spends as many evaluations, `population × (generations + 1)`, unless
    /// `max_evaluations` is given.
    pub generations: usize,
    /// DE's differential weight and crossover probability (L-SHADE adapts its own).
    pub f: f64,
    pub cr: f64,
    pub seed: u64,
    pub max_evaluations: Option<usize>,
    /// L-SHADE's Nelder–Mead polish budget (0: none) and tolerance (`None`: the default 1e-13).
    pub polish: usize,
    pub polish_tol: Option<f64>,
}

impl Method {
    /// The method called `name`: `"de"` (DE/rand/1/bin) or `"lshade"`, with `budget`.
    pub fn named(name: &str, budget: &Budget) -> Result<Method> {
        let b = budget;
        match name {
            "de" => Ok(Method::RandOneBin(DeConfig {
                population: b.population,
                generations: b.generations,
                f: b.f,
                cr: b.cr,
                seed: b.seed,
            })),
            "lshade" => Ok(Method::Lshade(LshadeConfig {
                max_evaluations: b
                    .max_evaluations
                    .unwrap_or(b.population * (b.generations + 1)),
                population_init: Some(b.population),
                polish_evaluations: b.polish,
                polish_x_tol: b.polish_tol.unwrap_or(LshadeConfig::default().polish_x_tol),
                seed: b.seed,
                ..LshadeConfig::lshade()
            })),
            other => Err(Error::Invalid(format!(
                "unknown method {other:?} (known: \"de\", \"lshade\")"
            ))),
        }
    }
}

/// What a search found.
#[derive(Clone, Debug)]
pub struct SearchResult {
    pub best: Vec<f64>,
    pub best_objectives: Vec<f64>,
    /// All evaluations, a polish's included.
    pub evaluations: usize,
    /// Generations run after the initial population.
    pub generations: usize,
    pub stop: StopReason,
    /// Final population size.
    pub population: usize,
    /// Present when a polish ran.
    pub polish: Option<PolishReport>,
}

impl SearchResult {
    /// The callback asked to stop.
    pub fn stopped(&self) -> bool {
        self.stop == StopReason::Callback
    }
}

/// Minimise `obj` within `bounds` (min, max per dimension; min == max fixes one) with `method`.
///
/// `callback` runs after the initial population and after every generation; returning `false` stops.
pub fn run<O, C>(
    method: &Method,
    obj: &O,
    bounds: &[(f64, f64)],
    callback: C,
) -> Result<SearchResult>
where
    O: Objective + ?Sized,
    C: FnMut(&GenerationReport) -> bool,
{
    run_polishing(method, obj, None::<&O>, bounds, None, callback)
}

/// [`run`], with a method's final polish on `polish_obj` where given (see
/// [`lshade::minimize_polishing_from`]; DE/rand/1/bin has no polish and ignores it), and L-SHADE's initial
/// population holding `start` where given ([`lshade::minimize_polishing_from`]; DE/rand/1/bin, the
/// paper's method, takes none).
pub fn run_polishing<O, P, C>(
    method: &Method,
    obj: &O,
    polish_obj: Option<&P>,
    bounds: &[(f64, f64)],
    start: Option<&[f64]>,
    callback: C,
) -> Result<SearchResult>
where
    O: Objective + ?Sized,
    P: Objective + ?Sized,
    C: FnMut(&GenerationReport) -> bool,
{
    match method {
        Method::RandOneBin(_) if start.is_some() => Err(Error::Invalid(
            "a start point needs the \"lshade\" method (DE/rand/1/bin draws its whole population)"
                .into(),
        )),
        Method::RandOneBin(cfg) => rand1bin::minimize(obj, bounds, cfg, callback),
        Method::Lshade(cfg) => {
            lshade::minimize_polishing_from(obj, polish_obj, bounds, cfg, start, callback)
                .map(|r| r.search)
        }
    }
}

fn report<'a>(
    g: usize,
    b: usize,
    pop: &'a [Vec<f64>],
    fit: &'a [Vec<f64>],
    evaluations: usize,
) -> GenerationReport<'a> {
    GenerationReport {
        generation: g,
        best: &pop[b],
        best_objectives: &fit[b],
        evaluations,
        population: pop,
        objectives: fit,
    }
}

/// Evaluate every `xs[i]` into `out[i]`; with `bounds`, single-objective values only need to be exact up
/// to `bounds[i][0]` (the trial's target), see `Objective::evaluate_bounded`.
fn evaluate_all<O: Objective + ?Sized>(
    obj: &O,
    xs: &[Vec<f64>],
    out: &mut [Vec<f64>],
    bounds: Option<&[Vec<f64>]>,
) {
    xs.par_iter()
        .zip(out.par_iter_mut())
        .enumerate()
        .for_each(|(i, (x, o))| {
            match bounds {
                Some(b) if o.len() == 1 => obj.evaluate_bounded(x, o, b[i][0]),
                _ => obj.evaluate(x, o),
            }
            for v in o.iter_mut() {
                if v.is_nan() {
                    *v = f64::INFINITY; // a NaN objective never wins a comparison
                }
            }
        });
}

/// Every bound finite with min <= max.
fn check_bounds(bounds: &[(f64, f64)]) -> Result<()> {
    for (k, &(lo, hi)) in bounds.iter().enumerate() {
        if !(lo.is_finite() && hi.is_finite() && lo <= hi) {
            return Err(Error::Invalid(format!(
                "bounds[{k}] must be finite with min <= max (got {lo}, {hi})"
            )));
        }
    }
    Ok(())
}

/// L-SHADE and Nelder–Mead: one objective, valid bounds.
fn check_single_objective<O: Objective + ?Sized>(obj: &O, bounds: &[(f64, f64)]) -> Result<()> {
    if obj.n_objectives() != 1 {
        return Err(Error::Invalid(format!(
            "L-SHADE and Nelder-Mead minimise one objective (got {})",
            obj.n_objectives()
        )));
    }
    check_bounds(bounds)
}
