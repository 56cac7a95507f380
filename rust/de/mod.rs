//! Differential evolution, DE/rand/1/bin (Storn & Price), with the whole population evaluated in
//! parallel and multi-objective (Pareto) selection.
//!
//! Determinism: every random draw (initial population, mutation indices, crossover) is made on the
//! calling thread from one seeded generator before a generation's trials are evaluated; the trials are
//! then evaluated in parallel by pure functions. The result therefore does not depend on the number of
//! threads.

pub mod rng;
pub mod shade;

use rayon::prelude::*;

use crate::error::{Error, Result};
pub use rng::Rng;

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

#[derive(Clone, Debug)]
pub struct DeConfig {
    pub population: usize,
    pub generations: usize,
    /// Differential weight F.
    pub f: f64,
    /// Crossover probability CR.
    pub cr: f64,
    pub seed: u64,
}

impl Default for DeConfig {
    /// The paper's settings.
    fn default() -> Self {
        DeConfig {
            population: 60,
            generations: 200,
            f: 0.6,
            cr: 0.8,
            seed: 0,
        }
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

#[derive(Clone, Debug)]
pub struct DeResult {
    pub best: Vec<f64>,
    pub best_objectives: Vec<f64>,
    pub evaluations: usize,
    pub generations: usize,
    /// True when the callback asked to stop early.
    pub stopped: bool,
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

/// Scalar used to rank individuals for "best": the sum of the objectives.
fn score(o: &[f64]) -> f64 {
    o.iter().sum()
}

/// `a` replaces `b`: single objective `a <= b`; several: no worse in every one and better in at least one.
pub fn replaces(a: &[f64], b: &[f64]) -> bool {
    if a.len() == 1 {
        return a[0] <= b[0];
    }
    a.iter().zip(b).all(|(x, y)| x <= y) && a.iter().zip(b).any(|(x, y)| x < y)
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

/// Minimise `obj` within `bounds` (min, max per dimension; min == max fixes a dimension).
///
/// `callback` runs after the initial population and after every generation; returning `false` stops.
pub fn minimize<O, C>(
    obj: &O,
    bounds: &[(f64, f64)],
    cfg: &DeConfig,
    mut callback: C,
) -> Result<DeResult>
where
    O: Objective + ?Sized,
    C: FnMut(&GenerationReport) -> bool,
{
    let dim = bounds.len();
    if cfg.population < 4 {
        return Err(Error::Invalid(format!(
            "population must be at least 4 for DE/rand/1 (got {})",
            cfg.population
        )));
    }
    if !(cfg.f > 0.0 && cfg.f <= 2.0) {
        return Err(Error::Invalid(format!(
            "F must be in (0, 2] (got {})",
            cfg.f
        )));
    }
    if !(0.0..=1.0).contains(&cfg.cr) {
        return Err(Error::Invalid(format!(
            "CR must be in [0, 1] (got {})",
            cfg.cr
        )));
    }
    for (k, &(lo, hi)) in bounds.iter().enumerate() {
        if !(lo.is_finite() && hi.is_finite() && lo <= hi) {
            return Err(Error::Invalid(format!(
                "bounds[{k}] must be finite with min <= max (got {lo}, {hi})"
            )));
        }
    }
    let np = cfg.population;
    let nobj = obj.n_objectives();
    let mut rng = Rng::new(cfg.seed);

    let mut pop: Vec<Vec<f64>> = (0..np)
        .map(|_| {
            bounds
                .iter()
                .map(|&(lo, hi)| lo + (hi - lo) * rng.uniform())
                .collect()
        })
        .collect();
    let mut fit = vec![vec![0.0; nobj]; np];
    evaluate_all(obj, &pop, &mut fit, None);
    let mut evaluations = np;

    let best_index = |fit: &[Vec<f64>]| {
        (0..np)
            .min_by(|&a, &b| score(&fit[a]).total_cmp(&score(&fit[b])))
            .expect("np >= 4")
    };
    let mut b = best_index(&fit);
    let mut stopped = !callback(&report(0, b, &pop, &fit, evaluations));
    let mut trials = vec![vec![0.0; dim]; np];
    let mut trial_fit = vec![vec![0.0; nobj]; np];
    let mut generations = 0;

    while !stopped && generations < cfg.generations {
        // All random draws happen here, serially.
        for (i, trial) in trials.iter_mut().enumerate() {
            let r1 = pick(&mut rng, np, &[i]);
            let r2 = pick(&mut rng, np, &[i, r1]);
            let r3 = pick(&mut rng, np, &[i, r1, r2]);
            let jrand = rng.below(dim.max(1));
            for j in 0..dim {
                let (lo, hi) = bounds[j];
                trial[j] = if j == jrand || rng.uniform() < cfg.cr {
                    let v = pop[r1][j] + cfg.f * (pop[r2][j] - pop[r3][j]);
                    // Out of bounds: move half way from the base vector to the violated bound.
                    if v < lo {
                        0.5 * (pop[r1][j] + lo)
                    } else if v > hi {
                        0.5 * (pop[r1][j] + hi)
                    } else {
                        v
                    }
                } else {
                    pop[i][j]
                };
            }
        }
        evaluate_all(obj, &trials, &mut trial_fit, Some(&fit));
        evaluations += np;
        for i in 0..np {
            if replaces(&trial_fit[i], &fit[i]) {
                std::mem::swap(&mut pop[i], &mut trials[i]);
                std::mem::swap(&mut fit[i], &mut trial_fit[i]);
            }
        }
        generations += 1;
        b = best_index(&fit);
        stopped = !callback(&report(generations, b, &pop, &fit, evaluations));
    }
    Ok(DeResult {
        best: pop[b].clone(),
        best_objectives: fit[b].clone(),
        evaluations,
        generations,
        stopped,
    })
}

fn pick(rng: &mut Rng, n: usize, exclude: &[usize]) -> usize {
    loop {
        let r = rng.below(n);
        if !exclude.contains(&r) {
            return r;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pareto_replacement_rule() {
        assert!(replaces(&[1.0, 2.0, 3.0], &[1.0, 2.0, 4.0]));
        assert!(!replaces(&[1.0, 2.0, 3.0], &[1.0, 2.0, 3.0]));
        assert!(!replaces(&[0.0, 3.0, 3.0], &[1.0, 2.0, 3.0]));
        assert!(replaces(&[1.0], &[1.0]));
    }

    #[test]
    fn bad_configuration_is_an_error_not_a_panic() {
        let f = |x: &[f64]| x[0];
        let b = [(0.0, 1.0)];
        for cfg in [
            DeConfig {
                population: 3,
                ..Default::default()
            },
            DeConfig {
                f: 0.0,
                ..Default::default()
            },
            DeConfig {
                cr: 1.5,
                ..Default::default()
            },
        ] {
            assert!(minimize(&f, &b, &cfg, |_| true).is_err());
        }
        assert!(minimize(&f, &[(1.0, 0.0)], &DeConfig::default(), |_| true).is_err());
        assert!(minimize(&f, &[(0.0, f64::NAN)], &DeConfig::default(), |_| true).is_err());
    }
}
