//! The per-block light terms of a group of active pixels: the irradiance max(0, n·l)/d² (at pixel centres,
//! or over a pixel's footprint where a sphere's terminator crosses it) and the shadow factor of the
//! group's possible occluders (soft where a shadow's edge crosses a pixel), for a point and a directional
//! light. The point light's irradiance has a scalar and an AVX2 form.

use glam::Vec3A;
use rayon::prelude::*;

use super::pixels::{offset, Gather, Group, Light, PlaneOccluder, SphereOccluder, BLOCK};
use crate::geometry::plane;
use crate::geometry::sphere::{line_to_sphere, segment_meets_sphere, Chord};
use crate::render::brdf::lambert;
use crate::render::footprint::{near_sphere_edge, sphere_edge_lit, terminator_cos};
use crate::render::light::{directional_irradiance, point_irradiance, point_irradiance_in, Lanes};

/// e = max(0, n·l) / d² (unit light), written into `e`; 0 for a light on the surface. On a sphere with
/// a footprint, max(0, n·l) is its mean over the pixel where the terminator crosses it.
#[inline(always)]
pub(crate) fn irradiance<const AVX2: bool>(
    g: &Group,
    r: std::ops::Range<usize>,
    light: &Light,
    e: &mut [f32],
) {
    irradiance_centre::<AVX2>(g, r.clone(), light, e);
    if let Some(radius) = g.own_radius {
        soft_terminator(g, r, light, radius, e);
    }
}

/// Where a sphere's terminator crosses a pixel of the block `r` (n·l within the normal's change over
/// the footprint, |x| / radius, of 0), `e` becomes the pixel mean of max(0, n·l) (`box_ramp`, n·l
/// linear across the pixel) over d².
#[inline(always)]
fn soft_terminator(
    g: &Group,
    r: std::ops::Range<usize>,
    light: &Light,
    radius: f32,
    e: &mut [f32],
) {
    let n = e.len();
    let spread = &g.spread[r.start..][..n];
    let mut near = [0u32; BLOCK];
    let mut span = (u32::MAX, 0u32);
    fn col(v: &[Vec<f32>; 3], start: usize, n: usize) -> [&[f32]; 3] {
        [
            &v[0][start..][..n],
            &v[1][start..][..n],
            &v[2][start..][..n],
        ]
    }
    let ([px, py, pz], [nx, ny, nz]) = (col(&g.p, r.start, n), col(&g.n, r.start, n));
    let inv_r2 = 1.0 / (radius * radius);
    let (l, point) = light.target();
    for i in 0..n {
        let d = offset(l, point, [px[i], py[i], pz[i]]);
        let nd = nx[i] * d[0] + ny[i] * d[1] + nz[i] * d[2];
        let d2 = d[0] * d[0] + d[1] * d[1] + d[2] * d[2];
        mark(
            nd * nd < spread[i] * spread[i] * inv_r2 * d2,
            i,
            &mut near,
            &mut span,
        );
    }
    if let Some((r, lo, hi)) = marked(r.start, span) {
        terminator_pixels(g, r, light, radius, &near[lo..hi], &mut e[lo..hi]);
    }
}

/// `soft_terminator`'s pixels marked `near`: their pixel mean of max(0, n·l) over d² (the whole block
/// in lanes, applied where marked).
#[inline(always)]
fn terminator_pixels<'a>(
    g: &'a Group,
    r: std::ops::Range<usize>,
    light: &Light,
    radius: f32,
    near: &[u32],
    e: &mut [f32],
) {
    let n = e.len();
    let col = |v: &'a [Vec<f32>; 3], c: usize| -> &'a [f32] { &v[c][r.start..][..n] };
    let (px, py, pz) = (col(&g.p, 0), col(&g.p, 1), col(&g.p, 2));
    let (nx, ny, nz) = (col(&g.n, 0), col(&g.n, 1), col(&g.n, 2));
    let (ux, uy, uz) = (col(&g.du, 0), col(&g.du, 1), col(&g.du, 2));
    let (vx, vy, vz) = (col(&g.dv, 0), col(&g.dv, 1), col(&g.dv, 2));
    let (e, near) = (&mut e[..n], &near[..n]);
    let (l, point) = light.target();
    for i in 0..n {
        let d = offset(l, point, [px[i], py[i], pz[i]]);
        let d2 = d[0] * d[0] + d[1] * d[1] + d[2] * d[2];
        // Unit l, and the fall-off 1/d² (none for a directional light).
        let inv = 1.0 / d2.sqrt().max(f32::MIN_POSITIVE);
        let fall = if point > 0.0 { inv * inv } else { 1.0 };
        let u = [d[0] * inv, d[1] * inv, d[2] * inv];
        let axes = [[ux[i], uy[i], uz[i]], [vx[i], vy[i], vz[i]]];
        let m = terminator_cos([nx[i], ny[i], nz[i]], u, axes, radius) * fall;
        e[i] = if near[i] != 0 && d2 > f32::MIN_POSITIVE {
            m
        } else {
            e[i]
        };
    }
}

/// `irradiance` at the pixel centres.
#[inline(always)]
fn irradiance_centre<const AVX2: bool>(
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
        unsafe { irradiance_avx2(g, r, light, e) };
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

/// AVX2 form of `irradiance` for a point light: `point_irradiance_in` eight pixels at a time (correctly
/// rounded square root and division, the same bits on every x86-64 CPU; the multiply-adds fused); the
/// tail goes through the scalar form.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
#[inline]
pub(crate) unsafe fn irradiance_avx2(
    g: &Group,
    r: std::ops::Range<usize>,
    light: &Light,
    e: &mut [f32],
) {
    use std::arch::x86_64::*;
    let n = e.len();
    let full = n - n % 8;
    let s = r.start;
    let l = light.pos.map(|v| _mm256_set1_ps(v));
    let mut i = 0;
    while i < full {
        let ld = |v: &Vec<f32>| _mm256_loadu_ps(v.as_ptr().add(s + i));
        let d: [__m256; 3] = std::array::from_fn(|c| _mm256_sub_ps(l[c], ld(&g.p[c])));
        let nv: [__m256; 3] = std::array::from_fn(|c| ld(&g.n[c]));
        _mm256_storeu_ps(e.as_mut_ptr().add(i), point_irradiance_in(d, nv));
        i += 8;
    }
    irradiance_exact(g, s + full..r.end, light, &mut e[full..]);
}

// The lanes of `irradiance_avx2`. SAFETY (every block): these run only inlined into `irradiance_avx2`,
// which is only called once the CPU's AVX2 and FMA were checked.
#[cfg(target_arch = "x86_64")]
impl Lanes for std::arch::x86_64::__m256 {
    #[inline(always)]
    fn splat(v: f32) -> Self {
        unsafe { std::arch::x86_64::_mm256_set1_ps(v) }
    }
    #[inline(always)]
    fn mul(self, b: Self) -> Self {
        unsafe { std::arch::x86_64::_mm256_mul_ps(self, b) }
    }
    #[inline(always)]
    fn mul_add(self, b: Self, c: Self) -> Self {
        unsafe { std::arch::x86_64::_mm256_fmadd_ps(self, b, c) }
    }
    #[inline(always)]
    fn div(self, b: Self) -> Self {
        unsafe { std::arch::x86_64::_mm256_div_ps(self, b) }
    }
    #[inline(always)]
    fn sqrt(self) -> Self {
        unsafe { std::arch::x86_64::_mm256_sqrt_ps(self) }
    }
    #[inline(always)]
    fn max0(self) -> Self {
        // the second operand where either is NaN, as f32::max's 0
        unsafe { std::arch::x86_64::_mm256_max_ps(self, std::arch::x86_64::_mm256_setzero_ps()) }
    }
    #[inline(always)]
    fn min(self, b: Self) -> Self {
        unsafe { std::arch::x86_64::_mm256_min_ps(self, b) }
    }
    #[inline(always)]
    fn where_above(self, x: Self, limit: Self) -> Self {
        use std::arch::x86_64::*;
        unsafe { _mm256_and_ps(self, _mm256_cmp_ps::<_CMP_GT_OQ>(x, limit)) }
    }
}

/// The segment x(t) = p + t·d, t in [0, 1], d = l - p, against the sphere of centre `c` and squared
/// radius `r2`: a = |d|² and the line's chord, the terms `segment_meets_sphere` takes.
#[inline(always)]
fn segment_to_sphere(p: [f32; 3], l: [f32; 3], c: [f32; 3], r2: f32) -> (f32, Chord) {
    let d = [l[0] - p[0], l[1] - p[1], l[2] - p[2]];
    let a = d[0] * d[0] + d[1] * d[1] + d[2] * d[2];
    (
        a,
        line_to_sphere([p[0] - c[0], p[1] - c[1], p[2] - c[2]], d, a, r2),
    )
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
        let spread = g.block_spread.get(r.start / BLOCK).copied().unwrap_or(0.0);
        if gap
            > (s.radius + reach + spread) * (1.0 + 1e-4) + 1e-6 * (c.abs().max_element() + s.radius)
        {
            continue;
        }
        let (c, r2) = (s.center, s.radius * s.radius);
        if g.spread.is_empty() {
            for i in 0..n {
                let (a, chord) = segment_to_sphere([px[i], py[i], pz[i]], light.pos, c, r2);
                let hit = segment_meets_sphere(chord, a, (0.0, 1.0));
                e[i] = if hit { 0.0 } else { e[i] };
            }
            continue;
        }
        // With a footprint, a pixel the edge may cross (`near_sphere_edge`) keeps its light here and gets
        // its lit fraction below.
        let spread = &g.spread[r.start..][..n];
        let mut near = [0u32; BLOCK];
        let mut span = (u32::MAX, 0u32);
        let rad = s.radius;
        for i in 0..n {
            let (a, chord) = segment_to_sphere([px[i], py[i], pz[i]], light.pos, c, r2);
            let hit = segment_meets_sphere(chord, a, (0.0, 1.0));
            let edge = near_sphere_edge::<true>(a, chord, spread[i], rad) & (e[i] > 0.0);
            mark(edge, i, &mut near, &mut span);
            e[i] = if hit & !edge { 0.0 } else { e[i] };
        }
        soft_edge::<true>(g, r.start, span, s, light.pos, &near, e);
    }
    for pl in &g.planes {
        let side_l = pl.normal[0] * (lx - pl.point[0])
            + pl.normal[1] * (ly - pl.point[1])
            + pl.normal[2] * (lz - pl.point[2]);
        plane_shadow(pl, r.start, side_l, e);
    }
}

/// Zero `e` (the pixels of a block from `start`) where plane `pl` lies between the pixel and the light:
/// the pixel's side and `side_l`, the light's (for a directional light, n·d: the side the ray heads to),
/// differ in sign.
#[inline(always)]
fn plane_shadow(pl: &PlaneOccluder, start: usize, side_l: f32, e: &mut [f32]) {
    let side = &pl.side[start..][..e.len()];
    for (e, &s) in e.iter_mut().zip(side) {
        *e = if plane::crosses(s, side_l) { 0.0 } else { *e };
    }
}

/// The pixel footprint at sphere `s`'s shadow edge: each pixel of the block `r` marked `near` (its light
/// still unshadowed in `e`) gets its lit fraction, the edge taken straight across the pixel
/// (`render::footprint::box_edge`). `BOUNDED`: a point light at `to` (the segment to it), else a
/// directional light towards the unit `to` (a ray). The whole block in lanes, applied where marked.
#[inline(always)]
fn soft_edge<'a, const BOUNDED: bool>(
    g: &'a Group,
    start: usize,
    span: (u32, u32),
    s: &SphereOccluder,
    to: [f32; 3],
    near: &[u32; BLOCK],
    e: &mut [f32],
) {
    let Some((r, lo, hi)) = marked(start, span) else {
        return;
    };
    let (near, e) = (&near[lo..hi], &mut e[lo..hi]);
    let n = e.len();
    let col = |v: &'a [Vec<f32>; 3], c: usize| -> &'a [f32] { &v[c][r.start..][..n] };
    let (px, py, pz) = (col(&g.p, 0), col(&g.p, 1), col(&g.p, 2));
    let (ux, uy, uz) = (col(&g.du, 0), col(&g.du, 1), col(&g.du, 2));
    let (vx, vy, vz) = (col(&g.dv, 0), col(&g.dv, 1), col(&g.dv, 2));
    let (e, near) = (&mut e[..n], &near[..n]);
    let point = if BOUNDED { 1.0 } else { 0.0 };
    for i in 0..n {
        let axes = [[ux[i], uy[i], uz[i]], [vx[i], vy[i], vz[i]]];
        let lit = sphere_edge_lit([px[i], py[i], pz[i]], axes, to, point, s.center, s.radius);
        e[i] = if near[i] != 0 { e[i] * lit } else { e[i] };
    }
}

/// Mark pixel `i` of a block as `edge` (or not) and widen `span`, the marked pixels' [first, last + 1).
#[inline(always)]
fn mark(edge: bool, i: usize, near: &mut [u32; BLOCK], span: &mut (u32, u32)) {
    near[i] = u32::from(edge);
    span.0 = span.0.min(if edge { i as u32 } else { u32::MAX });
    span.1 = span.1.max(if edge { i as u32 + 1 } else { 0 });
}

/// The group's range of a block's marked `span` (the block starting at `start`) and the span within the
/// block; `None` when nothing is marked.
#[inline(always)]
fn marked(start: usize, (lo, hi): (u32, u32)) -> Option<(std::ops::Range<usize>, usize, usize)> {
    let (lo, hi) = (lo as usize, hi as usize);
    (hi > lo).then(|| (start + lo..start + hi, lo, hi))
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
        let ([cx, cy, cz], r2) = (s.center, s.radius * s.radius);
        let mut near = [0u32; BLOCK];
        let mut span = (u32::MAX, 0u32);
        let footprint = !g.spread.is_empty();
        for i in 0..n {
            // |d| = 1: the ray t in (0, inf).
            let chord = line_to_sphere([px[i] - cx, py[i] - cy, pz[i] - cz], d, 1.0, r2);
            let hit = segment_meets_sphere(chord, 1.0, (0.0, f32::INFINITY));
            // As for a point light (`shadow`), with a = 1 and the ray's whole move.
            let edge = footprint && {
                let w = g.spread[r.start + i];
                near_sphere_edge::<false>(1.0, chord, w, s.radius) & (e[i] > 0.0)
            };
            mark(edge, i, &mut near, &mut span);
            e[i] = if hit & !edge { 0.0 } else { e[i] };
        }
        soft_edge::<false>(g, r.start, span, s, d, &near, e);
    }
    for pl in &g.planes {
        // The ray heads towards the plane's other side when n·d and the pixel's side differ in sign.
        let side_l = pl.normal[0] * d[0] + pl.normal[1] * d[1] + pl.normal[2] * d[2];
        plane_shadow(pl, r.start, side_l, e);
    }
}

impl Gather {
    /// The unit-light diffuse factor (irradiance / π, shadowed) at every point, into `e`; with
    /// `parallel`, runs of [`GATHER_LIGHT_RUN`] points spread over the current pool (each point's value
    /// is its own: the same either way).
    #[inline(always)]
    pub(crate) fn light<const AVX2: bool>(&self, light: &Light, e: &mut Vec<f32>, parallel: bool) {
        e.resize(self.points.len(), 0.0);
        let blocks = |first: usize, e: &mut [f32]| {
            for (k, e) in e.chunks_mut(BLOCK).enumerate() {
                let r = first + k * BLOCK..first + k * BLOCK + e.len();
                irradiance::<AVX2>(&self.points, r.clone(), light, e);
                shadow(&self.points, r, light, e);
                for v in e.iter_mut() {
                    *v = lambert(*v);
                }
            }
        };
        if parallel {
            e.par_chunks_mut(GATHER_LIGHT_RUN)
                .enumerate()
                .for_each(|(k, e)| blocks(k * GATHER_LIGHT_RUN, e));
        } else {
            blocks(0, e);
        }
    }
}

/// Points per parallel run of [`Gather::light`] (whole blocks, as the serial loop takes them).
const GATHER_LIGHT_RUN: usize = 16 * BLOCK;
