//! The active pixels in structure-of-arrays form: grouped by object, each group with its objective,
//! its possible occluders' light-independent terms, and the per-block light terms (irradiance, shadow,
//! lobe) an evaluation computes.

use glam::Vec3A;

use crate::render::light::{self, directional_irradiance, point_irradiance};
use crate::render::{brdf, shape::segment_meets_sphere};

/// Pixels per block: the working set of one block stays in L1.
pub const BLOCK: usize = 64;

pub(crate) struct SphereOccluder {
    pub(crate) center: [f32; 3],
    pub(crate) radius: f32,
    /// |p - c|² - r² per pixel of the group.
    pub(crate) c: Vec<f32>,
}

pub(crate) struct PlaneOccluder {
    pub(crate) normal: [f32; 3],
    pub(crate) point: [f32; 3],
    /// n·(p - q) per pixel of the group: which side of the plane the pixel lies on.
    pub(crate) side: Vec<f32>,
}

/// The pixels of one object (or of the background, `object == None`).
pub(crate) struct Group {
    pub(crate) object: Option<usize>,
    pub(crate) p: [Vec<f32>; 3],
    pub(crate) n: [Vec<f32>; 3],
    pub(crate) v: [Vec<f32>; 3],
    pub(crate) t: [Vec<f32>; 3],
    /// The objective in the loss space (its sRGB encoding); empty in the linear space, which uses `t`.
    pub(crate) te: [Vec<f32>; 3],
    /// The objective as the closed-form solve uses it: +inf where a pixel must not inform the products
    /// (a silhouette pixel, which the photo averages over two surfaces), so the saturation test drops it.
    pub(crate) ts: [Vec<f32>; 3],
    pub(crate) spheres: Vec<SphereOccluder>,
    pub(crate) planes: Vec<PlaneOccluder>,
    /// Bounding sphere (centre, radius) of each run of `BLOCK` pixels, for culling shadow tests.
    pub(crate) blocks: Vec<([f32; 3], f32)>,
}

impl Group {
    pub(crate) fn len(&self) -> usize {
        self.t[0].len()
    }
}

/// Per-candidate light terms shared by all groups.
#[derive(Clone, Copy)]
pub(crate) struct Light {
    pub(crate) pos: [f32; 3],
    /// A directional light's unit direction towards the light (then `pos` is unused).
    pub(crate) dir: Option<[f32; 3]>,
    /// intensity x colour.
    pub(crate) rgb: [f32; 3],
}

/// e = max(0, n·l) / d² (unit light), written into `e`; 0 for a light on the surface.
#[inline(always)]
pub(crate) fn irradiance<const AVX2: bool>(
    g: &Group,
    r: std::ops::Range<usize>,
    light: &Light,
    e: &mut [f32],
) {
    if let Some(d) = light.dir {
        // Directional light: no fall-off, e = max(0, n·l).
        let n = e.len();
        let (nx, ny, nz) = (
            &g.n[0][r.start..][..n],
            &g.n[1][r.start..][..n],
            &g.n[2][r.start..][..n],
        );
        for i in 0..n {
            e[i] = directional_irradiance(d, [nx[i], ny[i], nz[i]]);
        }
        return;
    }
    #[cfg(target_arch = "x86_64")]
    if AVX2 {
        // SAFETY: `AVX2` is only true on the path dispatched after checking the CPU's features.
        unsafe { super::simd::irradiance_avx2(g, r, light, e) };
        return;
    }
    irradiance_exact(g, r, light, e);
}

#[inline(always)]
/// The scalar form of `irradiance` for a point light.
pub(crate) fn irradiance_exact(g: &Group, r: std::ops::Range<usize>, light: &Light, e: &mut [f32]) {
    let n = e.len();
    let (px, py, pz) = (
        &g.p[0][r.start..][..n],
        &g.p[1][r.start..][..n],
        &g.p[2][r.start..][..n],
    );
    let (nx, ny, nz) = (
        &g.n[0][r.start..][..n],
        &g.n[1][r.start..][..n],
        &g.n[2][r.start..][..n],
    );
    let [lx, ly, lz] = light.pos;
    for i in 0..n {
        let d = [lx - px[i], ly - py[i], lz - pz[i]];
        e[i] = point_irradiance(d, [nx[i], ny[i], nz[i]]);
    }
}

/// Zero `e` where the segment from the pixel to the light is blocked by another object.
#[inline(always)]
pub(crate) fn shadow(g: &Group, r: std::ops::Range<usize>, light: &Light, e: &mut [f32]) {
    if let Some(d) = light.dir {
        shadow_directional(g, r, d, e);
        return;
    }
    let n = e.len();
    let (px, py, pz) = (
        &g.p[0][r.start..][..n],
        &g.p[1][r.start..][..n],
        &g.p[2][r.start..][..n],
    );
    let [lx, ly, lz] = light.pos;
    let (centre, reach) = g.blocks[r.start / BLOCK];
    let (b, l) = (Vec3A::from_array(centre), Vec3A::from_array(light.pos));
    for s in &g.spheres {
        // Every segment from a pixel of this block to the light stays within `reach` of the segment from
        // the block's centre to the light: if the sphere is farther than that, no pixel is shadowed by it.
        let c = Vec3A::from_array(s.center);
        let v = l - b;
        let t = if v.length_squared() > 0.0 {
            ((c - b).dot(v) / v.length_squared()).clamp(0.0, 1.0)
        } else {
            0.0
        };
        let gap = (c - (b + t * v)).length();
        if gap > (s.radius + reach) * (1.0 + 1e-4) + 1e-6 * (c.abs().max_element() + s.radius) {
            continue;
        }
        let cc = &s.c[r.start..][..n];
        let [cx, cy, cz] = s.center;
        for i in 0..n {
            // Segment x(t) = p + t·d, t in [0, 1], d = L - p; sphere |x - c|² = r².
            let dx = lx - px[i];
            let dy = ly - py[i];
            let dz = lz - pz[i];
            let a = dx * dx + dy * dy + dz * dz;
            let b = (px[i] - cx) * dx + (py[i] - cy) * dy + (pz[i] - cz) * dz;
            let hit = segment_meets_sphere::<true>(a, b, cc[i]);
            e[i] = if hit { 0.0 } else { e[i] };
        }
    }
    for pl in &g.planes {
        let side_l = pl.normal[0] * (lx - pl.point[0])
            + pl.normal[1] * (ly - pl.point[1])
            + pl.normal[2] * (lz - pl.point[2]);
        let side = &pl.side[r.start..][..n];
        for i in 0..n {
            e[i] = if side[i] * side_l < 0.0 { 0.0 } else { e[i] };
        }
    }
}

/// `shadow` for a directional light: rays p + t·d, t in (0, inf), d the unit direction to the light.
#[inline(always)]
pub(crate) fn shadow_directional(g: &Group, r: std::ops::Range<usize>, d: [f32; 3], e: &mut [f32]) {
    let n = e.len();
    let (px, py, pz) = (
        &g.p[0][r.start..][..n],
        &g.p[1][r.start..][..n],
        &g.p[2][r.start..][..n],
    );
    for s in &g.spheres {
        let cc = &s.c[r.start..][..n];
        let [cx, cy, cz] = s.center;
        for i in 0..n {
            // |d| = 1: blocked when the far root of t² + 2bt + c = 0 is positive.
            let b = (px[i] - cx) * d[0] + (py[i] - cy) * d[1] + (pz[i] - cz) * d[2];
            let hit = segment_meets_sphere::<false>(1.0, b, cc[i]);
            e[i] = if hit { 0.0 } else { e[i] };
        }
    }
    for pl in &g.planes {
        // The ray heads towards the plane's other side when n·d and the pixel's side differ in sign.
        let side_l = pl.normal[0] * d[0] + pl.normal[1] * d[1] + pl.normal[2] * d[2];
        let side = &pl.side[r.start..][..n];
        for i in 0..n {
            e[i] = if side[i] * side_l < 0.0 { 0.0 } else { e[i] };
        }
    }
}

/// max(0, n·h)^s for the pixel `s` of the group.
#[inline(always)]
pub(crate) fn blinn_phong(g: &Group, s: usize, light: &Light, shininess: f32) -> f32 {
    let p = Vec3A::new(g.p[0][s], g.p[1][s], g.p[2][s]);
    let n = Vec3A::new(g.n[0][s], g.n[1][s], g.n[2][s]);
    let v = Vec3A::new(g.v[0][s], g.v[1][s], g.v[2][s]);
    let l = light::toward(
        Vec3A::from_array(light.pos),
        light.dir.map(Vec3A::from_array),
        p,
    );
    brdf::blinn_phong(n, l, v, shininess)
}
