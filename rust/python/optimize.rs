//! `evaluate` and `optimize`: the fitness's values and the search, stage by stage.

use numpy::{
    PyArray1, PyArray2, PyArrayMethods, PyReadonlyArray1, PyReadonlyArray2, PyReadonlyArray3,
};
use pyo3::prelude::*;

use super::fitness::{fitness_args, Generation, OptimizeResult};
use super::pool::detach_in_pool;
use super::scene::PyScene;
use crate::error::Error;
use crate::fit::{run_passes, PassOptions};
use crate::search::{Budget, Method, Objective};

/// Objective values of each row of `population` (N, D): float64 (N, n_objectives). `norm` is the
/// per-pixel penalty ("l1", "l2", "huber", "huber:H"), `space` where it compares values ("linear" or
/// "srgb": the sRGB encodings of the clipped model and of the objective). `frozen_bounce`: with
/// interreflection and the projected loss, the bounce held at the scene's own values
/// (`Fitness::freeze_bounce`), as `optimize`'s first pass ranks lights.
#[pyfunction]
#[pyo3(signature = (scene, paths, target, population, pixels=None, loss="l1", clip=true, threads=None,
                    product_bounds=None, norm="l1", space="linear", footprint=false,
                    frozen_bounce=false, saturated=None, solve_margin=0))]
#[allow(clippy::too_many_arguments)]
pub(super) fn evaluate<'py>(
    py: Python<'py>,
    scene: &Bound<'py, PyScene>,
    paths: Vec<String>,
    target: PyReadonlyArray3<'py, f32>,
    population: PyReadonlyArray2<'py, f64>,
    pixels: Option<PyReadonlyArray1<'py, u32>>,
    loss: &str,
    clip: bool,
    threads: Option<usize>,
    product_bounds: Option<PyReadonlyArray3<'py, f64>>,
    norm: &str,
    space: &str,
    footprint: bool,
    frozen_bounce: bool,
    saturated: Option<f32>,
    solve_margin: usize,
) -> PyResult<Bound<'py, PyArray2<f64>>> {
    use rayon::prelude::*;
    let scene = &scene.get().0;
    let args = fitness_args(
        scene,
        &paths,
        &target,
        pixels,
        loss,
        clip,
        product_bounds,
        norm,
        space,
        footprint,
        saturated,
        solve_margin,
    )?;
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

/// Search the fitness of `paths` against `target` with DE/rand/1/bin (`method="de"`) or L-SHADE
/// (`"lshade"`, optionally followed by a Nelder-Mead `polish`). One call per stage; the GIL is released
/// except while `callback(generation, best, best_objectives, evaluations, products)` runs, after the
/// initial population and after every generation (returning False stops the search). `products` are the
/// closed-form products of the best for the projected loss when `with_products` (one row per object:
/// [P_r, P_g, P_b, Q], Q = intensity x specular), else None. `product_bounds` is (objects, 3, 2), or
/// (objects, 4, 2) with row 4 bounding Q for objects with a specular term. `norm` and `space` as for
/// `evaluate`; in "srgb" the closed-form products stay least squares in linear space, and the reported
/// `products` minimise the sRGB-space loss. `polish_tol`: the polish stops once its simplex spans less
/// than this fraction of every range (default 1e-13). `footprint`: the pixel footprint in the whole
/// search; `polish_footprint`: in the polish (and the products and loss reported) only. `frozen_bounce`:
/// with interreflection, the search
/// ranks lights with the bounce held at the scene's own values (`Fitness::freeze_bounce`; each evaluation
/// then costs a direct one's), the result's products and loss are the full bounce's at the found light;
/// `frozen_bounce=N` > 1 adds up to N - 1 passes, each holding the bounce at the light the previous found and
/// polishing from there, a third and later one only while the previous pass moved the light (the held
/// bounce's fixed point; `fit::PassOptions::passes`).
/// `x0`: a point (one value per searched parameter, clamped to their bounds) that L-SHADE's initial
/// population holds, so that a search refining it never ends worse than it (method "lshade" only).
/// `silhouettes` (with the footprint): "on" integrates the outline pixels over their area in every
/// footprint evaluation (`FitnessSpec::outlines`); "auto" (with `polish_footprint`) only where the
/// outline gate finds the photo needs it (`fit::outlines`; its evidence `OptimizeResult.outlines`); "off":
/// outlines at pixel centres.
/// Returns an `OptimizeResult`.
#[pyfunction]
#[pyo3(signature = (scene, paths, target, *, pixels=None, loss="l1", clip=true, population=60,
                    generations=200, f=0.6, cr=0.8, seed=0, threads=None, callback=None,
                    product_bounds=None, method="de", max_evaluations=None, polish=0, norm="l1",
                    with_products=true, space="linear", polish_tol=None, footprint=false,
                    polish_footprint=false, frozen_bounce=0, saturated=None, solve_margin=0, x0=None,
                    silhouettes="off"))]
#[allow(clippy::too_many_arguments)]
pub(super) fn optimize<'py>(
    py: Python<'py>,
    scene: &Bound<'py, PyScene>,
    paths: Vec<String>,
    target: PyReadonlyArray3<'py, f32>,
    pixels: Option<PyReadonlyArray1<'py, u32>>,
    loss: &str,
    clip: bool,
    population: usize,
    generations: usize,
    f: f64,
    cr: f64,
    seed: u64,
    threads: Option<usize>,
    callback: Option<Py<PyAny>>,
    product_bounds: Option<PyReadonlyArray3<'py, f64>>,
    method: &str,
    max_evaluations: Option<usize>,
    polish: usize,
    norm: &str,
    with_products: bool,
    space: &str,
    polish_tol: Option<f64>,
    footprint: bool,
    polish_footprint: bool,
    frozen_bounce: usize,
    saturated: Option<f32>,
    solve_margin: usize,
    x0: Option<Vec<f64>>,
    silhouettes: &str,
) -> PyResult<OptimizeResult> {
    let scene = &scene.get().0;
    let (outlines, outline_gate) = match silhouettes {
        "off" => (false, false),
        "auto" => (false, true),
        "on" => (true, false),
        other => {
            return Err(Error::Value(format!(
                "silhouettes: must be 'auto', 'on' or 'off' (got {other:?})"
            ))
            .into())
        }
    };
    let mut args = fitness_args(
        scene,
        &paths,
        &target,
        pixels,
        loss,
        clip,
        product_bounds,
        norm,
        space,
        footprint,
        saturated,
        solve_margin,
    )?;
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
    args.spec.outlines = outlines;
    let options = PassOptions {
        outline_gate,
        passes: frozen_bounce,
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

/// Held-out losses of the closed form of `target` at the light `x` (one value per parameter of `paths`):
/// the pixels (`pixels`, default all) split into folds by `folds` (uint8, one label per pixel of
/// `pixels`; labels 0..K-1), and per fold the loss of its pixels at the products solved on the other folds' pixels, in the
/// fit's `norm` and `space` (`Fitness::held_out`). `refine`: the products minimise the fit's own loss on
/// those pixels, else least squares (a bounce's fixed point as `evaluate` solves it). The arguments
/// otherwise as `evaluate`'s with `loss="l1_projected"`. Returns float64 (K, 2): per fold the held-out
/// loss and its number of pixels (the fixed background's left out).
#[pyfunction]
#[pyo3(signature = (scene, target, x, folds, paths, pixels=None, clip=true, threads=None,
                    product_bounds=None, norm="l1", space="linear", saturated=None, refine=true))]
#[allow(clippy::too_many_arguments)]
pub(super) fn held_out<'py>(
    py: Python<'py>,
    scene: &Bound<'py, PyScene>,
    target: PyReadonlyArray3<'py, f32>,
    x: PyReadonlyArray1<'py, f64>,
    folds: PyReadonlyArray1<'py, u8>,
    paths: Vec<String>,
    pixels: Option<PyReadonlyArray1<'py, u32>>,
    clip: bool,
    threads: Option<usize>,
    product_bounds: Option<PyReadonlyArray3<'py, f64>>,
    norm: &str,
    space: &str,
    saturated: Option<f32>,
    refine: bool,
) -> PyResult<Bound<'py, PyArray2<f64>>> {
    let scene = &scene.get().0;
    let n = (scene.width * scene.height) as usize;
    let chosen: Vec<u32> = match &pixels {
        Some(p) => p.as_slice()?.to_vec(),
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
    let args = fitness_args(
        scene,
        &paths,
        &target,
        pixels,
        "l1_projected",
        clip,
        product_bounds,
        norm,
        space,
        false,
        saturated,
        0,
    )?;
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
        args.build(scene)?.held_out(&x, &dense, count, refine)
    })??;
    let flat: Vec<f64> = out.iter().flat_map(|h| [h.loss, h.pixels as f64]).collect();
    PyArray1::from_vec(py, flat).reshape([count, 2])
}
