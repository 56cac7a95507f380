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
mod spec;
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

/// Adds each of the `#[pyfunction]`s to the module `m`.
macro_rules! add_functions {
    ($m:expr, [$($f:path),+ $(,)?]) => {
        $($m.add_function(wrap_pyfunction!($f, $m)?)?;)+
    };
}

#[pymodule(gil_used = false)]
fn _native(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<PyScene>()?;
    m.add_class::<OptimizeResult>()?;
    m.add_class::<spec::PyFitnessSpec>()?;
    add_functions!(
        m,
        [
            render::render,
            lights::fit_lights,
            lights::lights_solve,
            _kept_pools,
            render::object_ids,
            render::render_many,
            render::render_pixels,
            render::render_layers,
            render::composite,
            render::save_image,
            projection_blocker,
            constant_term,
            optimize::evaluate,
            optimize::optimize,
            optimize::held_out,
            uncertainty::fd_columns,
            uncertainty::block_scores,
            uncertainty::footprint_delta,
            render::render_centre_and_footprint,
            uncertainty::order_statistics,
            photo::noise_medians,
            photo::jpeg_phases,
            photo::codes8
        ]
    );
    m.add("RtloopError", m.py().get_type::<RtloopError>())?;
    m.add("SceneError", m.py().get_type::<SceneError>())?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    Ok(())
}
