//! The PyO3 layer: conversions only. Heavy calls copy their inputs out and release the GIL.

use std::path::PathBuf;

use numpy::{
    PyArray1, PyArray2, PyArray3, PyArrayMethods, PyReadonlyArray1, PyReadonlyArray2,
    PyReadonlyArray3, PyUntypedArrayMethods,
};
use pyo3::create_exception;
use pyo3::exceptions::{PyException, PyValueError};
use pyo3::prelude::*;
use pyo3::types::PyDict;

use crate::de::{self, DeConfig};
use crate::error::Error;
use crate::fitness::{Fitness, LossKind, Norm, Projection, Solved, Space};
use crate::params::ParamLayout;
use crate::render as core_render;
use crate::scene::Scene;

#[path = "de.rs"]
mod de_hooks;

create_exception!(
    _native,
    RtloopError,
    PyException,
    "Base class of rtloop's errors."
);
create_exception!(
    _native,
    SceneError,
    RtloopError,
    "The scene description is invalid; the message names the field."
);

impl From<Error> for PyErr {
    fn from(e: Error) -> PyErr {
        match e {
            Error::Scene(m) => SceneError::new_err(m),
            Error::Invalid(m) => RtloopError::new_err(m),
            Error::Io { .. } => RtloopError::new_err(e.to_string()),
        }
    }
}

/// A validated scene (immutable). Build one with `Scene(json_text)`; `rtloop.load_scene` is the friendly way.
#[pyclass(frozen, name = "Scene", module = "rtloop._native")]
pub struct PyScene(pub Scene);

#[pymethods]
impl PyScene {
    #[new]
    fn new(json_text: &str) -> PyResult<Self> {
        Ok(PyScene(Scene::from_json(json_text)?))
    }

    #[getter]
    fn width(&self) -> u32 {
        self.0.width
    }

    #[getter]
    fn height(&self) -> u32 {
        self.0.height
    }

    /// Object names in scene order.
    #[getter]
    fn object_names(&self) -> Vec<String> {
        self.0.objects.iter().map(|o| o.name.clone()).collect()
    }

    /// The fit section's paths in canonical order.
    #[getter]
    fn fit_paths(&self) -> Vec<String> {
        self.0.fit.iter().map(|f| f.path.clone()).collect()
    }

    /// Scalar parameter names (e.g. `light.position.x`) for `paths` (all fit paths when omitted).
    #[pyo3(signature = (paths=None))]
    fn param_names(&self, paths: Option<Vec<String>>) -> PyResult<Vec<String>> {
        Ok(layout(&self.0, paths)?.names)
    }

    /// (min, max) per scalar parameter.
    #[pyo3(signature = (paths=None))]
    fn bounds(&self, paths: Option<Vec<String>>) -> PyResult<Vec<(f64, f64)>> {
        Ok(layout(&self.0, paths)?.bounds)
    }

    /// Current values of the scalar parameters.
    #[pyo3(signature = (paths=None))]
    fn get_params(&self, paths: Option<Vec<String>>) -> PyResult<Vec<f64>> {
        let l = layout(&self.0, paths)?;
        Ok(l.read(&self.0))
    }

    /// A copy with the scalar parameters of `paths` set to `values` (no bounds check: bounds are the search's).
    #[pyo3(signature = (values, paths=None))]
    fn with_params(&self, values: Vec<f64>, paths: Option<Vec<String>>) -> PyResult<PyScene> {
        let l = layout(&self.0, paths)?;
        if values.len() != l.dim() {
            return Err(PyValueError::new_err(format!(
                "expected {} values, got {}",
                l.dim(),
                values.len()
            )));
        }
        if let Some(v) = values.iter().find(|v| !v.is_finite()) {
            return Err(PyValueError::new_err(format!(
                "parameter values must be finite (got {v})"
            )));
        }
        let mut s = self.0.clone();
        l.apply(&mut s, &values);
        Ok(PyScene(s))
    }

    /// The scene as JSON text in the public format, defaults written out.
    fn to_json(&self) -> String {
        serde_json::to_string_pretty(&self.0.to_value()).expect("a scene always serialises")
    }

    /// The scene as a plain dict in the public format (defaults written out).
    fn to_dict<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        py.import("json")?.call_method1("loads", (self.to_json(),))
    }

    fn __repr__(&self) -> String {
        format!(
            "<rtloop.Scene {}x{}, {} objects, {} free parameters>",
            self.0.width,
            self.0.height,
            self.0.objects.len(),
            ParamLayout::all(&self.0).dim()
        )
    }
}

fn layout(scene: &Scene, paths: Option<Vec<String>>) -> PyResult<ParamLayout> {
    Ok(match paths {
        Some(p) => ParamLayout::new(scene, &p)?,
        None => ParamLayout::all(scene),
    })
}

fn image_array<'py>(
    py: Python<'py>,
    h: u32,
    w: u32,
    rgb: Vec<f32>,
) -> PyResult<Bound<'py, PyArray3<f32>>> {
    PyArray1::from_vec(py, rgb).reshape([h as usize, w as usize, 3])
}

/// Render `scene` to a float32 (H, W, 3) linear RGB array.
#[pyfunction]
#[pyo3(signature = (scene, width=None, height=None, spp=1))]
fn render<'py>(
    py: Python<'py>,
    scene: &Bound<'py, PyScene>,
    width: Option<u32>,
    height: Option<u32>,
    spp: u32,
) -> PyResult<Bound<'py, PyArray3<f32>>> {
    let scene = &scene.get().0;
    let img = py.detach(|| core_render::render(scene, width, height, spp))?;
    image_array(py, img.height, img.width, img.rgb)
}

/// Object index per pixel centre, int32 (H, W), -1 for background.
#[pyfunction]
#[pyo3(signature = (scene, width=None, height=None))]
fn object_ids<'py>(
    py: Python<'py>,
    scene: &Bound<'py, PyScene>,
    width: Option<u32>,
    height: Option<u32>,
) -> PyResult<Bound<'py, PyArray2<i32>>> {
    let scene = &scene.get().0;
    let (w, h) = (width.unwrap_or(scene.width), height.unwrap_or(scene.height));
    if w == 0 || h == 0 || w > 16384 || h > 16384 {
        return Err(RtloopError::new_err(format!(
            "image size must be 1..16384 pixels per side (got {w}x{h})"
        )));
    }
    let ids = py.detach(|| core_render::object_ids(scene, Some(w), Some(h)));
    PyArray1::from_vec(py, ids).reshape([h as usize, w as usize])
}

/// None when the closed-form (projected) method applies to `scene` with the fit section `paths`, else why.
#[pyfunction]
fn projection_blocker(scene: &Bound<'_, PyScene>, paths: Vec<String>) -> Option<String> {
    crate::fitness::projection_blocker(&scene.get().0, &paths)
}

/// Write a linear float (H, W, 3) image as 8-bit sRGB PNG or BMP, atomically.
#[pyfunction]
fn save_image(py: Python<'_>, path: PathBuf, image: PyReadonlyArray3<'_, f32>) -> PyResult<()> {
    let shape = image.shape().to_vec();
    if shape[2] != 3 {
        return Err(PyValueError::new_err(format!(
            "expected an (H, W, 3) image, got shape {shape:?}"
        )));
    }
    let data = image.as_slice()?.to_vec();
    py.detach(|| core_render::save_srgb8(&path, shape[1] as u32, shape[0] as u32, &data))?;
    Ok(())
}

fn target_vec(scene: &Scene, target: &PyReadonlyArray3<'_, f32>) -> PyResult<Vec<f32>> {
    let shape = target.shape();
    if shape != [scene.height as usize, scene.width as usize, 3] {
        return Err(PyValueError::new_err(format!(
            "objective image has shape {shape:?}; the scene needs ({}, {}, 3)",
            scene.height, scene.width
        )));
    }
    Ok(target.as_slice()?.to_vec())
}

fn make_fitness(
    scene: &Scene,
    paths: &[String],
    target: &PyReadonlyArray3<'_, f32>,
    pixels: Option<PyReadonlyArray1<'_, u32>>,
    loss: &str,
    clip: bool,
    product_bounds: Option<PyReadonlyArray3<'_, f64>>,
    norm: &str,
    space: &str,
) -> PyResult<(Fitness, Vec<(f64, f64)>)> {
    let space = Space::parse(space).map_err(RtloopError::new_err)?;
    let layout = ParamLayout::new(scene, paths)?;
    let bounds = layout.bounds.clone();
    let target = target_vec(scene, target)?;
    let pixels: Option<Vec<u32>> = match pixels {
        Some(p) => Some(p.as_slice()?.to_vec()),
        None => None,
    };
    let projection = match product_bounds {
        Some(b) => {
            let a = b.as_array();
            let n = scene.objects.len();
            if a.ndim() != 3
                || a.shape()[0] != n
                || !(3..=4).contains(&a.shape()[1])
                || a.shape()[2] != 2
            {
                return Err(PyValueError::new_err(format!(
                    "product_bounds must have shape ({n}, 3, 2) or ({n}, 4, 2) (row 4: intensity x \
                     specular), got {:?}",
                    a.shape()
                )));
            }
            let mut proj = Projection::matte(
                (0..n)
                    .map(|k| std::array::from_fn(|c| (a[[k, c, 0]], a[[k, c, 1]])))
                    .collect(),
            );
            if a.shape()[1] == 4 {
                proj.specular = (0..n).map(|k| (a[[k, 3, 0]], a[[k, 3, 1]])).collect();
            }
            Some(proj)
        }
        None => None,
    };
    let kind = LossKind::parse(loss)?;
    let mut fitness = Fitness::new(
        scene,
        layout,
        &target,
        pixels.as_deref(),
        kind,
        clip,
        projection,
    )?;
    fitness.set_norm(Norm::parse(norm).map_err(RtloopError::new_err)?);
    fitness.set_space(space);
    Ok((fitness, bounds))
}

/// The closed-form solution for `x`, one row per object: [P_r, P_g, P_b, Q] (Q = intensity x specular,
/// 0 for a matte object).
fn solved_rows(fitness: &Fitness, x: &[f64]) -> Vec<Vec<f64>> {
    rows(&fitness.solved(x))
}

fn rows(s: &Solved) -> Vec<Vec<f64>> {
    s.products
        .iter()
        .zip(&s.specular)
        .map(|(p, &q)| vec![p[0], p[1], p[2], q])
        .collect()
}

/// A worker pool of `threads` threads (all cores when `None`), started once per size and kept: starting
/// threads costs more than a small fit's search. Results never depend on the pool (see `de`).
pub(crate) fn pool(threads: Option<usize>) -> PyResult<std::sync::Arc<rayon::ThreadPool>> {
    use std::collections::HashMap;
    use std::sync::{Arc, Mutex, OnceLock};
    static POOLS: OnceLock<Mutex<HashMap<Option<usize>, Arc<rayon::ThreadPool>>>> = OnceLock::new();
    if threads == Some(0) {
        return Err(PyValueError::new_err("threads must be >= 1"));
    }
    let mut pools = POOLS
        .get_or_init(|| Mutex::new(HashMap::new()))
        .lock()
        .unwrap_or_else(|e| e.into_inner());
    if let Some(p) = pools.get(&threads) {
        return Ok(p.clone());
    }
    let mut b = rayon::ThreadPoolBuilder::new();
    if let Some(n) = threads {
        b = b.num_threads(n);
    }
    let p = Arc::new(
        b.build()
            .map_err(|e| RtloopError::new_err(format!("cannot start worker threads: {e}")))?,
    );
    pools.insert(threads, p.clone());
    Ok(p)
}

/// Objective values of each row of `population` (N, D): float64 (N, n_objectives). `norm` is the
/// per-pixel penalty ("l1", "l2", "huber", "huber:H"), `space` where it compares values ("linear" or
/// "srgb": the sRGB encodings of the clipped model and of the objective).
#[pyfunction]
#[pyo3(signature = (scene, paths, target, population, pixels=None, loss="l1", clip=true, threads=None,
                    product_bounds=None, norm="l1", space="linear"))]
#[allow(clippy::too_many_arguments)]
fn evaluate<'py>(
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
) -> PyResult<Bound<'py, PyArray2<f64>>> {
    use de::Objective;
    use rayon::prelude::*;
    let scene = &scene.get().0;
    let (fitness, bounds) = make_fitness(
        scene,
        &paths,
        &target,
        pixels,
        loss,
        clip,
        product_bounds,
        norm,
        space,
    )?;
    let pop = population.as_array();
    if pop.ncols() != bounds.len() {
        return Err(PyValueError::new_err(format!(
            "population has {} columns; {} parameters",
            pop.ncols(),
            bounds.len()
        )));
    }
    let rows: Vec<Vec<f64>> = pop.rows().into_iter().map(|r| r.to_vec()).collect();
    let nobj = fitness.n_objectives();
    let pool = pool(threads)?;
    let out = py.detach(|| {
        pool.install(|| {
            let mut out = vec![0.0; rows.len() * nobj];
            out.par_chunks_mut(nobj)
                .zip(rows.par_iter())
                .for_each(|(o, x)| fitness.evaluate(x, o));
            out
        })
    });
    PyArray1::from_vec(py, out).reshape([rows.len(), nobj])
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
/// than this fraction of every range (default 1e-13).
#[pyfunction]
#[pyo3(signature = (scene, paths, target, *, pixels=None, loss="l1", clip=true, population=60,
                    generations=200, f=0.6, cr=0.8, seed=0, threads=None, callback=None,
                    product_bounds=None, method="de", max_evaluations=None, polish=0, norm="l1",
                    with_products=true, space="linear", polish_tol=None))]
#[allow(clippy::too_many_arguments)]
fn optimize<'py>(
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
) -> PyResult<Bound<'py, PyDict>> {
    let scene = &scene.get().0;
    let (fitness, bounds) = make_fitness(
        scene,
        &paths,
        &target,
        pixels,
        loss,
        clip,
        product_bounds,
        norm,
        space,
    )?;
    let cfg = DeConfig {
        population,
        generations,
        f,
        cr,
        seed,
    };
    let pool = pool(threads)?;
    let active = fitness.active_pixels();
    let mut error: Option<PyErr> = None;
    let result = py.detach(|| {
        pool.install(|| {
            let callback = |rep: &de::GenerationReport| {
                let Some(cb) = &callback else { return true };
                // The closed-form products of the best (one more evaluation) only when the caller wants them.
                let products: Option<Vec<Vec<f64>>> = (with_products
                    && fitness.kind() == LossKind::L1Projected)
                    .then(|| solved_rows(&fitness, rep.best));
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
            };
            let found = match method {
                "de" => de::minimize(&fitness, &bounds, &cfg, callback).map(|r| {
                    let why = if r.stopped {
                        "callback"
                    } else {
                        "max_generations"
                    };
                    (r, why, None)
                }),
                "lshade" => {
                    let scfg = de::shade::ShadeConfig {
                        max_evaluations: max_evaluations.unwrap_or(population * (generations + 1)),
                        population_init: Some(population),
                        polish_evaluations: polish,
                        polish_x_tol: polish_tol
                            .unwrap_or(de::shade::ShadeConfig::default().polish_x_tol),
                        seed,
                        ..de::shade::ShadeConfig::lshade()
                    };
                    de::shade::minimize(&fitness, &bounds, &scfg, callback).map(|r| {
                        let polish = r
                            .polish
                            .as_ref()
                            .map(|p| (p.evaluations, p.f_before, p.f_after));
                        let res = de::DeResult {
                            best: r.best,
                            best_objectives: r.best_objectives,
                            evaluations: r.evaluations,
                            generations: r.generations,
                            stopped: matches!(r.stop, de::shade::StopReason::Callback),
                        };
                        (res, r.stop.as_str(), polish)
                    })
                }
                other => Err(Error::Invalid(format!(
                    "unknown method {other:?} (known: \"de\", \"lshade\")"
                ))),
            }?;
            // The search ranks lights by least-squares products; the result carries the products that
            // minimise the loss itself (saturated pixels one-sided), and that loss (still without the GIL:
            // in the sRGB space this is a few line searches per object).
            let refined = fitness.refined(&found.0.best);
            Ok::<_, Error>((found, refined))
        })
    })?;
    let ((result, stop_reason, polish_report), refined) = result;
    if let Some(e) = error {
        return Err(e);
    }
    let d = PyDict::new(py);
    if let Some((solved, loss)) = refined {
        d.set_item("products", rows(&solved))?;
        d.set_item("lit_pixels", solved.lit)?;
        d.set_item("search_objectives", result.best_objectives.clone())?;
        d.set_item("objectives", vec![loss.iter().sum::<f64>()])?;
    } else {
        d.set_item("objectives", result.best_objectives)?;
    }
    d.set_item("x", PyArray1::from_vec(py, result.best))?;
    d.set_item("evaluations", result.evaluations)?;
    d.set_item("generations", result.generations)?;
    d.set_item("stopped", result.stopped)?;
    d.set_item("stop_reason", stop_reason)?;
    if let Some((evals, before, after)) = polish_report {
        d.set_item("polish", (evals, before, after))?;
    }
    d.set_item("active_pixels", active)?;
    Ok(d)
}

#[pymodule(gil_used = false)]
fn _native(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<PyScene>()?;
    de_hooks::register(m)?;
    m.add_function(wrap_pyfunction!(render, m)?)?;
    m.add_function(wrap_pyfunction!(object_ids, m)?)?;
    m.add_function(wrap_pyfunction!(save_image, m)?)?;
    m.add_function(wrap_pyfunction!(projection_blocker, m)?)?;
    m.add_function(wrap_pyfunction!(evaluate, m)?)?;
    m.add_function(wrap_pyfunction!(optimize, m)?)?;
    m.add("RtloopError", m.py().get_type::<RtloopError>())?;
    m.add("SceneError", m.py().get_type::<SceneError>())?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    Ok(())
}
