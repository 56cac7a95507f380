//! Integration tests of `rtloop::fitness`, a module each: the fused kernel (SoA, blocked, shadow terms
//! precomputed) against the plain per-pixel path through the renderer's `shade` (tests/common), on random
//! scenes with shadows, several spheres, specular terms, ambient light and saturated objective pixels; the
//! closed form, the refine, the sRGB space, the SIMD paths, the footprint and the held bounce. Run with
//! `cargo test --test fitness`.

#[path = "../common/mod.rs"]
mod common;
#[path = "../common/targets.rs"]
mod targets;

use common::Oracle;
use rtloop::fitness::SATURATED;
use rtloop::search::{Objective, Rng};
use rtloop::{render, Fitness, FitnessSpec, LossKind, Norm, ParamLayout, Projection, Scene};

mod footprint;
mod held;
mod kernel;
mod lobe;
mod projected;
mod refine;
mod simd;
mod srgb;
pub(crate) use targets::{clipped_render, random_candidate};
#[allow(unused_imports)]
use {footprint::*, held::*, kernel::*, lobe::*, projected::*, refine::*, simd::*, srgb::*};

pub(crate) fn random_scene(rng: &mut Rng, spheres: usize, specular: bool, ambient: bool) -> Scene {
    let mut u = |lo: f64, hi: f64| lo + (hi - lo) * rng.uniform();
    let mut objects = Vec::new();
    for k in 0..spheres {
        let r = u(0.3, 1.0);
        let (ks, s) = if specular {
            (u(0.0, 0.5), u(1.0, 60.0))
        } else {
            (0.0, 0.0)
        };
        objects.push(format!(
            r#"{{"name": "s{k}", "shape": "sphere", "center": [{}, {r}, {}], "radius": {r},
               "material": {{"albedo": [{}, {}, {}], "specular": {ks}, "shininess": {s}}}}}"#,
            u(-2.0, 2.0),
            u(-1.5, 1.5),
            u(0.05, 1.0),
            u(0.05, 1.0),
            u(0.05, 1.0)
        ));
    }
    objects.push(format!(
        r#"{{"name": "floor", "shape": "plane", "point": [0, 0, 0], "normal": [{}, 1, {}],
           "material": {{"albedo": [{}, {}, {}]}}}}"#,
        u(-0.05, 0.05),
        u(-0.05, 0.05),
        u(0.1, 0.9),
        u(0.1, 0.9),
        u(0.1, 0.9)
    ));
    let amb = if ambient { u(0.0, 0.2) } else { 0.0 };
    let mut fit = vec![
        r#""light.position": {"min": [-6, 0.5, -6], "max": [6, 8, 6]}"#.to_string(),
        r#""light.intensity": {"min": 1, "max": 200}"#.to_string(),
    ];
    for k in 0..spheres {
        fit.push(format!(r#""objects.s{k}.albedo": {{"min": 0, "max": 1}}"#));
    }
    fit.push(r#""objects.floor.albedo": {"min": 0, "max": 1}"#.to_string());
    let text = format!(
        r#"{{"image": {{"width": 96, "height": 72}},
            "camera": {{"position": [{}, {}, -7], "look_at": [0, 0.7, 0], "vfov_deg": 40}},
            "light": {{"position": [{}, {}, {}], "intensity": {}}},
            "ambient": [{amb}, {amb}, {amb}], "exposure": {},
            "objects": [{}], "fit": {{{}}}}}"#,
        u(-1.0, 1.0),
        u(1.0, 3.0),
        u(-4.0, 4.0),
        u(1.0, 6.0),
        u(-4.0, 4.0),
        u(20.0, 120.0),
        u(0.7, 1.5),
        objects.join(","),
        fit.join(",")
    );
    Scene::from_json(&text).unwrap()
}

/// A fitness of all of `layout` over the whole image, no closed-form products.
pub(crate) fn fitness(
    scene: &Scene,
    layout: &ParamLayout,
    target: &[f32],
    kind: LossKind,
    clip: bool,
) -> Fitness {
    Fitness::new(
        scene,
        layout.clone(),
        target,
        FitnessSpec {
            loss: kind,
            clip,
            ..Default::default()
        },
    )
    .unwrap()
}

/// The closed-form (projected) fitness of `layout` over the whole image.
pub(crate) fn projected(
    scene: &Scene,
    layout: ParamLayout,
    target: &[f32],
    proj: Projection,
    clip: bool,
) -> Fitness {
    Fitness::new(
        scene,
        layout,
        target,
        FitnessSpec {
            loss: LossKind::L1Projected,
            clip,
            projection: Some(proj),
            ..Default::default()
        },
    )
    .unwrap()
}

/// [`projected`] with every object's (matte) products bounded to [0, 200] in each channel.
pub(crate) fn matte_projected(
    scene: &Scene,
    layout: ParamLayout,
    target: &[f32],
    clip: bool,
) -> Fitness {
    let bounds = vec![[(0.0, 200.0); 3]; scene.objects.len()];
    projected(scene, layout, target, Projection::matte(bounds), clip)
}

/// [`Objective::evaluate_alone`] of `x` (one candidate spread over the pool) on a pool of `threads`.
pub(crate) fn alone_on(f: &Fitness, x: &[f64], threads: usize) -> f64 {
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .unwrap();
    let mut alone = [0.0];
    pool.install(|| f.evaluate_alone(x, &mut alone));
    alone[0]
}

/// The kernel's channel losses at `x` against the plain per-pixel path's (`reference_channel_losses`): each
/// [`close`] within `rel`, give or take `slack`; `what` names the case.
pub(crate) fn assert_matches_reference(
    f: &Fitness,
    x: &[f64],
    (rel, slack): (f64, f64),
    what: &str,
) {
    let (a, b) = (f.channel_losses(x), f.reference_channel_losses(x));
    for c in 0..3 {
        assert!(
            (a[c] - b[c]).abs() <= rel * a[c].abs().max(b[c].abs()).max(1.0) + slack,
            "{what} channel {c}: {a:?} vs {b:?}"
        );
    }
}

/// The loss at the scene's own values `truth`, asserted below `bound` (it vanishes up to rounding and the
/// table encoding); `what` names the case.
pub(crate) fn loss_at_truth(f: &Fitness, truth: &[f64], bound: f64, what: &str) -> f64 {
    let at_truth: f64 = f.channel_losses(truth).iter().sum();
    assert!(at_truth < bound, "{what}: loss at the truth {at_truth}");
    at_truth
}

/// `clean` with uniform noise `amplitude` wide added to every value, clamped to [0, 1].
pub(crate) fn noisy(clean: &[f32], rng: &mut Rng, amplitude: f32) -> Vec<f32> {
    clean
        .iter()
        .map(|v| (v + amplitude * (rng.uniform() as f32 - 0.5)).clamp(0.0, 1.0))
        .collect()
}

/// Relative difference with a floor: the losses are sums over ~7000 pixels x 3 channels of f32 terms.
pub(crate) fn close(a: f64, b: f64, rel: f64) -> bool {
    (a - b).abs() <= rel * a.abs().max(b.abs()).max(1.0)
}
