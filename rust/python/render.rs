//! Rendering from Python: images, object ids, layered and composite renders, saving images.

use std::path::PathBuf;

use numpy::{
    PyArray1, PyArray2, PyArray3, PyArrayMethods, PyReadonlyArray1, PyReadonlyArray2,
    PyReadonlyArray3, PyUntypedArrayMethods,
};
use pyo3::prelude::*;

use super::scene::PyScene;
use crate::error::Error;
use crate::render as core_render;

fn image_array<'py>(
    py: Python<'py>,
    h: u32,
    w: u32,
    rgb: Vec<f32>,
) -> PyResult<Bound<'py, PyArray3<f32>>> {
    PyArray1::from_vec(py, rgb).reshape([h as usize, w as usize, 3])
}

/// Render `scene` to a float32 (H, W, 3) linear RGB array (`footprint`: as the fitness with the
/// footprint models pixels).
#[pyfunction]
#[pyo3(signature = (scene, width=None, height=None, spp=1, footprint=false, outlines=false))]
pub(super) fn render<'py>(
    py: Python<'py>,
    scene: &Bound<'py, PyScene>,
    width: Option<u32>,
    height: Option<u32>,
    spp: u32,
    footprint: bool,
    outlines: bool,
) -> PyResult<Bound<'py, PyArray3<f32>>> {
    let scene = &scene.get().0;
    let size = (width, height);
    let img = py.detach(|| core_render::render_model(scene, size, spp, footprint, outlines))?;
    image_array(py, img.height, img.width, img.rgb)
}

/// The pixel-centre render and the footprint render of `scene` (its own size), float32 (H, W, 3) each, in
/// one pass (`render::render_centre_and_footprint`): `render(scene)` and `render(scene, footprint=True)` bit
/// for bit (`outlines`: as `render(scene, footprint=True, outlines=True)`).
#[pyfunction]
#[pyo3(signature = (scene, outlines=false))]
pub(super) fn render_centre_and_footprint<'py>(
    py: Python<'py>,
    scene: &Bound<'py, PyScene>,
    outlines: bool,
) -> PyResult<(Bound<'py, PyArray3<f32>>, Bound<'py, PyArray3<f32>>)> {
    let scene = &scene.get().0;
    let (c, f) = py.detach(|| core_render::render_centre_and_footprint(scene, outlines))?;
    Ok((
        image_array(py, c.height, c.width, c.rgb)?,
        image_array(py, f.height, f.width, f.rgb)?,
    ))
}

/// The pixels `idx` (flat indices `j * width + i`, uint32) of `render(scene, footprint=footprint)`, float32
/// (len(idx), 3): those pixels of the whole render bit for bit, for their cost alone.
#[pyfunction]
#[pyo3(signature = (scene, idx, footprint=false))]
pub(super) fn render_pixels<'py>(
    py: Python<'py>,
    scene: &Bound<'py, PyScene>,
    idx: PyReadonlyArray1<'py, u32>,
    footprint: bool,
) -> PyResult<Bound<'py, PyArray2<f32>>> {
    let scene = &scene.get().0;
    let idx = idx.as_slice()?;
    let rgb = py.detach(|| core_render::render_pixels(scene, idx, footprint))?;
    PyArray1::from_vec(py, rgb).reshape([idx.len(), 3])
}

/// Images float32 (H, W, 3) and an object index int32 (H, W).
type RendersAndIds<'py> = (Vec<Bound<'py, PyArray3<f32>>>, Bound<'py, PyArray2<i32>>);

/// The one-sample renders of `scenes` (one image size) in one pass, scenes with the same first hits finding
/// them once: (images float32 (H, W, 3) each, the first scene's object index per pixel, int32 (H, W)); the
/// values of `render` and `object_ids` bit for bit.
#[pyfunction]
pub(super) fn render_many<'py>(
    py: Python<'py>,
    scenes: Vec<Bound<'py, PyScene>>,
) -> PyResult<RendersAndIds<'py>> {
    let refs: Vec<&crate::scene::Scene> = scenes.iter().map(|b| &b.get().0).collect();
    let Some(first) = refs.first() else {
        return Err(Error::Invalid("render_many: no scenes".into()).into());
    };
    let (w, h) = (first.width as usize, first.height as usize);
    let (images, ids) = py.detach(|| core_render::render_many_with_ids(&refs))?;
    let images = images
        .into_iter()
        .map(|img| image_array(py, img.height, img.width, img.rgb))
        .collect::<PyResult<Vec<_>>>()?;
    Ok((images, PyArray1::from_vec(py, ids).reshape([h, w])?))
}

/// Object index per pixel centre, int32 (H, W), -1 for background.
#[pyfunction]
#[pyo3(signature = (scene, width=None, height=None))]
pub(super) fn object_ids<'py>(
    py: Python<'py>,
    scene: &Bound<'py, PyScene>,
    width: Option<u32>,
    height: Option<u32>,
) -> PyResult<Bound<'py, PyArray2<i32>>> {
    let scene = &scene.get().0;
    let (w, h) = (width.unwrap_or(scene.width), height.unwrap_or(scene.height));
    if w == 0 || h == 0 || w > 16384 || h > 16384 {
        return Err(Error::Invalid(format!(
            "image size must be 1..16384 pixels per side (got {w}x{h})"
        ))
        .into());
    }
    let ids = py.detach(|| core_render::object_ids(scene, Some(w), Some(h)));
    PyArray1::from_vec(py, ids).reshape([h as usize, w as usize])
}

/// Render `scenes` together at `width` x `height`, supersampling (`spp`) only where any of them has an
/// edge unless `adaptive` is false (see `render::adaptive`): (images (H, W, 3) each, coverage (H, W) of
/// the last scene's objects from `cover_from` on, pixels refined). `refine`: besides edges, "steps"
/// refines colour steps between neighbours (for compositing onto a photo), "curvature" only where the
/// colour bends (a standalone render). `progress(done, total)` is called with tiles done, at most every
/// 0.1 s, with the GIL; ^C (or an exception from `progress`) stops it.
#[pyfunction]
#[pyo3(signature = (scenes, width, height, spp=16, adaptive=true, cover_from=0, progress=None,
                    refine="steps"))]
#[allow(clippy::too_many_arguments, clippy::type_complexity)]
pub(super) fn render_layers<'py>(
    py: Python<'py>,
    scenes: Vec<Bound<'py, PyScene>>,
    width: u32,
    height: u32,
    spp: u32,
    adaptive: bool,
    cover_from: usize,
    progress: Option<Py<PyAny>>,
    refine: &str,
) -> PyResult<(
    Vec<Bound<'py, PyArray3<f32>>>,
    Bound<'py, PyArray2<f32>>,
    usize,
)> {
    use core_render::adaptive::Sampling;
    let sampling = match (adaptive, refine) {
        (false, _) => Sampling::Uniform,
        (true, "steps") => Sampling::Steps,
        (true, "curvature") => Sampling::Curvature,
        _ => {
            return Err(Error::Value(format!(
                "refine must be \"steps\" or \"curvature\" (got {refine:?})"
            ))
            .into())
        }
    };
    let scenes: Vec<&crate::scene::Scene> = scenes.iter().map(|s| &s.get().0).collect();
    let state = core_render::Progress::default();
    let mut failure: Option<PyErr> = None;
    let out = py.detach(|| {
        let (done_tx, done_rx) = std::sync::mpsc::channel();
        std::thread::scope(|scope| {
            let job = scope.spawn(|| {
                let out = core_render::render_layers(
                    &scenes, cover_from, width, height, spp, sampling, &state,
                );
                let _ = done_tx.send(());
                out
            });
            let mut shown = usize::MAX;
            let mut poll = |last: bool| {
                if failure.is_some() {
                    return;
                }
                Python::attach(|py| {
                    let done = state.done.load(std::sync::atomic::Ordering::Relaxed);
                    let total = state.total.load(std::sync::atomic::Ordering::Relaxed);
                    let r = py.check_signals().and_then(|()| match &progress {
                        Some(cb) if done != shown && (total > 0 || last) => {
                            shown = done;
                            cb.call1(py, (done, total)).map(drop)
                        }
                        _ => Ok(()),
                    });
                    if let Err(e) = r {
                        failure.get_or_insert(e);
                        state.stop.store(true, std::sync::atomic::Ordering::Relaxed);
                    }
                })
            };
            // Wakes at the end, or every 0.1 s to show progress and take ^C.
            while let Err(std::sync::mpsc::RecvTimeoutError::Timeout) =
                done_rx.recv_timeout(std::time::Duration::from_millis(100))
            {
                poll(false);
            }
            let out = job.join().unwrap_or_else(|p| std::panic::resume_unwind(p));
            poll(true);
            out
        })
    });
    if let Some(e) = failure {
        return Err(e);
    }
    let layers = out?.ok_or_else(|| Error::Invalid("render stopped".into()))?;
    let images = layers
        .images
        .into_iter()
        .map(|img| image_array(py, img.height, img.width, img.rgb))
        .collect::<PyResult<Vec<_>>>()?;
    let coverage =
        PyArray1::from_vec(py, layers.coverage).reshape([height as usize, width as usize])?;
    Ok((images, coverage, layers.refined))
}

/// The insertion composite of linear (H, W, 3) `photo`, `with` and `without` and the (H, W) `matte`
/// (see `render::composite`), float32 (H, W, 3).
#[pyfunction]
pub(super) fn composite<'py>(
    py: Python<'py>,
    photo: PyReadonlyArray3<'py, f32>,
    with: PyReadonlyArray3<'py, f32>,
    without: PyReadonlyArray3<'py, f32>,
    matte: PyReadonlyArray2<'py, f32>,
) -> PyResult<Bound<'py, PyArray3<f32>>> {
    let shape = photo.shape().to_vec();
    if with.shape() != shape || without.shape() != shape || matte.shape() != &shape[..2] {
        return Err(Error::Value(format!(
            "composite: photo {shape:?}, with {:?}, without {:?} and matte {:?} must agree",
            with.shape(),
            without.shape(),
            matte.shape()
        ))
        .into());
    }
    let (p, w, o, m) = (
        photo.as_slice()?,
        with.as_slice()?,
        without.as_slice()?,
        matte.as_slice()?,
    );
    let out = py.detach(|| core_render::composite(p, w, o, m))?;
    image_array(py, shape[0] as u32, shape[1] as u32, out)
}

/// Write a linear float (H, W, 3) image as 8-bit sRGB PNG or BMP, atomically.
#[pyfunction]
pub(super) fn save_image(
    py: Python<'_>,
    path: PathBuf,
    image: PyReadonlyArray3<'_, f32>,
) -> PyResult<()> {
    let shape = image.shape().to_vec();
    if shape[2] != 3 {
        return Err(
            Error::Value(format!("expected an (H, W, 3) image, got shape {shape:?}")).into(),
        );
    }
    let data = image.as_slice()?.to_vec();
    py.detach(|| core_render::save_srgb8(&path, shape[1] as u32, shape[0] as u32, &data))?;
    Ok(())
}
