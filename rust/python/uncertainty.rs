//! The uncertainty's kernels (`crate::uncertainty`): finite-difference columns, order statistics, the
//! footprint's deltas and the sandwich's block sums.

use numpy::{
    PyArray1, PyArray2, PyArrayMethods, PyReadonlyArray1, PyReadonlyArray2, PyReadonlyArray3,
    PyReadwriteArray1, PyReadwriteArray2, PyUntypedArrayMethods,
};
use pyo3::prelude::*;

use super::scene::PyScene;
use crate::error::Error;
use crate::uncertainty as core_uncertainty;

/// Finite-difference columns of the uncertainty's Jacobian over the used pixels `idx`, into the rows `rows`
/// of `jt` (P, 3 x used, float64, C-contiguous): column k is (f(`ups[k]`) - f(`downs[k]`)) / `denoms[k]`
/// (None: the optimum's used values `f0`; f64 from the f32 values, min(value, 1) with `clip`); the pixels
/// whose value crosses 1 (against `clipped0`) in a `free` channel are marked in `kink`, and (both sides
/// rendered) those whose forward and backward changes disagree like a jump (a shadow edge or the terminator
/// crossed inside the step) in `jump`. The scenes are rendered in one pass over the used pixels (scenes with
/// the same first hits find them once; `uncertainty::fd_columns`), the GIL released throughout.
#[pyfunction]
#[allow(clippy::too_many_arguments)]
pub(super) fn fd_columns<'py>(
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
pub(super) fn order_statistics<'py>(
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
pub(super) fn footprint_delta<'py>(
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
pub(super) fn block_scores<'py>(
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
