//! Every light after the first, and the sphere light's soft shadow: the unit-intensity irradiance a light
//! gives a surface point, shadowed. `shade` adds each light's term through the same BRDF as the first
//! light's; the lights fit (`fitness::lights`) uses the same irradiance as its linear columns.
//!
//! A sphere light of radius r and intensity I (radiance I/(pi r^2)) gives an unoccluded point above its
//! horizon exactly the irradiance I cos(theta)/d^2 of a point light at its centre; an occluder hides part
//! of it: the visible fraction is estimated from `SOFT_SAMPLES` fixed points of a sunflower spiral on the disc the
//! sphere shows the point (no random numbers: the same image on any thread count).
//!
//! A rectangle light (a window) of area A and intensity I (its radiant intensity along its normal;
//! radiance I/A) is integrated by the midpoint rule over a fixed `RECT_GRID` x `RECT_GRID` grid of cells:
//! each cell's centre q is a small emitter of intensity I/N along the normal, giving
//! (I/N) cos(theta_e) cos(theta) / |q - x|^2, shadowed by its own shadow ray. One-sided: a point behind
//! the rectangle's plane gets nothing. The same grid makes its soft shadow.

use glam::Vec3A;

use super::hit::{occluded, Surfel};
use super::light::{incidence, irradiance, unit_or_up};
use super::shape::PShape;
use crate::scene::PointLight;

/// The shadow rays per sphere light and surface point.
pub const SOFT_SAMPLES: usize = 16;

/// A rectangle light's grid: `RECT_GRID` x `RECT_GRID` cells, one shadow ray each.
pub const RECT_GRID: usize = 4;

/// A rectangle light in working form: half its width along `half_u`, half its height along `half_v`,
/// shining towards the unit `normal`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RectAxes {
    pub half_u: Vec3A,
    pub half_v: Vec3A,
    pub normal: Vec3A,
}

impl RectAxes {
    pub fn new(r: &crate::scene::RectLight) -> RectAxes {
        let n = glam::DVec3::from_array(r.normal);
        let up = glam::DVec3::from_array(r.up);
        let u = up.cross(n).normalize_or_zero();
        RectAxes {
            half_u: (u * (0.5 * r.size[0])).as_vec3a(),
            half_v: (up * (0.5 * r.size[1])).as_vec3a(),
            normal: n.as_vec3a(),
        }
    }

    /// The same rectangle with its width and height set to `size` (metres; each at least
    /// `scene::MIN_SIZE`), its centre and orientation kept.
    pub fn resized(&self, size: [f64; 2]) -> RectAxes {
        use crate::scene::positive_size;
        RectAxes {
            half_u: self.half_u.normalize_or_zero() * (0.5 * positive_size(size[0])) as f32,
            half_v: self.half_v.normalize_or_zero() * (0.5 * positive_size(size[1])) as f32,
            normal: self.normal,
        }
    }
}

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
    /// A rectangle light's shape (centred at `position`).
    pub rect: Option<RectAxes>,
}

impl Emitter {
    pub fn new(l: &PointLight) -> Emitter {
        let v3 = |a: [f64; 3]| glam::DVec3::from_array(a).as_vec3a();
        Emitter {
            position: v3(l.position),
            direction: l.direction.map(|d| unit_or_up(v3(d))),
            intensity: l.intensity as f32,
            color: v3(l.color),
            radius: l.radius as f32,
            rect: l.rect.as_ref().map(RectAxes::new),
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
    if let Some(r) = &e.rect {
        return rect_irradiance(s, e.position, r, shapes, shadows);
    }
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

/// A unit-intensity rectangle light's irradiance at `s` (the midpoint rule over its fixed grid, each
/// cell's shadow ray when `shadows`) and the unit direction its light arrives from on average (for the
/// specular lobe); `None` where no cell lights the point.
pub fn rect_irradiance(
    s: &Surfel,
    center: Vec3A,
    r: &RectAxes,
    shapes: &[PShape],
    shadows: bool,
) -> Option<(Vec3A, f32)> {
    let mut sum = 0.0f32;
    let mut towards = Vec3A::ZERO;
    for i in 0..RECT_GRID {
        for j in 0..RECT_GRID {
            let a = (2.0 * i as f32 + 1.0) / RECT_GRID as f32 - 1.0;
            let b = (2.0 * j as f32 + 1.0) / RECT_GRID as f32 - 1.0;
            let w = center + a * r.half_u + b * r.half_v - s.position;
            let d2 = w.length_squared();
            if !(d2 > f32::MIN_POSITIVE) {
                continue;
            }
            let dist = d2.sqrt();
            let dir = w / dist;
            let (cos, cos_e) = (s.normal.dot(dir), -r.normal.dot(dir));
            if cos <= 0.0 || cos_e <= 0.0 || (shadows && occluded(s, dir, dist, shapes)) {
                continue;
            }
            let e = cos * cos_e / d2;
            sum += e;
            towards += e * dir;
        }
    }
    let sum = (sum / (RECT_GRID * RECT_GRID) as f32).min(f32::MAX);
    (sum > 0.0).then(|| {
        let fallback = (center - s.position).normalize_or_zero();
        (towards.normalize_or(fallback), sum)
    })
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
