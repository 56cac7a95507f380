//! The occluded environment: a constant environment radiance L_env seen past the scene's own shapes.
//!
//! A diffuse surface point under a constant environment receives ρ·L_env·V, with V the cosine-weighted
//! fraction of its hemisphere that sees the environment (the sky view factor): 1 minus the form factors
//! of the other shapes from the point. Both forms are closed:
//! - a sphere of radius r whose centre is at distance d, at angle φ from the normal (H = d/r):
//!   cos φ / H² while it is wholly above the horizon (cos φ ≥ 1/H), 0 wholly below (cos φ ≤ -1/H), and
//!   in between the partly-visible form (Howell's catalogue of configuration factors, "differential
//!   planar element to sphere", case of a sphere cut by the element's plane; see [`sphere_view`]);
//! - an infinite plane seen from its front side covers (1 - n·N)/2, N its normal towards the point.
//!
//! Occluders are summed and V clamped to [0, 1]: exact for one occluder, an over-estimate of the
//! occlusion where two occluders hide the same directions (a ball's lower part seen against the floor
//! from a neighbouring ball). The renderer (`shade`) and the fitness (`fitness::pixels`) both call
//! [`sky_view`], the only place this lives.

use glam::Vec3A;

use super::shape::PShape;

/// The cosine-weighted fraction of the hemisphere around the unit normal `n` at `p` that a sphere
/// (`center`, `radius`) covers: its configuration factor from a differential area at `p`.
pub fn sphere_view(p: Vec3A, n: Vec3A, center: Vec3A, radius: f32) -> f32 {
    let to = center - p;
    let d = to.length();
    if radius.is_nan() || radius <= 0.0 || !d.is_finite() {
        return 0.0;
    }
    // A point on (or inside) the sphere sees it cover everything above the horizon towards its centre.
    let h = (d / radius).max(1.0);
    let cos_phi = if d > 0.0 {
        (n.dot(to) / d).clamp(-1.0, 1.0)
    } else {
        1.0
    };
    let inv_h = 1.0 / h;
    if cos_phi >= inv_h {
        return cos_phi * inv_h * inv_h;
    }
    if cos_phi <= -inv_h {
        return 0.0;
    }
    // Partly above the horizon: sin φ > sqrt(1 - 1/H²) > 0 here, so no division by zero.
    let (h, cos_phi) = (h as f64, cos_phi as f64);
    let sin_phi = (1.0 - cos_phi * cos_phi).sqrt();
    let x = (h * h - 1.0).sqrt();
    let y = -x * cos_phi / sin_phi;
    let f = 0.5 - (x / (h * sin_phi)).clamp(-1.0, 1.0).asin() / std::f64::consts::PI
        + (cos_phi * y.clamp(-1.0, 1.0).acos()
            - x * (1.0 - h * h * cos_phi * cos_phi).max(0.0).sqrt())
            / (std::f64::consts::PI * h * h);
    f.clamp(0.0, 1.0) as f32
}

/// The fraction of the hemisphere around `n` at `p` that an infinite plane (`point`, unit `normal`)
/// covers: (1 - n·N)/2 with N the plane's normal turned towards `p`; 0 for a point on the plane.
pub fn plane_view(p: Vec3A, n: Vec3A, point: Vec3A, normal: Vec3A) -> f32 {
    let side = normal.dot(p - point);
    if side == 0.0 || !side.is_finite() {
        return 0.0;
    }
    let towards = if side > 0.0 { normal } else { -normal };
    (0.5 * (1.0 - n.dot(towards))).clamp(0.0, 1.0)
}

/// The sky view factor V at a surface point of object `own` (`p`, unit normal `n`): the cosine-weighted
/// fraction of its hemisphere that sees the environment past every other shape, in [0, 1].
pub fn sky_view(p: Vec3A, n: Vec3A, own: usize, shapes: &[PShape]) -> f32 {
    let mut covered = 0.0f32;
    for (k, shape) in shapes.iter().enumerate() {
        if k == own {
            continue; // a sphere does not see itself, a plane does not see itself
        }
        covered += match *shape {
            PShape::Sphere { center, radius } => sphere_view(p, n, center, radius),
            PShape::Plane { point, normal } => plane_view(p, n, point, normal),
            PShape::Mesh(_) => 0.0, // meshes do not occlude the environment (docs/scene-format.md)
        };
    }
    (1.0 - covered).clamp(0.0, 1.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Monte Carlo reference: cosine-weighted directions (stratified), the fraction that meets the sphere.
    fn sphere_view_mc(p: Vec3A, n: Vec3A, c: Vec3A, r: f32, k: usize) -> f64 {
        let (t, b) = n.any_orthonormal_pair();
        let mut hits = 0usize;
        for i in 0..k {
            for j in 0..k {
                let (u1, u2) = ((i as f32 + 0.5) / k as f32, (j as f32 + 0.5) / k as f32);
                let (rr, phi) = (u1.sqrt(), 2.0 * std::f32::consts::PI * u2);
                let w =
                    t * (rr * phi.cos()) + b * (rr * phi.sin()) + n * (1.0 - u1).max(0.0).sqrt();
                // Ray p + s w meets the sphere for some s > 0?
                let oc = p - c;
                let bq = oc.dot(w);
                let cq = oc.length_squared() - r * r;
                let disc = bq * bq - cq;
                if disc >= 0.0 && (-bq + disc.sqrt()) > 0.0 && (cq > 0.0 && -bq > 0.0 || cq <= 0.0)
                {
                    hits += 1;
                }
            }
        }
        hits as f64 / (k * k) as f64
    }

    #[test]
    fn sphere_view_matches_monte_carlo_above_across_and_below_the_horizon() {
        let n = Vec3A::Y;
        let p = Vec3A::ZERO;
        for &(h, phi_deg) in &[
            (1.5f32, 0.0f32),
            (3.0, 30.0),
            (1.2, 60.0),
            (2.0, 80.0),
            (1.5, 90.0),
            (3.0, 95.0),
            (1.1, 110.0),
            (2.0, 125.0),
            (4.0, 100.0),
        ] {
            let phi = phi_deg.to_radians();
            let c = Vec3A::new(phi.sin(), phi.cos(), 0.0) * h * 0.5;
            let got = sphere_view(p, n, c, 0.5) as f64;
            let want = sphere_view_mc(p, n, c, 0.5, 600);
            assert!(
                (got - want).abs() < 2e-3,
                "H {h}, phi {phi_deg}: {got} vs MC {want}"
            );
        }
    }

    #[test]
    fn sphere_view_limits() {
        // Touching the floor straight below the centre: everything covered; a sphere behind: nothing.
        let v = sphere_view(Vec3A::ZERO, Vec3A::Y, Vec3A::new(0.0, 1.0, 0.0), 1.0);
        assert!((v - 1.0).abs() < 1e-6, "{v}");
        assert_eq!(
            sphere_view(Vec3A::ZERO, Vec3A::Y, Vec3A::new(0.0, -3.0, 0.0), 1.0),
            0.0
        );
        // Far away: cos φ r²/d².
        let v = sphere_view(Vec3A::ZERO, Vec3A::Y, Vec3A::new(0.0, 100.0, 0.0), 1.0);
        assert!((v - 1e-4).abs() < 1e-9);
        // Degenerate inputs give a number in [0, 1], never NaN.
        for v in [
            sphere_view(Vec3A::ZERO, Vec3A::Y, Vec3A::ZERO, 1.0),
            sphere_view(Vec3A::ZERO, Vec3A::Y, Vec3A::X, 0.0),
            sphere_view(Vec3A::ZERO, Vec3A::Y, Vec3A::splat(f32::INFINITY), 1.0),
        ] {
            assert!((0.0..=1.0).contains(&v), "{v}");
        }
    }

    #[test]
    fn plane_view_is_the_tilted_sky_factor() {
        let (q, up) = (Vec3A::ZERO, Vec3A::Y);
        let p = Vec3A::new(0.0, 1.0, 0.0);
        assert_eq!(plane_view(p, up, q, up), 0.0); // facing away from the floor
        assert_eq!(plane_view(p, -up, q, up), 1.0); // facing the floor
        assert!((plane_view(p, Vec3A::X, q, up) - 0.5).abs() < 1e-7); // a wall's view of the floor
        assert!((plane_view(-p, Vec3A::X, q, -up) - 0.5).abs() < 1e-7); // either side
        assert_eq!(plane_view(q, up, q, up), 0.0);
    }

    #[test]
    fn ball_on_floor_views() {
        let shapes = crate::render::shape::ball_over_floor(1.0, 1.0);
        // The ball's top sees all the sky, its equator half, its bottom none.
        assert_eq!(
            sky_view(Vec3A::new(0.0, 2.0, 0.0), Vec3A::Y, 1, &shapes),
            1.0
        );
        assert!((sky_view(Vec3A::new(1.0, 1.0, 0.0), Vec3A::X, 1, &shapes) - 0.5).abs() < 1e-6);
        assert_eq!(
            sky_view(Vec3A::new(0.0, 1e-3, 0.0), -Vec3A::Y, 1, &shapes),
            0.0
        );
        // The floor: dark under the ball, 1 - 1/x² ... at distance x from the contact point (H = sqrt(x²+1)).
        assert_eq!(sky_view(Vec3A::ZERO, Vec3A::Y, 0, &shapes), 0.0);
        let x = 3.0f32;
        let h2 = x * x + 1.0;
        let want = 1.0 - (1.0 / h2.sqrt()) / h2;
        assert!((sky_view(Vec3A::new(x, 0.0, 0.0), Vec3A::Y, 0, &shapes) - want).abs() < 1e-6);
    }
}
