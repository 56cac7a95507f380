//! Bounded Nelder–Mead with adaptive coefficients: the local polish of a search's best point.

use rayon::prelude::*;

use super::{check_single_objective, Objective};
use crate::error::{Error, Result};

/// Result of [`nelder_mead`].
#[derive(Clone, Debug)]
pub struct NelderMeadResult {
    /// The best point seen (`x0` itself, bit for bit, when nothing beat `f0`).
    pub x: Vec<f64>,
    pub f: f64,
    pub evaluations: usize,
    /// The simplex shrank below `x_tol` before the budget was spent.
    pub converged: bool,
}

struct Vertex {
    /// Normalised coordinates of the free dimensions, in [0, 1].
    t: Vec<f64>,
    x: Vec<f64>,
    f: f64,
}

/// Bounded Nelder–Mead from `x0` (whose value `f0` is known), with the adaptive coefficients of Gao & Han
/// (2012): reflection 1, expansion 1 + 2/n, contraction 0.75 − 1/(2n), shrink 1 − 1/n for n free
/// dimensions.
///
/// The search runs in normalised coordinates `t = (x − lo) / (hi − lo)` of the free dimensions; every
/// point is clamped to the box before it is evaluated (fixed dimensions keep `x0`'s value). The initial
/// simplex is `x0` plus `step[j]` (a fraction of the range) along each free dimension `j` (minus, where
/// plus would leave the box). It stops after `max_evaluations` evaluations or when every vertex lies
/// within `x_tol` (normalised, per dimension) of the best. The initial simplex and shrink steps are
/// evaluated in parallel; the result does not depend on the number of threads.
pub fn nelder_mead<O: Objective + ?Sized>(
    obj: &O,
    bounds: &[(f64, f64)],
    x0: &[f64],
    f0: f64,
    step: &[f64],
    max_evaluations: usize,
    x_tol: f64,
) -> Result<NelderMeadResult> {
    check_single_objective(obj, bounds)?;
    if x0.len() != bounds.len() || step.len() != bounds.len() {
        return Err(Error::Invalid(format!(
            "x0 and step need {} values (got {} and {})",
            bounds.len(),
            x0.len(),
            step.len()
        )));
    }
    let free: Vec<usize> = (0..bounds.len())
        .filter(|&j| bounds[j].0 < bounds[j].1)
        .collect();
    let n = free.len();
    let f0 = if f0.is_nan() { f64::INFINITY } else { f0 };
    let to_x = |t: &[f64]| -> Vec<f64> {
        let mut x = x0.to_vec();
        for (k, &j) in free.iter().enumerate() {
            let (lo, hi) = bounds[j];
            x[j] = (lo + (hi - lo) * t[k]).clamp(lo, hi);
        }
        x
    };
    let eval = |x: &[f64]| {
        let mut o = [0.0];
        obj.evaluate_alone(x, &mut o);
        if o[0].is_nan() {
            f64::INFINITY
        } else {
            o[0]
        }
    };
    let make = |t: Vec<f64>| {
        let t: Vec<f64> = t.into_iter().map(|v| v.clamp(0.0, 1.0)).collect();
        let x = to_x(&t);
        Vertex { t, x, f: 0.0 }
    };
    let evaluate_batch = |vs: &mut [Vertex]| {
        vs.par_iter_mut().for_each(|v| v.f = eval(&v.x));
    };

    let t0: Vec<f64> = free
        .iter()
        .map(|&j| {
            let (lo, hi) = bounds[j];
            ((x0[j] - lo) / (hi - lo)).clamp(0.0, 1.0)
        })
        .collect();
    let mut simplex = vec![Vertex {
        t: t0.clone(),
        x: x0.to_vec(),
        f: f0,
    }];
    let mut evaluations = 0usize;
    if n == 0 || max_evaluations == 0 {
        return Ok(NelderMeadResult {
            x: x0.to_vec(),
            f: f0,
            evaluations,
            converged: n == 0,
        });
    }
    let mut initial: Vec<Vertex> = free
        .iter()
        .enumerate()
        .take(max_evaluations)
        .map(|(k, &j)| {
            let s = if step[j].is_finite() && step[j] > 0.0 {
                step[j].min(0.5)
            } else {
                0.05
            };
            let mut t = t0.clone();
            t[k] = if t0[k] + s <= 1.0 {
                t0[k] + s
            } else {
                t0[k] - s
            };
            make(t)
        })
        .collect();
    evaluate_batch(&mut initial);
    evaluations += initial.len();
    simplex.extend(initial);
    let mut converged = false;

    if simplex.len() == n + 1 {
        let nf = n as f64;
        let (alpha, beta, gamma, delta) = (1.0, 1.0 + 2.0 / nf, 0.75 - 0.5 / nf, 1.0 - 1.0 / nf);
        // Points along the line from the centroid `c` through the worst vertex: c + coef (c - worst).
        let along = |c: &[f64], w: &[f64], coef: f64| -> Vec<f64> {
            c.iter().zip(w).map(|(c, w)| c + coef * (c - w)).collect()
        };
        loop {
            simplex.sort_by(|a, b| a.f.total_cmp(&b.f));
            let spread = simplex[1..]
                .iter()
                .flat_map(|v| v.t.iter().zip(&simplex[0].t).map(|(a, b)| (a - b).abs()))
                .fold(0.0, f64::max);
            if spread <= x_tol {
                converged = true;
                break;
            }
            if evaluations >= max_evaluations {
                break;
            }
            let mut c = vec![0.0; n];
            for v in &simplex[..n] {
                for (c, t) in c.iter_mut().zip(&v.t) {
                    *c += t / nf;
                }
            }
            let worst_t = simplex[n].t.clone();
            let (f_best, f_second, f_worst) = (simplex[0].f, simplex[n - 1].f, simplex[n].f);
            let mut r = make(along(&c, &worst_t, alpha));
            r.f = eval(&r.x);
            evaluations += 1;
            let mut shrink = false;
            if r.f < f_best {
                if evaluations < max_evaluations {
                    let mut e = make(along(&c, &worst_t, alpha * beta));
                    e.f = eval(&e.x);
                    evaluations += 1;
                    simplex[n] = if e.f < r.f { e } else { r };
                } else {
                    simplex[n] = r;
                }
            } else if r.f < f_second {
                simplex[n] = r;
            } else if evaluations >= max_evaluations {
                if r.f < f_worst {
                    simplex[n] = r;
                }
            } else if r.f < f_worst {
                // Outside contraction.
                let mut oc = make(along(&c, &worst_t, alpha * gamma));
                oc.f = eval(&oc.x);
                evaluations += 1;
                if oc.f <= r.f {
                    simplex[n] = oc;
                } else {
                    simplex[n] = r;
                    shrink = true;
                }
            } else {
                // Inside contraction.
                let mut ic = make(along(&c, &worst_t, -gamma));
                ic.f = eval(&ic.x);
                evaluations += 1;
                if ic.f < f_worst {
                    simplex[n] = ic;
                } else {
                    shrink = true;
                }
            }
            if shrink && evaluations < max_evaluations {
                let best_t = simplex[0].t.clone();
                let take = n.min(max_evaluations - evaluations);
                let mut shrunk: Vec<Vertex> = simplex[1..=take]
                    .iter()
                    .map(|v| {
                        make(
                            best_t
                                .iter()
                                .zip(&v.t)
                                .map(|(b, t)| b + delta * (t - b))
                                .collect(),
                        )
                    })
                    .collect();
                evaluate_batch(&mut shrunk);
                evaluations += take;
                for (k, v) in shrunk.into_iter().enumerate() {
                    simplex[1 + k] = v;
                }
            }
        }
    }
    let best = simplex
        .into_iter()
        .min_by(|a, b| a.f.total_cmp(&b.f))
        .expect("simplex is never empty");
    Ok(NelderMeadResult {
        x: best.x,
        f: best.f,
        evaluations,
        converged,
    })
}
