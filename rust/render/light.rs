//! The light: a point light (inverse-square fall-off) or a directional one; direction, distance and
//! irradiance at a surface point. `shade` uses the vector forms; the fitness kernel the scalar form over
//! its structure-of-arrays data (it rounds differently, and each is pinned as it is).

use glam::Vec3A;

/// Unit direction towards the light, its distance and the inverse-square factor 1/d², at `p`.
/// `None` for a point light on the surface itself (d = 0): it lies in the tangent plane, no direct light.
#[inline(always)]
pub fn incidence(position: Vec3A, direction: Option<Vec3A>, p: Vec3A) -> Option<(Vec3A, f32, f32)> {
    match direction {
        // Directional: no fall-off, shadow rays to infinity.
        Some(dir) => Some((dir, f32::INFINITY, 1.0)),
        None => {
            let d = position - p;
            let d2 = d.length_squared();
            if d2 <= f32::MIN_POSITIVE {
                return None;
            }
            let dist = d2.sqrt();
            Some((d / dist, dist, 1.0 / d2))
        }
    }
}

/// Irradiance from a unit light: cos θ times the fall-off, clamped so that a light almost touching the
/// surface gives a huge but finite value.
#[inline(always)]
pub fn irradiance(cos: f32, falloff: f32) -> f32 {
    (cos * falloff).min(f32::MAX)
}

/// The unit direction towards the light as the kernel's lobe uses it (zero for a light at `p`).
#[inline(always)]
pub fn toward(position: Vec3A, direction: Option<Vec3A>, p: Vec3A) -> Vec3A {
    match direction {
        Some(d) => d,
        None => (position - p).normalize_or_zero(),
    }
}

/// max(0, n·d)/|d|³ for the offset `d` = light - p and normal `n` (scalar form, unit light): the point
/// light's irradiance; 0 for a light on the surface.
#[inline(always)]
pub fn point_irradiance(d: [f32; 3], n: [f32; 3]) -> f32 {
    point_irradiance_in(d, n)
}

/// [`point_irradiance`] on one value or on lanes of values (the fitness kernel's AVX2 form): the sums
/// (x·x + y·y) + z·z, the correctly rounded square root and division, the same operations in the same
/// order for both (a lane's multiply-add is fused).
#[inline(always)]
pub fn point_irradiance_in<T: Lanes>([dx, dy, dz]: [T; 3], n: [T; 3]) -> T {
    let d2 = dz.mul_add(dz, dy.mul_add(dy, dx.mul(dx)));
    let nl = n[2].mul_add(dz, n[1].mul_add(dy, n[0].mul(dx))).max0();
    let v = nl.div(d2.mul(d2.sqrt())).min(T::splat(f32::MAX));
    v.where_above(d2, T::splat(f32::MIN_POSITIVE))
}

/// The arithmetic of [`point_irradiance_in`]: on `f32`, and on a vector of lanes.
pub trait Lanes: Copy {
    fn splat(v: f32) -> Self;
    fn mul(self, b: Self) -> Self;
    /// self·b + c: rounded twice on `f32` (Rust does not fuse it), once on lanes (a fused multiply-add).
    fn mul_add(self, b: Self, c: Self) -> Self;
    fn div(self, b: Self) -> Self;
    fn sqrt(self) -> Self;
    /// max(self, 0), 0 for NaN.
    fn max0(self) -> Self;
    /// min(self, b), b for NaN.
    fn min(self, b: Self) -> Self;
    /// self where `x` > `limit`, else 0.
    fn where_above(self, x: Self, limit: Self) -> Self;
}

impl Lanes for f32 {
    #[inline(always)]
    fn splat(v: f32) -> f32 {
        v
    }
    #[inline(always)]
    fn mul(self, b: f32) -> f32 {
        self * b
    }
    #[inline(always)]
    fn mul_add(self, b: f32, c: f32) -> f32 {
        // (c + self·b, as x·x + y·y is summed: IEEE addition is commutative)
        self * b + c
    }
    #[inline(always)]
    fn div(self, b: f32) -> f32 {
        self / b
    }
    #[inline(always)]
    fn sqrt(self) -> f32 {
        f32::sqrt(self)
    }
    #[inline(always)]
    fn max0(self) -> f32 {
        self.max(0.0)
    }
    #[inline(always)]
    fn min(self, b: f32) -> f32 {
        f32::min(self, b)
    }
    #[inline(always)]
    fn where_above(self, x: f32, limit: f32) -> f32 {
        if x > limit {
            self
        } else {
            0.0
        }
    }
}

/// max(0, n·l) for a directional light's unit direction `l` (scalar form).
#[inline(always)]
pub fn directional_irradiance(l: [f32; 3], n: [f32; 3]) -> f32 {
    (n[0] * l[0] + n[1] * l[1] + n[2] * l[2]).max(0.0)
}

/// The unit vector along `d`; straight up for a zero (or non-finite) candidate direction.
pub fn unit_or_up(d: Vec3A) -> Vec3A {
    d.try_normalize().unwrap_or(Vec3A::Y)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn point_forms_agree_and_the_surface_gets_nothing() {
        let (p, n, l) = (Vec3A::ZERO, Vec3A::Y, Vec3A::new(1.0, 2.0, 0.5));
        let (dir, dist, falloff) = incidence(l, None, p).unwrap();
        let e = irradiance(n.dot(dir), falloff);
        let s = point_irradiance((l - p).to_array(), n.to_array());
        assert!((e - s).abs() < 1e-6 * s && (dist - l.length()).abs() < 1e-6);
        assert!(incidence(p, None, p).is_none());
        assert_eq!(point_irradiance([0.0; 3], n.to_array()), 0.0);
        assert_eq!(directional_irradiance([0.0, -1.0, 0.0], n.to_array()), 0.0);
        assert_eq!(toward(p, None, p), Vec3A::ZERO);
    }
}
