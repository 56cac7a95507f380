//! The renderer's shapes (spheres, planes, meshes) and their ray tests, which are `geometry`'s.

use std::sync::Arc;

use glam::Vec3A;

use crate::geometry::mesh::Mesh;
use crate::geometry::ShapeHit;
use crate::geometry::{plane, sphere};
use crate::scene::Shape;

/// A shape in the renderer's working form.
#[derive(Clone, Debug)]
pub enum PShape {
    Sphere {
        center: Vec3A,
        radius: f32,
    },
    /// `normal` is unit length; the plane is `normal · x = offset`.
    Plane {
        point: Vec3A,
        normal: Vec3A,
    },
    /// A triangle mesh with its BVH (world space, two-sided).
    Mesh(Arc<Mesh>),
}

impl PShape {
    pub fn new(s: &Shape) -> PShape {
        match s {
            Shape::Sphere { center, radius } => PShape::Sphere {
                center: glam::DVec3::from_array(*center).as_vec3a(),
                radius: *radius as f32,
            },
            Shape::Plane { point, normal } => PShape::Plane {
                point: glam::DVec3::from_array(*point).as_vec3a(),
                normal: crate::scene::unit(*normal).as_vec3a(),
            },
            Shape::Mesh { mesh, .. } => PShape::Mesh(Arc::clone(mesh)),
        }
    }

    /// A length that sets the scale of this shape's coordinates, for scale-aware epsilons.
    pub fn scale(&self) -> f32 {
        match self {
            PShape::Sphere { center, radius } => center.abs().max_element() + radius,
            PShape::Plane { point, .. } => point.abs().max_element(),
            PShape::Mesh(m) => m.scale(),
        }
    }

    /// Nearest hit with `t` in (`tmin`, `tmax`) along the unit direction `dir`.
    #[inline]
    pub fn intersect(&self, origin: Vec3A, dir: Vec3A, tmin: f32, tmax: f32) -> Option<ShapeHit> {
        match *self {
            PShape::Mesh(ref m) => m.intersect(origin, dir, tmin, tmax),
            PShape::Sphere { center, radius } => {
                sphere::intersect((center, radius), (origin, dir), (tmin, tmax))
            }
            PShape::Plane { point, normal } => {
                plane::intersect((point, normal), (origin, dir), (tmin, tmax))
            }
        }
    }

    /// True if the open segment `origin + t·dir`, `t` in (`tmin`, `tmax`), meets the shape.
    #[inline]
    pub fn hits_segment(&self, origin: Vec3A, dir: Vec3A, tmin: f32, tmax: f32) -> bool {
        match *self {
            PShape::Sphere { center, radius } => {
                sphere::hits_segment((center, radius), (origin, dir), (tmin, tmax))
            }
            PShape::Plane { point, normal } => {
                plane::hits_segment((point, normal), (origin, dir), (tmin, tmax))
            }
            PShape::Mesh(ref m) => m.hits_segment(origin, dir, tmin, tmax),
        }
    }
}

/// Test scenes' shapes: the floor y = 0 and a sphere of `radius` centred at height `y` above the origin.
#[cfg(test)]
pub(crate) fn ball_over_floor(y: f32, radius: f32) -> [PShape; 2] {
    [
        PShape::Plane {
            point: Vec3A::ZERO,
            normal: Vec3A::Y,
        },
        PShape::Sphere {
            center: Vec3A::new(0.0, y, 0.0),
            radius,
        },
    ]
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::sphere::{line_to_sphere, segment_meets_sphere};
    use glam::DVec3;

    fn sphere(c: [f32; 3], r: f32) -> PShape {
        PShape::Sphere {
            center: Vec3A::from_array(c),
            radius: r,
        }
    }

    /// Float64 reference: nearest positive root of |o + t d - c|² = r².
    fn ref_sphere(o: DVec3, d: DVec3, c: DVec3, r: f64) -> Option<(f64, DVec3)> {
        let oc = o - c;
        let b = oc.dot(d);
        let cc = oc.dot(oc) - r * r;
        let disc = b * b - cc;
        if disc < 0.0 {
            return None;
        }
        let t = -b - disc.sqrt();
        let t = if t > 0.0 { t } else { -b + disc.sqrt() };
        (t > 0.0).then(|| (t, (o + t * d - c) / r))
    }

    /// The fitness kernel's form (t in (0, 1) along d = l - p, a = |d|²; the ray t in (0, inf) for a
    /// directional light) decides as the renderer's unit-direction segment does.
    #[test]
    fn segment_test_agrees_with_the_ray_test() {
        let s = sphere([0.0, 1.0, 0.0], 0.5);
        let PShape::Sphere { center, radius } = s else {
            unreachable!()
        };
        for (p, l) in [
            ([0.0, 0.0, 0.0], [0.0, 2.0, 0.0]),
            ([0.0, 0.0, 0.0], [0.0, 0.2, 0.0]),
            ([3.0, 0.0, 0.0], [0.0, 2.0, 0.0]),
            ([0.0, 3.0, 0.0], [0.0, 4.0, 0.0]),
            ([0.0, 3.0, 0.0], [0.0, -4.0, 0.0]),
        ] {
            let (p, l) = (Vec3A::from_array(p), Vec3A::from_array(l));
            let (d, oc, r2) = (l - p, (p - center).to_array(), radius * radius);
            let a = d.length_squared();
            let chord = line_to_sphere(oc, d.to_array(), a, r2);
            let want = s.hits_segment(p, d.normalize(), 0.0, d.length());
            assert_eq!(
                segment_meets_sphere(chord, a, (0.0, 1.0)),
                want,
                "{p} -> {l}"
            );
            let ray = s.hits_segment(p, d.normalize(), 0.0, f32::INFINITY);
            let unit = line_to_sphere(oc, d.normalize().to_array(), 1.0, r2);
            let got = segment_meets_sphere(unit, 1.0, (0.0, f32::INFINITY));
            assert_eq!(got, ray, "{p} ray");
        }
    }

    #[test]
    fn head_on_hit() {
        let s = sphere([0.0, 0.0, 5.0], 1.0);
        let h = s
            .intersect(Vec3A::ZERO, Vec3A::Z, 0.0, f32::INFINITY)
            .unwrap();
        assert!((h.t - 4.0).abs() < 1e-6);
        assert!((h.normal - Vec3A::NEG_Z).length() < 1e-6);
    }

    #[test]
    fn tangent_rays_graze_without_nan() {
        let s = sphere([0.0, 0.0, 5.0], 1.0);
        // Exactly tangent, just inside and just outside.
        for (x, expect) in [
            (1.0f32, None),
            (0.999_9, Some(true)),
            (1.000_1, Some(false)),
        ] {
            let h = s.intersect(Vec3A::new(x, 0.0, 0.0), Vec3A::Z, 0.0, f32::INFINITY);
            if let Some(e) = expect {
                assert_eq!(h.is_some(), e, "x = {x}");
            }
            if let Some(h) = h {
                assert!(h.t.is_finite() && h.normal.is_finite());
                assert!((h.normal.length() - 1.0).abs() < 1e-5);
            }
        }
    }

    #[test]
    fn origin_on_surface_does_not_self_hit_going_out() {
        let s = sphere([0.0, 0.0, 0.0], 1.0);
        let o = Vec3A::new(0.0, 1.0, 0.0);
        assert!(s.intersect(o, Vec3A::Y, 1e-5, f32::INFINITY).is_none());
        // Going in, it finds the far side at t = 2.
        let h = s.intersect(o, Vec3A::NEG_Y, 1e-5, f32::INFINITY).unwrap();
        assert!((h.t - 2.0).abs() < 1e-5);
    }

    #[test]
    fn ray_parallel_to_plane_misses() {
        let p = PShape::Plane {
            point: Vec3A::ZERO,
            normal: Vec3A::Y,
        };
        assert!(p
            .intersect(Vec3A::new(0.0, 1.0, 0.0), Vec3A::X, 0.0, f32::INFINITY)
            .is_none());
        assert!(p
            .intersect(Vec3A::ZERO, Vec3A::X, 0.0, f32::INFINITY)
            .is_none());
        let h = p
            .intersect(Vec3A::new(0.0, 1.0, 0.0), Vec3A::NEG_Y, 0.0, f32::INFINITY)
            .unwrap();
        assert!((h.t - 1.0).abs() < 1e-7);
    }

    #[test]
    fn huge_and_tiny_scales_match_f64() {
        for scale in [1e-3f64, 1.0, 1e3] {
            let c = DVec3::new(0.3, -0.2, 10.0) * scale;
            let r = 1.5 * scale;
            let o = DVec3::new(0.1, 0.05, 0.0) * scale;
            for k in 0..50 {
                let a = k as f64 / 49.0 * 0.2 - 0.1;
                let d = DVec3::new(a, 0.3 * a, 1.0).normalize();
                let s = sphere((c.as_vec3()).to_array(), r as f32);
                let got = s.intersect(o.as_vec3a(), d.as_vec3a(), 0.0, f32::INFINITY);
                let want = ref_sphere(o, d, c, r);
                assert_eq!(got.is_some(), want.is_some(), "scale {scale} k {k}");
                if let (Some(g), Some((t, n))) = (got, want) {
                    assert!(
                        ((g.t as f64) - t).abs() <= 1e-5 * t,
                        "scale {scale}: t {} vs {t}",
                        g.t
                    );
                    assert!((g.normal.as_dvec3() - n).length() < 1e-4);
                }
            }
        }
    }

    /// Camera 1000 m from a 1 m sphere: the textbook f32 discriminant `b² - c` loses the silhouette and
    /// the normals; the stable form matches a float64 reference.
    #[test]
    fn telephoto_silhouette_and_normals_match_f64() {
        let c = DVec3::new(0.0, 0.0, 1000.0);
        let o = DVec3::ZERO;
        let s = sphere([0.0, 0.0, 1000.0], 1.0);
        let (mut ours_bad, mut textbook_bad, mut ours_nerr, mut textbook_nerr) =
            (0, 0, 0.0f64, 0.0f64);
        let n = 2001;
        for k in 0..n {
            // Sweep across the silhouette: offsets from 0.9 to 1.1 radii at 1000 m.
            let y = 0.9e-3 + 0.2e-3 * k as f64 / (n - 1) as f64;
            let d = DVec3::new(0.0, y, 1.0).normalize();
            let want = ref_sphere(o, d, c, 1.0);
            let got = s.intersect(o.as_vec3a(), d.as_vec3a(), 0.0, f32::INFINITY);
            // Textbook single precision.
            let (of, df, cf) = (o.as_vec3a(), d.as_vec3a(), c.as_vec3a());
            let ocf = of - cf;
            let bf = ocf.dot(df);
            let ccf = ocf.dot(ocf) - 1.0;
            let discf = bf * bf - ccf;
            let textbook = (discf >= 0.0).then(|| {
                let t = -bf - discf.sqrt();
                (t, ((of + t * df - cf) / 1.0).normalize())
            });
            if got.is_some() != want.is_some() {
                ours_bad += 1;
            }
            if textbook.is_some() != want.is_some() {
                textbook_bad += 1;
            }
            if let (Some(g), Some((_, wn))) = (got, want) {
                ours_nerr = ours_nerr.max((g.normal.as_dvec3() - wn).length());
            }
            if let (Some((_, tn)), Some((_, wn))) = (textbook, want) {
                textbook_nerr = textbook_nerr.max((tn.as_dvec3() - wn).length());
            }
        }
        // The rays are themselves rounded to f32, so allow the few rays that f32 cannot place.
        assert!(ours_bad <= 2, "stable form misclassified {ours_bad} rays");
        assert!(ours_nerr < 2e-2, "stable form normal error {ours_nerr}");
        assert!(
            textbook_bad > 10 * (ours_bad + 1),
            "textbook misclassified only {textbook_bad}"
        );
        assert!(
            textbook_nerr > 10.0 * ours_nerr,
            "textbook normal error {textbook_nerr} vs {ours_nerr}"
        );
    }
}
