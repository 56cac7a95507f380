//! `evaluate` and `optimize`: the fitness's values and the search, stage by stage.

use numpy::{
    PyArray1, PyArray2, PyArrayMethods, PyReadonlyArray1, PyReadonlyArray2, PyReadonlyArray3,
};
use pyo3::prelude::*;

use super::fitness::{fitness_args, Generation, OptimizeResult};
use super::pool::detach_in_pool;
use super::scene::PyScene;
use crate::error::Error;
use crate::search::{lshade::LshadeConfig, Budget, Method, Objective};
use crate::stage::run_stage;

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
pub(super) fn evaluate<'py>(
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
pub(super) fn optimize<'py>(
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
