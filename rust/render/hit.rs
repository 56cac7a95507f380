//! Where camera rays first meet the scene (`Geometry`, `Surfel`, `GBuffer`, `closest_hit`) and whether a
//! shadow ray is blocked (`occluded`).

use glam::Vec3A;
use rayon::prelude::*;

use super::camera::CameraFrame;
use super::shape::PShape;
use crate::geometry::ShapeHit;
use crate::scene::Scene;

/// The first hit of one camera sample: everything shading needs that the light and materials don't change.
#[derive(Clone, Copy, Debug)]
pub struct Surfel {
    pub position: Vec3A,
    /// Unit normal facing the viewer for planes (two-sided), outward for spheres.
    pub normal: Vec3A,
    /// Unit direction from the hit towards the eye.
    pub view: Vec3A,
    /// Index of the object hit, `u32::MAX` for a miss.
    pub object: u32,
    /// Scale-aware minimum distance for the shadow ray, from the hit point's rounding error.
    pub eps: f32,
}

impl Surfel {
    pub const MISS: Surfel = Surfel {
        position: Vec3A::ZERO,
        normal: Vec3A::ZERO,
        view: Vec3A::ZERO,
        object: u32::MAX,
        eps: 0.0,
    };

    /// The shadow ray's start `eps` of a point whose coordinates (and its shape's) are of size `scale`:
    /// the rounding error of a hit point there.
    #[inline]
    pub fn eps_at(scale: f32) -> f32 {
        64.0 * f32::EPSILON * scale
    }

    /// The open range (tmin, tmax) of the shadow ray from this point to a light `dist` away: from `eps`
    /// to just short of the light.
    #[inline]
    pub fn shadow_range(&self, dist: f32) -> (f32, f32) {
        (self.eps, dist * (1.0 - 4.0 * f32::EPSILON))
    }
}

/// The scene's fixed geometry in working form.
#[derive(Clone, Debug)]
pub struct Geometry {
    pub camera: CameraFrame,
    pub shapes: Vec<PShape>,
}

impl Geometry {
    pub fn new(scene: &Scene) -> Geometry {
        Geometry {
            camera: CameraFrame::new(&scene.camera),
            shapes: scene
                .objects
                .iter()
                .map(|o| PShape::new(&o.shape))
                .collect(),
        }
    }

    /// Closest hit along the camera ray through image position (`px`, `py`).
    pub fn primary(&self, px: f32, py: f32, width: u32, height: u32) -> Surfel {
        let dir = self.camera.generate_ray(px, py, width, height);
        closest_hit(&self.shapes, self.camera.origin, dir)
    }
}

/// The closest hit of the ray from `origin` along the unit `dir` among `shapes`, as a `Surfel`.
#[inline]
pub fn closest_hit(shapes: &[PShape], origin: Vec3A, dir: Vec3A) -> Surfel {
    let mut best: Option<(usize, ShapeHit)> = None;
    for (k, s) in shapes.iter().enumerate() {
        let tmax = best.map_or(f32::INFINITY, |(_, h)| h.t);
        if let Some(h) = s.intersect(origin, dir, 0.0, tmax) {
            best = Some((k, h));
        }
    }
    match best {
        None => Surfel::MISS,
        Some((k, h)) => {
            let mut normal = h.normal;
            if matches!(shapes[k], PShape::Plane { .. }) && normal.dot(dir) > 0.0 {
                normal = -normal;
            }
            // Rounding error of the hit point grows with the coordinates involved.
            let scale =
                h.position.abs().max_element() + shapes[k].scale() + origin.abs().max_element();
            Surfel {
                position: h.position,
                normal,
                view: -dir,
                object: k as u32,
                eps: Surfel::eps_at(scale),
            }
        }
    }
}

/// True if any object other than `skip` blocks the segment from `s` to the light.
///
/// A sphere (convex) or a plane can never shadow its own lit side, so the surface the point lies on is
/// not tested at all: no self-intersection and no offset that could leak light through thin occluders.
/// Meshes (two-sided: their normal already faces the viewer) are.
#[inline]
pub fn occluded(s: &Surfel, to_light: Vec3A, dist: f32, shapes: &[PShape]) -> bool {
    let (tmin, tmax) = s.shadow_range(dist);
    // A mesh need not be convex: it may shadow itself, so its own triangles are tested from `eps` on.
    shapes.iter().enumerate().any(|(k, sh)| {
        (k as u32 != s.object || matches!(sh, PShape::Mesh(_)))
            && sh.hits_segment(s.position, to_light, tmin, tmax)
    })
}

/// Camera-ray first hits at pixel centres for a `width` x `height` image, row-major.
#[derive(Clone, Debug)]
pub struct GBuffer {
    pub width: u32,
    pub height: u32,
    pub surfels: Vec<Surfel>,
}

impl GBuffer {
    pub fn new(geometry: &Geometry, width: u32, height: u32) -> GBuffer {
        let mut surfels = vec![Surfel::MISS; (width * height) as usize];
        surfels
            .par_chunks_mut(width as usize)
            .enumerate()
            .for_each(|(j, row)| {
                for (i, s) in row.iter_mut().enumerate() {
                    *s = geometry.primary(i as f32 + 0.5, j as f32 + 0.5, width, height);
                }
            });
        GBuffer {
            width,
            height,
            surfels,
        }
    }

    /// Object index per pixel, -1 for background.
    pub fn object_ids(&self) -> Vec<i32> {
        self.surfels
            .iter()
            .map(|s| {
                if s.object == u32::MAX {
                    -1
                } else {
                    s.object as i32
                }
            })
            .collect()
    }
}
