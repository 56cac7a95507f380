//! The photo's statistics' loops (`crate::photo`): noise medians, 8-bit codes, the JPEG blocking's phases.

use numpy::{
    PyArray1, PyArray2, PyArrayMethods, PyReadonlyArray1, PyReadonlyArray3, PyUntypedArrayMethods,
};
use pyo3::prelude::*;

use crate::error::Error;

/// Per channel, the median absolute response of Immerkaer's kernel over the interior of float32 (H, W, 3)
/// `image` (C-contiguous, H and W >= 3; see `photo::noise_medians`), float32 (3,).
#[pyfunction]
pub(super) fn noise_medians<'py>(
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
pub(super) fn codes8<'py>(
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
pub(super) fn jpeg_phases<'py>(
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
