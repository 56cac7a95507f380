//! Ray–sphere tests in `f32`, written to stay accurate far from the origin and at grazing angles.
//!
//! The sphere test never forms the textbook discriminant `b² - c` (which cancels catastrophically when
//! the sphere is small and far away, e.g. a telephoto view); it measures the squared distance from the
//! centre to the ray's line directly, `r² - |oc - (oc·d)d|²` ([`line_to_sphere`], which every sphere test
//! here and in the fitness kernel's shadow lanes starts from), and takes the roots in the stable form
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
    let Chord { b, mid, disc } =
        line_to_sphere(oc.to_array(), dir.to_array(), 1.0, radius * radius);
    // f = oc - b·d (unit `dir`: mid = -b), the line's closest point to the centre, from it.
    let f = oc + mid * dir;
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
    let (oc, d) = ((origin - center).to_array(), dir.to_array());
    segment_meets_sphere(
        line_to_sphere(oc, d, 1.0, radius * radius),
        1.0,
        (tmin, tmax),
    )
}

/// The line x(t) = p + t·d against a sphere: b = (p - c)·d, the middle of the chord t = -b/a (a = |d|²)
/// and `disc` = r² - h², h the line's distance from the centre.
#[derive(Clone, Copy, Debug)]
pub struct Chord {
    pub b: f32,
    pub mid: f32,
    pub disc: f32,
}

/// The [`Chord`] of the line x(t) = p + t·d, from the offset `oc` = p - c of its start from the centre,
/// `d`, a = |d|² and r². h is measured directly as |oc + mid·d| (never as the difference b² - ac of two
/// large terms, which cancels when the sphere is small and far); the chord is mid ± √(disc/a) where
/// disc ≥ 0. Per component, so the fitness kernel's lane loops call it per lane.
#[inline(always)]
pub fn line_to_sphere(oc: [f32; 3], d: [f32; 3], a: f32, r2: f32) -> Chord {
    let b = oc[0] * d[0] + oc[1] * d[1] + oc[2] * d[2];
    let s = b / a;
    let f = [oc[0] - s * d[0], oc[1] - s * d[1], oc[2] - s * d[2]];
    Chord {
        b,
        mid: -s,
        disc: r2 - (f[0] * f[0] + f[1] * f[1] + f[2] * f[2]),
    }
}

/// Whether the open segment t in (`tmin`, `tmax`) of a line meets a sphere, from the line's [`Chord`]
/// and a = |d|²: the chord mid ± √(disc/a) is real and overlaps the range. Branch-free and without a
/// square root or a division: with x = mid - tmin, mid + √(disc/a) > tmin holds when x > 0 or
/// disc > a·x² (both sides of the root's inequality non-negative otherwise), and alike at `tmax`
/// (an infinite `tmax` passes on its sign). The one sphere occlusion test, of the renderer's shadow rays
/// and of the fitness kernel's lanes.
#[inline(always)]
pub fn segment_meets_sphere(c: Chord, a: f32, (tmin, tmax): (f32, f32)) -> bool {
    let (below, above) = (c.mid - tmin, tmax - c.mid);
    (c.disc >= 0.0)
        & ((below > 0.0) | (c.disc > a * below * below))
        & ((above > 0.0) | (c.disc > a * above * above))
}

/// |oc|² - r² for the offset `oc` from a sphere's centre (the power of the point), factored to keep its
/// relative accuracy near the surface.
#[inline(always)]
pub fn sphere_power(oc: Vec3A, radius: f32) -> f32 {
    let l = oc.length();
    (l - radius) * (l + radius)
}
