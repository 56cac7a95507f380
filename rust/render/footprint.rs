//! The pixel footprint: a pixel's area on the surface it sees (`axes`), and the box filter a camera
//! applies over it: the lit fraction at a straight shadow edge (`box_edge`), the mean of a clamped
//! cosine across a sphere's terminator (`box_ramp`), and at an object's outline the first hits of a
//! stratified grid of sub-pixel rays (`silhouette_samples`), whose shaded values a pixel averages.

use glam::Vec3A;

use crate::geometry::sphere::Chord;

use super::camera::CameraFrame;
use super::hit::{closest_hit, GBuffer, Surfel};
use super::shape::PShape;

/// The sub-pixel rays per silhouette pixel ([`silhouette_offsets`]).
pub const SILHOUETTE_SAMPLES: u32 = 16;

/// Where the sub-pixel rays of a silhouette pixel cross it, in [0, 1)²: one in each cell of a 4 x 4 grid,
/// shifted inside its cell so that no two share a column or a row of the 16 x 16 grid (the canonical
/// multi-jittered pattern). A straight outline along a pixel row or column (a horizon) then cuts off a
/// sixteenth per step, where the 4 x 4 grid's cell centres give quarters.
pub fn silhouette_offsets() -> impl Iterator<Item = (f32, f32)> {
    (0..4u8).flat_map(|j| {
        (0..4u8).map(move |i| {
            let (i, j) = (i as f32, j as f32);
            ((i + (j + 0.5) / 4.0) / 4.0, (j + (i + 0.5) / 4.0) / 4.0)
        })
    })
}

/// Whether pixel `i` is off every silhouette: its 4-neighbours show its own object. A silhouette pixel
/// mixes two surfaces in a photo; the closed-form solve leaves it out.
pub fn interior(gbuffer: &GBuffer, i: usize) -> bool {
    let (w, h) = (gbuffer.width as usize, gbuffer.height as usize);
    let id = |x: usize, y: usize| gbuffer.surfels[y * w + x].object;
    let (x, y) = (i % w, i / w);
    let o = id(x, y);
    (x == 0 || id(x - 1, y) == o)
        && (x + 1 == w || id(x + 1, y) == o)
        && (y == 0 || id(x, y - 1) == o)
        && (y + 1 == h || id(x, y + 1) == o)
}

/// The first hits of the [`SILHOUETTE_SAMPLES`] sub-pixel rays of pixel `i` of `gbuffer` (the first hits
/// at the pixel centres of the image `camera` sees of `shapes`), where the pixel straddles an outline: a
/// 4-neighbour shows another object or the background ([`interior`]) and some sub-pixel ray sees another
/// surface than the centre's. `None` elsewhere: the pixel is one surface, shaded at its centre (with its
/// footprint). The pixel's value is the mean of its samples' values, each shaded as a pixel centre is
/// (a miss takes the background).
pub fn silhouette_samples(
    camera: &CameraFrame,
    shapes: &[PShape],
    gbuffer: &GBuffer,
    i: usize,
) -> Option<Vec<Surfel>> {
    if interior(gbuffer, i) {
        return None;
    }
    let (w, h) = (gbuffer.width, gbuffer.height);
    let (x, y) = ((i % w as usize) as f32, (i / w as usize) as f32);
    let own = gbuffer.surfels[i].object;
    let samples: Vec<Surfel> = silhouette_offsets()
        .map(|(dx, dy)| {
            let dir = camera.generate_ray(x + dx, y + dy, w, h);
            closest_hit(shapes, camera.origin, dir)
        })
        .collect();
    samples.iter().any(|s| s.object != own).then_some(samples)
}

/// The world vectors spanned by one pixel step in x and in y on the tangent plane of `s`, the first hit
/// at the centre of pixel (`i`, `j`) of a `width` x `height` image; zero where the plane is seen edge-on
/// or behind the camera. On a sphere (`shape`) the tangent plane stands for the surface only while the
/// footprint is small against the radius: at the limb each vector is cut to a quarter of it.
pub fn axes(
    camera: &CameraFrame,
    s: &Surfel,
    shape: &PShape,
    (i, j): (u32, u32),
    (width, height): (u32, u32),
) -> [Vec3A; 2] {
    // The ray differentials of the pixel-centre ray d(px, py) (before normalising) on that plane:
    // x = o + t d with t = n·(p - o) / n·d, so dx = t (dd - d (n·dd) / (n·d)) per pixel step.
    let (w, h) = (width as f32, height as f32);
    let (x, y) = (
        (2.0 * (i as f32 + 0.5) / w - 1.0) * camera.tan_half * (w / h),
        (1.0 - 2.0 * (j as f32 + 0.5) / h) * camera.tan_half,
    );
    let d = camera.forward + x * camera.right + y * camera.true_up;
    let nd = s.normal.dot(d);
    let t = s.normal.dot(s.position - camera.origin) / nd;
    if !(t.is_finite() && t > 0.0 && nd.abs() > 1e-6 * d.length()) {
        return [Vec3A::ZERO; 2];
    }
    let cap = match shape {
        PShape::Sphere { radius, .. } => 0.25 * radius,
        _ => f32::INFINITY,
    };
    let step = |dd: Vec3A| {
        let v = t * (dd - d * (s.normal.dot(dd) / nd));
        let l = v.length();
        if !l.is_finite() {
            Vec3A::ZERO
        } else if l > cap {
            v * (cap / l)
        } else {
            v
        }
    };
    [
        step(camera.right * (2.0 * camera.tan_half / h)),
        step(camera.true_up * (-2.0 * camera.tan_half / h)),
    ]
}

/// Half of |du| + |dv|: no point of the pixel's footprint is farther from its centre.
#[inline]
pub fn spread([du, dv]: &[Vec3A; 2]) -> f32 {
    0.5 * (du.length() + dv.length())
}

/// The lit fraction of a pixel at `p` (footprint `du`, `dv`) next to the shadow of the sphere (`c`,
/// `radius`), the edge taken straight across the pixel: `point` 1 for a point light at `to` (the
/// segment to it), 0 for a directional light towards the unit `to` (a ray). Meaningful where the line's
/// closest approach to the centre lies between the point and the light (t in (0, 1); a ray: t > 0).
#[inline(always)]
pub fn sphere_edge_lit(
    p: [f32; 3],
    [du, dv]: [[f32; 3]; 2],
    to: [f32; 3],
    point: f32,
    c: [f32; 3],
    radius: f32,
) -> f32 {
    let d = [
        to[0] - point * p[0],
        to[1] - point * p[1],
        to[2] - point * p[2],
    ];
    let pc = [p[0] - c[0], p[1] - c[1], p[2] - c[2]];
    let a = d[0] * d[0] + d[1] * d[1] + d[2] * d[2];
    let t = -(pc[0] * d[0] + pc[1] * d[1] + pc[2] * d[2]) / a;
    // w: from the closest point to the centre, length h. Moving the pixel's point by x moves the closest
    // point by (1 - t) x (a ray: by x), so h by -(1 - t) w·x / h.
    let w = [
        -(pc[0] + t * d[0]),
        -(pc[1] + t * d[1]),
        -(pc[2] + t * d[2]),
    ];
    let h = (w[0] * w[0] + w[1] * w[1] + w[2] * w[2]).sqrt();
    let k = (1.0 - point * t) / h.max(f32::MIN_POSITIVE);
    let alpha = k * (w[0] * du[0] + w[1] * du[1] + w[2] * du[2]);
    let beta = k * (w[0] * dv[0] + w[1] * dv[1] + w[2] * dv[2]);
    box_edge(h - radius, alpha, beta)
}

/// Whether the line from a point towards the light passes a sphere's centre closest between the two,
/// from a = |d|² and b = (p - c)·d (d from the point `p` towards the light, `c` the centre): t = -b/a > 0
/// and, for a point light (`BOUNDED`, the segment to it), t < 1. Where [`sphere_edge_lit`] applies.
#[inline(always)]
pub fn edge_between<const BOUNDED: bool>(a: f32, b: f32) -> bool {
    (b < 0.0) & (!BOUNDED | (a + b > 0.0))
}

/// Whether a pixel whose footprint reaches `w` from its centre may cross the shadow edge of a sphere of
/// `radius`, from a = |d|² and the line's [`Chord`] (`geometry::sphere::line_to_sphere`): the edge lies
/// between the point and the light ([`edge_between`]) and the line's distance h from the centre is within
/// w of the radius, |r² - h²| < 2rw + w² (w bounds the line's move across the pixel).
#[inline(always)]
pub fn near_sphere_edge<const BOUNDED: bool>(a: f32, c: Chord, w: f32, radius: f32) -> bool {
    let close = c.disc.abs() < w * (2.0 * radius + w);
    close & edge_between::<BOUNDED>(a, c.b)
}

/// The pixel mean of max(0, n·l) on a sphere of `radius` (unit `n`, unit `l` towards the light,
/// footprint `du`, `dv`): across the pixel the normal turns by x / radius, so n·l by l·x / radius.
#[inline(always)]
pub fn terminator_cos(n: [f32; 3], l: [f32; 3], [du, dv]: [[f32; 3]; 2], radius: f32) -> f32 {
    let c = n[0] * l[0] + n[1] * l[1] + n[2] * l[2];
    let alpha = (l[0] * du[0] + l[1] * du[1] + l[2] * du[2]) / radius;
    let beta = (l[0] * dv[0] + l[1] * dv[1] + l[2] * dv[2]) / radius;
    box_ramp(c, alpha, beta)
}

/// The fraction of the unit pixel square, (u, v) in [-1/2, 1/2]², where `alpha` u + `beta` v < `s`: the
/// lit part of a pixel crossed by a straight shadow edge (`s` the signed distance of the pixel centre
/// from the edge, lit side positive, `alpha`/`beta` its change per pixel step). It is the distribution
/// function of the sum of two uniform variables, (x₊² - (x-a)₊² - (x-b)₊² + (x-a-b)₊²) / 2ab at
/// x = s + (a+b)/2; branch-free, so the fitness kernel's lanes share it.
#[inline(always)]
pub fn box_edge(s: f32, alpha: f32, beta: f32) -> f32 {
    let (a, b) = widths(alpha, beta);
    let x = s + 0.5 * (a + b);
    let q = |y: f32| {
        let y = y.max(0.0);
        y * y
    };
    let f = (q(x) - q(x - a) - q(x - b) + q(x - a - b)) / (2.0 * a * b);
    // Outside the box the value is exact (no rounding of the differences above).
    if x <= 0.0 {
        0.0
    } else if x >= a + b {
        1.0
    } else {
        f.clamp(0.0, 1.0)
    }
}

/// The mean over the unit pixel square, (u, v) in [-1/2, 1/2]², of max(0, `c` + `alpha` u + `beta` v):
/// the pixel average of a clamped cosine max(0, n·l) that changes by `alpha`/`beta` per pixel step, as at
/// a sphere's terminator. The integral of `box_edge`: c + (z₊³ - (z-a)₊³ - (z-b)₊³ + (z-a-b)₊³) / 6ab at
/// z = (a+b)/2 - c; branch-free.
#[inline(always)]
pub fn box_ramp(c: f32, alpha: f32, beta: f32) -> f32 {
    let (a, b) = widths(alpha, beta);
    let z = 0.5 * (a + b) - c;
    let q = |y: f32| {
        let y = y.max(0.0);
        y * y * y
    };
    let f = c + (q(z) - q(z - a) - q(z - b) + q(z - a - b)) / (6.0 * a * b);
    if z <= 0.0 {
        c
    } else if z >= a + b {
        0.0
    } else {
        f.max(0.0)
    }
}

/// The two widths |alpha| >= |beta| of the box, each at least 1/64 of the larger and above zero: the
/// closed forms divide by their product (a sliver as thin as that changes them by under 1 %).
#[inline(always)]
fn widths(alpha: f32, beta: f32) -> (f32, f32) {
    let a = alpha.abs().max(beta.abs()).max(1e-12);
    let b = alpha.abs().min(beta.abs()).max(a / 64.0);
    (a, b)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::Camera;

    /// The centres (u, v) of an n x n grid of sub-pixels over the pixel [-0.5, 0.5]^2, row by row.
    fn sub_pixels(n: usize) -> impl Iterator<Item = (f32, f32)> {
        (0..n).flat_map(move |i| {
            (0..n).map(move |j| {
                let u = (i as f32 + 0.5) / n as f32 - 0.5;
                let v = (j as f32 + 0.5) / n as f32 - 0.5;
                (u, v)
            })
        })
    }

    /// Calls `f(alpha, beta, s)` for each of a few edge slopes and offsets s = -0.84 .. 0.84.
    fn each_edge(mut f: impl FnMut(f32, f32, f32)) {
        for &(alpha, beta) in &[
            (1.0, 0.0),
            (0.3, 0.7),
            (-0.9, 0.2),
            (0.5, -0.5),
            (2.0, 1e-9),
        ] {
            for k in -12..=12 {
                f(alpha, beta, k as f32 * 0.07);
            }
        }
    }

    /// The fraction of an n x n grid of sub-pixel points where alpha u + beta v < s.
    fn counted(s: f32, alpha: f32, beta: f32, n: usize) -> f32 {
        let lit = sub_pixels(n)
            .filter(|&(u, v)| alpha * u + beta * v < s)
            .count();
        lit as f32 / (n * n) as f32
    }

    #[test]
    fn box_edge_matches_counting_sub_pixels() {
        each_edge(|alpha, beta, s| {
            let (f, c) = (box_edge(s, alpha, beta), counted(s, alpha, beta, 800));
            assert!(
                (f - c).abs() < 4e-3,
                "s {s} alpha {alpha} beta {beta}: {f} vs {c}"
            );
        });
        assert_eq!(box_edge(0.1, 0.0, 0.0), 1.0);
        assert_eq!(box_edge(-0.1, 0.0, 0.0), 0.0);
    }

    #[test]
    fn box_ramp_matches_averaging_sub_pixels() {
        each_edge(|alpha, beta, c| {
            let n = 600;
            let mut sum = 0.0f64;
            for (u, v) in sub_pixels(n) {
                sum += (c + alpha * u + beta * v).max(0.0) as f64;
            }
            let mean = (sum / (n * n) as f64) as f32;
            let f = box_ramp(c, alpha, beta);
            assert!(
                (f - mean).abs() < 1e-4,
                "c {c} alpha {alpha} beta {beta}: {f} vs {mean}"
            );
        });
        assert_eq!(box_ramp(0.3, 0.0, 0.0), 0.3);
        assert_eq!(box_ramp(-0.3, 0.0, 0.0), 0.0);
    }

    #[test]
    fn axes_span_the_pixel_on_a_floor_seen_from_above() {
        // A camera straight above the floor y = 0 at height 2 with a 90 deg vertical field of view on a
        // 100 x 100 image: the floor it sees is 4 m wide, so a pixel step is 4 cm.
        let cam = CameraFrame::new(&Camera {
            position: [0.0, 2.0, 0.0],
            look_at: [0.0, 0.0, 0.0],
            up: [0.0, 0.0, 1.0],
            vfov_deg: 90.0,
        });
        let s = Surfel {
            position: Vec3A::ZERO,
            normal: Vec3A::Y,
            view: Vec3A::Y,
            object: 0,
            eps: 0.0,
        };
        let floor = PShape::Plane {
            point: Vec3A::ZERO,
            normal: Vec3A::Y,
        };
        let [du, dv] = axes(&cam, &s, &floor, (49, 49), (100, 100));
        assert!((du.length() - 0.04).abs() < 1e-4 && (dv.length() - 0.04).abs() < 1e-4);
        assert!(du.dot(dv).abs() < 1e-6 && du.y.abs() < 1e-6);
    }
}
