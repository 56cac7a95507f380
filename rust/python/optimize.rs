//! `evaluate`, `optimize` and `held_out`: the fitness's values, the search stage by stage and the
//! held-out losses, each of the fitness a `FitnessSpec` describes.

use numpy::{
    PyArray1, PyArray2, PyArrayMethods, PyReadonlyArray1, PyReadonlyArray2, PyReadonlyArray3,
};
use pyo3::prelude::*;

use super::fitness::{Generation, OptimizeResult};
use super::pool::detach_in_pool;
use super::scene::PyScene;
use super::spec::PyFitnessSpec;
use crate::error::Error;
use crate::fit::{run_passes, PassOptions};
use crate::fitness::LossKind;
use crate::search::{Budget, Method, Objective};

/// Objective values of each row of `population` (N, D) for the fitness `spec` (a `FitnessSpec`):
/// float64 (N, n_objectives). With interreflection and the projected loss, a spec whose
/// `frozen_bounce` is >= 1 holds the bounce at the scene's own values (`Fitness::freeze_bounce`), as
/// `optimize`'s first pass ranks lights.
#[pyfunction]
#[pyo3(signature = (scene, target, population, spec, threads=None))]
pub(super) fn evaluate<'py>(
    py: Python<'py>,
    scene: &Bound<'py, PyScene>,
    target: PyReadonlyArray3<'py, f32>,
    population: PyReadonlyArray2<'py, f64>,
    spec: &Bound<'py, PyFitnessSpec>,
    threads: Option<usize>,
) -> PyResult<Bound<'py, PyArray2<f64>>> {
    use rayon::prelude::*;
    let scene = &scene.get().0;
    let spec = spec.get();
    let args = spec.args(scene, &target)?;
    let frozen_bounce = spec.frozen_bounce_passes() > 0;
    let pop = population.as_array();
    parameters_match(pop.ncols(), args.layout.bounds.len(), || {
        format!("population has {} columns", pop.ncols())
    })?;
    let rows: Vec<Vec<f64>> = pop.rows().into_iter().map(|r| r.to_vec()).collect();
    let out = detach_in_pool(py, threads, || {
        let mut fitness = args.build(scene)?;
        if frozen_bounce {
            fitness.freeze_bounce(None);
        }
        let nobj = fitness.n_objectives();
        let mut out = vec![0.0; rows.len() * nobj];
        out.par_chunks_mut(nobj)
            .zip(rows.par_iter())
            .for_each(|(o, x)| fitness.evaluate(x, o));
        Ok::<_, crate::error::Error>((out, nobj))
    })??;
    let (out, nobj) = out;
    PyArray1::from_vec(py, out).reshape([rows.len(), nobj])
}

/// An error "`what()`; `want` parameters" unless `got` == `want`.
fn parameters_match(got: usize, want: usize, what: impl FnOnce() -> String) -> PyResult<()> {
    if got != want {
        return Err(Error::Value(format!("{}; {want} parameters", what())).into());
    }
    Ok(())
}

/// Search the fitness `spec` (a `FitnessSpec`) of `target` with DE/rand/1/bin (`method="de"`) or L-SHADE
/// (`"lshade"`, optionally followed by a Nelder-Mead `polish`). One call per stage; the GIL is released
/// except while `callback(generation, best, best_objectives, evaluations, products)` runs, after the
/// initial population and after every generation (returning False stops the search). `products` are the
/// closed-form products of the best for the projected loss when `with_products` (one row per object:
/// [P_r, P_g, P_b, Q], Q = intensity x specular), else None. In the "srgb" space the closed-form products
/// stay least squares in linear space, and the reported `products` minimise the sRGB-space loss.
/// `polish_tol`: the polish stops once its simplex spans less than this fraction of every range
/// (default 1e-13). The spec's `footprint`: the pixel footprint in the whole search; `polish_footprint`:
/// in the polish (and the products and loss reported) only. The spec's `frozen_bounce`: with
/// interreflection, N >= 1 ranks lights with the bounce held at the scene's own values
/// (`Fitness::freeze_bounce`; each evaluation then costs a direct one's), the result's products and loss
/// are the full bounce's at the found light; N > 1 adds up to N - 1 passes, each holding the bounce at
/// the light the previous found and polishing from there, a third and later one only while the previous
/// pass moved the light (the held bounce's fixed point; `fit::PassOptions::passes`).
/// `x0`: a point (one value per searched parameter, clamped to their bounds) that L-SHADE's initial
/// population holds, so that a search refining it never ends worse than it (method "lshade" only).
/// `silhouettes` (with the footprint): "on" integrates the outline pixels in every footprint evaluation
/// (`FitnessSpec::outlines`); "auto" (with `polish_footprint`) only where the outline gate finds the photo
/// needs it (`fit::outlines`; its evidence `OptimizeResult.outlines`); "off": outlines at pixel centres.
/// Returns an `OptimizeResult`.
#[pyfunction]
#[pyo3(signature = (scene, target, spec, *, population=60, generations=200, f=0.6, cr=0.8, seed=0,
                    method="de", max_evaluations=None, polish=0, polish_tol=None,
                    polish_footprint=false, with_products=true, x0=None, callback=None, threads=None,
                    silhouettes="off"))]
#[allow(clippy::too_many_arguments)]
pub(super) fn optimize<'py>(
    py: Python<'py>,
    scene: &Bound<'py, PyScene>,
    target: PyReadonlyArray3<'py, f32>,
    spec: &Bound<'py, PyFitnessSpec>,
    population: usize,
    generations: usize,
    f: f64,
    cr: f64,
    seed: u64,
    method: &str,
    max_evaluations: Option<usize>,
    polish: usize,
    polish_tol: Option<f64>,
    polish_footprint: bool,
    with_products: bool,
    x0: Option<Vec<f64>>,
    callback: Option<Py<PyAny>>,
    threads: Option<usize>,
    silhouettes: &str,
) -> PyResult<OptimizeResult> {
    let scene = &scene.get().0;
    let spec = spec.get();
    let (outlines, outline_gate) = match silhouettes {
        "off" => (false, false),
        "auto" => (false, true),
        "on" => (true, false),
        other => {
            let msg = format!("silhouettes: must be 'auto', 'on' or 'off' (got {other:?})");
            return Err(Error::Invalid(msg).into());
        }
    };
    let mut args = spec.args(scene, &target)?;
    args.spec.outlines = outlines;
    let budget = Budget {
        population,
        generations,
        f,
        cr,
        seed,
        max_evaluations,
        polish,
        polish_tol,
    };
    let options = PassOptions {
        outline_gate,
        passes: spec.frozen_bounce_passes(),
        polish_footprint,
        start: x0,
        with_products: with_products && callback.is_some(),
    };
    let mut error: Option<PyErr> = None;
    let mut history = Vec::new();
    let result = detach_in_pool(py, threads, || {
        let method = Method::named(method, &budget)?;
        run_passes(
            scene,
            args.layout,
            &args.target,
            args.spec,
            &method,
            &options,
            |rep| {
                history.push(Generation {
                    generation: rep.generation,
                    best: rep.best.to_vec(),
                    objectives: rep.best_objectives.to_vec(),
                    evaluations: rep.evaluations,
                });
                let Some(cb) = &callback else { return true };
                let products: Option<Vec<Vec<f64>>> = rep
                    .products
                    .as_ref()
                    .map(|rows| rows.iter().map(|r| r.to_vec()).collect());
                Python::attach(|py| {
                    let best = PyArray1::from_slice(py, rep.best);
                    let objectives = rep.best_objectives.to_vec();
                    match cb.call1(
                        py,
                        (rep.generation, best, objectives, rep.evaluations, products),
                    ) {
                        Ok(v) => !v.bind(py).is(&*pyo3::types::PyBool::new(py, false)),
                        Err(e) => {
                            error = Some(e);
                            false
                        }
                    }
                })
            },
        )
    })??;
    if let Some(e) = error {
        return Err(e);
    }
    Ok(OptimizeResult { result, history })
}

/// Held-out losses of the closed form of `target` at the light `x` (one value per parameter of the spec's
/// paths): the spec's pixels (default all) split into folds by `folds` (uint8, one label per pixel;
/// labels 0..K-1), and per fold the loss of its pixels at the products solved on the other folds'
/// pixels, in the spec's norm and space (`Fitness::held_out`). The spec's loss must be "l1_projected".
/// `refine`: the products minimise the fit's own loss on those pixels, else least squares (a bounce's
/// fixed point as `evaluate` solves it, held where the spec's `frozen_bounce` holds it). Returns float64
/// (K, 2): per fold the held-out loss and its number of pixels (the fixed background's left out).
#[pyfunction]
#[pyo3(signature = (scene, target, x, folds, spec, threads=None, refine=true))]
#[allow(clippy::too_many_arguments)]
pub(super) fn held_out<'py>(
    py: Python<'py>,
    scene: &Bound<'py, PyScene>,
    target: PyReadonlyArray3<'py, f32>,
    x: PyReadonlyArray1<'py, f64>,
    folds: PyReadonlyArray1<'py, u8>,
    spec: &Bound<'py, PyFitnessSpec>,
    threads: Option<usize>,
    refine: bool,
) -> PyResult<Bound<'py, PyArray2<f64>>> {
    let scene = &scene.get().0;
    let spec = spec.get();
    if spec.loss_kind() != LossKind::L1Projected {
        let msg = "spec: held-out losses need the projected loss (loss=\"l1_projected\")";
        return Err(Error::Invalid(msg.into()).into());
    }
    let n = (scene.width * scene.height) as usize;
    let chosen: Vec<u32> = match spec.pixels() {
        Some(p) => p.to_vec(),
        None => (0..n as u32).collect(),
    };
    let labels = folds.as_slice()?;
    if labels.len() != chosen.len() {
        return Err(Error::Value(format!(
            "folds has {} labels; pixels has {} (one label per pixel)",
            labels.len(),
            chosen.len()
        ))
        .into());
    }
    if labels.contains(&u8::MAX) {
        return Err(Error::Value("folds: labels must be below 255".into()).into());
    }
    let count = labels.iter().map(|&l| l as usize + 1).max().unwrap_or(0);
    let args = spec.args(scene, &target)?;
    let frozen_bounce = spec.frozen_bounce_passes() > 0;
    let x = x.as_slice()?.to_vec();
    parameters_match(x.len(), args.layout.bounds.len(), || {
        format!("x has {} values", x.len())
    })?;
    let mut dense = vec![u8::MAX; n];
    for (&p, &l) in chosen.iter().zip(labels) {
        if let Some(d) = dense.get_mut(p as usize) {
            *d = l;
        }
    }
    let out = detach_in_pool(py, threads, || {
        let mut fitness = args.build(scene)?;
        if frozen_bounce {
            fitness.freeze_bounce(None);
        }
        fitness.held_out(&x, &dense, count, refine)
    })??;
    let flat: Vec<f64> = out.iter().flat_map(|h| [h.loss, h.pixels as f64]).collect();
    PyArray1::from_vec(py, flat).reshape([count, 2])
}
