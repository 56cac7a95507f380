//! One bounce fit through the core's pass driver (`rtloop::fit::run_passes`), shared by tests/passes.rs
//! and benches/passes.rs: a red ball on a grey floor with interreflection (the floor's bounce lights the
//! ball's underside), 80 x 60, its light at [1.5, 3.5, -2] and intensity 60; the objective is its own
//! render clipped at 1 (as the fitness clips); the light's position is searched within +-0.6 m with the
//! closed form (matte products) in three held-bounce passes, L-SHADE 12 x 20 with a 200-evaluation polish.

use rtloop::fit::{run_passes, PassOptions};
use rtloop::search::{Budget, Method};
use rtloop::{render, FitnessSpec, LossKind, ParamLayout, Projection, Scene, StageResult};

pub fn bounce_scene() -> Scene {
    Scene::from_json(
        r#"{"image": {"width": 80, "height": 60},
            "camera": {"position": [0, 1.5, -6], "look_at": [0, 0.6, 0], "vfov_deg": 35},
            "light": {"position": [1.5, 3.5, -2.0], "intensity": 60},
            "interreflection": true,
            "objects": [
              {"name": "ball", "shape": "sphere", "center": [0, 0.8, 0], "radius": 0.8,
               "material": {"albedo": [0.7, 0.3, 0.2]}},
              {"name": "floor", "shape": "plane", "point": [0, 0, 0], "normal": [0, 1, 0],
               "material": {"albedo": [0.6, 0.6, 0.6]}}],
            "fit": {"light.position": {"min": [0.9, 2.9, -2.6], "max": [2.1, 4.1, -1.4]}}}"#,
    )
    .unwrap()
}

/// The render of `scene` clipped at 1.
pub fn clipped(scene: &Scene) -> Vec<f32> {
    let image = render(scene, None, None, 1).unwrap();
    image.rgb.iter().map(|v| v.min(1.0)).collect()
}

/// The fit of [`bounce_scene`]'s light to `target`; `callback` sees every generation's report.
pub fn bounce_fit(
    scene: &Scene,
    target: &[f32],
    callback: impl FnMut(&rtloop::stage::StageReport) -> bool,
) -> StageResult {
    let layout = ParamLayout::new(scene, &["light.position".to_string()]).unwrap();
    let products = vec![[(0.0, 400.0); 3]; scene.objects.len()];
    let spec = FitnessSpec {
        loss: LossKind::L1Projected,
        projection: Some(Projection::matte(products)),
        ..Default::default()
    };
    let budget = Budget {
        population: 12,
        generations: 20,
        f: 0.6,
        cr: 0.8,
        seed: 3,
        max_evaluations: None,
        polish: 200,
        polish_tol: None,
    };
    let method = Method::named("lshade", &budget).unwrap();
    let options = PassOptions {
        passes: 3,
        ..Default::default()
    };
    run_passes(scene, layout, target, spec, &method, &options, callback).unwrap()
}
