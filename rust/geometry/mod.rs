//! The shapes' geometry below both the scene format and the renderer: the hit record, the ray–sphere
//! and ray–plane tests and triangle meshes with their BVH. It knows nothing of scenes or shading.

use glam::Vec3A;

pub mod mesh;
pub mod plane;
pub mod sphere;

/// A ray–shape hit: distance along the (unit) ray and the outward/geometric normal.
#[derive(Clone, Copy, Debug)]
pub struct ShapeHit {
    pub t: f32,
    /// Hit point; for spheres computed as centre + local offset.
    pub position: Vec3A,
    /// Unit normal (outward for spheres; the plane's own normal, not yet flipped toward the viewer).
    pub normal: Vec3A,
}
