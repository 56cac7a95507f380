//! Every light after the first, and the sphere light's soft shadow: the unit-intensity irradiance a light
//! gives a surface point, shadowed. `shade` adds each light's term through the same BRDF as the first
//! light's; the lights fit (`fitness::lights`) uses the same irradiance as its linear columns.
//!
//! A sphere light of radius r and intensity I (radiance I/(pi r^2)) gives an unoccluded point above its
//! horizon exactly the irradiance I cos(theta)/d^2 of a point light at its centre; an occluder hides part
//! of it: the visible fraction is estimated from `SOFT_SAMPLES` fixed points of a sunflower spiral on the disc the
//! sphere shows the point (no random numbers: the same image on any thread count).

use glam::Vec3A;

use super::hit::{occluded, Surfel};
use super::light::{incidence, irradiance};
use super::shape::PShape;
use crate::scene::PointLight;

/// The shadow rays per sphere light and surface point.
pub const SOFT_SAMPLES: usize = 16;

/// A light in working form.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Emitter {
    pub position: Vec3A,
    /// `Some(unit vector towards the light)` for a directional light.
    pub direction: Option<Vec3A>,
    pub intensity: f32,
    pub color: Vec3A,
    /// 0 for a point or directional light.
    pub radius: f32,
}

impl Emitter {
    pub fn new(l: &PointLight) -> Emitter {
        let v3 = |a: [f64; 3]| glam::DVec3::from_array(a).as_vec3a();
        Emitter {
            position: v3(l.position),
            direction: l.direction.map(|d| super::shade::unit_or_up(v3(d))),
            intensity: l.intensity as f32,
            color: v3(l.color),
            radius: l.radius as f32,
        }
    }

    /// Intensity times colour, per channel.
    pub fn rgb(&self) -> Vec3A {
        self.color * self.intensity
    }
}

/// The fixed points of the unit disc: a sunflower (Vogel) spiral, point k at radius sqrt((k + 1/2)/n)
/// and the golden angle apart, so that every ring and every sector of the disc holds its share of
/// points (each of the n radii its own: an occluder's edge moves the count one point at a time).
fn disc_points() -> [[f32; 2]; SOFT_SAMPLES] {
    let golden = std::f64::consts::PI * (3.0 - 5f64.sqrt());
    std::array::from_fn(|k| {
        let r = ((k as f64 + 0.5) / SOFT_SAMPLES as f64).sqrt();
        let phi = k as f64 * golden;
        [(r * phi.cos()) as f32, (r * phi.sin()) as f32]
    })
}

/// The fraction of a sphere light (centre `center`, `radius`) that `s` sees past the scene's shapes:
/// shadow rays to the fixed points of the disc it shows `s`. 1 for a point inside the light.
pub fn sphere_visibility(s: &Surfel, center: Vec3A, radius: f32, shapes: &[PShape]) -> f32 {
    let w = center - s.position;
    let d = w.length();
    if !(d > radius) {
        return 1.0;
    }
    let w = w / d;
    let a = w.any_orthonormal_vector();
    let b = w.cross(a);
    // The disc of the sphere's silhouette seen from `s`: its radius and distance along `w`.
    let sin = radius / d;
    let rim = radius * (1.0 - sin * sin).max(0.0).sqrt();
    let base = s.position + w * (d - radius * sin);
    let mut seen = 0u32;
    for [u, v] in disc_points() {
        let q = base + rim * (u * a + v * b);
        let to = q - s.position;
        let dist = to.length();
        if dist > 0.0 && !occluded(s, to / dist, dist, shapes) {
            seen += 1;
        }
    }
    seen as f32 / SOFT_SAMPLES as f32
}

/// The unit-intensity irradiance (cos(theta) x fall-off x visibility) and the unit direction to the
/// light `e` at `s`, with shadow rays when `shadows`; `None` where the light is behind the surface or
/// fully hidden.
#[inline]
pub fn unit_irradiance(
    s: &Surfel,
    e: &Emitter,
    shapes: &[PShape],
    shadows: bool,
) -> Option<(Vec3A, f32)> {
    let (dir, dist, falloff) = incidence(e.position, e.direction, s.position)?;
    let ndotl = s.normal.dot(dir);
    if ndotl <= 0.0 {
        return None;
    }
    let visible = match (shadows, e.radius > 0.0 && e.direction.is_none()) {
        (false, _) => 1.0,
        (true, false) => f32::from(u8::from(!occluded(s, dir, dist, shapes))),
        (true, true) => sphere_visibility(s, e.position, e.radius, shapes),
    };
    (visible > 0.0).then(|| (dir, irradiance(ndotl, falloff) * visible))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn disc_points_share_the_disc_area_ring_by_ring() {
        let pts = disc_points();
        for k in 0..=100 {
            let rho = k as f32 / 100.0;
            let inside = pts
                .iter()
                .filter(|[x, y]| x * x + y * y < rho * rho)
                .count() as f32;
            let share = inside / SOFT_SAMPLES as f32;
            assert!(
                (share - rho * rho).abs() <= 0.5 / SOFT_SAMPLES as f32 + 1e-6,
                "{rho}: {share}"
            );
        }
    }
}
