//! The PyO3 layer: the `_native` module and its functions, conversions only. Heavy calls copy their
//! inputs out and release the GIL ([`pool::detach_in_pool`]); the decisions live in the core.

use numpy::{
    PyArray1, PyArray2, PyArrayMethods, PyReadonlyArray1, PyReadonlyArray2, PyReadonlyArray3,
    PyReadwriteArray1, PyReadwriteArray2, PyUntypedArrayMethods,
};
use pyo3::prelude::*;

use crate::error::Error;
use crate::uncertainty as core_uncertainty;

mod errors;
mod fitness;
mod lights;
mod optimize;
mod pool;
mod render;
mod scene;
#[cfg(feature = "test-hooks")]
mod test_hooks;

use errors::{RtloopError, SceneError};
use fitness::OptimizeResult;
use scene::PyScene;

/// Per channel, the median absolute response of Immerkaer's kernel over the interior of float32 (H, W, 3)
/// `image` (C-contiguous, H and W >= 3; see `photo::noise_medians`), float32 (3,).
#[pyfunction]
fn noise_medians<'py>(
    py: Python<'py>,
    image: PyReadonlyArray3<'py, f32>,
) -> PyResult<Bound<'py, PyArray1<f32>>> {
    let shape = image.shape().to_vec();
    if shape[0] < 3 || shape[1] < 3 || shape[2] != 3 {
        return Err(Error::Value(format!(
            "noise_medians: an (H, W, 3) image, H and W >= 3 (got {shape:?})"
        ))
        .into());
    }
    let rgb = image.as_slice()?;
    let m = py.detach(|| crate::photo::noise_medians(rgb, shape[0], shape[1]));
    Ok(PyArray1::from_vec(py, m.to_vec()))
}

/// The 8-bit codes (uint8) of the float32 `values` (1-D) if each is bit for bit a code's value in `table`,
/// else None (see `photo::codes8`; `buckets` and `shift` as `rtloop._srgb` builds them).
#[pyfunction]
fn codes8<'py>(
    py: Python<'py>,
    values: PyReadonlyArray1<'py, f32>,
    table: PyReadonlyArray1<'py, f32>,
    buckets: PyReadonlyArray1<'py, i16>,
    shift: u32,
) -> PyResult<Option<Bound<'py, PyArray1<u8>>>> {
    let (v, t, b) = (values.as_slice()?, table.as_slice()?, buckets.as_slice()?);
    let codes = py.detach(|| crate::photo::codes8(v, t, b, shift.min(31)));
    Ok(codes.map(|c| PyArray1::from_vec(py, c)))
}

/// The JPEG blocking's mean clipped squared jump per phase of the `block`-pixel grid, float64 (block, 3),
/// of the float32 (H, W, 3) sRGB `codes` (C-contiguous, H and W >= 4; see `photo::jpeg_phases`).
#[pyfunction]
fn jpeg_phases<'py>(
    py: Python<'py>,
    codes: PyReadonlyArray3<'py, f32>,
    block: usize,
    edge_sq: f32,
) -> PyResult<Bound<'py, PyArray2<f64>>> {
    let shape = codes.shape().to_vec();
    if shape[0] < 4 || shape[1] < 4 || shape[2] != 3 || block == 0 {
        return Err(Error::Value(format!(
            "jpeg_phases: an (H, W, 3) image, H and W >= 4, and a block > 0 (got {shape:?}, {block})"
        ))
        .into());
    }
    let c = codes.as_slice()?;
    let phases = py.detach(|| crate::photo::jpeg_phases(c, shape[0], shape[1], block, edge_sq));
    let flat: Vec<f64> = phases.iter().flatten().copied().collect();
    PyArray1::from_vec(py, flat).reshape([block, 3])
}

/// Finite-difference columns of the uncertainty's Jacobian over the used pixels `idx`, into the rows `rows`
/// of `jt` (P, 3 x used, float64, C-contiguous): column k is (f(`ups[k]`) - f(`downs[k]`)) / `denoms[k]`
/// (None: the optimum's used values `f0`; f64 from the f32 values, min(value, 1) with `clip`); the pixels
/// whose value crosses 1 (against `clipped0`) in a `free` channel are marked in `kink`, and (both sides
/// rendered) those whose forward and backward changes disagree like a jump (a shadow edge or the terminator
/// crossed inside the step) in `jump`. The scenes are rendered in one pass over the used pixels (scenes with
/// the same first hits find them once; `uncertainty::fd_columns`), the GIL released throughout.
#[pyfunction]
#[allow(clippy::too_many_arguments)]
fn fd_columns<'py>(
    py: Python<'py>,
    ups: Vec<Option<Bound<'py, PyScene>>>,
    downs: Vec<Option<Bound<'py, PyScene>>>,
    denoms: Vec<f64>,
    rows: Vec<usize>,
    f0: PyReadonlyArray1<'py, f32>,
    idx: PyReadonlyArray1<'py, u32>,
    clipped0: PyReadonlyArray1<'py, bool>,
    free: PyReadonlyArray1<'py, bool>,
    clip: bool,
    mut kink: PyReadwriteArray1<'py, bool>,
    mut jump: PyReadwriteArray1<'py, bool>,
    mut jt: PyReadwriteArray2<'py, f64>,
) -> PyResult<()> {
    let k = rows.len();
    if ups.len() != k || downs.len() != k || denoms.len() != k {
        return Err(Error::Invalid(format!(
            "fd_columns: {k} rows need as many ups, downs and denoms (got {}, {}, {})",
            ups.len(),
            downs.len(),
            denoms.len()
        ))
        .into());
    }
    let m = jt.shape()[1];
    let p = jt.shape()[0];
    if let Some(&r) = rows.iter().find(|&&r| r >= p) {
        return Err(Error::Invalid(format!("fd_columns: row {r} of {p}")).into());
    }
    let mut seen = vec![false; p];
    for &r in &rows {
        if std::mem::replace(&mut seen[r], true) {
            return Err(Error::Invalid(format!("fd_columns: row {r} given twice")).into());
        }
    }
    fn scene<'a>(s: &'a Option<Bound<'_, PyScene>>) -> Option<&'a crate::scene::Scene> {
        s.as_ref().map(|b| &b.get().0) // frozen + Sync: no borrow flag
    }
    let columns: Vec<core_uncertainty::Column<'_>> = (0..k)
        .map(|c| core_uncertainty::Column {
            up: scene(&ups[c]),
            down: scene(&downs[c]),
            denom: denoms[c],
        })
        .collect();
    let (f0, idx, clipped0, free) = (
        f0.as_slice()?,
        idx.as_slice()?,
        clipped0.as_slice()?,
        free.as_slice()?,
    );
    let (kink, jump, jt) = (
        kink.as_slice_mut()?,
        jump.as_slice_mut()?,
        jt.as_slice_mut()?,
    );
    // the rows asked for, in the order of `rows`
    let mut by_row: Vec<Option<&mut [f64]>> = jt.chunks_mut(m.max(1)).map(Some).collect();
    let mut out: Vec<&mut [f64]> = rows
        .iter()
        .map(|&r| by_row[r].take().unwrap_or_default())
        .collect();
    py.detach(|| {
        core_uncertainty::fd_columns(
            &columns, f0, idx, clipped0, free, clip, kink, jump, &mut out,
        )
    })?;
    Ok(())
}

/// The `ks`-th smallest of `values` (0-based), as `np.partition(values, ks)[ks]`: exact elements.
#[pyfunction]
fn order_statistics<'py>(
    py: Python<'py>,
    values: PyReadonlyArray1<'py, f64>,
    ks: Vec<usize>,
) -> PyResult<Vec<f64>> {
    let values = values.as_slice()?;
    Ok(py.detach(|| core_uncertainty::order_statistics(values, &ks))?)
}

/// The pixel footprint's Δ per used residual (float64, 3 per used pixel `idx`) from the pixel-centre render
/// `centre` (H, W, 3) float32: `uncertainty::footprint_delta`.
#[pyfunction]
fn footprint_delta<'py>(
    py: Python<'py>,
    centre: PyReadonlyArray3<'py, f32>,
    idx: PyReadonlyArray1<'py, u32>,
    f0: PyReadonlyArray1<'py, f32>,
) -> PyResult<Bound<'py, PyArray1<f64>>> {
    let shape = centre.shape();
    if shape[2] != 3 {
        return Err(Error::Invalid(format!(
            "footprint_delta: centre has {} channels, not 3",
            shape[2]
        ))
        .into());
    }
    let (width, height) = (shape[1], shape[0]);
    let (centre, idx, f0) = (centre.as_slice()?, idx.as_slice()?, f0.as_slice()?);
    let d = py.detach(|| core_uncertainty::footprint_delta(centre, (width, height), idx, f0))?;
    Ok(PyArray1::from_vec(py, d))
}

/// The sandwich's block sums: (len(rows), blocks) float64, g[a, b] = sum of jt[rows[a], i] * r[i] over the
/// residuals i whose pixel is in block b (`block_of`, one per pixel, three residuals each), in order.
#[pyfunction]
fn block_scores<'py>(
    py: Python<'py>,
    jt: PyReadonlyArray2<'py, f64>,
    rows: Vec<usize>,
    r: PyReadonlyArray1<'py, f64>,
    block_of: PyReadonlyArray1<'py, i64>,
    blocks: usize,
) -> PyResult<Bound<'py, PyArray2<f64>>> {
    let (jt, r) = (jt.as_slice()?, r.as_slice()?);
    let block_of: Vec<usize> = block_of
        .as_slice()?
        .iter()
        .map(|&b| b.max(0) as usize)
        .collect();
    let p = rows.len();
    let g = py.detach(|| core_uncertainty::block_scores(jt, &rows, r, &block_of, blocks))?;
    PyArray1::from_vec(py, g).reshape([p, blocks])
}

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
    m.add_function(wrap_pyfunction!(fd_columns, m)?)?;
    m.add_function(wrap_pyfunction!(block_scores, m)?)?;
    m.add_function(wrap_pyfunction!(footprint_delta, m)?)?;
    m.add_function(wrap_pyfunction!(render::render_centre_and_footprint, m)?)?;
    m.add_function(wrap_pyfunction!(order_statistics, m)?)?;
    m.add_function(wrap_pyfunction!(noise_medians, m)?)?;
    m.add_function(wrap_pyfunction!(jpeg_phases, m)?)?;
    m.add_function(wrap_pyfunction!(codes8, m)?)?;
    m.add("RtloopError", m.py().get_type::<RtloopError>())?;
    m.add("SceneError", m.py().get_type::<SceneError>())?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    Ok(())
}
