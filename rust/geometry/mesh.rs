//! Triangle meshes: Möller–Trumbore ray–triangle tests over a binary BVH (median split
//! on the longest centroid axis), for camera rays (`intersect`) and shadow rays (`hits_segment`).

use glam::{DVec3, Vec3A};

use super::ShapeHit;

/// Triangles per leaf at most.
const LEAF: usize = 4;

/// One triangle: a vertex, its two edges and their (unnormalised) cross product.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Tri {
    v0: Vec3A,
    e1: Vec3A,
    e2: Vec3A,
    /// e1 × e2: the face normal times twice the area.
    n: Vec3A,
}

/// A BVH node: its box; a leaf holds `count` > 0 triangles from `first`, an inner node has children
/// `first` and `first + 1`.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Node {
    lo: Vec3A,
    hi: Vec3A,
    first: u32,
    count: u32,
}

/// A triangle mesh in world space with its BVH, ready to intersect.
#[derive(Clone, PartialEq)]
pub struct Mesh {
    tris: Vec<Tri>,
    /// Per-triangle vertex normals (unit), when the file has them.
    normals: Option<Vec<[Vec3A; 3]>>,
    nodes: Vec<Node>,
    /// The largest coordinate magnitude, for scale-aware epsilons.
    scale: f32,
}

impl std::fmt::Debug for Mesh {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "Mesh({} triangles, {} nodes)",
            self.tris.len(),
            self.nodes.len()
        )
    }
}

/// Twice the area of the triangle, in f64.
fn area2(v: &[DVec3; 3]) -> f64 {
    (v[1] - v[0]).cross(v[2] - v[0]).length()
}

impl Mesh {
    /// Build from world-space triangles (f64, as the scene holds them) and optional vertex normals.
    /// Degenerate triangles (zero area in f32) are dropped: they can never be hit. `None` when no
    /// triangle is left.
    pub fn new(triangles: &[[DVec3; 3]], normals: Option<&[[DVec3; 3]]>) -> Option<Mesh> {
        let mut tris = Vec::with_capacity(triangles.len());
        let mut nrm = normals.map(|_| Vec::with_capacity(triangles.len()));
        for (k, t) in triangles.iter().enumerate() {
            let v0 = t[0].as_vec3a();
            let (e1, e2) = ((t[1] - t[0]).as_vec3a(), (t[2] - t[0]).as_vec3a());
            let n = e1.cross(e2);
            let extent = e1.length().max(e2.length());
            if !(n.length() > 1e-6 * extent * extent) || area2(t) == 0.0 {
                continue;
            }
            tris.push(Tri { v0, e1, e2, n });
            if let (Some(out), Some(ns)) = (nrm.as_mut(), normals) {
                let unit = |v: DVec3| {
                    let u = v.normalize_or_zero().as_vec3a();
                    if u == Vec3A::ZERO {
                        n.normalize()
                    } else {
                        u
                    }
                };
                out.push([unit(ns[k][0]), unit(ns[k][1]), unit(ns[k][2])]);
            }
        }
        if tris.is_empty() {
            return None;
        }
        let scale = tris
            .iter()
            .map(|t| {
                t.v0.abs()
                    .max((t.v0 + t.e1).abs())
                    .max((t.v0 + t.e2).abs())
                    .max_element()
            })
            .fold(0.0f32, f32::max);
        let mut mesh = Mesh {
            tris,
            normals: nrm,
            nodes: Vec::new(),
            scale,
        };
        mesh.build();
        Some(mesh)
    }

    pub fn triangle_count(&self) -> usize {
        self.tris.len()
    }

    pub fn scale(&self) -> f32 {
        self.scale
    }

    /// The box of triangles `idx`, padded.
    fn bounds(&self, idx: &[u32]) -> (Vec3A, Vec3A) {
        let mut lo = Vec3A::splat(f32::INFINITY);
        let mut hi = Vec3A::splat(f32::NEG_INFINITY);
        for t in idx.iter().map(|&i| &self.tris[i as usize]) {
            for v in [t.v0, t.v0 + t.e1, t.v0 + t.e2] {
                lo = lo.min(v);
                hi = hi.max(v);
            }
        }
        // Widen by the rounding of v0 + e: the box must contain what the triangle test sees.
        let pad = Vec3A::splat(4.0 * f32::EPSILON * self.scale);
        (lo - pad, hi + pad)
    }

    /// Median split on the longest axis of the triangle centroids, leaves of at most `LEAF` triangles.
    fn build(&mut self) {
        let n = self.tris.len();
        let mut order: Vec<u32> = (0..n as u32).collect();
        let centroid = |t: &Tri| t.v0 + (t.e1 + t.e2) / 3.0;
        let cents: Vec<Vec3A> = self.tris.iter().map(centroid).collect();
        let (lo, hi) = self.bounds(&order);
        self.nodes.push(Node {
            lo,
            hi,
            first: 0,
            count: n as u32,
        });
        // (node index, start, end) into `order`.
        let mut stack = vec![(0usize, 0usize, n)];
        while let Some((node, start, end)) = stack.pop() {
            if end - start <= LEAF {
                self.nodes[node].first = start as u32;
                self.nodes[node].count = (end - start) as u32;
                continue;
            }
            let (mut clo, mut chi) = (Vec3A::splat(f32::INFINITY), Vec3A::splat(f32::NEG_INFINITY));
            for &i in &order[start..end] {
                clo = clo.min(cents[i as usize]);
                chi = chi.max(cents[i as usize]);
            }
            let ext = chi - clo;
            let axis = if ext.x >= ext.y && ext.x >= ext.z {
                0
            } else if ext.y >= ext.z {
                1
            } else {
                2
            };
            let mid = (start + end) / 2;
            order[start..end].select_nth_unstable_by(mid - start, |&a, &b| {
                cents[a as usize][axis].total_cmp(&cents[b as usize][axis])
            });
            let first = self.nodes.len();
            for (s, e) in [(start, mid), (mid, end)] {
                let (lo, hi) = self.bounds(&order[s..e]);
                self.nodes.push(Node {
                    lo,
                    hi,
                    first: 0,
                    count: 0,
                });
            }
            self.nodes[node].first = first as u32;
            self.nodes[node].count = 0;
            stack.push((first, start, mid));
            stack.push((first + 1, mid, end));
        }
        self.tris = order.iter().map(|&i| self.tris[i as usize]).collect();
        if let Some(ns) = &self.normals {
            self.normals = Some(order.iter().map(|&i| ns[i as usize]).collect());
        }
    }

    /// Entry distance of the ray into the node's box within (`tmin`, `tmax`), if it enters.
    #[inline]
    fn enter(node: &Node, origin: Vec3A, inv: Vec3A, tmin: f32, tmax: f32) -> Option<f32> {
        let a = (node.lo - origin) * inv;
        let b = (node.hi - origin) * inv;
        // NaN (0 · inf, a ray in a box's face plane) is dropped by min/max: the other slabs decide.
        let near = a.min(b).max_element().max(tmin);
        let far = a.max(b).min_element().min(tmax);
        (near <= far).then_some(near)
    }

    /// Walk the BVH; `visit(k, tmax)` tests triangle `k` and returns a new `tmax` on a hit, and
    /// `any` stops at the first hit.
    #[inline]
    fn walk(
        &self,
        origin: Vec3A,
        dir: Vec3A,
        tmin: f32,
        mut tmax: f32,
        any: bool,
        mut visit: impl FnMut(usize, f32) -> Option<f32>,
    ) -> bool {
        let inv = dir.recip();
        let mut stack = [0u32; 64];
        let mut sp = 0usize;
        let mut node = 0usize;
        let mut hit = false;
        if Self::enter(&self.nodes[0], origin, inv, tmin, tmax).is_none() {
            return false;
        }
        loop {
            let n = &self.nodes[node];
            if n.count > 0 {
                for k in n.first as usize..(n.first + n.count) as usize {
                    if let Some(t) = visit(k, tmax) {
                        hit = true;
                        if any {
                            return true;
                        }
                        tmax = t;
                    }
                }
            } else {
                let (l, r) = (n.first as usize, n.first as usize + 1);
                let tl = Self::enter(&self.nodes[l], origin, inv, tmin, tmax);
                let tr = Self::enter(&self.nodes[r], origin, inv, tmin, tmax);
                match (tl, tr) {
                    (Some(a), Some(b)) => {
                        let (near, far) = if a <= b { (l, r) } else { (r, l) };
                        if sp < stack.len() {
                            stack[sp] = far as u32;
                            sp += 1;
                        }
                        node = near;
                        continue;
                    }
                    (Some(_), None) => {
                        node = l;
                        continue;
                    }
                    (None, Some(_)) => {
                        node = r;
                        continue;
                    }
                    (None, None) => {}
                }
            }
            if sp == 0 {
                return hit;
            }
            sp -= 1;
            node = stack[sp] as usize;
        }
    }

    /// Nearest hit in (`tmin`, `tmax`) along the unit `dir`; the normal faces the ray's origin
    /// (two-sided), smooth where the file has normals.
    pub fn intersect(&self, origin: Vec3A, dir: Vec3A, tmin: f32, tmax: f32) -> Option<ShapeHit> {
        let mut best: Option<(usize, f32, f32, f32)> = None;
        self.walk(origin, dir, tmin, tmax, false, |k, tmax| {
            let (t, u, v) = triangle(&self.tris[k], origin, dir, tmin, tmax)?;
            best = Some((k, t, u, v));
            Some(t)
        });
        let (k, t, u, v) = best?;
        let tri = &self.tris[k];
        let mut ng = tri.n.normalize();
        if ng.dot(dir) > 0.0 {
            ng = -ng;
        }
        let normal = match &self.normals {
            None => ng,
            Some(ns) => {
                let [n0, n1, n2] = ns[k];
                let s = ((1.0 - u - v) * n0 + u * n1 + v * n2).normalize_or(ng);
                if s.dot(ng) < 0.0 {
                    -s
                } else {
                    s
                }
            }
        };
        Some(ShapeHit {
            t,
            position: tri.v0 + u * tri.e1 + v * tri.e2,
            normal,
        })
    }

    /// True if the open segment `origin + t·dir`, `t` in (`tmin`, `tmax`), meets a triangle.
    pub fn hits_segment(&self, origin: Vec3A, dir: Vec3A, tmin: f32, tmax: f32) -> bool {
        self.walk(origin, dir, tmin, tmax, true, |k, tmax| {
            triangle(&self.tris[k], origin, dir, tmin, tmax).map(|h| h.0)
        })
    }
}

/// Möller–Trumbore: (t, u, v) of the ray's hit on `tri` with `t` in (`tmin`, `tmax`). Rays within
/// ~1e-7 rad of the triangle's plane (relative to its size, so any scale) and degenerate triangles miss.
#[inline(always)]
fn triangle(tri: &Tri, origin: Vec3A, dir: Vec3A, tmin: f32, tmax: f32) -> Option<(f32, f32, f32)> {
    let p = dir.cross(tri.e2);
    let det = tri.e1.dot(p);
    // det = -dir · n; |det| / |n| is the cosine between the ray and the plane's normal.
    if !(det.abs() > 1e-7 * tri.n.length()) {
        return None;
    }
    let inv = 1.0 / det;
    let s = origin - tri.v0;
    let u = s.dot(p) * inv;
    if !(0.0..=1.0).contains(&u) {
        return None;
    }
    let q = s.cross(tri.e1);
    let v = dir.dot(q) * inv;
    if v < 0.0 || u + v > 1.0 {
        return None;
    }
    let t = tri.e2.dot(q) * inv;
    (t > tmin && t < tmax).then_some((t, u, v))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Float64 reference by the plane equation and barycentric areas (not Möller–Trumbore).
    fn ref_hit(v: &[DVec3; 3], o: DVec3, d: DVec3) -> Option<f64> {
        let n = (v[1] - v[0]).cross(v[2] - v[0]);
        let denom = n.dot(d);
        if denom.abs() < 1e-300 {
            return None;
        }
        let t = n.dot(v[0] - o) / denom;
        let p = o + t * d;
        let inside = (0..3).all(|i| {
            let (a, b) = (v[i], v[(i + 1) % 3]);
            (b - a).cross(p - a).dot(n) >= 0.0
        });
        (inside && t > 0.0).then_some(t)
    }

    /// A tiny deterministic generator (no dependency).
    fn lcg(state: &mut u64) -> f64 {
        *state = state
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (*state >> 11) as f64 / (1u64 << 53) as f64
    }

    #[test]
    fn ray_triangle_matches_f64_reference_at_every_scale() {
        let mut st = 7u64;
        for scale in [1e-3f64, 1.0, 1e3] {
            let (mut agree, mut total, mut terr) = (0, 0, 0.0f64);
            for _ in 0..2000 {
                let mut r = || DVec3::new(lcg(&mut st), lcg(&mut st), lcg(&mut st)) - 0.5;
                let v = [r() * scale, r() * scale, r() * scale];
                let o = (r() * 4.0 + DVec3::new(0.0, 0.0, 3.0)) * scale;
                let target = (v[0] + v[1] + v[2]) / 3.0 + r() * scale * 0.8;
                let d = (target - o).normalize();
                let mesh = Mesh::new(&[v], None).unwrap();
                let got = mesh.intersect(o.as_vec3a(), d.as_vec3a(), 0.0, f32::INFINITY);
                let want = ref_hit(&v, o, d);
                total += 1;
                if got.is_some() == want.is_some() {
                    agree += 1;
                }
                if let (Some(g), Some(t)) = (got, want) {
                    terr = terr.max(((g.t as f64) - t).abs() / t);
                    let n = (v[1] - v[0]).cross(v[2] - v[0]).normalize();
                    let n = if n.dot(d) > 0.0 { -n } else { n };
                    assert!((g.normal.as_dvec3() - n).length() < 1e-4, "scale {scale}");
                }
            }
            // Only rays within f32 rounding of an edge may disagree.
            assert!(agree >= total - 4, "scale {scale}: {agree}/{total} agree");
            assert!(terr < 1e-4, "scale {scale}: relative t error {terr}");
        }
    }

    #[test]
    fn degenerate_triangles_are_never_hit() {
        let z = DVec3::new(0.0, 0.0, 2.0);
        let line = [z, z + DVec3::X, z + 2.0 * DVec3::X];
        let point = [z, z, z];
        assert!(Mesh::new(&[line], None).is_none());
        assert!(Mesh::new(&[point], None).is_none());
        // Mixed with a good triangle, only the good one is hit.
        let good = [
            DVec3::new(-1.0, -1.0, 5.0),
            DVec3::new(1.0, -1.0, 5.0),
            DVec3::new(0.0, 1.0, 5.0),
        ];
        let m = Mesh::new(&[line, good, point], None).unwrap();
        assert_eq!(m.triangle_count(), 1);
        for x in [0.0f32, 0.5, 1.0, 1.5, 2.0] {
            let o = Vec3A::new(x, 0.0, 0.0);
            let h = m.intersect(o, Vec3A::Z, 0.0, f32::INFINITY);
            assert!(h.map_or(true, |h| (h.t - 5.0).abs() < 1e-5), "x {x}");
        }
        // Rays grazing a triangle's plane miss instead of returning NaN.
        let g = m.intersect(Vec3A::new(-2.0, 0.0, 5.0), Vec3A::X, 0.0, f32::INFINITY);
        assert!(g.is_none());
    }

    #[test]
    fn bvh_finds_the_same_nearest_hit_as_brute_force() {
        let mut st = 11u64;
        let tris: Vec<[DVec3; 3]> = (0..500)
            .map(|_| {
                let c = DVec3::new(lcg(&mut st), lcg(&mut st), lcg(&mut st)) * 10.0;
                let mut r = || DVec3::new(lcg(&mut st), lcg(&mut st), lcg(&mut st)) - 0.5;
                [c + r(), c + r(), c + r()]
            })
            .collect();
        let m = Mesh::new(&tris, None).unwrap();
        for _ in 0..500 {
            let o = DVec3::new(lcg(&mut st), lcg(&mut st), -5.0) * 10.0;
            let d = (DVec3::new(lcg(&mut st), lcg(&mut st), lcg(&mut st)) * 10.0 - o).normalize();
            let want = tris
                .iter()
                .filter_map(|t| ref_hit(t, o, d))
                .fold(f64::INFINITY, f64::min);
            let got = m.intersect(o.as_vec3a(), d.as_vec3a(), 0.0, f32::INFINITY);
            match got {
                Some(h) => assert!(((h.t as f64) - want).abs() < 1e-4 * want),
                None => assert!(want.is_infinite()),
            }
            let seg = m.hits_segment(o.as_vec3a(), d.as_vec3a(), 0.0, 1e3);
            assert_eq!(seg, want.is_finite());
        }
    }
}
