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
    // With the bounce, one sample per pixel: the light-independent gathers kept from the last render of
    // this geometry (`bounce::Gathered`; a fit's uncertainty renders it with the light moved).
    let c = &scene.camera;
    let camera_key = [
        c.position[0],
        c.position[1],
        c.position[2],
        c.look_at[0],
        c.look_at[1],
        c.look_at[2],
        c.up[0],
        c.up[1],
        c.up[2],
        c.vfov_deg,
    ];
    let cache = (params.interreflection && spp == 1)
        .then(|| {
            let sky = params.environment != Vec3A::ZERO;
            bounce::Gathered::for_render(&geometry, camera_key, (width, height), sky)
        })
        .flatten();
    match &cache {
        Some(cache) => params.prepare_bounce_cached(&geometry.shapes, cache),
        None => params.prepare_bounce(&geometry.shapes),
    }
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
                    let gathered = cache.as_ref().map(|c| c.pixel(j * width as usize + i));
                    sum += shade::shade_pixel_cached(
                        &s,
                        axes.as_ref(),
                        &params,
                        &geometry.shapes,
                        shadows,
                        gathered,
                    );
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

#[cfg(test)]
mod tests {
    use super::*;

    fn bounce_scene(light_x: f64, ball_y: f64, environment: f64) -> Scene {
        Scene::from_json(&format!(
            r#"{{"image": {{"width": 40, "height": 30}},
                "camera": {{"position": [0, 2, -5], "look_at": [0, 0.6, 0], "vfov_deg": 40}},
                "light": {{"position": [{light_x}, 3, -1], "intensity": 40}},
                "environment": [{environment}, {environment}, {environment}], "interreflection": true,
                "objects": [
                  {{"name": "ball", "shape": "sphere", "center": [0, {ball_y}, 0], "radius": 0.6,
                    "material": {{"albedo": [0.8, 0.2, 0.1]}}}},
                  {{"name": "small", "shape": "sphere", "center": [1.1, 0.3, -0.2], "radius": 0.3,
                    "material": {{"albedo": [0.2, 0.7, 0.3]}}}},
                  {{"name": "floor", "shape": "plane", "point": [0, 0, 0], "normal": [0, 1, 0],
                    "material": {{"albedo": [0.6, 0.6, 0.6]}}}}]}}"#
        ))
        .unwrap()
    }

    /// The render as it was before the gathers were kept: every pixel gathers its points itself.
    fn gathering(scene: &Scene, footprint: bool) -> Vec<f32> {
        let geometry = Geometry::new(scene);
        let mut params = ShadeParams::new(scene);
        params.prepare_bounce(&geometry.shapes);
        let (w, h) = (scene.width, scene.height);
        let mut out = Vec::new();
        for j in 0..h {
            for i in 0..w {
                let s = geometry.primary(i as f32 + 0.5, j as f32 + 0.5, w, h);
                let axes = (footprint && s.object != u32::MAX).then(|| {
                    let shape = &geometry.shapes[s.object as usize];
                    footprint::axes(&geometry.camera, &s, shape, (i, j), (w, h))
                });
                let v = shade_pixel(&s, axes.as_ref(), &params, &geometry.shapes, true);
                out.extend_from_slice(&v.min(Vec3A::splat(f32::MAX)).to_array());
            }
        }
        out
    }

    /// A render with interreflection keeps the light-independent gathers of its geometry
    /// (`bounce::Gathered`): renders that reuse them (the light moved, the environment switched on or
    /// off) and those that must not (the ball moved) give the gathering render's values bit for bit.
    #[test]
    fn kept_gathers_give_the_gathering_render_bit_for_bit() {
        let cases = [
            (0.5, 0.6, 0.0, false),
            (1.5, 0.6, 0.0, false),
            (1.5, 0.6, 0.0, true),
            (1.5, 0.6, 0.3, false),
            (-1.0, 0.6, 0.0, true),
            (-1.0, 0.65, 0.3, false),
            (-1.0, 0.65, 0.0, true),
        ];
        for (x, y, env, footprint) in cases {
            let scene = bounce_scene(x, y, env);
            let img = render_with(&scene, None, None, 1, footprint).unwrap();
            let want = gathering(&scene, footprint);
            assert_eq!(img.rgb.len(), want.len());
            for (k, (a, b)) in img.rgb.iter().zip(&want).enumerate() {
                assert_eq!(
                    a.to_bits(),
                    b.to_bits(),
                    "{x} {y} {env} {footprint}: value {k}"
                );
            }
        }
        // The bounce is in those values: without it the ball's underside is darker.
        let mut off = bounce_scene(0.5, 0.6, 0.0);
        off.interreflection = false;
        let with = render(&bounce_scene(0.5, 0.6, 0.0), None, None, 1).unwrap();
        let without = render(&off, None, None, 1).unwrap();
        assert!(with.rgb.iter().sum::<f32>() > without.rgb.iter().sum::<f32>() * 1.01);
    }
}
