//! One diffuse bounce between the scene's objects (interreflection): the floor lighting a ball's
//! underside, a red ball tinting the white floor beside it, one ball lighting another.
//!
//! A diffuse point p (normal n, albedo ρ) of one object receives from each other object k the radiance
//! that k sends it: ρ·Σ_k F_k(p)·L_k, with F_k the configuration factor of k from p (the cosine-weighted
//! fraction of p's hemisphere that k covers, the same one that darkens the environment: `environment`)
//! and L_k the radiance k leaves towards p (its direct light, environment and ambient, not its own
//! bounce: one bounce). A sphere, seen small, gives one representative point, the one nearest p, with
//! its closed-form factor; a plane, which covers much of the hemisphere with radiance that varies over
//! it (a ball's shadow on the floor), is integrated with a fixed stratified set of 32 cosine-weighted
//! directions from p, each that meets the plane first a point of weight 1/32.
//! The renderer (`shade`) and the fitness (`fitness::pixels`, light-independent part precomputed) both
//! call [`gather`], the only place the geometry lives.

use glam::Vec3A;

use super::environment::{plane_view, sphere_view};
use super::shape::PShape;

/// Senders whose configuration factor is below this are left out (a ball seen from a floor point more
/// than about 20 radii away).
pub const MIN_FORM: f32 = 2e-3;

/// The quadrature over a plane sender: `STRATA` rings (cos² of the polar angle at their centres) times
/// `PHI` azimuths, `DIRECTIONS` cosine-weighted directions in all.
const STRATA: [f32; 4] = [0.125, 0.375, 0.625, 0.875];
const PHI: [f32; 8] = [
    0.0625, 0.1875, 0.3125, 0.4375, 0.5625, 0.6875, 0.8125, 0.9375,
];
const DIRECTIONS: usize = STRATA.len() * PHI.len();

/// A sphere whose configuration factor from p is at least this is integrated over the cap p sees
/// (`CONE_RINGS` x `CONE_PHI` directions) rather than taken at its nearest point.
pub const CONE_FORM: f32 = 0.05;
const CONE_RINGS: [f32; 4] = [0.125, 0.375, 0.625, 0.875];
const CONE_PHI: [f32; 4] = [0.125, 0.375, 0.625, 0.875];

/// Where receiver point p gathers from one other object.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GatherPoint {
    /// The sending object.
    pub sender: usize,
    /// Its configuration factor from p.
    pub form: f32,
    /// The representative point on it and its normal there (facing p).
    pub position: Vec3A,
    pub normal: Vec3A,
}

/// Points per sphere at which its own bounce is tabulated (a Fibonacci lattice): a sphere seen as a
/// sender carries the light the floor (or another object) bounced onto it, the second bounce that colours
/// the floor next to a red ball; a sender point takes the value of its nearest table point.
pub const TABLE: usize = 64;

/// The table points of a sphere: positions and outward normals, a Fibonacci lattice of [`TABLE`] points.
pub fn table_points(center: Vec3A, radius: f32) -> Vec<(Vec3A, Vec3A)> {
    let golden = std::f32::consts::PI * (3.0 - 5.0f32.sqrt());
    (0..TABLE)
        .map(|i| {
            let y = 1.0 - 2.0 * (i as f32 + 0.5) / TABLE as f32;
            let r = (1.0 - y * y).max(0.0).sqrt();
            let phi = golden * i as f32;
            let n = Vec3A::new(r * phi.cos(), y, r * phi.sin());
            (center + radius * n, n)
        })
        .collect()
}

/// The table point of a sphere nearest to the point of it with outward normal `n` (any length): the
/// one whose normal has the largest dot product with `n`, the first of equals, as a scan of all
/// [`TABLE`] points finds it, from the few points [`TableIndex`] keeps for `n`'s cell.
pub fn nearest_table(n: Vec3A) -> usize {
    static INDEX: std::sync::OnceLock<TableIndex> = std::sync::OnceLock::new();
    INDEX.get_or_init(TableIndex::new).nearest(n)
}

/// The table points that can be nearest to a direction, per cell of a cube map ([`INDEX_CELLS`]² cells
/// per face): a cell lies within the cap of angular radius ρ about its centre direction c, so the
/// nearest point to any direction in it is within θ_min + 2ρ of c (θ_min: the nearest point's angle to
/// c); each cell keeps, in index order, the points within that angle plus [`INDEX_MARGIN`]. A point
/// left out is then at least the margin further from the direction than the nearest point, far more
/// than float rounding moves a dot product, so the first largest dot product among the kept points is
/// the scan's.
struct TableIndex {
    normals: Vec<Vec3A>,
    cells: Vec<Vec<u8>>,
}

/// Cube-map cells per face edge of [`TableIndex`]: 384 cells of about 11 degrees, 1-7 points each (3.1 on
/// average, against the scan's 64).
const INDEX_CELLS: usize = 8;
/// The angle (radians) by which a point left out of a [`TableIndex`] cell is further than the nearest.
const INDEX_MARGIN: f64 = 0.01;

impl TableIndex {
    fn new() -> TableIndex {
        let normals: Vec<Vec3A> = table_points(Vec3A::ZERO, 1.0)
            .into_iter()
            .map(|p| p.1)
            .collect();
        let angle = |a: [f64; 3], b: Vec3A| {
            let b = [b.x as f64, b.y as f64, b.z as f64];
            let nb = (b[0] * b[0] + b[1] * b[1] + b[2] * b[2]).sqrt();
            ((a[0] * b[0] + a[1] * b[1] + a[2] * b[2]) / nb)
                .clamp(-1.0, 1.0)
                .acos()
        };
        let mut cells = Vec::with_capacity(6 * INDEX_CELLS * INDEX_CELLS);
        for face in 0..6 {
            for iu in 0..INDEX_CELLS {
                for iv in 0..INDEX_CELLS {
                    let edge = |i: usize| -1.0 + 2.0 * i as f64 / INDEX_CELLS as f64;
                    let dir = |u: f64, v: f64| unit(face_direction(face, u, v));
                    let (u0, u1, v0, v1) = (edge(iu), edge(iu + 1), edge(iv), edge(iv + 1));
                    let c = dir(0.5 * (u0 + u1), 0.5 * (v0 + v1));
                    let rho = [(u0, v0), (u0, v1), (u1, v0), (u1, v1)]
                        .iter()
                        .map(|&(u, v)| {
                            let d = dir(u, v);
                            (c[0] * d[0] + c[1] * d[1] + c[2] * d[2])
                                .clamp(-1.0, 1.0)
                                .acos()
                        })
                        .fold(0.0, f64::max);
                    let theta: Vec<f64> = normals.iter().map(|&m| angle(c, m)).collect();
                    let min = theta.iter().copied().fold(f64::INFINITY, f64::min);
                    cells.push(
                        (0..normals.len())
                            .filter(|&k| theta[k] <= min + 2.0 * rho + INDEX_MARGIN)
                            .map(|k| k as u8)
                            .collect(),
                    );
                }
            }
        }
        TableIndex { normals, cells }
    }

    fn nearest(&self, n: Vec3A) -> usize {
        let scan = |ks: &mut dyn Iterator<Item = usize>| {
            let mut best = (0, f32::NEG_INFINITY);
            for k in ks {
                let d = self.normals[k].dot(n);
                if d > best.1 {
                    best = (k, d);
                }
            }
            best.0
        };
        let a = n.abs();
        let m = a.max_element();
        // Too short or not finite: every point, as the scan itself (the cells' reasoning needs a direction).
        if !(m > 1e-6 && m.is_finite()) {
            return scan(&mut (0..self.normals.len()));
        }
        let (face, u, v) = if a.x == m {
            (usize::from(n.x < 0.0), n.y / a.x, n.z / a.x)
        } else if a.y == m {
            (2 + usize::from(n.y < 0.0), n.z / a.y, n.x / a.y)
        } else {
            (4 + usize::from(n.z < 0.0), n.x / a.z, n.y / a.z)
        };
        let cell = |t: f32| (((t + 1.0) * 0.5 * INDEX_CELLS as f32) as usize).min(INDEX_CELLS - 1);
        let kept = &self.cells[(face * INDEX_CELLS + cell(u)) * INDEX_CELLS + cell(v)];
        scan(&mut kept.iter().map(|&k| k as usize))
    }
}

/// The direction of cube-map face `face` (+x, -x, +y, -y, +z, -z) at face coordinates (u, v) in
/// [-1, 1], as [`TableIndex::nearest`] reads them: +-x takes (y, z), +-y (z, x), +-z (x, y).
fn face_direction(face: usize, u: f64, v: f64) -> [f64; 3] {
    let s = if face % 2 == 0 { 1.0 } else { -1.0 };
    match face / 2 {
        0 => [s, u, v],
        1 => [v, s, u],
        _ => [u, v, s],
    }
}

fn unit(d: [f64; 3]) -> [f64; 3] {
    let l = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
    [d[0] / l, d[1] / l, d[2] / l]
}

/// The representative points of every other shape that the surface point `p` (unit normal `n`) of
/// object `own` sees with a configuration factor of at least [`MIN_FORM`], in shape order.
pub fn gather(p: Vec3A, n: Vec3A, own: usize, shapes: &[PShape], out: &mut Vec<GatherPoint>) {
    out.clear();
    for (k, shape) in shapes.iter().enumerate() {
        if k == own {
            continue;
        }
        match *shape {
            PShape::Sphere { center, radius } => {
                let form = sphere_view(p, n, center, radius);
                let to = center - p;
                let d = to.length();
                if form < MIN_FORM || !(d > radius) {
                    continue;
                }
                let w = to / d;
                if form < CONE_FORM {
                    out.push(GatherPoint {
                        sender: k,
                        form,
                        position: center - radius * w,
                        normal: -w,
                    });
                    continue;
                }
                // Seen large (a floor point by the ball): its radiance varies over the visible cap (lit on
                // one side), so a stratified set of directions inside the cone it subtends, each weighted by
                // its cosine and solid angle, the weights scaled to the closed-form factor.
                let cos_max = (1.0 - (radius / d).powi(2)).max(0.0).sqrt();
                let (u_axis, v_axis) = w.any_orthonormal_pair();
                let start = out.len();
                let mut total = 0.0f32;
                for (ci, pj) in CONE_RINGS
                    .iter()
                    .flat_map(|&c| CONE_PHI.iter().map(move |&p| (c, p)))
                {
                    let cos_t = 1.0 - ci * (1.0 - cos_max);
                    let sin_t = (1.0 - cos_t * cos_t).max(0.0).sqrt();
                    let phi = std::f32::consts::TAU * pj;
                    let dir =
                        w * cos_t + u_axis * (sin_t * phi.cos()) + v_axis * (sin_t * phi.sin());
                    let weight = n.dot(dir);
                    if !(weight > 0.0) {
                        continue;
                    }
                    // The near intersection with the sphere.
                    let b = dir.dot(to);
                    let t = b - (radius * radius - (d * d - b * b)).max(0.0).sqrt();
                    // A direction another shape hides counts in the total (that shape gathers it).
                    total += weight;
                    let blocked = shapes
                        .iter()
                        .enumerate()
                        .any(|(j, sh)| j != k && j != own && sh.hits_segment(p, dir, 0.0, t));
                    if blocked {
                        continue;
                    }
                    let y = p + t * dir;
                    out.push(GatherPoint {
                        sender: k,
                        form: weight,
                        position: y,
                        normal: ((y - center) / radius).normalize_or_zero(),
                    });
                }
                if total > 0.0 {
                    for g in &mut out[start..] {
                        g.form *= form / total;
                    }
                }
            }
            PShape::Plane { point, normal } => {
                let form = plane_view(p, n, point, normal);
                if form < MIN_FORM {
                    continue;
                }
                let side = normal.dot(p - point);
                let towards = if side > 0.0 { normal } else { -normal };
                // A plane covers much of the hemisphere and its radiance varies over it (a ball's shadow on
                // the floor below it): a fixed stratified set of cosine-weighted directions, each that meets
                // the plane first (no other shape in between) a point of weight 1/DIRECTIONS.
                let (t_axis, b_axis) = n.any_orthonormal_pair();
                let w = 1.0 / DIRECTIONS as f32;
                for (u1, u2) in STRATA
                    .iter()
                    .flat_map(|&u1| PHI.iter().map(move |&u2| (u1, u2)))
                {
                    let (r, phi) = (u1.sqrt(), std::f32::consts::TAU * u2);
                    let d =
                        t_axis * (r * phi.cos()) + b_axis * (r * phi.sin()) + n * (1.0 - u1).sqrt();
                    let down = -d.dot(towards);
                    if !(down > 1e-6) {
                        continue;
                    }
                    let t = side.abs() / down;
                    let blocked = shapes
                        .iter()
                        .enumerate()
                        .any(|(j, sh)| j != k && j != own && sh.hits_segment(p, d, 0.0, t));
                    if !blocked {
                        out.push(GatherPoint {
                            sender: k,
                            form: w,
                            position: p + t * d,
                            normal: towards,
                        });
                    }
                }
            }
            PShape::Mesh(_) => {} // meshes neither send nor (here) block bounce light (docs/scene-format.md)
        }
    }
}

/// One gather point as a render keeps it: the point, its sender's table point (`u32::MAX` for a plane
/// sender, which has no table) and, where the cache was built for a scene with environment light, the
/// point's sky view (NaN otherwise): everything of a sender's radiance that does not depend on the light
/// or the materials.
#[derive(Clone, Copy, Debug)]
pub struct CachedPoint {
    pub point: GatherPoint,
    pub table: u32,
    pub sky: f32,
}

/// The light-independent part of one bounce render (`render::render_with`, one sample per pixel): per
/// pixel centre its gather points, and per sphere the gather points of its table points (see
/// [`TABLE`]). Every render with the same camera, image size and shapes gathers from the same points (a
/// fit's uncertainty renders the scene eight times with the light moved), so the last one built is kept
/// ([`Gathered::for_render`]) and a render with interreflection costs its shadow rays and shading, not
/// the geometry again: the same values, bit for bit.
#[derive(Debug)]
pub struct Gathered {
    key: Vec<u32>,
    /// Pixel i's points are `points[offsets[i]..offsets[i + 1]]`.
    offsets: Vec<u32>,
    points: Vec<CachedPoint>,
    /// Per shape: for a sphere, per table point, its points as `table_points[..]` ranges; empty otherwise.
    tables: Vec<Vec<Vec<CachedPoint>>>,
}

/// The last [`Gathered`] built (one: a fit renders one geometry many times; another geometry replaces it).
static LAST: std::sync::Mutex<Option<std::sync::Arc<Gathered>>> = std::sync::Mutex::new(None);

/// The bits of what a render's first hits depend on: the image size, the camera settings (`camera_key`) and
/// the spheres and planes of `geometry`; `None` with a mesh (not compared). Two renders with the same key
/// see the same surfaces at every pixel.
pub(crate) fn geometry_key(
    geometry: &super::hit::Geometry,
    camera_key: [f64; 10],
    (width, height): (u32, u32),
) -> Option<Vec<u32>> {
    let mut key = vec![width, height];
    for v in camera_key {
        let b = v.to_bits();
        key.extend([b as u32, (b >> 32) as u32]);
    }
    for s in &geometry.shapes {
        match *s {
            PShape::Sphere { center, radius } => {
                key.push(0);
                key.extend(center.to_array().map(f32::to_bits));
                key.push(radius.to_bits());
            }
            PShape::Plane { point, normal } => {
                key.push(1);
                key.extend(point.to_array().map(f32::to_bits));
                key.extend(normal.to_array().map(f32::to_bits));
            }
            PShape::Mesh(_) => return None,
        }
    }
    Some(key)
}

impl Gathered {
    /// Pixel `i`'s gather points.
    #[inline]
    pub fn pixel(&self, i: usize) -> &[CachedPoint] {
        &self.points[self.offsets[i] as usize..self.offsets[i + 1] as usize]
    }

    /// Shape `k`'s table: per table point its gather points (empty for a plane).
    pub fn table(&self, k: usize) -> &[Vec<CachedPoint>] {
        self.tables.get(k).map_or(&[], |t| &t[..])
    }

    /// The gathers of a render of `width` x `height` pixel centres through `camera` (its scene's camera
    /// settings, `camera_key`) over `shapes`, with the sky views when `sky`: the last one built if its
    /// geometry is the same (bit for bit), else built (in parallel) and kept. `None` with a mesh.
    pub fn for_render(
        geometry: &super::hit::Geometry,
        camera_key: [f64; 10],
        (width, height): (u32, u32),
        sky: bool,
    ) -> Option<std::sync::Arc<Gathered>> {
        use rayon::prelude::*;
        let shapes = &geometry.shapes[..];
        let mut key = geometry_key(geometry, camera_key, (width, height))?;
        key.push(u32::from(sky));
        if let Some(last) = LAST.lock().ok().and_then(|g| g.clone()) {
            if last.key == key {
                return Some(last);
            }
        }
        let at: Vec<Vec<(Vec3A, Vec3A)>> = shapes
            .iter()
            .map(|s| match *s {
                PShape::Sphere { center, radius } => table_points(center, radius),
                _ => Vec::new(),
            })
            .collect();
        let keep =
            |own: usize, p: Vec3A, n: Vec3A, out: &mut Vec<GatherPoint>| -> Vec<CachedPoint> {
                gather(p, n, own, shapes, out);
                out.iter()
                    .map(|g| CachedPoint {
                        point: *g,
                        table: if at[g.sender].is_empty() {
                            u32::MAX
                        } else {
                            nearest_table(g.normal) as u32
                        },
                        sky: if sky {
                            super::environment::sky_view(g.position, g.normal, g.sender, shapes)
                        } else {
                            f32::NAN
                        },
                    })
                    .collect()
            };
        let rows: Vec<Vec<Vec<CachedPoint>>> = (0..height)
            .into_par_iter()
            .map(|j| {
                let mut out = Vec::new();
                (0..width)
                    .map(|i| {
                        let s = geometry.primary(i as f32 + 0.5, j as f32 + 0.5, width, height);
                        if s.object == u32::MAX {
                            Vec::new()
                        } else {
                            keep(s.object as usize, s.position, s.normal, &mut out)
                        }
                    })
                    .collect()
            })
            .collect();
        let mut offsets = Vec::with_capacity((width * height) as usize + 1);
        let mut points = Vec::new();
        offsets.push(0u32);
        for px in rows.into_iter().flatten() {
            points.extend_from_slice(&px);
            offsets.push(points.len() as u32);
        }
        let mut out = Vec::new();
        let tables = at
            .iter()
            .enumerate()
            .map(|(k, pts)| pts.iter().map(|&(y, n)| keep(k, y, n, &mut out)).collect())
            .collect();
        let built = std::sync::Arc::new(Gathered {
            key,
            offsets,
            points,
            tables,
        });
        if let Ok(mut g) = LAST.lock() {
            *g = Some(built.clone());
        }
        Some(built)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ball_on_floor() -> [PShape; 2] {
        crate::render::shape::ball_over_floor(1.0, 1.0)
    }

    #[test]
    fn a_ball_gathers_from_the_floor_below_it() {
        let shapes = ball_on_floor();
        let mut out = Vec::new();
        let total = |out: &[GatherPoint]| out.iter().map(|g| g.form).sum::<f32>();
        // The ball's bottom (just above the floor) sees only floor: every direction, all near the contact.
        gather(Vec3A::new(0.0, 0.01, 0.0), -Vec3A::Y, 1, &shapes, &mut out);
        assert_eq!(out.len(), DIRECTIONS);
        assert!((total(&out) - 1.0).abs() < 1e-5);
        assert!(out
            .iter()
            .all(|g| g.sender == 0 && g.normal == Vec3A::Y && g.position.y.abs() < 1e-6));
        // The quadrature's weight matches the closed-form factor within one direction's share, at any tilt.
        for deg in [10.0f32, 45.0, 80.0, 100.0, 135.0] {
            let (s, c) = deg.to_radians().sin_cos();
            let n = Vec3A::new(s, c, 0.0);
            let p = Vec3A::new(0.0, 1.0, 0.0) + n;
            gather(p, n, 1, &shapes, &mut out);
            let want = plane_view(p, n, Vec3A::ZERO, Vec3A::Y);
            assert!(
                (total(&out) - want).abs() <= 1.5 / DIRECTIONS as f32,
                "{deg}: {} vs {want}",
                total(&out)
            );
            assert!(out.iter().all(|g| g.position.y.abs() < 1e-4));
        }
        // The top sees no floor.
        gather(Vec3A::new(0.0, 2.0, 0.0), Vec3A::Y, 1, &shapes, &mut out);
        assert!(out.is_empty());
    }

    #[test]
    fn a_ball_in_between_hides_the_floor_behind_it() {
        // A second ball right beside the first: directions that meet it first do not reach the floor.
        let mut shapes = ball_on_floor().to_vec();
        shapes.push(PShape::Sphere {
            center: Vec3A::new(2.2, 1.0, 0.0),
            radius: 1.0,
        });
        let mut out = Vec::new();
        let p = Vec3A::new(1.0, 1.0, 0.0);
        gather(p, Vec3A::X, 1, &shapes, &mut out);
        let floor: f32 = out.iter().filter(|g| g.sender == 0).map(|g| g.form).sum();
        assert!(floor < 0.45, "{floor}");
        assert!(out.iter().any(|g| g.sender == 2));
    }

    /// The first largest dot product over all table points: what [`nearest_table`] must return.
    fn nearest_by_scan(n: Vec3A) -> usize {
        let at = table_points(Vec3A::ZERO, 1.0);
        let mut best = (0, f32::NEG_INFINITY);
        for (k, &(_, m)) in at.iter().enumerate() {
            let d = m.dot(n);
            if d > best.1 {
                best = (k, d);
            }
        }
        best.0
    }

    #[test]
    fn the_table_index_finds_the_scans_point() {
        let index = TableIndex::new();
        let sizes: Vec<usize> = index.cells.iter().map(Vec::len).collect();
        assert!(sizes.iter().all(|&k| k >= 1));
        assert!(*sizes.iter().max().unwrap() < TABLE / 4, "{sizes:?}");
        let at = table_points(Vec3A::new(1.0, -2.0, 0.5), 0.3);
        let mut hard: Vec<Vec3A> = Vec::new();
        // The table points, the midpoints of every pair (ties between two points), cube-map cell
        // corners and edges, axes, and lengths from tiny to huge.
        for &(_, m) in &at {
            hard.push(m);
            for &(_, q) in &at {
                hard.push(0.5 * (m + q));
            }
        }
        for face in 0..6 {
            for i in 0..=INDEX_CELLS {
                for j in 0..=2 * INDEX_CELLS {
                    let u = -1.0 + 2.0 * i as f64 / INDEX_CELLS as f64;
                    let v = -1.0 + j as f64 / INDEX_CELLS as f64;
                    let d = face_direction(face, u, v);
                    hard.push(Vec3A::new(d[0] as f32, d[1] as f32, d[2] as f32));
                    let d = face_direction(face, v, u);
                    hard.push(Vec3A::new(d[0] as f32, d[1] as f32, d[2] as f32));
                }
            }
        }
        let scaled: Vec<Vec3A> = hard
            .iter()
            .flat_map(|&n| [n * 1e-5, n * 3.7, n * 1e20])
            .collect();
        hard.extend(scaled);
        hard.extend([
            Vec3A::ZERO,
            Vec3A::splat(f32::NAN),
            Vec3A::new(f32::INFINITY, 0.0, 1.0),
            Vec3A::splat(1e-30),
        ]);
        for n in hard {
            assert_eq!(nearest_table(n), nearest_by_scan(n), "{n}");
        }
    }

    proptest::proptest! {
        #[test]
        fn the_table_index_agrees_with_the_scan(x in -1.0f32..1.0, y in -1.0f32..1.0, z in -1.0f32..1.0,
                                               scale in -3.0f32..3.0) {
            let n = Vec3A::new(x, y, z) * 10f32.powf(scale);
            proptest::prop_assert_eq!(nearest_table(n), nearest_by_scan(n));
        }
    }

    #[test]
    fn table_points_cover_the_sphere() {
        let at = table_points(Vec3A::new(1.0, 2.0, 3.0), 0.5);
        assert_eq!(at.len(), TABLE);
        for &(p, n) in &at {
            assert!(
                ((p - Vec3A::new(1.0, 2.0, 3.0)).length() - 0.5).abs() < 1e-5
                    && (n.length() - 1.0).abs() < 1e-5
            );
        }
        // Every direction has a table point within ~20 degrees.
        for k in 0..200 {
            let z = 1.0 - 2.0 * (k as f32 + 0.5) / 200.0;
            let r = (1.0 - z * z).sqrt();
            let n = Vec3A::new(r * (k as f32).cos(), z, r * (k as f32).sin());
            let j = nearest_table(n);
            assert!(at[j].1.dot(n) > 20f32.to_radians().cos(), "{n}");
        }
    }

    #[test]
    fn the_floor_gathers_from_the_ball() {
        let shapes = ball_on_floor();
        let mut out = Vec::new();
        let c = Vec3A::new(0.0, 1.0, 0.0);
        // Seen small, the ball is its nearest point with the closed-form factor.
        let far = Vec3A::new(5.0, 0.0, 0.0);
        gather(far, Vec3A::Y, 0, &shapes, &mut out);
        assert_eq!(out.len(), 1);
        let w = (c - far).normalize();
        assert!((out[0].position - (c - w)).length() < 1e-5);
        assert!((out[0].form - sphere_view(far, Vec3A::Y, c, 1.0)).abs() < 1e-9);
        // Seen large, the cap it sees: points on the sphere facing p, weights summing to the factor.
        let near = Vec3A::new(1.2, 0.0, 0.3);
        gather(near, Vec3A::Y, 0, &shapes, &mut out);
        assert!(out.len() > 8);
        let total: f32 = out.iter().map(|g| g.form).sum();
        assert!((total - sphere_view(near, Vec3A::Y, c, 1.0)).abs() < 1e-5);
        for g in &out {
            assert!(((g.position - c).length() - 1.0).abs() < 1e-4);
            assert!(
                g.normal.dot(near - g.position) > 0.0,
                "a point of the cap faces p"
            );
        }
        // Far away the ball's factor falls below MIN_FORM: nothing gathered.
        gather(Vec3A::new(60.0, 0.0, 0.0), Vec3A::Y, 0, &shapes, &mut out);
        assert!(out.is_empty());
    }
}
