//! Objectives and candidates shared by the fitness tests and the benches.

use rtloop::search::Rng;
use rtloop::{render, ParamLayout, Scene};

/// The scene's render as the fitness models pixels, clipped at 1 as a photo saturates.
pub fn clipped_render(scene: &Scene) -> Vec<f32> {
    render(scene, None, None, 1)
        .unwrap()
        .rgb
        .iter()
        .map(|v| v.min(1.0))
        .collect()
}

/// A candidate drawn uniformly within the bounds of `layout`, one draw of `rng` per parameter in order.
pub fn random_candidate(rng: &mut Rng, layout: &ParamLayout) -> Vec<f64> {
    layout
        .bounds
        .iter()
        .map(|&(lo, hi)| lo + (hi - lo) * rng.uniform())
        .collect()
}
