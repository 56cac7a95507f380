//! Ray–sphere tests in `f32`, written to stay accurate far from the origin and at grazing angles.
//!
//! The sphere test never forms the textbook discriminant `b² - c` (which cancels catastrophically when
//! the sphere is small and far away, e.g. a telephoto view); it measures the squared distance from the
//! centre to the ray's line directly, `r² - |oc - (oc·d)d|²`, and takes the roots in the stable form
//! `q = -b - sign(b)·√disc`, `t0 = c/q`, `t1 = q`. The hit point is returned relative to the centre as
//! `f ∓ √disc·d`, so normals stay accurate even when `t` is large.

use glam::Vec3A;

use super::ShapeHit;

/// The nearest hit with `t` in (`tmin`, `tmax`) of the ray `origin + t·dir` (unit `dir`) on the sphere.
#[inline]
pub fn intersect(
    (center, radius): (Vec3A, f32),
    (origin, dir): (Vec3A, Vec3A),
    (tmin, tmax): (f32, f32),
) -> Option<ShapeHit> {
    let oc = origin - center;
    let (b, f) = closest(oc, dir);
    let r2 = radius * radius;
    let disc = r2 - f.length_squared();
    if disc < 0.0 {
        return None;
    }
    let sq = disc.sqrt();
    let c = sphere_power(oc, radius);
    let q = if b > 0.0 { -b - sq } else { -b + sq };
    let (t0, t1) = if q == 0.0 {
        (0.0, 0.0)
    } else {
        let (a, b2) = (c / q, q);
        if a <= b2 {
            (a, b2)
        } else {
            (b2, a)
        }
    };
    let (t, local) = if t0 > tmin && t0 < tmax {
        (t0, f - sq * dir)
    } else if t1 > tmin && t1 < tmax {
        (t1, f + sq * dir)
    } else {
        return None;
    };
    let normal = local / radius;
    Some(ShapeHit {
        t,
        position: center + local,
        normal: normal.normalize_or(normal),
    })
}

/// True if the open segment `origin + t·dir` (unit `dir`), `t` in (`tmin`, `tmax`), meets the sphere.
#[inline]
pub fn hits_segment(
    (center, radius): (Vec3A, f32),
    (origin, dir): (Vec3A, Vec3A),
    (tmin, tmax): (f32, f32),
) -> bool {
    let (b, f) = closest(origin - center, dir);
    let disc = radius * radius - f.length_squared();
    if disc < 0.0 {
        return false;
    }
    let sq = disc.sqrt();
    // The chord is t in [-b - sq, -b + sq]; it overlaps (tmin, tmax)?
    let (t0, t1) = (-b - sq, -b + sq);
    t1 > tmin && t0 < tmax
}

/// b = oc·d and f = oc - b·d for the offset `oc` from the centre and the unit `dir`: the line's closest
/// point to the centre, from it.
#[inline(always)]
fn closest(oc: Vec3A, dir: Vec3A) -> (f32, Vec3A) {
    let b = oc.dot(dir);
    (b, oc - b * dir)
}

/// |oc|² - r² for the offset `oc` from a sphere's centre (the power of the point), factored to keep its
/// relative accuracy near the surface.
#[inline(always)]
pub fn sphere_power(oc: Vec3A, radius: f32) -> f32 {
    let l = oc.length();
    (l - radius) * (l + radius)
}

/// Whether the segment x(t) = p + t·d, t in (0, 1) (in (0, ∞) without `BOUNDED`), meets a sphere, from
/// a = |d|², b = (p - c)·d and the power c = |p - c|² - r²: the roots (-b ± √(b² - ac))/a are real, the
/// far one is > 0 and (bounded) the near one < 1. Branch-free, for the fitness kernel's lane loops.
#[inline(always)]
pub fn segment_meets_sphere<const BOUNDED: bool>(a: f32, b: f32, c: f32) -> bool {
    let disc = b * b - a * c;
    let far_positive = (b < 0.0) | (c < 0.0);
    if !BOUNDED {
        return (disc >= 0.0) & far_positive;
    }
    let ab = a + b;
    let near_below_one = (ab > 0.0) | (disc > ab * ab);
    (disc >= 0.0) & far_positive & near_below_one
}
