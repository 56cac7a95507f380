//! Test hooks for the optimisers, only with the `test-hooks` feature (the wheel does not build it): the
//! extension module `_rtloop_test_hooks` runs L-SHADE, jSO or the paper's DE/rand/1/bin on a standard
//! test function from Python (`tests/test_de_scipy.py` compares them with SciPy; `.ci/build-test-hooks`
//! builds it). Conversions only.

use pyo3::prelude::*;
use pyo3::types::PyDict;

use super::errors::RtloopError;
use super::pool::detach_in_pool;
use crate::error::Error;
use crate::search::{lshade, nelder_mead, normalized_spreads, rand1bin};
use crate::search::{DeConfig, Init, LshadeConfig};

#[path = "../../tests/common/test_functions.rs"]
mod test_functions;

#[pymodule(gil_used = false)]
fn _rtloop_test_hooks(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(minimize_test_function, m)?)?;
    m.add_function(wrap_pyfunction!(test_function_value, m)?)?;
    m.add("RtloopError", m.py().get_type::<RtloopError>())?;
    Ok(())
}

/// Minimise the test function `name` (sphere, rosenbrock, rastrigin, ackley, griewank; minimum 0) in
/// `dim` dimensions on the box [lo, hi]^dim.
///
/// `method`: "lshade", "jso" (both from `rtloop::search::lshade`) or "de" (the paper's DE/rand/1/bin, F 0.6,
/// CR 0.8, run for `max_evaluations // population - 1` generations). `polish`: Nelder–Mead evaluation
/// budget after the evolution (0: none). `population`: L-SHADE's initial population (default 18 D) or
/// DE's population (default 60). `x_tol`, `stall_generations`: the stopping rules of `LshadeConfig`
/// (defaults 1e-9 and 0 = off; `x_tol` applies to "de" too, through its callback). Returns a dict with
/// `x`, `f`, `evaluations` (polish included), `generations`, `stop_reason`, `population` (final size),
/// `polish_evaluations`, `polish_improvement` and `history` (best value after every generation).
#[pyfunction]
#[pyo3(signature = (name, dim, lo, hi, *, method="lshade", max_evaluations=10_000, seed=0, polish=0,
                    population=None, x_tol=None, stall_generations=0, init="lhs", threads=None))]
#[allow(clippy::too_many_arguments)]
fn minimize_test_function<'py>(
    py: Python<'py>,
    name: &str,
    dim: usize,
    lo: f64,
    hi: f64,
    method: &str,
    max_evaluations: usize,
    seed: u64,
    polish: usize,
    population: Option<usize>,
    x_tol: Option<f64>,
    stall_generations: usize,
    init: &str,
    threads: Option<usize>,
) -> PyResult<Bound<'py, PyDict>> {
    let f = test_functions::by_name(name).ok_or_else(|| {
        Error::Value(format!(
            "unknown test function {name:?} (known: {})",
            test_functions::NAMES.join(", ")
        ))
    })?;
    if dim == 0 {
        return Err(Error::Value("dim must be >= 1".into()).into());
    }
    let init = match init {
        "lhs" => Init::LatinHypercube,
        "uniform" => Init::Uniform,
        _ => {
            return Err(Error::Value(format!(
                "init must be \"lhs\" or \"uniform\" (got {init:?})"
            ))
            .into())
        }
    };
    let bounds = vec![(lo, hi); dim];
    let x_tol = x_tol.unwrap_or(LshadeConfig::default().x_tol);
    let mut history: Vec<f64> = Vec::new();

    struct Out {
        x: Vec<f64>,
        f: f64,
        evaluations: usize,
        generations: usize,
        stop: &'static str,
        population: usize,
        polish_evaluations: usize,
        polish_improvement: f64,
    }

    let out: Out = match method {
        "lshade" | "jso" => {
            let cfg = LshadeConfig {
                max_evaluations,
                population_init: population,
                x_tol,
                stall_generations,
                polish_evaluations: polish,
                init,
                seed,
                ..if method == "jso" {
                    LshadeConfig::jso()
                } else {
                    LshadeConfig::lshade()
                }
            };
            let r = detach_in_pool(py, threads, || {
                lshade::minimize(&f, &bounds, &cfg, |rep| {
                    history.push(rep.best_objectives[0]);
                    true
                })
            })??
            .search;
            let (pe, pi) = r
                .polish
                .as_ref()
                .map_or((0, 0.0), |p| (p.evaluations, p.improvement));
            Out {
                f: r.best_objectives[0],
                x: r.best,
                evaluations: r.evaluations,
                generations: r.generations,
                stop: r.stop.as_str(),
                population: r.population,
                polish_evaluations: pe,
                polish_improvement: pi,
            }
        }
        "de" => {
            let np = population.unwrap_or(60);
            if max_evaluations < np {
                return Err(Error::Value(format!(
                    "max_evaluations ({max_evaluations}) must cover the population ({np})"
                ))
                .into());
            }
            let cfg = DeConfig {
                population: np,
                generations: max_evaluations / np - 1,
                seed,
                ..DeConfig::default()
            };
            let mut spread = vec![0.0; dim];
            let mut converged = false;
            let r = detach_in_pool(py, threads, || {
                rand1bin::minimize(&f, &bounds, &cfg, |rep| {
                    history.push(rep.best_objectives[0]);
                    spread = normalized_spreads(rep.population, &bounds);
                    converged = x_tol > 0.0 && spread.iter().all(|&s| s < x_tol);
                    !converged
                })
            })??;
            let mut out = Out {
                x: r.best.clone(),
                f: r.best_objectives[0],
                evaluations: r.evaluations,
                generations: r.generations,
                stop: if converged {
                    "converged"
                } else {
                    "max_generations"
                },
                population: np,
                polish_evaluations: 0,
                polish_improvement: 0.0,
            };
            if polish > 0 {
                let step: Vec<f64> = spread.iter().map(|s| s.clamp(1e-8, 0.1)).collect();
                let nm = detach_in_pool(py, threads, || {
                    nelder_mead(
                        &f,
                        &bounds,
                        &r.best,
                        out.f,
                        &step,
                        polish,
                        LshadeConfig::default().polish_x_tol,
                    )
                })??;
                out.evaluations += nm.evaluations;
                out.polish_evaluations = nm.evaluations;
                if nm.f < out.f {
                    out.polish_improvement = out.f - nm.f;
                    out.x = nm.x;
                    out.f = nm.f;
                }
            }
            out
        }
        _ => {
            return Err(Error::Value(format!(
                "method must be \"lshade\", \"jso\" or \"de\" (got {method:?})"
            ))
            .into())
        }
    };
    let d = PyDict::new(py);
    d.set_item("x", out.x)?;
    d.set_item("f", out.f)?;
    d.set_item("evaluations", out.evaluations)?;
    d.set_item("generations", out.generations)?;
    d.set_item("stop_reason", out.stop)?;
    d.set_item("population", out.population)?;
    d.set_item("polish_evaluations", out.polish_evaluations)?;
    d.set_item("polish_improvement", out.polish_improvement)?;
    d.set_item("history", history)?;
    Ok(d)
}

/// The value of the test function `name` at `x` (to check the Rust definitions against NumPy's).
#[pyfunction]
fn test_function_value(name: &str, x: Vec<f64>) -> PyResult<f64> {
    let f = test_functions::by_name(name)
        .ok_or_else(|| Error::Value(format!("unknown test function {name:?}")))?;
    Ok(f(&x))
}
