//! The paper's differential evolution, DE/rand/1/bin (Storn & Price), with the whole population evaluated
//! in parallel and multi-objective (Pareto) selection.
//!
//! Determinism: every random draw (initial population, mutation indices, crossover) is made on the
//! calling thread from one seeded generator before a generation's trials are evaluated; the trials are
//! then evaluated in parallel by pure functions. The result therefore does not depend on the number of
//! threads.

use super::rng::{pick, Rng};
use super::select::{best_by_sum, replaces};
use super::{
    check_bounds, evaluate_all, report, GenerationReport, Objective, SearchResult, StopReason,
};
use crate::error::{Error, Result};

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

/// What [`minimize`] found (its stop reason: the callback or the generation budget).
pub type DeResult = SearchResult;

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
    check_bounds(bounds)?;
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

    let mut b = best_by_sum(&fit);
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
        b = best_by_sum(&fit);
        stopped = !callback(&report(generations, b, &pop, &fit, evaluations));
    }
    Ok(SearchResult {
        best: pop[b].clone(),
        best_objectives: fit[b].clone(),
        evaluations,
        generations,
        stop: if stopped {
            StopReason::Callback
        } else {
            StopReason::MaxGenerations
        },
        population: np,
        polish: None,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bad_configuration_is_an_error_not_a_panic() {
        let f = |x: &[f64]| x[0];
        let b = [(0.0, 1.0)];
        // One field out of its range each, the others default.
        let bad: [fn(&mut DeConfig); 3] = [|c| c.population = 3, |c| c.f = 0.0, |c| c.cr = 1.5];
        for set in bad {
            let mut cfg = DeConfig::default();
            set(&mut cfg);
            assert!(minimize(&f, &b, &cfg, |_| true).is_err());
        }
        assert!(minimize(&f, &[(1.0, 0.0)], &DeConfig::default(), |_| true).is_err());
        assert!(minimize(&f, &[(0.0, f64::NAN)], &DeConfig::default(), |_| true).is_err());
    }
}
