//! L-SHADE (Tanabe & Fukunaga, CEC 2014): success-history based parameter adaptation (SHADE, Tanabe &
//! Fukunaga 2013) with linear population size reduction, current-to-pbest/1 mutation with an external
//! archive, binomial crossover and the midpoint-to-bound repair, plus the jSO refinements (Brest, Maučec
//! & Bošković 2017) as an option, stopping rules on convergence, and a final Nelder–Mead polish
//! ([`super::nelder_mead`]).
//!
//! The plain DE/rand/1/bin of [`super::rand1bin`] stays the engine of the paper protocol; this module is
//! the modern alternative with the same contracts:
//!
//! * one objective ([`Objective`] with `n_objectives() == 1`), minimised within `bounds`; a dimension with
//!   `min == max` stays fixed;
//! * every trial vector lies within the bounds (a mutant component outside its range is put half way
//!   between the parent's component and the violated bound, as in L-SHADE);
//! * a NaN objective value is stored as `+inf`, so it never wins a comparison;
//! * the callback runs after the initial population and after every generation and stops the search by
//!   returning `false`;
//! * determinism: every random draw (initialisation, memory slots, F and CR, pbest and the two difference
//!   vectors, crossover, archive replacement) is made on the calling thread from one seeded generator; a
//!   generation's trials are then evaluated in parallel (rayon) by the pure objective, and the selection,
//!   the memory update and the population reduction run serially again. The result is bit-identical on
//!   any number of threads.
//!
//! One generation of L-SHADE, population `N` (best first in the ranking), memory `M_F`, `M_CR` of size `H`:
//!
//! 1. for each target `x_i`: pick a memory slot `r` uniformly; `CR_i ~ N(M_CR[r], 0.1)` clipped to [0, 1]
//!    (0 when the slot holds the terminal value), `F_i ~ Cauchy(M_F[r], 0.1)` redrawn while `<= 0` and
//!    truncated to 1; `x_pbest` uniform among the best `max(2, round(p N))`, `x_r1` from the population
//!    (`r1 != i`), `x_r2` from population ∪ archive (`r2 != i, r1`);
//!    `v = x_i + F_i (x_pbest − x_i) + F_i (x_r1 − x_r2)`, binomial crossover with `CR_i`, repair;
//! 2. evaluate the trials in parallel; a trial replaces its target when not worse; a strictly better one
//!    sends its parent to the archive (a random member is overwritten when the archive is full) and
//!    records `F_i`, `CR_i` and the improvement;
//! 3. the next memory slot (cyclically) becomes the improvement-weighted Lehmer mean of the successful
//!    `F` and `CR` (CR becomes terminal for good if all successful CR were 0);
//! 4. linear population size reduction: `N = round(N_init + (N_min − N_init) · evaluations / max_evaluations)`,
//!    the worst individuals are removed and the archive is cut to `round(archive_rate · N)` at random.
//!
//! jSO ([`Variant::Jso`]) changes: `N_init = round(25 ln(D) √D)`, `H = 5` with the last slot fixed at 0.9,
//! memory initialised at `M_F = 0.3`, `M_CR = 0.8`, `p` decreasing linearly from 0.25 to 0.125, archive
//! rate 1, CR floored at 0.7 / 0.6 in the first quarter / half of the budget, F capped at 0.7 in the first
//! 60%, the pbest difference weighted by `F_w = 0.7 F, 0.8 F, 1.2 F` (before 20%, 40%, after), and the
//! memory update averaging the new mean with the old value.

use super::nelder_mead::nelder_mead;
use super::rng::{pick, Rng};
use super::select::{best_index, normalized_spread, normalized_spreads, ranking};
use super::{
    check_single_objective, evaluate_all, report, GenerationReport, Objective, PolishReport,
    SearchResult, StopReason,
};
use crate::error::{Error, Result};

mod config;
pub use config::{Init, LshadeConfig, Variant};

/// What [`minimize`] found: the common [`SearchResult`] (its fields read through), plus the final memory.
#[derive(Clone, Debug)]
pub struct LshadeResult {
    pub search: SearchResult,
    /// Final success-history memory (`None`: the terminal CR value).
    pub memory_f: Vec<f64>,
    pub memory_cr: Vec<Option<f64>>,
}

impl std::ops::Deref for LshadeResult {
    type Target = SearchResult;
    fn deref(&self) -> &SearchResult {
        &self.search
    }
}

/// A normal draw (Box–Muller, two uniforms, no caching so every draw costs the same).
fn normal(rng: &mut Rng, mean: f64, sd: f64) -> f64 {
    let u1 = 1.0 - rng.uniform(); // (0, 1]
    let u2 = rng.uniform();
    mean + sd * (-2.0 * u1.ln()).sqrt() * (2.0 * std::f64::consts::PI * u2).cos()
}

/// A Cauchy draw.
fn cauchy(rng: &mut Rng, loc: f64, scale: f64) -> f64 {
    loc + scale * (std::f64::consts::PI * (rng.uniform() - 0.5)).tan()
}

/// Initial population of `n` individuals within `bounds` (fixed dimensions at their value).
fn initial_population(rng: &mut Rng, bounds: &[(f64, f64)], n: usize, init: Init) -> Vec<Vec<f64>> {
    let mut pop = vec![vec![0.0; bounds.len()]; n];
    for (j, &(lo, hi)) in bounds.iter().enumerate() {
        if lo == hi {
            pop.iter_mut().for_each(|x| x[j] = lo);
            continue;
        }
        match init {
            Init::Uniform => {
                for x in pop.iter_mut() {
                    x[j] = (lo + (hi - lo) * rng.uniform()).clamp(lo, hi);
                }
            }
            Init::LatinHypercube => {
                // A random permutation of the strata (Fisher-Yates).
                let mut strata: Vec<usize> = (0..n).collect();
                for i in (1..n).rev() {
                    strata.swap(i, rng.below(i + 1));
                }
                for (x, &s) in pop.iter_mut().zip(&strata) {
                    let t = (s as f64 + rng.uniform()) / n as f64;
                    x[j] = (lo + (hi - lo) * t).clamp(lo, hi);
                }
            }
        }
    }
    pop
}

/// Improvement-weighted Lehmer mean `Σ w s² / Σ w s` of `s` (weights proportional to `delta`).
fn weighted_lehmer_mean(s: &[f64], delta: &[f64]) -> f64 {
    // Improvements are > 0; an infinite one (a trial beating an infinite/NaN parent) takes all the weight.
    let w: Vec<f64> = if delta.iter().any(|d| !d.is_finite()) {
        delta
            .iter()
            .map(|d| if d.is_finite() { 0.0 } else { 1.0 })
            .collect()
    } else {
        delta.to_vec()
    };
    let num: f64 = w.iter().zip(s).map(|(w, s)| w * s * s).sum();
    let den: f64 = w.iter().zip(s).map(|(w, s)| w * s).sum();
    if den > 0.0 && den.is_finite() && num.is_finite() {
        num / den
    } else {
        // Degenerate weights: the unweighted Lehmer mean.
        let num: f64 = s.iter().map(|s| s * s).sum();
        let den: f64 = s.iter().sum();
        num / den
    }
}

/// Minimise the single objective `obj` within `bounds` with L-SHADE (or jSO, see [`LshadeConfig`]).
///
/// `callback` runs after the initial population and after every generation with the current (shrinking)
/// population; returning `false` stops the search (and skips the polish). The search also stops on the
/// budget, the generation cap, convergence or stall; [`LshadeResult::stop`] says which (checked in the
/// order callback, converged, stalled, evaluations, generations).
pub fn minimize<O, C>(
    obj: &O,
    bounds: &[(f64, f64)],
    cfg: &LshadeConfig,
    callback: C,
) -> Result<LshadeResult>
where
    O: Objective + ?Sized,
    C: FnMut(&GenerationReport) -> bool,
{
    minimize_polishing_from(obj, None::<&O>, bounds, cfg, None, callback)
}

/// [`minimize`], with the final polish on `polish_obj` where given: a finer model of the same loss (the
/// pixel footprint) that only the last digits need. The polish starts from the search's best, re-evaluated
/// on `polish_obj`; the result's value is `polish_obj`'s. With `start`, where given, as the initial
/// population's first individual (clamped to `bounds`; the others drawn as without it, from the same random
/// numbers): a search that refines a point already found (a refit with one more image term, near the light
/// found without it) then never ends worse than that point, whatever its small population draws.
pub fn minimize_polishing_from<O, P, C>(
    obj: &O,
    polish_obj: Option<&P>,
    bounds: &[(f64, f64)],
    cfg: &LshadeConfig,
    start: Option<&[f64]>,
    mut callback: C,
) -> Result<LshadeResult>
where
    O: Objective + ?Sized,
    P: Objective + ?Sized,
    C: FnMut(&GenerationReport) -> bool,
{
    check_single_objective(obj, bounds)?;
    if let Some(x0) = start {
        if x0.len() != bounds.len() || x0.iter().any(|v| !v.is_finite()) {
            return Err(Error::Invalid(format!(
                "the start needs {} finite values (got {:?})",
                bounds.len(),
                x0
            )));
        }
    }
    if let Some(p) = polish_obj {
        check_single_objective(p, bounds)?;
    }
    let dim = bounds.len();
    let free = bounds.iter().filter(|(lo, hi)| lo < hi).count();
    let n_init = cfg.initial_population(free);
    cfg.validate(n_init)?;
    let jso = cfg.variant == Variant::Jso;
    let max_evals = cfg.max_evaluations;
    let h = cfg.memory_size;

    let mut rng = Rng::new(cfg.seed);
    let mut pop = initial_population(&mut rng, bounds, n_init, cfg.init);
    if let Some(x0) = start {
        for (j, (v, &(lo, hi))) in x0.iter().zip(bounds).enumerate() {
            pop[0][j] = v.clamp(lo, hi);
        }
    }
    let mut fit = vec![vec![0.0; 1]; n_init];
    evaluate_all(obj, &pop, &mut fit, None);
    let mut evaluations = n_init;

    let mut memory_f = vec![cfg.memory_f; h];
    let mut memory_cr: Vec<Option<f64>> = vec![Some(cfg.memory_cr); h];
    // jSO keeps the last slot at 0.9 and cycles the updates over the others.
    let update_slots = if jso && h > 1 {
        memory_f[h - 1] = 0.9;
        memory_cr[h - 1] = Some(0.9);
        h - 1
    } else {
        h
    };
    let mut slot = 0usize;
    let mut archive: Vec<Vec<f64>> = Vec::new();
    let mut archive_cap = (cfg.archive_rate * n_init as f64).round() as usize;

    let mut generations = 0usize;
    let mut b = best_index(&fit);
    let mut reference_best = fit[b][0];
    let mut since_improvement = 0usize;

    let stop_check = |cb_ok: bool,
                      pop: &[Vec<f64>],
                      since_improvement: usize,
                      evaluations: usize,
                      generations: usize|
     -> Option<StopReason> {
        if !cb_ok {
            Some(StopReason::Callback)
        } else if cfg.x_tol > 0.0 && normalized_spread(pop, bounds) < cfg.x_tol {
            Some(StopReason::Converged)
        } else if cfg.stall_generations > 0 && since_improvement >= cfg.stall_generations {
            Some(StopReason::Stalled)
        } else if evaluations >= max_evals {
            Some(StopReason::MaxEvaluations)
        } else if cfg.max_generations.is_some_and(|g| generations >= g) {
            Some(StopReason::MaxGenerations)
        } else {
            None
        }
    };

    let ok = callback(&report(0, b, &pop, &fit, evaluations));
    let mut stop = stop_check(ok, &pop, 0, evaluations, 0);

    // Per-generation scratch.
    let mut trials: Vec<Vec<f64>> = Vec::new();
    let mut trial_fit: Vec<Vec<f64>> = Vec::new();
    let mut f_used: Vec<f64> = Vec::new();
    let mut cr_used: Vec<f64> = Vec::new();

    while stop.is_none() {
        let n = pop.len();
        let k = n.min(max_evals - evaluations);
        let progress = evaluations as f64 / max_evals as f64;
        let p = if jso {
            cfg.p_best * (1.0 - 0.5 * progress)
        } else {
            cfg.p_best
        };
        let n_top = ((p * n as f64).round() as usize).clamp(2, n);
        let order = ranking(&fit);

        // All random draws of the generation, serially.
        trials.resize_with(k, || vec![0.0; dim]);
        trial_fit.resize_with(k, || vec![0.0; 1]);
        f_used.clear();
        cr_used.clear();
        for (i, trial) in trials.iter_mut().enumerate() {
            let r = rng.below(h);
            let mut cr = match memory_cr[r] {
                None => 0.0,
                Some(m) => normal(&mut rng, m, 0.1).clamp(0.0, 1.0),
            };
            let mut f = loop {
                let v = cauchy(&mut rng, memory_f[r], 0.1);
                if v > 0.0 {
                    break v.min(1.0);
                }
            };
            let mut fw = f;
            if jso {
                if progress < 0.25 {
                    cr = cr.max(0.7);
                } else if progress < 0.5 {
                    cr = cr.max(0.6);
                }
                if progress < 0.6 {
                    f = f.min(0.7);
                }
                fw = f * if progress < 0.2 {
                    0.7
                } else if progress < 0.4 {
                    0.8
                } else {
                    1.2
                };
            }
            f_used.push(f);
            cr_used.push(cr);
            let pbest = order[rng.below(n_top)];
            let r1 = pick(&mut rng, n, &[i]);
            let r2 = pick(&mut rng, n + archive.len(), &[i, r1]);
            let (x, xp, x1) = (&pop[i], &pop[pbest], &pop[r1]);
            let x2 = if r2 < n { &pop[r2] } else { &archive[r2 - n] };
            let jrand = rng.below(dim.max(1));
            for j in 0..dim {
                let (lo, hi) = bounds[j];
                trial[j] = if lo == hi {
                    lo
                } else if j == jrand || rng.uniform() < cr {
                    let v = x[j] + fw * (xp[j] - x[j]) + f * (x1[j] - x2[j]);
                    // Out of bounds: half way between the parent and the violated bound.
                    let v = if v < lo {
                        0.5 * (lo + x[j])
                    } else if v > hi {
                        0.5 * (hi + x[j])
                    } else {
                        v
                    };
                    v.clamp(lo, hi)
                } else {
                    x[j]
                };
            }
        }

        // A trial only has to be exact when it beats its target (failures are discarded, and the
        // success history uses the improvements of successes only), so the objective may exit early.
        evaluate_all(obj, &trials, &mut trial_fit, Some(&fit[..k]));
        evaluations += k;

        // Selection, archive and the success history, serially.
        let mut s_f = Vec::new();
        let mut s_cr = Vec::new();
        let mut s_delta = Vec::new();
        for i in 0..k {
            let (tf, pf) = (trial_fit[i][0], fit[i][0]);
            if tf <= pf {
                std::mem::swap(&mut pop[i], &mut trials[i]);
                std::mem::swap(&mut fit[i], &mut trial_fit[i]);
                if tf < pf {
                    // trials[i] now holds the replaced parent.
                    if archive_cap > 0 {
                        if archive.len() < archive_cap {
                            archive.push(trials[i].clone());
                        } else {
                            let r = rng.below(archive.len());
                            archive[r].clone_from(&trials[i]);
                        }
                    }
                    s_f.push(f_used[i]);
                    s_cr.push(cr_used[i]);
                    s_delta.push(pf - tf);
                }
            }
        }
        if !s_f.is_empty() {
            let mean_f = weighted_lehmer_mean(&s_f, &s_delta);
            let max_cr = s_cr.iter().copied().fold(0.0, f64::max);
            let new_cr = match memory_cr[slot] {
                Some(old) if max_cr > 0.0 => {
                    let m = weighted_lehmer_mean(&s_cr, &s_delta);
                    Some(if jso { 0.5 * (m + old) } else { m })
                }
                _ => None,
            };
            memory_f[slot] = if jso {
                0.5 * (mean_f + memory_f[slot])
            } else {
                mean_f
            };
            memory_cr[slot] = new_cr;
            slot = (slot + 1) % update_slots;
        }
        generations += 1;

        // Linear population size reduction.
        let planned = n_init as f64
            + (cfg.min_population as f64 - n_init as f64) * evaluations as f64 / max_evals as f64;
        let n_new = (planned.round() as usize).clamp(cfg.min_population, n);
        if n_new < n {
            let order = ranking(&fit);
            let mut keep = vec![false; n];
            for &i in &order[..n_new] {
                keep[i] = true;
            }
            let mut it = keep.iter();
            pop.retain(|_| *it.next().unwrap());
            let mut it = keep.iter();
            fit.retain(|_| *it.next().unwrap());
            archive_cap = (cfg.archive_rate * n_new as f64).round() as usize;
            while archive.len() > archive_cap {
                let r = rng.below(archive.len());
                archive.swap_remove(r);
            }
        }

        b = best_index(&fit);
        if fit[b][0] < reference_best - cfg.stall_tol {
            reference_best = fit[b][0];
            since_improvement = 0;
        } else {
            since_improvement += 1;
        }
        let ok = callback(&report(generations, b, &pop, &fit, evaluations));
        stop = stop_check(ok, &pop, since_improvement, evaluations, generations);
    }
    let stop = stop.expect("the loop ends with a reason");

    let mut best = pop[b].clone();
    let mut best_f = fit[b][0];
    let mut polish = None;
    if cfg.polish_evaluations > 0 && stop != StopReason::Callback {
        let step: Vec<f64> = normalized_spreads(&pop, bounds)
            .into_iter()
            .map(|s| s.clamp(1e-8, 0.1))
            .collect();
        // The polish on `polish_obj` starts from its own value at the search's best (one evaluation).
        fn polish_on<Q: Objective + ?Sized>(
            q: &Q,
            bounds: &[(f64, f64)],
            x0: &[f64],
            f0: f64,
            step: &[f64],
            cfg: &LshadeConfig,
        ) -> Result<super::nelder_mead::NelderMeadResult> {
            nelder_mead(
                q,
                bounds,
                x0,
                f0,
                step,
                cfg.polish_evaluations,
                cfg.polish_x_tol,
            )
        }
        let nm = match polish_obj {
            None => polish_on(obj, bounds, &best, best_f, &step, cfg)?,
            Some(p) => {
                let mut o = [0.0];
                p.evaluate_alone(&best, &mut o);
                best_f = if o[0].is_nan() { f64::INFINITY } else { o[0] };
                evaluations += 1;
                polish_on(p, bounds, &best, best_f, &step, cfg)?
            }
        };
        evaluations += nm.evaluations;
        let f_before = best_f;
        if nm.f < best_f {
            best = nm.x;
            best_f = nm.f;
        }
        polish = Some(PolishReport {
            evaluations: nm.evaluations,
            f_before,
            f_after: best_f,
            improvement: if best_f < f_before {
                f_before - best_f
            } else {
                0.0
            },
            converged: nm.converged,
        });
    }

    Ok(LshadeResult {
        search: SearchResult {
            best,
            best_objectives: vec![best_f],
            evaluations,
            generations,
            stop,
            population: pop.len(),
            polish,
        },
        memory_f,
        memory_cr,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lehmer_mean_weights_and_degenerate_cases() {
        // Equal weights: Σs²/Σs.
        assert!((weighted_lehmer_mean(&[0.2, 0.4], &[1.0, 1.0]) - 0.2 / 0.6).abs() < 1e-15);
        // All weight on one value.
        assert_eq!(weighted_lehmer_mean(&[0.2, 0.4], &[0.0, 3.0]), 0.4);
        // An infinite improvement takes all the weight instead of giving NaN.
        let m = weighted_lehmer_mean(&[0.2, 0.4], &[f64::INFINITY, 1.0]);
        assert!((m - 0.2).abs() < 1e-15, "{m}");
    }

    #[test]
    fn latin_hypercube_has_one_point_per_stratum() {
        let mut rng = Rng::new(3);
        let bounds = [(-1.0, 3.0), (2.0, 2.0), (0.0, 1e-3)];
        let n = 17;
        let pop = initial_population(&mut rng, &bounds, n, Init::LatinHypercube);
        for (j, &(lo, hi)) in bounds.iter().enumerate() {
            if lo == hi {
                assert!(pop.iter().all(|x| x[j] == lo));
                continue;
            }
            let mut seen = vec![0; n];
            for x in &pop {
                assert!(lo <= x[j] && x[j] <= hi);
                let s = (((x[j] - lo) / (hi - lo)) * n as f64).floor() as usize;
                seen[s.min(n - 1)] += 1;
            }
            assert!(seen.iter().all(|&c| c == 1), "dimension {j}: {seen:?}");
        }
    }

    #[test]
    fn samplers_have_the_right_location() {
        let mut rng = Rng::new(11);
        let m = 20_000;
        let mean = (0..m).map(|_| normal(&mut rng, 0.5, 0.1)).sum::<f64>() / m as f64;
        assert!((mean - 0.5).abs() < 0.005, "{mean}");
        let mut c: Vec<f64> = (0..m).map(|_| cauchy(&mut rng, 0.5, 0.1)).collect();
        c.sort_by(f64::total_cmp);
        let median = c[m / 2];
        let q1 = c[m / 4];
        assert!((median - 0.5).abs() < 0.01, "{median}");
        // The Cauchy quartiles are loc ± scale.
        assert!((q1 - 0.4).abs() < 0.01, "{q1}");
    }
}
