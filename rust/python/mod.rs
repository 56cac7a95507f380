//! The PyO3 layer: the `_native` module and its functions, conversions only. Heavy calls copy their
//! inputs out and release the GIL ([`pool::detach_in_pool`]); the decisions live in the core.

use std::path::PathBuf;

use numpy::{
    PyArray1, PyArray2, PyArray3, PyArrayMethods, PyReadonlyArray1, PyReadonlyArray2,
    PyReadonlyArray3, PyReadwriteArray1, PyReadwriteArray2, PyUntypedArrayMethods,
};
use pyo3::prelude::*;

use crate::error::Error;
use crate::render as core_render;
use crate::search::{lshade::LshadeConfig, Budget, Method, Objective};
use crate::stage::run_stage;
use crate::uncertainty as core_uncertainty;

mod errors;
mod fitness;
mod lights;
mod pool;
mod scene;
#[cfg(feature = "test-hooks")]
mod test_hooks;

use errors::{RtloopError, SceneError};
use fitness::{fitness_args, Generation, OptimizeResult};
use pool::detach_in_pool;
use scene::PyScene;

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
#[pyo3(signature = (scene, width=None, height=None, spp=1, footprint=false))]
fn render<'py>(
    py: Python<'py>,
    scene: &Bound<'py, PyScene>,
    width: Option<u32>,
    height: Option<u32>,
    spp: u32,
    footprint: bool,
) -> PyResult<Bound<'py, PyArray3<f32>>> {
    let scene = &scene.get().0;
    let img = py.detach(|| core_render::render_with(scene, width, height, spp, footprint))?;
    image_array(py, img.height, img.width, img.rgb)
}

/// The pixel-centre render and the footprint render of `scene` (its own size), float32 (H, W, 3) each, in
/// one pass (`render::render_centre_and_footprint`): `render(scene)` and `render(scene, footprint=True)` bit
/// for bit.
#[pyfunction]
fn render_centre_and_footprint<'py>(
    py: Python<'py>,
    scene: &Bound<'py, PyScene>,
) -> PyResult<(Bound<'py, PyArray3<f32>>, Bound<'py, PyArray3<f32>>)> {
    let scene = &scene.get().0;
    let (c, f) = py.detach(|| core_render::render_centre_and_footprint(scene))?;
    Ok((
        image_array(py, c.height, c.width, c.rgb)?,
        image_array(py, f.height, f.width, f.rgb)?,
    ))
}

/// Images float32 (H, W, 3) and an object index int32 (H, W).
type RendersAndIds<'py> = (Vec<Bound<'py, PyArray3<f32>>>, Bound<'py, PyArray2<i32>>);

/// The one-sample renders of `scenes` (one image size) in one pass, scenes with the same first hits finding
/// them once: (images float32 (H, W, 3) each, the first scene's object index per pixel, int32 (H, W)); the
/// values of `render` and `object_ids` bit for bit.
#[pyfunction]
fn render_many<'py>(
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
fn object_ids<'py>(
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
fn render_layers<'py>(
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

/// The insertion composite of linear (H, W, 3) `photo`, `with` and `without` and the (H, W) `matte`
/// (see `render::composite`), float32 (H, W, 3).
#[pyfunction]
fn composite<'py>(
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

/// Write a linear float (H, W, 3) image as 8-bit sRGB PNG or BMP, atomically.
#[pyfunction]
fn save_image(py: Python<'_>, path: PathBuf, image: PyReadonlyArray3<'_, f32>) -> PyResult<()> {
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
    if pop.ncols() != args.bounds.len() {
        return Err(Error::Value(format!(
            "population has {} columns; {} parameters",
            pop.ncols(),
            args.bounds.len()
        ))
        .into());
    }
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
/// polishing from there ([`REPASS_POLISH`], as the first pass's own polish then), a third and later one only
/// while the previous pass moved the light by more than [`REPASS_TOL`] (the held bounce's fixed point).
/// `x0`: a point (one value per searched parameter, clamped to their bounds) that L-SHADE's initial
/// population holds, so that a search refining it never ends worse than it (method "lshade" only).
/// Returns an `OptimizeResult`.
#[pyfunction]
#[pyo3(signature = (scene, paths, target, *, pixels=None, loss="l1", clip=true, population=60,
                    generations=200, f=0.6, cr=0.8, seed=0, threads=None, callback=None,
                    product_bounds=None, method="de", max_evaluations=None, polish=0, norm="l1",
                    with_products=true, space="linear", polish_tol=None, footprint=false,
                    polish_footprint=false, frozen_bounce=0, saturated=None, solve_margin=0, x0=None))]
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
    footprint: bool,
    polish_footprint: bool,
    frozen_bounce: usize,
    saturated: Option<f32>,
    solve_margin: usize,
    x0: Option<Vec<f64>>,
) -> PyResult<OptimizeResult> {
    let scene = &scene.get().0;
    // Where only the polish takes the pixel footprint, the search's fitness is the polish's at pixel
    // centres (one set-up for both).
    let only_polish = polish_footprint && !footprint;
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
        footprint || only_polish,
        saturated,
        solve_margin,
    )?;
    let bounds = args.bounds.clone();
    if let Some(x0) = &x0 {
        if x0.len() != bounds.len() || x0.iter().any(|v| !v.is_finite()) {
            return Err(Error::Invalid(format!(
                "x0: needs {} finite values, one per searched parameter ({}) (got {:?})",
                bounds.len(),
                args.layout.names.join(", "),
                x0
            ))
            .into());
        }
    }
    // The light's searched parameters: where the bounce is held depends on them alone (a lobe's shininess
    // shapes no diffuse bounce), so a pass's move is measured on them (on every parameter if none is).
    let names = &args.layout.names;
    let light_dims: Vec<bool> = if names.iter().any(|n| n.starts_with("light.")) {
        names.iter().map(|n| n.starts_with("light.")).collect()
    } else {
        vec![true; names.len()]
    };
    // The bounce held for the search and the polish alike (a polish on the full bounce would cost the
    // full fixed point per evaluation).
    fn freeze(
        fitness: &mut crate::Fitness,
        finer: &mut Option<crate::Fitness>,
        at: Option<&[f64]>,
    ) -> bool {
        // One fixed point for both: the footprint fitness's bounce, held for the pixel-centre search as
        // well (the same pixels; the bounce differs between the two only through their products).
        match finer.as_mut() {
            Some(f) => {
                let held = f.freeze_bounce(at);
                if let Some(frozen) = f.frozen_bounce() {
                    fitness.hold_bounce(frozen);
                }
                held
            }
            None => fitness.freeze_bounce(at),
        }
    }
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
    let mut error: Option<PyErr> = None;
    let mut history = Vec::new();
    let result = detach_in_pool(py, threads, || {
        let method = Method::named(method, &budget)?;
        let built = args.build(scene)?;
        let (mut fitness, mut finer) = if only_polish {
            (built.at_pixel_centres(), Some(built))
        } else {
            (built, None)
        };
        let passes = if frozen_bounce > 0 && freeze(&mut fitness, &mut finer, None) {
            frozen_bounce
        } else {
            1
        };
        let with_products = with_products && callback.is_some();
        let (mut done, mut generations) = (0, 0);
        let mut last: Option<crate::stage::StageResult> = None;
        let mut box_ = bounds.clone();
        for pass in 0..passes {
            if let Some(prev) = &last {
                // the bounce held again, at the light the previous pass found
                freeze(&mut fitness, &mut finer, Some(&prev.x));
                done += prev.evaluations;
                generations += prev.generations + 1;
                box_ = box_
                    .iter()
                    .zip(&prev.x)
                    .map(|(&(lo, hi), &x)| {
                        let h = 0.5 * REPASS_BOX * (hi - lo);
                        ((x - h).max(lo), (x + h).min(hi))
                    })
                    .collect();
            }
            let (done, generations) = (done, generations);
            // A later pass polishes from the light the previous one found (its population would only
            // find the same basin again); a method without a polish searches as the first pass did.
            let polishes = match &method {
                Method::Lshade(cfg) if cfg.polish_evaluations > 0 => Some(cfg),
                _ => None,
            };
            if let (Some(prev), Some(cfg)) = (&last, polishes) {
                let x_tol = cfg.polish_x_tol;
                let evaluations = repass_polish(cfg.polish_evaluations);
                let mut stage = crate::stage::polish_stage(
                    &fitness,
                    finer.as_ref(),
                    &box_,
                    &prev.x,
                    REPASS_STEP,
                    evaluations,
                    x_tol,
                )?;
                // Another pass holds the bounce where this one ended, unless it barely moved the light
                // from where this one held it: the passes have reached the held bounce's fixed point.
                let moved = (0..bounds.len()).any(|i| {
                    let (lo, hi) = bounds[i];
                    light_dims[i] && (stage.x[i] - prev.x[i]).abs() > REPASS_TOL * (hi - lo)
                });
                if pass + 1 < passes && moved {
                    last = Some(stage);
                    continue;
                }
                stage.refine(&fitness, finer.as_ref());
                last = Some(stage);
                break;
            }
            // A first pass that others follow polishes with the repasses' share of the budget: its light
            // only says where the next pass holds the bounce, and that pass polishes from there.
            let first_of_many = match &method {
                Method::Lshade(cfg) if passes > 1 => Some(Method::Lshade(LshadeConfig {
                    polish_evaluations: repass_polish(cfg.polish_evaluations),
                    ..cfg.clone()
                })),
                _ => None,
            };
            let stage = run_stage(
                &fitness,
                finer.as_ref(),
                &box_,
                first_of_many.as_ref().unwrap_or(&method),
                x0.as_deref(),
                with_products,
                // a pass that another follows gives only its light (the next holds the bounce there)
                pass + 1 == passes,
                |rep| {
                    history.push(Generation {
                        generation: generations + rep.generation,
                        best: rep.best.to_vec(),
                        objectives: rep.best_objectives.to_vec(),
                        evaluations: done + rep.evaluations,
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
                            (
                                generations + rep.generation,
                                best,
                                objectives,
                                done + rep.evaluations,
                                products,
                            ),
                        ) {
                            Ok(v) => !v.bind(py).is(&*pyo3::types::PyBool::new(py, false)),
                            Err(e) => {
                                error = Some(e);
                                false
                            }
                        }
                    })
                },
            )?;
            let stopped = stage.stop == crate::search::StopReason::Callback;
            last = Some(stage);
            if stopped {
                break;
            }
        }
        let mut result = last.expect("at least one pass");
        result.evaluations += done;
        result.generations += generations;
        Ok::<_, crate::error::Error>(result)
    })??;
    if let Some(e) = error {
        return Err(e);
    }
    Ok(OptimizeResult { result, history })
}

/// `optimize(frozen_bounce=N)`: each pass after the first searches this fraction of the previous pass's
/// box (per dimension, centred on its light, inside it): a pass moves the light by the change in the
/// held bounce, centimetres where the box spans metres.
const REPASS_BOX: f64 = 0.1;
/// A pass after the first is a Nelder–Mead polish from the previous pass's light (`stage::polish_stage`)
/// with this fraction of the polish budget, its initial simplex [`REPASS_STEP`] of the pass's box: on 14
/// bounce photos (the 6 test photos and 8 held-out ones) the mean light error 6.56 -> 6.55 mm (max 19.8
/// -> 19.5) against a full search (population and polish) per pass, for a third fewer evaluations.
/// The first pass's own polish takes the same fraction where passes follow it: on 25 bounce, lamp and
/// environment photos (11 test photos, 14 held out) the mean light error 8.84 -> 8.78 mm and the mean
/// worst product error 2.03 -> 1.95 %, for half the polish's evaluations (60 or 107 per bounce photo: a
/// quarter of the budget instead gave 9.02 mm, the median 5.7 -> 7.4 mm; none, 46.5 mm, the search's
/// best too coarse a start).
const REPASS_POLISH: f64 = 0.5;
const REPASS_STEP: f64 = 0.25;

/// The polish evaluations of a pass that other passes follow or precede ([`REPASS_POLISH`] of the
/// method's).
fn repass_polish(evaluations: usize) -> usize {
    (evaluations as f64 * REPASS_POLISH).ceil() as usize
}
/// `optimize(frozen_bounce=N)`: a pass after the second runs only where the previous pass moved some
/// searched parameter of the light by more than this fraction of its range (the search box's; a lobe's
/// shininess, which the diffuse bounce does not depend on, does not count): each pass holds the
/// bounce at the light the previous found, a fixed-point iteration that contracts the move about
/// threefold per pass; a light the first fit put far off (a term it lacked) takes three or four.
const REPASS_TOL: f64 = 1e-3;

#[pymodule(gil_used = false)]
fn _native(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<PyScene>()?;
    m.add_class::<OptimizeResult>()?;
    m.add_function(wrap_pyfunction!(render, m)?)?;
    m.add_function(wrap_pyfunction!(lights::fit_lights, m)?)?;
    m.add_function(wrap_pyfunction!(lights::lights_solve, m)?)?;
    m.add_function(wrap_pyfunction!(_kept_pools, m)?)?;
    m.add_function(wrap_pyfunction!(object_ids, m)?)?;
    m.add_function(wrap_pyfunction!(render_many, m)?)?;
    m.add_function(wrap_pyfunction!(render_layers, m)?)?;
    m.add_function(wrap_pyfunction!(composite, m)?)?;
    m.add_function(wrap_pyfunction!(save_image, m)?)?;
    m.add_function(wrap_pyfunction!(projection_blocker, m)?)?;
    m.add_function(wrap_pyfunction!(constant_term, m)?)?;
    m.add_function(wrap_pyfunction!(evaluate, m)?)?;
    m.add_function(wrap_pyfunction!(optimize, m)?)?;
    m.add_function(wrap_pyfunction!(fd_columns, m)?)?;
    m.add_function(wrap_pyfunction!(block_scores, m)?)?;
    m.add_function(wrap_pyfunction!(footprint_delta, m)?)?;
    m.add_function(wrap_pyfunction!(render_centre_and_footprint, m)?)?;
    m.add_function(wrap_pyfunction!(order_statistics, m)?)?;
    m.add_function(wrap_pyfunction!(noise_medians, m)?)?;
    m.add_function(wrap_pyfunction!(jpeg_phases, m)?)?;
    m.add_function(wrap_pyfunction!(codes8, m)?)?;
    m.add("RtloopError", m.py().get_type::<RtloopError>())?;
    m.add("SceneError", m.py().get_type::<SceneError>())?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    Ok(())
}
