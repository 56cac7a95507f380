//! The renderer: camera rays -> closest hit -> direct lighting -> linear RGB image.
//!
//! The data flow is split at the first hit: `hit` finds what does not depend on the light or the
//! materials (`Surfel`: hit point, normal, view direction, object), and `shade` turns one into radiance
//! with the `brdf` and `light` formulas. A fit does not call `render`: the fitness evaluates the same
//! `brdf`/`light` formulas over precomputed first hits (see `crate::fitness`).

pub mod adaptive;
pub mod bounce;
pub mod brdf;
pub mod camera;
pub mod composite;
pub mod environment;
pub mod film;
pub mod footprint;
pub mod hit;
pub mod light;
pub mod mesh;
pub mod shade;
pub mod shape;

use glam::Vec3A;
use rayon::prelude::*;

use crate::error::{Error, Result};
use crate::scene::Scene;
pub use adaptive::{render_layers, Layers, Progress};
pub use camera::{sample_offsets, CameraFrame};
pub use composite::composite;
pub use film::{linear_to_srgb, save_srgb8, to_srgb8, Image};
pub use hit::{closest_hit, occluded, GBuffer, Geometry, Surfel};
pub use shade::{shade, shade_pixel, shade_shadowed, ShadeParams};
pub use shape::PShape;

/// Render `scene` at `width` x `height` (the scene's own size when `None`) with `spp` samples per pixel
/// (one: the pixel centre).
pub fn render(scene: &Scene, width: Option<u32>, height: Option<u32>, spp: u32) -> Result<Image> {
    render_with(scene, width, height, spp, false)
}

/// [`render`], with `footprint` (one sample per pixel): sphere shadow edges and terminators integrated
/// over each pixel's footprint in closed form, as the fitness with the footprint models a photo.
pub fn render_with(
    scene: &Scene,
    width: Option<u32>,
    height: Option<u32>,
    spp: u32,
    footprint: bool,
) -> Result<Image> {
    let width = width.unwrap_or(scene.width);
    let height = height.unwrap_or(scene.height);
    if width == 0 || height == 0 || width > 16384 || height > 16384 {
        return Err(Error::Invalid(format!(
            "image size must be 1..16384 pixels per side (got {width}x{height})"
        )));
    }
    if spp == 0 || spp > 4096 {
        return Err(Error::Invalid(format!("spp must be 1..4096 (got {spp})")));
    }
    let geometry = Geometry::new(scene);
    let mut params = ShadeParams::new(scene);
    params.prepare_bounce(&geometry.shapes);
    let shadows = scene.can_occlude();
    let offsets = sample_offsets(spp); // spp = 1: the pixel centre
                                       // The footprint (meshes aside, as the fitness refuses them) where the scene can shadow at all.
    if footprint && spp != 1 {
        return Err(Error::Invalid(format!(
            "the footprint render takes one sample per pixel (got spp {spp})"
        )));
    }
    let footprint =
        footprint && shadows && !geometry.shapes.iter().any(|s| matches!(s, PShape::Mesh(_)));
    let inv = 1.0 / offsets.len() as f32;
    let mut rgb = vec![0.0f32; (width * height * 3) as usize];
    rgb.par_chunks_mut(3 * width as usize)
        .enumerate()
        .for_each(|(j, row)| {
            for (i, px) in row.chunks_exact_mut(3).enumerate() {
                let mut sum = Vec3A::ZERO;
                for &(dx, dy) in &offsets {
                    let s = geometry.primary(i as f32 + dx, j as f32 + dy, width, height);
                    let axes = (footprint && s.object != u32::MAX).then(|| {
                        let shape = &geometry.shapes[s.object as usize];
                        let at = (i as u32, j as u32);
                        footprint::axes(&geometry.camera, &s, shape, at, (width, height))
                    });
                    sum += shade_pixel(&s, axes.as_ref(), &params, &geometry.shapes, shadows);
                }
                let v = (sum * inv).min(Vec3A::splat(f32::MAX));
                px.copy_from_slice(&v.to_array());
            }
        });
    Ok(Image { width, height, rgb })
}

/// Object index per pixel centre (-1 for background).
pub fn object_ids(scene: &Scene, width: Option<u32>, height: Option<u32>) -> Vec<i32> {
    let geometry = Geometry::new(scene);
    GBuffer::new(
        &geometry,
        width.unwrap_or(scene.width),
        height.unwrap_or(scene.height),
    )
    .object_ids()
}
