//! Conversions between Python's arrays and the fitness: the arguments a [`Fitness`] is built from
//! (`spec::PyFitnessSpec::args` reads them), and the typed result of `optimize`.

use numpy::PyArray1;
use pyo3::prelude::*;

use crate::error::Error;
use crate::fitness::{Fitness, FitnessSpec};
use crate::params::ParamLayout;
use crate::scene::Scene;
use crate::stage::StageResult;

/// Checks that `shape` is the image shape of `scene`, (H, W, 3); else a value error whose message
/// `mismatch(shape, H, W)` writes.
pub(super) fn check_image_shape(
    scene: &Scene,
    shape: &[usize],
    mismatch: impl FnOnce(&[usize], u32, u32) -> String,
) -> PyResult<()> {
    if shape != [scene.height as usize, scene.width as usize, 3] {
        return Err(Error::Value(mismatch(shape, scene.height, scene.width)).into());
    }
    Ok(())
}

/// A fitness's arguments, read from Python (with the GIL, every check that names an argument done):
/// [`FitnessArgs::build`] then builds it without the GIL, inside the call's worker pool.
pub(crate) struct FitnessArgs {
    /// The searched parameters of `paths`, with their bounds.
    pub(crate) layout: ParamLayout,
    pub(crate) target: Vec<f32>,
    pub(crate) spec: FitnessSpec,
}

impl FitnessArgs {
    /// The fitness (its geometry, pixel groups and the bounce's gathers spread over the current pool).
    pub(crate) fn build(self, scene: &Scene) -> crate::error::Result<Fitness> {
        Fitness::new(scene, self.layout, &self.target, self.spec)
    }
}

/// What `optimize` found (immutable). For the projected loss `products` (per object [P_r, P_g, P_b, Q]:
/// the products minimising the loss at `x`), `lit_pixels` (per object) and `search_objectives` (the loss
/// at the least-squares products the search ranked candidates by) are set, else None. `history` holds
/// the best of every generation, recorded without the GIL (a Python callback is needed only to watch).
#[pyclass(frozen, name = "OptimizeResult", module = "rtloop._native")]
pub struct OptimizeResult {
    pub result: StageResult,
    pub history: Vec<Generation>,
}

/// One generation's best: generation, best parameter vector, its objectives, evaluations so far.
pub struct Generation {
    pub generation: usize,
    pub best: Vec<f64>,
    pub objectives: Vec<f64>,
    pub evaluations: usize,
}

#[pymethods]
impl OptimizeResult {
    /// The best parameter vector (float64).
    #[getter]
    fn x<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        PyArray1::from_slice(py, &self.result.x)
    }
    /// The loss at `x` (for the projected loss: its sum at `products`).
    #[getter]
    fn objectives(&self) -> Vec<f64> {
        self.result.objectives.clone()
    }
    #[getter]
    fn search_objectives(&self) -> Option<Vec<f64>> {
        self.result.search_objectives.clone()
    }
    /// All evaluations, the polish's included.
    #[getter]
    fn evaluations(&self) -> usize {
        self.result.evaluations
    }
    #[getter]
    fn generations(&self) -> usize {
        self.result.generations
    }
    /// The callback stopped the search.
    #[getter]
    fn stopped(&self) -> bool {
        self.result.stop == crate::search::StopReason::Callback
    }
    /// "max_generations", "max_evaluations", "converged", "stalled" or "callback".
    #[getter]
    fn stop_reason(&self) -> &'static str {
        self.result.stop.as_str()
    }
    /// (evaluations, value before, value after) of the Nelder-Mead polish; None when none ran.
    #[getter]
    fn polish(&self) -> Option<(usize, f64, f64)> {
        self.result
            .polish
            .as_ref()
            .map(|p| (p.evaluations, p.f_before, p.f_after))
    }
    #[getter]
    fn active_pixels(&self) -> usize {
        self.result.active_pixels
    }
    #[getter]
    fn products(&self) -> Option<Vec<Vec<f64>>> {
        self.result.products.as_ref().map(|rows| rows.to_vec())
    }
    #[getter]
    fn lit_pixels(&self) -> Option<Vec<usize>> {
        self.result.lit_pixels.clone()
    }
    /// With interreflection (the projected loss): 1 / the intensity the bounce was solved with.
    #[getter]
    fn gauge(&self) -> Option<f64> {
        self.result.gauge
    }
    /// The outline gate's evidence (`optimize(..., silhouettes="auto")`, `fit::outlines`): (the fit's loss
    /// with outlines at pixel centres, the same with them averaged over their sub-pixel rays, the outline
    /// pixels, the largest share of an object's lit pixels on its outline, whether it fired, the loss after
    /// the polish with them integrated or None, whether that result was kept); None where it did not run.
    #[getter]
    #[allow(clippy::type_complexity)]
    fn outlines(&self) -> Option<(f64, f64, usize, f64, bool, Option<f64>, bool)> {
        self.result.outlines.map(|e| {
            (
                e.centre,
                e.integrated,
                e.pixels,
                e.share,
                e.fired,
                e.polished,
                e.kept,
            )
        })
    }

    /// (generation, best (float64), best's objectives, evaluations) after the initial population and
    /// after every generation, as the callback sees them.
    #[getter]
    fn history<'py>(
        &self,
        py: Python<'py>,
    ) -> Vec<(usize, Bound<'py, PyArray1<f64>>, Vec<f64>, usize)> {
        self.history
            .iter()
            .map(|g| {
                let best = PyArray1::from_slice(py, &g.best);
                (g.generation, best, g.objectives.clone(), g.evaluations)
            })
            .collect()
    }

    fn __repr__(&self) -> String {
        format!(
            "<rtloop.OptimizeResult objectives={:?}, {} evaluations, {} generations, stop {}>",
            self.result.objectives,
            self.result.evaluations,
            self.result.generations,
            self.result.stop.as_str()
        )
    }
}
