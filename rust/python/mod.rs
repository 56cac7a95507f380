//! The PyO3 layer: the `_native` module and its functions, conversions only. Heavy calls copy their
//! inputs out and release the GIL ([`pool::detach_in_pool`]); the decisions live in the core.

use pyo3::prelude::*;

mod errors;
mod fitness;
mod lights;
mod optimize;
mod photo;
mod pool;
mod render;
mod scene;
#[cfg(feature = "test-hooks")]
mod test_hooks;
mod uncertainty;

use errors::{RtloopError, SceneError};
use fitness::OptimizeResult;
use scene::PyScene;

/// None when the closed-form (projected) method applies to `scene` with the fit section `paths`, else why.
#[pyfunction]
fn projection_blocker(scene: &Bound<'_, PyScene>, paths: Vec<String>) -> Option<String> {
    crate::fitness::projection_blocker(&scene.get().0, &paths)
}

/// Which constant radiance the closed form's second column models for `scene`: "environment" (occluded)
/// or "ambient" (unoccluded), as `fitness::constant_term` decides.
#[pyfunction]
fn constant_term(scene: &Bound<'_, PyScene>) -> &'static str {
    match crate::fitness::constant_term(&scene.get().0) {
        crate::fitness::Sky::Open => "ambient",
        _ => "environment",
    }
}

/// The thread counts of the worker pools kept (least recently used first; None: all cores), for tests.
#[pyfunction]
fn _kept_pools() -> Vec<Option<usize>> {
    pool::kept_pools()
}

#[pymodule(gil_used = false)]
fn _native(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<PyScene>()?;
    m.add_class::<OptimizeResult>()?;
    m.add_function(wrap_pyfunction!(render::render, m)?)?;
    m.add_function(wrap_pyfunction!(lights::fit_lights, m)?)?;
    m.add_function(wrap_pyfunction!(lights::lights_solve, m)?)?;
    m.add_function(wrap_pyfunction!(_kept_pools, m)?)?;
    m.add_function(wrap_pyfunction!(render::object_ids, m)?)?;
    m.add_function(wrap_pyfunction!(render::render_many, m)?)?;
    m.add_function(wrap_pyfunction!(render::render_layers, m)?)?;
    m.add_function(wrap_pyfunction!(render::composite, m)?)?;
    m.add_function(wrap_pyfunction!(render::save_image, m)?)?;
    m.add_function(wrap_pyfunction!(projection_blocker, m)?)?;
    m.add_function(wrap_pyfunction!(constant_term, m)?)?;
    m.add_function(wrap_pyfunction!(optimize::evaluate, m)?)?;
    m.add_function(wrap_pyfunction!(optimize::optimize, m)?)?;
    m.add_function(wrap_pyfunction!(uncertainty::fd_columns, m)?)?;
    m.add_function(wrap_pyfunction!(uncertainty::block_scores, m)?)?;
    m.add_function(wrap_pyfunction!(uncertainty::footprint_delta, m)?)?;
    m.add_function(wrap_pyfunction!(render::render_centre_and_footprint, m)?)?;
    m.add_function(wrap_pyfunction!(uncertainty::order_statistics, m)?)?;
    m.add_function(wrap_pyfunction!(photo::noise_medians, m)?)?;
    m.add_function(wrap_pyfunction!(photo::jpeg_phases, m)?)?;
    m.add_function(wrap_pyfunction!(photo::codes8, m)?)?;
    m.add("RtloopError", m.py().get_type::<RtloopError>())?;
    m.add("SceneError", m.py().get_type::<SceneError>())?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    Ok(())
}
