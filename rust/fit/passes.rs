//! The held-bounce pass driver. With interreflection the closed form's full bounce is a fixed point per
//! evaluation; a pass instead ranks lights with the bounce held at one light (`Fitness::freeze_bounce`),
//! costing a direct evaluation each. The first pass holds it at the scene's own values and searches the
//! whole box; each later pass holds it at the light the previous pass found and polishes from there, in a
//! box around it, until the light stops moving (the held bounce's fixed point) or the passes run out.

use super::outlines::outline_gate;
use crate::error::{Error, Result};
use crate::fitness::{Fitness, FitnessSpec};
use crate::params::ParamLayout;
use crate::scene::Scene;
use crate::search::{lshade::LshadeConfig, Method, StopReason};
use crate::stage::{polish_stage, run_stage, StageReport, StageResult};

/// How [`run_passes`] searches, besides its method. `PassOptions::default()` is one search with the full
/// bounce, no start point and no products in the reports.
#[derive(Clone, Debug, Default)]
pub struct PassOptions {
    /// With interreflection (the projected loss), 1 or more: the search ranks lights with the bounce held
    /// at the scene's own values (each evaluation then costs a direct one's), and the result's products
    /// and loss are the full bounce's at the found light; `passes` = N > 1 adds up to N - 1 passes, each
    /// holding the bounce at the light the previous found and polishing from there ([`REPASS_POLISH`], as
    /// the first pass's own polish then), a third and later one only while the previous pass moved the
    /// light by more than [`REPASS_TOL`]. 0 (or a scene without a bounce to hold): one search, the full
    /// bounce in every evaluation.
    pub passes: usize,
    /// The pixel footprint ([`FitnessSpec::footprint`]) in the polish (and the products and loss
    /// reported) only, the search at pixel centres: both from one set-up.
    pub polish_footprint: bool,
    /// A point (one value per searched parameter, clamped to their bounds) that L-SHADE's initial
    /// population holds, so that a search refining it never ends worse than it (L-SHADE only).
    pub start: Option<Vec<f64>>,
    /// The reports carry the closed-form products of the best (projected loss only).
    pub with_products: bool,
    /// With `polish_footprint` (and no bounce): the outline gate (`fit::outlines`) after the search, the
    /// outlines integrated where the photo shows it needs them. `FitnessSpec::outlines` instead takes them
    /// in every evaluation of the footprint.
    pub outline_gate: bool,
}

/// Each pass after the first searches this fraction of the previous pass's box (per dimension, centred
/// on its light, inside it): a pass moves the light by the change in the held bounce, centimetres where
/// the box spans metres.
pub const REPASS_BOX: f64 = 0.1;
/// A pass after the first is a Nelder–Mead polish from the previous pass's light (`stage::polish_stage`)
/// with this fraction of the polish budget, its initial simplex [`REPASS_STEP`] of the pass's box: on 14
/// bounce photos (the 6 test photos and 8 held-out ones) the mean light error 6.56 -> 6.55 mm (max 19.8
/// -> 19.5) against a full search (population and polish) per pass, for a third fewer evaluations.
/// The first pass's own polish takes the same fraction where passes follow it: on 25 bounce, lamp and
/// environment photos (11 test photos, 14 held out) the mean light error 8.84 -> 8.78 mm and the mean
/// worst product error 2.03 -> 1.95 %, for half the polish's evaluations (60 or 107 per bounce photo: a
/// quarter of the budget instead gave 9.02 mm, the median 5.7 -> 7.4 mm; none, 46.5 mm, the search's
/// best too coarse a start).
pub const REPASS_POLISH: f64 = 0.5;
pub const REPASS_STEP: f64 = 0.25;
/// A pass after the second runs only where the previous pass moved some searched parameter of the light
/// by more than this fraction of its range (the search box's; a lobe's shininess, which the diffuse
/// bounce does not depend on, does not count): each pass holds the bounce at the light the previous
/// found, a fixed-point iteration that contracts the move about threefold per pass; a light the first
/// fit put far off (a term it lacked) takes three or four.
pub const REPASS_TOL: f64 = 1e-3;

/// The polish evaluations of a pass that other passes follow or precede ([`REPASS_POLISH`] of the
/// method's).
fn repass_polish(evaluations: usize) -> usize {
    (evaluations as f64 * REPASS_POLISH).ceil() as usize
}

/// Hold the bounce (at `at`, else at the scene's own values) for the search and the polish alike (a polish
/// on the full bounce would cost the full fixed point per evaluation); false where there is none to hold.
/// One fixed point for both: the footprint fitness's (`finer`) bounce, held for the pixel-centre search
/// as well (the same pixels; the bounce differs between the two only through their products).
fn freeze(fitness: &mut Fitness, finer: &mut Option<Fitness>, at: Option<&[f64]>) -> bool {
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

/// Fit `layout`'s parameters of `scene` to `target` (linear RGB at the scene's size, row-major, 3 floats
/// per pixel): the fitness `spec` describes, searched with `method` within the layout's bounds, in
/// [`PassOptions::passes`] held-bounce passes where the scene has a bounce. `callback` runs after each
/// pass's initial population and every generation (returning `false` stops), its generation and
/// evaluation counts running on across the passes. The result's evaluations and generations are all the
/// passes'; its products and loss are the refined ones at the found light (`StageResult::refine`).
/// Runs on the current rayon pool.
pub fn run_passes<C>(
    scene: &Scene,
    layout: ParamLayout,
    target: &[f32],
    spec: FitnessSpec,
    method: &Method,
    options: &PassOptions,
    mut callback: C,
) -> Result<StageResult>
where
    C: FnMut(&StageReport) -> bool,
{
    let bounds = layout.bounds.clone();
    if let Some(x0) = &options.start {
        if x0.len() != bounds.len() || x0.iter().any(|v| !v.is_finite()) {
            return Err(Error::Invalid(format!(
                "x0: needs {} finite values, one per searched parameter ({}) (got {:?})",
                bounds.len(),
                layout.names.join(", "),
                x0
            )));
        }
    }
    // The light's searched parameters: where the bounce is held depends on them alone (a lobe's shininess
    // shapes no diffuse bounce), so a pass's move is measured on them (on every parameter if none is).
    let names = &layout.names;
    let light_dims: Vec<bool> = if names.iter().any(|n| n.starts_with("light.")) {
        names.iter().map(|n| n.starts_with("light.")).collect()
    } else {
        vec![true; names.len()]
    };
    // Where only the polish takes the pixel footprint, the search's fitness is the polish's at pixel
    // centres (one set-up for both).
    let only_polish = options.polish_footprint && !spec.footprint;
    let gated = options.outline_gate && only_polish && !spec.outlines && !scene.interreflection;
    let spec = FitnessSpec {
        footprint: spec.footprint || only_polish,
        outline_gate: gated,
        ..spec
    };
    // where the gate fires, the fitness with the outlines integrated is built from the same arguments
    let gate = gated.then(|| (layout.clone(), spec.clone()));
    let built = Fitness::new(scene, layout, target, spec)?;
    let (mut fitness, mut finer) = if only_polish {
        (built.at_pixel_centres(), Some(built))
    } else {
        (built, None)
    };
    let passes = if options.passes > 0 && freeze(&mut fitness, &mut finer, None) {
        options.passes
    } else {
        1
    };
    let (mut done, mut generations) = (0, 0);
    let mut last: Option<StageResult> = None;
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
        // A later pass polishes from the light the previous one found (its population would only find
        // the same basin again); a method without a polish searches as the first pass did.
        let polishes = match method {
            Method::Lshade(cfg) if cfg.polish_evaluations > 0 => Some(cfg),
            _ => None,
        };
        if let (Some(prev), Some(cfg)) = (&last, polishes) {
            let mut stage = polish_stage(
                &fitness,
                finer.as_ref(),
                &box_,
                &prev.x,
                REPASS_STEP,
                repass_polish(cfg.polish_evaluations),
                cfg.polish_x_tol,
            )?;
            // Another pass holds the bounce where this one ended, unless it barely moved the light from
            // where this one held it: the passes have reached the held bounce's fixed point.
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
        // A first pass that others follow polishes with the repasses' share of the budget: its light only
        // says where the next pass holds the bounce, and that pass polishes from there.
        let first_of_many = match method {
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
            first_of_many.as_ref().unwrap_or(method),
            options.start.as_deref(),
            options.with_products,
            // a pass that another follows gives only its light (the next holds the bounce there)
            pass + 1 == passes,
            |rep| {
                callback(&StageReport {
                    generation: generations + rep.generation,
                    best: rep.best,
                    best_objectives: rep.best_objectives,
                    evaluations: done + rep.evaluations,
                    products: rep.products.clone(),
                })
            },
        )?;
        let stopped = stage.stop == StopReason::Callback;
        last = Some(stage);
        if stopped {
            break;
        }
    }
    let mut result = last.expect("at least one pass");
    if let (Some((layout, spec)), Method::Lshade(cfg), Some(finer)) = (gate, method, &finer) {
        if result.stop != StopReason::Callback && result.products.is_some() {
            let budget = (cfg.polish_evaluations, cfg.polish_x_tol);
            let model = (scene, layout, target, spec);
            result.outlines = outline_gate(finer, model, &bounds, budget, &mut result)?;
        }
    }
    result.evaluations += done;
    result.generations += generations;
    Ok(result)
}
