//! The fit's pass driver through the core API (`rtloop::fit::run_passes`): a bounce fit of a small
//! rendered scene recovers its light. Run with `cargo test --test passes`.

#[path = "common/bounce_fit.rs"]
mod bounce_fit;

use bounce_fit::{bounce_fit, bounce_scene, clipped};

/// The held-bounce passes on rtloop's own render of the truth: there the held bounce at the true light
/// is the full one, so the passes' fixed point is the true light and only the polish's tolerance and
/// rounding stand between the two (about 10 µm and 1e-5 of the gauge, measured). The light must come
/// back within 1 mm (0.1 % of the 1.2 m box; a pass that stopped at the bounce-free fit's pull would be
/// centimetres off), the gauge (1 / intensity) within 1e-4 of 1/60.
#[test]
fn a_bounce_fit_recovers_the_light_of_its_render() {
    let scene = bounce_scene();
    let target = clipped(&scene);
    let mut reports = 0;
    let found = bounce_fit(&scene, &target, |_| {
        reports += 1;
        true
    });
    let truth = scene.light.position;
    let err = (0..3)
        .map(|i| (found.x[i] - truth[i]).powi(2))
        .sum::<f64>()
        .sqrt();
    assert!(err < 1e-3, "light {:?} is {err} m from {truth:?}", found.x);
    let gauge = found.gauge.expect("the bounce's gauge");
    assert!((gauge * 60.0 - 1.0).abs() < 1e-4, "gauge {gauge}");
    assert!(found.products.is_some() && reports > 0);
}
