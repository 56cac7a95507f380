//! `fit_lights` and `lights_solve`: the lights fit's search and closed form (`fitness::lights`).

use numpy::{PyReadonlyArray1, PyReadonlyArray3, PyUntypedArrayMethods};
use pyo3::prelude::*;

use super::fitness::check_image_shape;
use super::pool::detach_in_pool;
use super::scene::PyScene;
use crate::error::Error;
use crate::fitness::lights::LightsFitness;
use crate::params::ParamLayout;
use crate::search::{Budget, Method};

type Products = Vec<Vec<[f64; 3]>>;

fn lights_fitness(
    scene: &Bound<'_, PyScene>,
    image: &PyReadonlyArray3<'_, f32>,
    paths: &[String],
    pixels: &PyReadonlyArray1<'_, u32>,
) -> PyResult<LightsFitness> {
    let s = &scene.get().0;
    check_image_shape(s, image.shape(), |shape, h, w| {
        format!("image: expected shape ({h}, {w}, 3), got {shape:?}")
    })?;
    let layout = ParamLayout::new(s, paths)?;
    Ok(LightsFitness::new(
        s,
        layout,
        image.as_slice()?,
        pixels.as_slice()?,
    )?)
}

/// Search the lights' geometry (`paths`) with L-SHADE (`seed`, `population`, `generations`, then a
/// Nelder–Mead polish of `polish` evaluations) against the linear float32 (H, W, 3) `image` at `pixels`
/// (flat indices); `bounds` (min, max per value; min == max holds one) replaces the scene's search box
/// and `start` joins the initial population. Returns (x, loss, products per object and light then the
/// constant, evaluations).
#[pyfunction]
#[pyo3(signature = (scene, image, paths, pixels, seed=0, population=40, generations=100, threads=None,
                    start=None, bounds=None, polish=200))]
#[allow(clippy::too_many_arguments)]
pub(super) fn fit_lights<'py>(
    py: Python<'py>,
    scene: &Bound<'py, PyScene>,
    image: PyReadonlyArray3<'py, f32>,
    paths: Vec<String>,
    pixels: PyReadonlyArray1<'py, u32>,
    seed: u64,
    population: usize,
    generations: usize,
    threads: Option<usize>,
    start: Option<Vec<f64>>,
    bounds: Option<Vec<(f64, f64)>>,
    polish: usize,
) -> PyResult<(Vec<f64>, f64, Products, usize)> {
    if population < 4 || generations == 0 {
        return Err(Error::Value(format!(
            "population must be >= 4 and generations >= 1 (got {population}, {generations})"
        ))
        .into());
    }
    let fitness = lights_fitness(scene, &image, &paths, &pixels)?;
    if fitness.pixels() == 0 {
        return Err(Error::Value("no chosen pixel sees an object".into()).into());
    }
    let budget = Budget {
        population,
        generations,
        f: 0.5,
        cr: 0.9,
        seed,
        max_evaluations: None,
        polish,
        polish_tol: None,
    };
    let method = Method::named("lshade", &budget)?;
    let dim = fitness.layout.dim();
    for (what, n) in [
        ("start", start.as_ref().map(Vec::len)),
        ("bounds", bounds.as_ref().map(Vec::len)),
    ] {
        if let Some(n) = n.filter(|&n| n != dim) {
            return Err(Error::Value(format!("{what}: expected {dim} values, got {n}")).into());
        }
    }
    let bounds = bounds.unwrap_or_else(|| fitness.layout.bounds.clone());
    let found = detach_in_pool(py, threads, || {
        crate::search::run_polishing(
            &method,
            &fitness,
            None::<&LightsFitness>,
            &bounds,
            start.as_deref(),
            |_| true,
        )
        .map(|r| {
            let solve = fitness.solve(&r.best);
            (r.best, solve.loss, solve.products, r.evaluations)
        })
    })??;
    Ok(found)
}

/// The closed form at the lights' geometry `x` (over `paths`): (loss, products as `fit_lights` gives them).
#[pyfunction]
pub(super) fn lights_solve<'py>(
    scene: &Bound<'py, PyScene>,
    image: PyReadonlyArray3<'py, f32>,
    paths: Vec<String>,
    pixels: PyReadonlyArray1<'py, u32>,
    x: Vec<f64>,
) -> PyResult<(f64, Products)> {
    let fitness = lights_fitness(scene, &image, &paths, &pixels)?;
    if x.len() != fitness.layout.dim() {
        return Err(Error::Value(format!(
            "x: expected {} values, got {}",
            fitness.layout.dim(),
            x.len()
        ))
        .into());
    }
    let s = fitness.solve(&x);
    Ok((s.loss, s.products))
}
