//! The fused fitness kernel: shading and loss for one candidate over precomputed pixels.
//!
//! `Kernel::new` does all candidate-independent work once per fit: the first hits are stored as a
//! structure of arrays, grouped by object (so each group shares one material and one list of possible
//! occluders), together with the objective and, per pixel and occluder, the part of the shadow test that
//! does not depend on the light (`|p - c|² - r²` for a sphere, the signed distance `n·(p - q)` for a plane).
//! An evaluation then walks the groups in blocks of `BLOCK` pixels with branch-free loops the compiler
//! vectorises, never renders an image and never allocates.
//!
//! Model only what the scene needs: an object is never tested as its own occluder (a sphere or a plane
//! cannot shadow its lit side), a scene with one object has no shadow tests at all, the Blinn–Phong lobe
//! is compiled out when every specular is 0, background pixels under a fixed background are not here
//! at all (their loss is a constant), and the linear loss space compiles the encoding away (the sRGB
//! space's loops are separate monomorphisations: see [`crate::space::Encoding`]).

use glam::Vec3A;
use rayon::prelude::*;

use crate::render::{PShape, ShadeParams, Surfel};
use crate::space::{Encoding, Identity, Space, SrgbLut};

/// How a pixel's difference d = model - objective is penalised. `L1` is the paper's; `L2` is the maximum
/// likelihood under Gaussian noise; `Huber(h)` is quadratic within `h` and linear beyond (d²/(2h), then
/// |d| - h/2), robust to a few pixels the scene does not model.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Norm {
    L1,
    L2,
    Huber(f32),
}

impl Norm {
    /// "l1", "l2", "huber" (h = 0.02) or "huber:H".
    pub fn parse(s: &str) -> Result<Norm, String> {
        match s {
            "l1" => Ok(Norm::L1),
            "l2" => Ok(Norm::L2),
            "huber" => Ok(Norm::Huber(0.02)),
            _ => match s.strip_prefix("huber:").map(str::parse::<f32>) {
                Some(Ok(h)) if h > 0.0 && h.is_finite() => Ok(Norm::Huber(h)),
                _ => Err(format!(
                    "unknown norm {s:?} (known: \"l1\", \"l2\", \"huber\", \"huber:H\" with H > 0)"
                )),
            },
        }
    }

    #[inline(always)]
    pub fn penalty(self, d: f32) -> f32 {
        match self {
            Norm::L1 => d.abs(),
            Norm::L2 => d * d,
            Norm::Huber(h) => {
                let a = d.abs();
                if a <= h {
                    0.5 * d * d / h
                } else {
                    a - 0.5 * h
                }
            }
        }
    }

    /// The derivative of `penalty` (a subgradient for L1: 0 at 0).
    #[inline(always)]
    pub fn slope(self, d: f64) -> f64 {
        match self {
            Norm::L1 => {
                if d > 0.0 {
                    1.0
                } else if d < 0.0 {
                    -1.0
                } else {
                    0.0
                }
            }
            Norm::L2 => 2.0 * d,
            Norm::Huber(h) => (d / h as f64).clamp(-1.0, 1.0),
        }
    }
}

/// Pixels per block: the working set of one block stays in L1.
pub const BLOCK: usize = 64;
const INV_PI: f32 = std::f32::consts::FRAC_1_PI;
/// Objective values at or above this are saturated: they only say "at least this bright".
pub const SATURATED: f32 = 0.999;

struct SphereOccluder {
    center: [f32; 3],
    radius: f32,
    /// |p - c|² - r² per pixel of the group.
    c: Vec<f32>,
}

struct PlaneOccluder {
    normal: [f32; 3],
    point: [f32; 3],
    /// n·(p - q) per pixel of the group: which side of the plane the pixel lies on.
    side: Vec<f32>,
}

/// The pixels of one object (or of the background, `object == None`).
struct Group {
    object: Option<usize>,
    p: [Vec<f32>; 3],
    n: [Vec<f32>; 3],
    v: [Vec<f32>; 3],
    t: [Vec<f32>; 3],
    /// The objective in the loss space (its sRGB encoding); empty in the linear space, which uses `t`.
    te: [Vec<f32>; 3],
    /// The objective as the closed-form solve uses it: +inf where a pixel must not inform the products
    /// (a silhouette pixel, which the photo averages over two surfaces), so the saturation test drops it.
    ts: [Vec<f32>; 3],
    spheres: Vec<SphereOccluder>,
    planes: Vec<PlaneOccluder>,
    /// Bounding sphere (centre, radius) of each run of `BLOCK` pixels, for culling shadow tests.
    blocks: Vec<([f32; 3], f32)>,
}

impl Group {
    fn len(&self) -> usize {
        self.t[0].len()
    }
}

pub struct Kernel {
    /// The per-pixel penalty of every loss this kernel computes.
    pub norm: Norm,
    /// Where the penalty compares values (see [`Kernel::set_space`]).
    space: Space,
    groups: Vec<Group>,
    pixels: usize,
}

/// Per-candidate light terms shared by all groups.
#[derive(Clone, Copy)]
struct Light {
    pos: [f32; 3],
    /// A directional light's unit direction towards the light (then `pos` is unused).
    dir: Option<[f32; 3]>,
    /// intensity x colour.
    rgb: [f32; 3],
}

impl Kernel {
    /// `surfels` and `targets` are the active pixels; `shapes` the scene's shapes.
    /// `solve[i]` says whether pixel i may inform the closed-form products (see `projected`).
    pub fn new(
        surfels: &[Surfel],
        targets: &[Vec3A],
        solve: &[bool],
        shapes: &[PShape],
        shadows: bool,
    ) -> Kernel {
        // Pixels grouped by object (background last), row-major inside a group: a counting sort.
        let slot = |o: u32| {
            if o == u32::MAX {
                shapes.len()
            } else {
                o as usize
            }
        };
        let mut count = vec![0usize; shapes.len() + 2];
        for s in surfels {
            count[slot(s.object) + 1] += 1;
        }
        for k in 1..count.len() {
            count[k] += count[k - 1];
        }
        let mut order = vec![0usize; surfels.len()];
        for (i, s) in surfels.iter().enumerate() {
            let k = slot(s.object);
            order[count[k]] = i;
            count[k] += 1;
        }
        let mut groups: Vec<Group> = Vec::new();
        let mut start = 0;
        while start < order.len() {
            let obj = surfels[order[start]].object;
            let mut end = start;
            while end < order.len() && surfels[order[end]].object == obj {
                end += 1;
            }
            let idx = &order[start..end];
            let col = |f: &dyn Fn(&Surfel) -> f32| {
                idx.iter().map(|&i| f(&surfels[i])).collect::<Vec<f32>>()
            };
            let tcol = |c: usize| idx.iter().map(|&i| targets[i][c]).collect::<Vec<f32>>();
            let object = (obj != u32::MAX).then_some(obj as usize);
            let mut g = Group {
                object,
                p: [
                    col(&|s| s.position.x),
                    col(&|s| s.position.y),
                    col(&|s| s.position.z),
                ],
                n: [
                    col(&|s| s.normal.x),
                    col(&|s| s.normal.y),
                    col(&|s| s.normal.z),
                ],
                v: [col(&|s| s.view.x), col(&|s| s.view.y), col(&|s| s.view.z)],
                t: [tcol(0), tcol(1), tcol(2)],
                te: Default::default(),
                ts: std::array::from_fn(|c| {
                    idx.iter()
                        .map(|&i| {
                            if solve[i] {
                                targets[i][c]
                            } else {
                                f32::INFINITY
                            }
                        })
                        .collect()
                }),
                spheres: Vec::new(),
                planes: Vec::new(),
                blocks: idx
                    .chunks(BLOCK)
                    .map(|chunk| {
                        let pos = |&i: &usize| surfels[i].position;
                        let centre = chunk.iter().map(pos).fold(Vec3A::ZERO, |a, p| a + p)
                            / chunk.len() as f32;
                        let radius = chunk
                            .iter()
                            .map(|i| (pos(i) - centre).length())
                            .fold(0.0f32, f32::max);
                        (centre.to_array(), radius)
                    })
                    .collect(),
            };
            if shadows && object.is_some() {
                for (k, shape) in shapes.iter().enumerate() {
                    if Some(k) == object {
                        continue;
                    }
                    match *shape {
                        PShape::Sphere { center, radius } => g.spheres.push(SphereOccluder {
                            center: center.to_array(),
                            radius,
                            c: idx
                                .iter()
                                .map(|&i| {
                                    let oc = surfels[i].position - center;
                                    let l = oc.length();
                                    (l - radius) * (l + radius)
                                })
                                .collect(),
                        }),
                        PShape::Plane { point, normal } => g.planes.push(PlaneOccluder {
                            normal: normal.to_array(),
                            point: point.to_array(),
                            side: idx
                                .iter()
                                .map(|&i| normal.dot(surfels[i].position - point))
                                .collect(),
                        }),
                    }
                }
            }
            groups.push(g);
            start = end;
        }
        Kernel {
            norm: Norm::L1,
            space: Space::Linear,
            groups,
            pixels: surfels.len(),
        }
    }

    pub fn pixels(&self) -> usize {
        self.pixels
    }

    /// Compare values in `space` in every loss of this kernel: for sRGB the objective is encoded here,
    /// once, and every model value per evaluation (see [`crate::space`]).
    pub fn set_space(&mut self, space: Space) {
        self.space = space;
        let lut = SrgbLut::get();
        for g in &mut self.groups {
            g.te = match space {
                Space::Linear => Default::default(),
                Space::Srgb => {
                    std::array::from_fn(|c| g.t[c].iter().map(|&t| lut.encode(t)).collect())
                }
            };
        }
    }

    pub fn space(&self) -> Space {
        self.space
    }

    /// Per-channel sums of penalty(enc(min(render, 1)) - enc(objective)) (no clamp without `clip`; enc the
    /// identity in the linear space, the sRGB encoding in [`Space::Srgb`]). Once the running total
    /// exceeds `bound` the sum stops early and the partial sums (already above `bound`) are returned: pass
    /// `f64::INFINITY` for the exact value.
    pub fn l1(&self, p: &ShadeParams, clip: bool, bound: f64) -> [f64; 3] {
        #[cfg(target_arch = "x86_64")]
        {
            if std::arch::is_x86_feature_detected!("avx2")
                && std::arch::is_x86_feature_detected!("fma")
            {
                // SAFETY: the CPU supports the features the function was compiled for.
                return unsafe {
                    match self.space {
                        Space::Linear => self.l1_avx2(p, clip, bound, Identity),
                        Space::Srgb => self.l1_avx2(p, clip, bound, SrgbLut::get()),
                    }
                };
            }
        }
        match self.space {
            Space::Linear => self.l1_generic::<false, _>(p, clip, bound, Identity),
            Space::Srgb => self.l1_generic::<false, _>(p, clip, bound, SrgbLut::get()),
        }
    }

    /// One function per encoding, so the linear space's is exactly the code it was without the option.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma")]
    unsafe fn l1_avx2<E: Encoding>(
        &self,
        p: &ShadeParams,
        clip: bool,
        bound: f64,
        enc: E,
    ) -> [f64; 3] {
        self.l1_generic::<true, E>(p, clip, bound, enc)
    }

    #[inline(always)]
    fn l1_generic<const AVX2: bool, E: Encoding>(
        &self,
        p: &ShadeParams,
        clip: bool,
        bound: f64,
        enc: E,
    ) -> [f64; 3] {
        let light = Light {
            pos: p.light_position.to_array(),
            dir: p.light_direction.map(|d| d.to_array()),
            rgb: p.light_rgb.to_array(),
        };
        let mut acc = [0.0f64; 3];
        let mut e = [0.0f32; BLOCK];
        for g in &self.groups {
            let n = g.len();
            // The objective in the loss space.
            let gt = if E::ENCODES { &g.te } else { &g.t };
            let Some(obj) = g.object else {
                // Background whose value a free parameter (exposure) changes.
                let bg = p.exposure * p.background;
                for s in 0..n {
                    for c in 0..3 {
                        let m = if clip { bg[c].min(1.0) } else { bg[c] };
                        acc[c] += self.norm.penalty(enc.any(m) - gt[c][s]) as f64;
                    }
                }
                continue;
            };
            let m = &p.materials[obj];
            let specular = p.any_specular && m.specular > 0.0;
            // m_c = exposure * (rho_c * ambient_c + e * I_c * rho_c / pi)  (+ specular lobe)
            let a: [f32; 3] = std::array::from_fn(|c| p.exposure * m.albedo[c] * p.ambient[c]);
            let k: [f32; 3] =
                std::array::from_fn(|c| p.exposure * light.rgb[c] * m.albedo[c] * INV_PI);
            let ks: [f32; 3] = std::array::from_fn(|c| {
                p.exposure * light.rgb[c] * m.specular * (m.shininess + 8.0) * (INV_PI / 8.0)
            });
            let mut start = 0;
            while start < n {
                let len = BLOCK.min(n - start);
                let r = start..start + len;
                irradiance::<AVX2>(g, r.clone(), &light, &mut e[..len]);
                shadow(g, r.clone(), &light, &mut e[..len]);
                if specular {
                    for c in 0..3 {
                        let mut sum = 0.0f32;
                        for (i, s) in r.clone().enumerate() {
                            let lobe = blinn_phong(g, s, &light, m.shininess);
                            let v = a[c] + e[i] * (k[c] + ks[c] * lobe);
                            let v = if clip { v.min(1.0) } else { v };
                            sum += self.norm.penalty(enc.any(v) - gt[c][s]);
                        }
                        acc[c] += sum as f64;
                    }
                } else {
                    let t = [&gt[0][r.clone()], &gt[1][r.clone()], &gt[2][r.clone()]];
                    let top = if clip { 1.0 } else { f32::INFINITY };
                    let sums = rgb_loss_in(self.norm, &e[..len], t, a, k, top, enc);
                    for c in 0..3 {
                        acc[c] += sums[c] as f64;
                    }
                }
                start += len;
                if acc[0] + acc[1] + acc[2] > bound {
                    return acc;
                }
            }
        }
        acc
    }

    /// Variable projection for a scene without ambient light: for the light `p`, the per-object,
    /// per-channel least-squares products P (clamped to their bounds), for objects with a specular term also
    /// the scalar specular product Q (see [`Projection`]), and the resulting per-channel loss.
    /// `scratch` holds the unit-light diffuse and specular factors per pixel between the two passes.
    ///
    /// With `parallel` the pixels of each object are split over the current rayon pool in runs of `CHUNK`
    /// (for one candidate alone, as a local polish evaluates them; the early exit at `bound` is then
    /// skipped). Either way every sum is taken run by run and the runs are added in order, so the result
    /// is the same bit for bit, serial or parallel, on any number of threads.
    #[allow(clippy::too_many_arguments)]
    pub fn projected(
        &self,
        p: &ShadeParams,
        clip: bool,
        proj: &Projection,
        out: &mut Solved,
        scratch: &mut Vec<f32>,
        bound: f64,
        parallel: bool,
    ) -> [f64; 3] {
        #[cfg(target_arch = "x86_64")]
        {
            if std::arch::is_x86_feature_detected!("avx2")
                && std::arch::is_x86_feature_detected!("fma")
            {
                // SAFETY: the CPU supports the features the function was compiled for.
                return unsafe {
                    match self.space {
                        Space::Linear => self
                            .projected_avx2(p, clip, proj, out, scratch, bound, parallel, Identity),
                        Space::Srgb => self.projected_avx2(
                            p,
                            clip,
                            proj,
                            out,
                            scratch,
                            bound,
                            parallel,
                            SrgbLut::get(),
                        ),
                    }
                };
            }
        }
        match self.space {
            Space::Linear => self.projected_generic::<false, _>(
                p, clip, proj, out, scratch, bound, parallel, Identity,
            ),
            Space::Srgb => self.projected_generic::<false, _>(
                p,
                clip,
                proj,
                out,
                scratch,
                bound,
                parallel,
                SrgbLut::get(),
            ),
        }
    }

    /// One function per encoding, as `l1_avx2`.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma")]
    #[allow(clippy::too_many_arguments)]
    unsafe fn projected_avx2<E: Encoding + Send + Sync>(
        &self,
        p: &ShadeParams,
        clip: bool,
        proj: &Projection,
        out: &mut Solved,
        scratch: &mut Vec<f32>,
        bound: f64,
        parallel: bool,
        enc: E,
    ) -> [f64; 3] {
        self.projected_generic::<true, E>(p, clip, proj, out, scratch, bound, parallel, enc)
    }

    #[inline(always)]
    #[allow(clippy::too_many_arguments)]
    fn projected_generic<const AVX2: bool, E: Encoding + Send + Sync>(
        &self,
        p: &ShadeParams,
        clip: bool,
        proj: &Projection,
        out: &mut Solved,
        scratch: &mut Vec<f32>,
        bound: f64,
        parallel: bool,
        enc: E,
    ) -> [f64; 3] {
        let light = Light {
            pos: p.light_position.to_array(),
            dir: p.light_direction.map(|d| d.to_array()),
            rgb: [1.0; 3],
        };
        // First half: diffuse factor a per pixel; second half: specular factor b (specular objects only).
        scratch.resize(2 * self.pixels, 0.0);
        let (a_all, b_all) = scratch.split_at_mut(self.pixels);
        out.products.clear();
        out.products
            .extend(proj.diffuse.iter().map(|b| [b[0].0, b[1].0, b[2].0])); // objects with no visible pixels
        out.specular.clear();
        out.specular.extend(proj.specular.iter().map(|b| b.0));
        let sat = if clip { SATURATED } else { f32::INFINITY };
        let top = if clip { 1.0 } else { f32::INFINITY };
        let mut acc = [0.0f64; 3];
        let mut offset = 0;
        for g in &self.groups {
            let n = g.len();
            let e_all = &mut a_all[offset..offset + n];
            let s_all = &mut b_all[offset..offset + n];
            offset += n;
            let Some(obj) = g.object else {
                // Black background (ambient-free scene): enc(0) = 0.
                let gt = if E::ENCODES { &g.te } else { &g.t };
                for s in 0..n {
                    for c in 0..3 {
                        acc[c] += self.norm.penalty(gt[c][s]) as f64;
                    }
                }
                continue;
            };
            let run = Run {
                g,
                light: &light,
                specular: proj.specular[obj].1 > 0.0,
                shininess: p.materials[obj].shininess,
                sat,
                top,
                norm: self.norm,
            };
            // Pass 1: unit-light irradiance / pi (and the specular factor), and the normal equations.
            let mut sums = SolveSums::default();
            if parallel {
                let parts: Vec<SolveSums> = e_all
                    .par_chunks_mut(CHUNK)
                    .zip(s_all.par_chunks_mut(CHUNK))
                    .enumerate()
                    .map(|(k, (e, b))| run.factors_dispatch::<AVX2>(k * CHUNK, e, b))
                    .collect();
                for part in &parts {
                    sums.add(part);
                }
            } else {
                for (k, (e, b)) in e_all
                    .chunks_mut(CHUNK)
                    .zip(s_all.chunks_mut(CHUNK))
                    .enumerate()
                {
                    sums.add(&run.factors::<AVX2>(k * CHUNK, e, b));
                }
            }
            let (pk, q) = solve_object(
                &sums,
                proj.weight,
                &proj.diffuse[obj],
                if run.specular {
                    proj.specular[obj]
                } else {
                    (0.0, 0.0)
                },
                |c| fallback_sums(&e_all[..n], &g.t[c], sat),
            );
            out.products[obj] = pk;
            out.specular[obj] = q;
            let pk: [f32; 3] = std::array::from_fn(|c| pk[c] as f32);
            let qw: [f32; 3] = std::array::from_fn(|c| (q * proj.weight[c] as f64) as f32);
            let q_on = run.specular && q > 0.0;
            // Pass 2: the loss at those products (serially, stopping once it exceeds `bound`).
            let (e_all, s_all) = (&*e_all, &*s_all);
            if parallel {
                let parts: Vec<[f64; 3]> = e_all
                    .par_chunks(CHUNK)
                    .zip(s_all.par_chunks(CHUNK))
                    .enumerate()
                    .map(|(k, (e, b))| {
                        run.loss_dispatch::<AVX2, E>(k * CHUNK, e, b, pk, qw, q_on, enc, None)
                    })
                    .collect();
                for part in &parts {
                    for c in 0..3 {
                        acc[c] += part[c];
                    }
                }
            } else {
                for (k, (e, b)) in e_all.chunks(CHUNK).zip(s_all.chunks(CHUNK)).enumerate() {
                    let part =
                        run.loss::<AVX2, E>(k * CHUNK, e, b, pk, qw, q_on, enc, Some((acc, bound)));
                    for c in 0..3 {
                        acc[c] += part[c];
                    }
                    if acc[0] + acc[1] + acc[2] > bound {
                        return acc;
                    }
                }
            }
        }
        acc
    }

    /// The products that minimise this kernel's own loss (norm, clip and space) rather than least squares,
    /// for one light: called once at the end of a search, after `projected` has filled `out` and `scratch`
    /// for that light. Least squares treats a pixel saturated in the objective as missing, which biases
    /// a bright channel down under noise (the pixels that noise pushed up to 1 are dropped, those it pushed
    /// down are kept). Here a saturated pixel counts one-sidedly, as the loss does: it pulls the product up
    /// while the model is below 1, and says nothing once the model reaches 1. The loss is then minimised
    /// per object by block coordinate descent, each P_c given Q and then Q given the P's. In the linear
    /// space each step is exact for L1 ([`l1_line_min`]) and otherwise bisection on the loss's
    /// derivative, e.g. Σ a·slope(P a + Q w b - y) (non-decreasing: every term is convex once an
    /// unsaturated pixel's clip at 1 is dropped). In the sRGB space no term is linear or convex in the
    /// unknown any more, but each is still unimodal in it with the same breakpoint (the encoding is
    /// monotone), so each step is the branch and bound of [`encoded_line_min`], for every norm. Returns
    /// the per-channel loss at the refined products.
    pub fn refine(
        &self,
        clip: bool,
        proj: &Projection,
        out: &mut Solved,
        scratch: &[f32],
    ) -> [f64; 3] {
        let (a_all, b_all) = scratch.split_at(self.pixels);
        let sat = if clip { SATURATED } else { f32::INFINITY };
        let top = if clip { 1.0f64 } else { f64::INFINITY };
        let srgb = self.space == Space::Srgb;
        out.lit.clear();
        out.lit.resize(proj.diffuse.len(), 0);
        // The objects' groups with their diffuse and specular factors.
        let mut objects: Vec<RefineObject> = Vec::new();
        let mut acc = [0.0f64; 3];
        let mut offset = 0;
        for g in &self.groups {
            let n = g.len();
            let (a, b) = (&a_all[offset..offset + n], &b_all[offset..offset + n]);
            offset += n;
            let Some(obj) = g.object else {
                let gt = if srgb { &g.te } else { &g.t };
                for c in 0..3 {
                    acc[c] += gt[c]
                        .iter()
                        .map(|&t| self.norm.penalty(t) as f64)
                        .sum::<f64>();
                }
                continue;
            };
            out.lit[obj] = a.iter().filter(|&&v| v > 0.0).count();
            objects.push(RefineObject {
                g,
                obj,
                a,
                b,
                specular: proj.specular[obj].1 > 0.0,
                informed: std::array::from_fn(|c| {
                    (0..n).any(|i| g.ts[c][i].is_finite() && a[i] > 0.0)
                }),
            });
        }
        // Block coordinate descent per object: each P_c given Q, then Q given the P's (four rounds for a
        // glossy object; one for a matte one, whose channels are independent). Every line search depends
        // only on its own object's values, so those of a round run in parallel over (object, channel)
        // and the result is the same on any number of threads.
        let rounds = if objects.iter().any(|o| o.specular) {
            4
        } else {
            1
        };
        for round in 0..rounds {
            let tasks: Vec<(usize, usize)> = objects
                .iter()
                .enumerate()
                .filter(|(_, o)| round == 0 || o.specular)
                .flat_map(|(k, o)| (0..3).filter(|&c| o.informed[c]).map(move |c| (k, c)))
                .collect();
            let solved: Vec<f64> = tasks
                .par_iter()
                .map(|&(k, c)| {
                    let o = &objects[k];
                    let q = out.specular[o.obj];
                    self.refine_diffuse(o, c, q, out.products[o.obj][c], proj, sat, top)
                })
                .collect();
            for (&(k, c), v) in tasks.iter().zip(solved) {
                out.products[objects[k].obj][c] = v;
            }
            let glossy: Vec<usize> = (0..objects.len())
                .filter(|&k| objects[k].specular && objects[k].informed.iter().all(|&i| i))
                .collect();
            let solved: Vec<f64> = glossy
                .par_iter()
                .map(|&k| {
                    let o = &objects[k];
                    let (pk, q) = (out.products[o.obj], out.specular[o.obj]);
                    self.refine_specular(o, pk, q, proj, sat, top)
                })
                .collect();
            for (&k, v) in glossy.iter().zip(solved) {
                out.specular[objects[k].obj] = v;
            }
        }
        // The loss at the refined products, per object and channel, added in the groups' order.
        let losses: Vec<f64> = (0..objects.len() * 3)
            .into_par_iter()
            .map(|kc| {
                let (o, c) = (&objects[kc / 3], kc % 3);
                let (pc, q) = (out.products[o.obj][c], out.specular[o.obj]);
                let gt = if srgb { &o.g.te[c] } else { &o.g.t[c] };
                (0..o.a.len())
                    .map(|i| {
                        let m = o.model(pc, q, proj.weight[c], i).min(top) as f32;
                        let m = if srgb { SrgbLut::get().encode(m) } else { m };
                        self.norm.penalty(m - gt[i]) as f64
                    })
                    .sum::<f64>()
            })
            .collect();
        // Background first, as the groups are ordered (objects, then the background).
        let mut total = [0.0f64; 3];
        for (kc, l) in losses.iter().enumerate() {
            total[kc % 3] += l;
        }
        for c in 0..3 {
            total[c] += acc[c];
        }
        total
    }

    /// [`Kernel::refine`]'s line search for P_c of one object given its specular product `q`, starting
    /// from `start` (the sRGB branch and bound uses it).
    #[allow(clippy::too_many_arguments)]
    fn refine_diffuse(
        &self,
        o: &RefineObject,
        c: usize,
        q: f64,
        start: f64,
        proj: &Projection,
        sat: f32,
        top: f64,
    ) -> f64 {
        let (n, a, t) = (o.a.len(), o.a, &o.g.ts[c]);
        let w = proj.weight[c];
        let bounds = proj.diffuse[o.obj][c];
        if self.space == Space::Srgb {
            // Terms enc(min(a P + s, top)) against the encoded objective.
            let terms: Vec<EncodedTerm> = (0..n)
                .filter(|&i| a[i] > 0.0 && t[i].is_finite())
                .map(|i| EncodedTerm {
                    k: a[i] as f64,
                    o: o.model(0.0, q, w, i),
                    y: t[i] as f64,
                    ye: o.g.te[c][i],
                    saturated: t[i] >= sat,
                })
                .collect();
            encoded_line_min(&terms, self.norm, top, bounds, start)
        } else if self.norm == Norm::L1 {
            // Terms |min(a P + s, top) - y|: coefficient a, offset s (the lobe).
            let terms = (0..n)
                .filter(|&i| a[i] > 0.0 && t[i].is_finite())
                .map(|i| (a[i] as f64, o.model(0.0, q, w, i), t[i] as f64, t[i] >= sat));
            l1_line_min(terms, bounds, top)
        } else {
            bisect(bounds, |pc| {
                (0..n)
                    .filter(|&i| a[i] > 0.0)
                    .map(|i| a[i] as f64 * self.refine_slope(o.model(pc, q, w, i), t[i], sat, top))
                    .sum()
            })
        }
    }

    /// [`Kernel::refine`]'s line search for Q of one glossy object given its diffuse products `pk`.
    #[allow(clippy::too_many_arguments)]
    fn refine_specular(
        &self,
        o: &RefineObject,
        pk: [f64; 3],
        q: f64,
        proj: &Projection,
        sat: f32,
        top: f64,
    ) -> f64 {
        let (n, a, b, t) = (o.a.len(), o.a, o.b, &o.g.ts);
        let bounds = proj.specular[o.obj];
        if self.space == Space::Srgb {
            let terms: Vec<EncodedTerm> = (0..3)
                .flat_map(|c| {
                    (0..n)
                        .filter(move |&i| b[i] > 0.0 && t[c][i].is_finite())
                        .map(move |i| EncodedTerm {
                            k: proj.weight[c] as f64 * b[i] as f64,
                            o: pk[c] * a[i] as f64,
                            y: t[c][i] as f64,
                            ye: o.g.te[c][i],
                            saturated: t[c][i] >= sat,
                        })
                })
                .collect();
            encoded_line_min(&terms, self.norm, top, bounds, q)
        } else if self.norm == Norm::L1 {
            let terms = (0..3).flat_map(|c| {
                (0..n)
                    .filter(move |&i| b[i] > 0.0 && t[c][i].is_finite())
                    .map(move |i| {
                        let k = proj.weight[c] as f64 * b[i] as f64;
                        (k, pk[c] * a[i] as f64, t[c][i] as f64, t[c][i] >= sat)
                    })
            });
            l1_line_min(terms, bounds, top)
        } else {
            bisect(bounds, |q| {
                (0..3)
                    .map(|c| {
                        let w = proj.weight[c];
                        (0..n)
                            .filter(|&i| b[i] > 0.0)
                            .map(|i| {
                                w as f64
                                    * b[i] as f64
                                    * self.refine_slope(o.model(pk[c], q, w, i), t[c][i], sat, top)
                            })
                            .sum::<f64>()
                    })
                    .sum()
            })
        }
    }

    /// d/dm of one pixel's loss at model value m against objective `y` (a silhouette pixel, y = inf,
    /// counts nothing; a saturated one only while the model is below `top`).
    fn refine_slope(&self, m: f64, y: f32, sat: f32, top: f64) -> f64 {
        if !y.is_finite() {
            0.0
        } else if y < sat {
            self.norm.slope(m - y as f64)
        } else {
            self.norm.slope((m - top).min(0.0))
        }
    }
}

/// One object's pixels and unit-light factors, for [`Kernel::refine`].
struct RefineObject<'a> {
    g: &'a Group,
    obj: usize,
    a: &'a [f32],
    b: &'a [f32],
    specular: bool,
    /// A channel with a pixel that is lit and informs the products.
    informed: [bool; 3],
}

impl RefineObject<'_> {
    /// Model value of pixel `i` in a channel of specular weight `w` at products `pc` and `q`.
    fn model(&self, pc: f64, q: f64, w: f32, i: usize) -> f64 {
        pc * self.a[i] as f64
            + if self.specular {
                q * w as f64 * self.b[i] as f64
            } else {
                0.0
            }
    }
}

/// One pixel's term in a line search of [`Kernel::refine`] in the sRGB space: the model k x + o (k > 0)
/// clipped at `top` and encoded, g(x) = enc(min(k x + o, top)), against the encoded objective `ye`
/// (`y` linear); a saturated pixel (objective at the clip) only penalises a model below `top`.
#[derive(Clone, Copy, Debug)]
pub struct EncodedTerm {
    pub k: f64,
    pub o: f64,
    pub y: f64,
    pub ye: f32,
    pub saturated: bool,
}

impl EncodedTerm {
    /// Where the term's loss is least: (y - o)/k, or (top - o)/k for a saturated pixel.
    fn at(&self, top: f64) -> f64 {
        (if self.saturated { top } else { self.y } - self.o) / self.k
    }

    /// g(x) and its right derivative.
    #[inline]
    fn g(&self, x: f64, top: f64, lut: &SrgbLut) -> (f64, f64) {
        let m = self.k * x + self.o;
        if m >= top {
            (lut.encode(top as f32) as f64, 0.0)
        } else {
            let (v, d) = lut.encode_slope(m as f32);
            (v as f64, d as f64 * self.k)
        }
    }

    /// The loss at g(x) = `g`: penalty(g - ye), or penalty(min(g - enc(top), 0)) when saturated.
    #[inline]
    fn loss(&self, g: f64, g_top: f64, norm: Norm) -> f64 {
        let d = if self.saturated {
            (g - g_top).min(0.0)
        } else {
            g - self.ye as f64
        };
        norm.penalty(d as f32) as f64
    }
}

/// Midpoints evaluated at most by one [`encoded_line_min`] (each one pass over the terms; typically 20-50).
const MAX_SPLITS: usize = 200;

/// The minimiser over [lo, hi] of F(x) = Σ_j ℓ_j(x) for the sRGB-space terms of [`EncodedTerm`], with
/// `norm`'s penalty: the exact step of [`Kernel::refine`] in the sRGB space.
///
/// Each g_j is concave and non-decreasing (the encoding is, so is its table, and so is a clip), so each
/// ℓ_j is unimodal, least at its breakpoint `at` (where the model meets the objective), but a sum of them
/// is not, and unlike in linear space need not be least at a breakpoint: a term rising in the encoding's
/// flat part beside one falling in its steep part makes an interior minimum (see the tests). So this is a
/// branch and bound on x with a convex minorant per interval [u, v]: a term with its breakpoint at or
/// left of u rises there, and ℓ ≥ penalty(chord of g - ye) (g is concave, the penalty increasing on the
/// positive side), which is convex; one with its breakpoint at or right of v falls there, and is convex
/// itself (an increasing convex penalty of the convex ye - g); any other term is at least 0. Their sum Λ
/// is convex and at least the larger of its tangents at u and v, whose least value on [u, v] is the
/// interval's bound. The bound's gap shrinks with the square of the interval's width, so only intervals
/// near the minimum survive: the interval with the lowest bound is split at its midpoint until no
/// bound is below the best value found by more than 1e-8 of it (the best is then the global minimum to
/// that tolerance; the terms are f32), intervals narrower than 1e-7 of their position (the model is f32)
/// are not split, and at most `MAX_SPLITS` midpoints are evaluated. `start` (clamped to the bounds) is
/// evaluated first: the result is never worse than it. Each evaluated point keeps every term's g and g'
/// while an interval ends there, so a split encodes each term once.
pub fn encoded_line_min(
    terms: &[EncodedTerm],
    norm: Norm,
    top: f64,
    (lo, hi): (f64, f64),
    start: f64,
) -> f64 {
    if !(lo < hi) {
        return lo;
    }
    let lut = SrgbLut::get();
    let g_top = lut.encode(top as f32) as f64;
    let at: Vec<f64> = terms.iter().map(|t| t.at(top)).collect();
    // A point: x, F(x), and per term g(x) and its right derivative.
    let eval = |x: f64| -> Point {
        let g: Vec<[f64; 2]> = terms.iter().map(|t| t.g(x, top, lut).into()).collect();
        let f = terms
            .iter()
            .zip(&g)
            .map(|(t, gi)| t.loss(gi[0], g_top, norm))
            .sum();
        Point { x, f, g }
    };
    // The least value on [u, v] of the larger tangent of the convex minorant Λ at u and v.
    let bound = |pu: &Point, pv: &Point| -> f64 {
        let (u, v) = (pu.x, pv.x);
        let (mut fu, mut du, mut fv, mut dv) = (0.0f64, 0.0f64, 0.0f64, 0.0f64);
        for (j, (t, &b)) in terms.iter().zip(&at).enumerate() {
            if b > u && b < v {
                continue;
            }
            let ([gu, su], [gv, sv]) = (pu.g[j], pv.g[j]);
            if b <= u {
                if t.saturated {
                    continue; // 0 from its breakpoint on
                }
                // Rising: penalty(chord - ye), with the chord's slope.
                let s = (gv - gu) / (v - u);
                let (du_, dv_) = (gu - t.ye as f64, gv - t.ye as f64);
                fu += norm.penalty(du_ as f32) as f64;
                fv += norm.penalty(dv_ as f32) as f64;
                du += rising_slope(norm, du_) * s;
                dv += rising_slope(norm, dv_) * s;
            } else {
                // Falling: convex; its right derivative at either end is a valid tangent slope.
                let target = if t.saturated { g_top } else { t.ye as f64 };
                fu += t.loss(gu, g_top, norm);
                fv += t.loss(gv, g_top, norm);
                du -= norm.slope(target - gu) * su;
                dv -= norm.slope(target - gv) * sv;
            }
        }
        let tangents = |x: f64| (fu + du * (x - u)).max(fv + dv * (x - v));
        let mut least = tangents(u).min(tangents(v));
        if du < dv {
            let x = (fv - fu - dv * v + du * u) / (du - dv);
            if x > u && x < v {
                least = least.min(tangents(x));
            }
        }
        least
    };
    let start = if start.is_finite() {
        start.clamp(lo, hi)
    } else {
        lo
    };
    // Points by index, each freed once no interval in the heap ends there. An interval whose bound
    // cannot beat the best value is never pushed.
    let tol = |best: f64| 1e-8 * best.abs();
    let mut points: Vec<Option<Point>> = Vec::new();
    let mut refs: Vec<u32> = Vec::new();
    let mut best = (start, f64::INFINITY);
    let mut xs = vec![lo, start, hi];
    xs.dedup();
    // `start` first, so that it wins ties.
    for x in std::iter::once(start).chain(xs.iter().copied().filter(|&x| x != start)) {
        let p = eval(x);
        if p.f < best.1 {
            best = (p.x, p.f);
        }
        points.push(Some(p));
        refs.push(0);
    }
    let mut ids: Vec<usize> = (0..points.len()).collect();
    let x_of = |points: &[Option<Point>], k: usize| points[k].as_ref().expect("a live point").x;
    ids.sort_by(|&i, &j| x_of(&points, i).total_cmp(&x_of(&points, j)));
    let mut heap = std::collections::BinaryHeap::new();
    let push = |a: usize,
                c: usize,
                points: &[Option<Point>],
                refs: &mut [u32],
                heap: &mut std::collections::BinaryHeap<Interval>,
                best: f64| {
        let (pa, pc) = (points[a].as_ref(), points[c].as_ref());
        let b = bound(pa.expect("a live point"), pc.expect("a live point"));
        if b < best - tol(best) {
            heap.push(Interval {
                bound: b,
                u: a,
                v: c,
            });
            refs[a] += 1;
            refs[c] += 1;
        }
    };
    for w in ids.windows(2) {
        push(w[0], w[1], &points, &mut refs, &mut heap, best.1);
    }
    let mut splits = 0;
    while let Some(Interval { bound: b, u, v }) = heap.pop() {
        if b >= best.1 - tol(best.1) || splits >= MAX_SPLITS {
            break;
        }
        let (xu, xv) = (x_of(&points, u), x_of(&points, v));
        let mid = 0.5 * (xu + xv);
        if xv - xu > 1e-7 * xu.abs().max(xv.abs()) && mid > xu && mid < xv {
            splits += 1;
            let p = eval(mid);
            if p.f < best.1 {
                best = (p.x, p.f);
            }
            points.push(Some(p));
            refs.push(0);
            let m = points.len() - 1;
            push(u, m, &points, &mut refs, &mut heap, best.1);
            push(m, v, &points, &mut refs, &mut heap, best.1);
            if refs[m] == 0 {
                points[m] = None;
            }
        }
        for k in [u, v] {
            refs[k] -= 1;
            if refs[k] == 0 {
                points[k] = None;
            }
        }
    }
    best.0
}

/// A point of [`encoded_line_min`]: x, F(x), and per term g(x) and its right derivative.
struct Point {
    x: f64,
    f: f64,
    g: Vec<[f64; 2]>,
}

/// The slope of penalty(d) for a rising term (d ≥ 0, increasing): L1's is 1 at d = 0 too.
#[inline]
fn rising_slope(norm: Norm, d: f64) -> f64 {
    match norm {
        Norm::L1 => 1.0,
        _ => norm.slope(d.max(0.0)),
    }
}

/// An interval of [`encoded_line_min`] between two points (by index) with its lower bound; the heap pops
/// the lowest bound first.
struct Interval {
    bound: f64,
    u: usize,
    v: usize,
}

impl PartialEq for Interval {
    fn eq(&self, other: &Self) -> bool {
        self.bound.total_cmp(&other.bound).is_eq()
    }
}

impl Eq for Interval {}

impl PartialOrd for Interval {
    fn partial_cmp(&self, other: &Self) -> Option<std::cmp::Ordering> {
        Some(self.cmp(other))
    }
}

impl Ord for Interval {
    fn cmp(&self, other: &Self) -> std::cmp::Ordering {
        other.bound.total_cmp(&self.bound)
    }
}

/// The exact minimiser over [lo, hi] of Σ_j ℓ_j(x) for terms (k > 0, o, y, saturated): ℓ = |min(k x + o,
/// top) - y| for an unsaturated pixel, max(0, top - k x - o) for a saturated one (it only says "at least
/// top"). Each ℓ is piecewise linear in x, so the minimum lies at a breakpoint ((y - o)/k or
/// (top - o)/k) or an end: one sweep over the sorted breakpoints, tracking the slope, finds it. Unlike a
/// convex stand-in, this keeps the clip exact, so the estimate stays median-unbiased where noise pushes a
/// pixel across the clip (an unsaturated pixel of a model already at `top` costs a constant).
pub fn l1_line_min(
    terms: impl Iterator<Item = (f64, f64, f64, bool)>,
    (lo, hi): (f64, f64),
    top: f64,
) -> f64 {
    // Breakpoints with the slope change there; the slope left of every breakpoint is -Σk.
    let mut events: Vec<(f64, f64)> = Vec::new();
    let mut slope = 0.0;
    for (k, o, y, saturated) in terms {
        slope -= k;
        if saturated {
            events.push(((top - o) / k, k));
        } else {
            events.push(((y - o) / k, 2.0 * k));
            events.push(((top - o) / k, -k));
        }
    }
    events.retain(|e| !e.0.is_nan());
    radix_sort_by_position(&mut events);
    let (mut x, mut f) = (lo, 0.0);
    let (mut best_x, mut best_f) = (lo, 0.0);
    for &(at, ds) in &events {
        if at > x {
            let to = at.min(hi);
            f += slope * (to - x);
            x = to;
            if f < best_f {
                (best_x, best_f) = (x, f);
            }
            if x >= hi {
                break;
            }
        }
        slope += ds;
    }
    if x < hi {
        f += slope * (hi - x);
        if f < best_f {
            best_x = hi;
        }
    }
    best_x
}

/// Sort (position, slope change) events by position: an LSD radix sort on an order-preserving 32-bit key
/// of the position rounded to f32 (three 11-bit passes; a comparison sort of the ~10⁴ events per object and
/// channel cost more than the rest of a small fit's finish). Rounding to f32 (a relative 6e-8) only
/// merges breakpoints closer than the renderer's own precision.
fn radix_sort_by_position(events: &mut Vec<(f64, f64)>) {
    let key = |x: f64| {
        let b = (x as f32).to_bits();
        if b >> 31 == 1 {
            !b
        } else {
            b | (1 << 31)
        }
    };
    let mut from: Vec<(u32, (f64, f64))> = events.iter().map(|&e| (key(e.0), e)).collect();
    let mut to = from.clone();
    for shift in [0u32, 11, 22] {
        let mut count = [0usize; 2049];
        for e in &from {
            count[((e.0 >> shift) & 2047) as usize + 1] += 1;
        }
        for k in 1..count.len() {
            count[k] += count[k - 1];
        }
        for e in &from {
            let d = ((e.0 >> shift) & 2047) as usize;
            to[count[d]] = *e;
            count[d] += 1;
        }
        std::mem::swap(&mut from, &mut to);
    }
    for (dst, src) in events.iter_mut().zip(&from) {
        *dst = src.1;
    }
}

/// The zero of a non-decreasing `derivative` on [lo, hi] by bisection (an end when it does not change
/// sign there): the minimiser of a convex function of one variable.
fn bisect((mut lo, mut hi): (f64, f64), derivative: impl Fn(f64) -> f64) -> f64 {
    if !(derivative(lo) < 0.0) {
        return lo;
    }
    if !(derivative(hi) > 0.0) {
        return hi;
    }
    for _ in 0..64 {
        if hi - lo <= 1e-9 * hi.abs().max(lo.abs()).max(f64::MIN_POSITIVE) {
            break;
        }
        let mid = 0.5 * (lo + hi);
        if derivative(mid) < 0.0 {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    0.5 * (lo + hi)
}

/// What the closed-form solve may choose, per object: the bounds of its diffuse products
/// P_c = exposure x intensity x colour_c x albedo_c and of its specular product Q = intensity x specular,
/// which enters channel c as Q x `weight[c]` (`weight` = exposure x light colour). An object whose
/// specular bounds are (0, 0) is matte: no specular factor is computed for it at all.
#[derive(Clone, Debug)]
pub struct Projection {
    pub diffuse: Vec<[(f64, f64); 3]>,
    pub specular: Vec<(f64, f64)>,
    pub weight: [f32; 3],
}

impl Projection {
    /// Matte objects only.
    pub fn matte(diffuse: Vec<[(f64, f64); 3]>) -> Projection {
        let n = diffuse.len();
        Projection {
            diffuse,
            specular: vec![(0.0, 0.0); n],
            weight: [1.0; 3],
        }
    }
}

/// The closed-form solution for one candidate: per object its diffuse products and specular product.
#[derive(Clone, Debug, Default)]
pub struct Solved {
    pub products: Vec<[f64; 3]>,
    pub specular: Vec<f64>,
    /// Per object: its pixels that receive direct light (filled by `Kernel::refine` only).
    pub lit: Vec<usize>,
}

/// Per-channel sums over an object's informing pixels (t < saturation): diffuse factor a, specular
/// factor b, objective y.
#[derive(Clone, Copy, Debug, Default)]
pub struct SolveSums {
    pub saa: [f64; 3],
    pub sab: [f64; 3],
    pub sbb: [f64; 3],
    pub sya: [f64; 3],
    pub syb: [f64; 3],
}

impl SolveSums {
    #[inline(always)]
    fn add_specular(&mut self, c: usize, a: &[f32], b: &[f32], t: &[f32], sat: f32) {
        let (mut aa, mut ab, mut bb, mut ya, mut yb) = (0.0f64, 0.0f64, 0.0f64, 0.0f64, 0.0f64);
        for i in 0..a.len() {
            if t[i] < sat {
                let (ai, bi, yi) = (a[i] as f64, b[i] as f64, t[i] as f64);
                aa += ai * ai;
                ab += ai * bi;
                bb += bi * bi;
                ya += yi * ai;
                yb += yi * bi;
            }
        }
        self.saa[c] += aa;
        self.sab[c] += ab;
        self.sbb[c] += bb;
        self.sya[c] += ya;
        self.syb[c] += yb;
    }
}

impl SolveSums {
    fn add(&mut self, o: &SolveSums) {
        for c in 0..3 {
            self.saa[c] += o.saa[c];
            self.sab[c] += o.sab[c];
            self.sbb[c] += o.sbb[c];
            self.sya[c] += o.sya[c];
            self.syb[c] += o.syb[c];
        }
    }
}

/// Pixels per unit of work of the projected kernel: its sums are taken per run of `CHUNK` pixels and the
/// runs added in order, so that a parallel evaluation gives the serial one's value bit for bit.
pub const CHUNK: usize = 8 * BLOCK;

/// One object's pixels under one candidate light, for the projected kernel's runs of `CHUNK` pixels.
struct Run<'a> {
    g: &'a Group,
    light: &'a Light,
    specular: bool,
    shininess: f32,
    sat: f32,
    top: f32,
    norm: Norm,
}

impl Run<'_> {
    /// Pass 1 over the run starting at pixel `start` of the group: unit-light diffuse factors into `e`,
    /// specular factors into `b` (specular objects only), and their normal equations.
    #[inline(always)]
    fn factors<const AVX2: bool>(&self, start: usize, e: &mut [f32], b: &mut [f32]) -> SolveSums {
        let g = self.g;
        let mut sums = SolveSums::default();
        let mut i0 = 0;
        while i0 < e.len() {
            let len = BLOCK.min(e.len() - i0);
            let r = start + i0..start + i0 + len;
            let e = &mut e[i0..i0 + len];
            irradiance::<AVX2>(g, r.clone(), self.light, e);
            shadow(g, r.clone(), self.light, e);
            for ei in e.iter_mut() {
                *ei *= INV_PI;
            }
            if self.specular {
                let b = &mut b[i0..i0 + len];
                let norm = (self.shininess + 8.0) / 8.0;
                for (i, s) in r.clone().enumerate() {
                    // (s+8)/(8 pi) max(0, n.h)^s cos / d² = e · (s+8)/8 · max(0, n.h)^s
                    b[i] = if e[i] > 0.0 {
                        (e[i] * norm * blinn_phong(g, s, self.light, self.shininess)).min(f32::MAX)
                    } else {
                        0.0
                    };
                }
                for c in 0..3 {
                    sums.add_specular(c, e, b, &g.ts[c][r.clone()], self.sat);
                }
            } else {
                for c in 0..3 {
                    let (a, b) = normal_equations::<AVX2>(e, &g.ts[c][r.clone()], self.sat);
                    sums.sya[c] += a as f64;
                    sums.saa[c] += b as f64;
                }
            }
            i0 += len;
        }
        sums
    }

    /// `factors` compiled for AVX2 where `AVX2` says the CPU has it, for a task of the thread pool.
    fn factors_dispatch<const AVX2: bool>(
        &self,
        start: usize,
        e: &mut [f32],
        b: &mut [f32],
    ) -> SolveSums {
        #[cfg(target_arch = "x86_64")]
        if AVX2 {
            // SAFETY: `AVX2` is only true on the path dispatched after checking the CPU's features.
            return unsafe { self.factors_avx2(start, e, b) };
        }
        self.factors::<false>(start, e, b)
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma")]
    unsafe fn factors_avx2(&self, start: usize, e: &mut [f32], b: &mut [f32]) -> SolveSums {
        self.factors::<true>(start, e, b)
    }

    /// Pass 2 over the run starting at pixel `start`: the per-channel loss at products `pk` (and `qw`, the
    /// specular product per channel, where `q_on`). With `stop = Some((acc, bound))` it returns early once
    /// `acc` plus the run's loss so far exceeds `bound`.
    #[inline(always)]
    #[allow(clippy::too_many_arguments)]
    fn loss<const AVX2: bool, E: Encoding>(
        &self,
        start: usize,
        e: &[f32],
        b: &[f32],
        pk: [f32; 3],
        qw: [f32; 3],
        q_on: bool,
        enc: E,
        stop: Option<([f64; 3], f64)>,
    ) -> [f64; 3] {
        let g = self.g;
        // The objective in the loss space (the solve uses the linear `ts`).
        let gt = if E::ENCODES { &g.te } else { &g.t };
        let mut part = [0.0f64; 3];
        let mut i0 = 0;
        while i0 < e.len() {
            let len = BLOCK.min(e.len() - i0);
            let r = start + i0..start + i0 + len;
            let e = &e[i0..i0 + len];
            let t = [&gt[0][r.clone()], &gt[1][r.clone()], &gt[2][r.clone()]];
            let sums = if q_on {
                let b = &b[i0..i0 + len];
                let mut sums = [0.0f32; 3];
                for c in 0..3 {
                    for i in 0..len {
                        let v = (pk[c] * e[i] + qw[c] * b[i]).min(self.top);
                        sums[c] += self.norm.penalty(enc.any(v) - t[c][i]);
                    }
                }
                sums
            } else {
                rgb_loss_in(self.norm, e, t, [0.0; 3], pk, self.top, enc)
            };
            for c in 0..3 {
                part[c] += sums[c] as f64;
            }
            i0 += len;
            if let Some((acc, bound)) = stop {
                if (acc[0] + part[0]) + (acc[1] + part[1]) + (acc[2] + part[2]) > bound {
                    return part;
                }
            }
        }
        part
    }

    /// `loss` compiled for AVX2 where `AVX2` says the CPU has it, for a task of the thread pool.
    #[allow(clippy::too_many_arguments)]
    fn loss_dispatch<const AVX2: bool, E: Encoding>(
        &self,
        start: usize,
        e: &[f32],
        b: &[f32],
        pk: [f32; 3],
        qw: [f32; 3],
        q_on: bool,
        enc: E,
        stop: Option<([f64; 3], f64)>,
    ) -> [f64; 3] {
        #[cfg(target_arch = "x86_64")]
        if AVX2 {
            // SAFETY: as in `factors_dispatch`.
            return unsafe { self.loss_avx2(start, e, b, pk, qw, q_on, enc, stop) };
        }
        self.loss::<false, E>(start, e, b, pk, qw, q_on, enc, stop)
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma")]
    #[allow(clippy::too_many_arguments)]
    unsafe fn loss_avx2<E: Encoding>(
        &self,
        start: usize,
        e: &[f32],
        b: &[f32],
        pk: [f32; 3],
        qw: [f32; 3],
        q_on: bool,
        enc: E,
        stop: Option<([f64; 3], f64)>,
    ) -> [f64; 3] {
        self.loss::<true, E>(start, e, b, pk, qw, q_on, enc, stop)
    }
}

/// One object's products from its sums: the least-squares (P_r, P_g, P_b, Q) of
/// y_c = P_c·a + Q·w_c·b over the informing pixels, then clamped to the bounds in two rounds: Q to its
/// bounds and every P_c given Q; if a P_c was clamped, Q again given the P's, and the unclamped P_c given
/// the new Q. A matte object (`qb == (0, 0)`) reduces to P_c = Σya / Σaa. A channel with no informing
/// pixel (Σaa = 0: rim-lit, or every pixel saturated) is solved over all of the object's pixels by
/// `fallback(c)` (see [`fallback_sums`]), without the specular term.
pub fn solve_object(
    s: &SolveSums,
    w: [f32; 3],
    pb: &[(f64, f64); 3],
    qb: (f64, f64),
    fallback: impl Fn(usize) -> (f64, f64, f32),
) -> ([f64; 3], f64) {
    let clampq = |q: f64| {
        if q.is_finite() {
            q.clamp(qb.0, qb.1)
        } else {
            qb.0
        }
    };
    let w: [f64; 3] = std::array::from_fn(|c| w[c] as f64);
    let informed = s.saa.iter().all(|&v| v > 0.0);
    let mut q = qb.0;
    if qb.1 > 0.0 && informed {
        // Schur complement of the diagonal P block: Q·Σ_c w_c²(Σbb - Σab²/Σaa) = Σ_c w_c(Σyb - Σab Σya/Σaa).
        let (mut num, mut den) = (0.0, 0.0);
        for c in 0..3 {
            num += w[c] * (s.syb[c] - s.sab[c] * s.sya[c] / s.saa[c]);
            den += w[c] * w[c] * (s.sbb[c] - s.sab[c] * s.sab[c] / s.saa[c]);
        }
        if den > 0.0 {
            q = clampq(num / den);
        }
    }
    let p_given = |c: usize, q: f64| (s.sya[c] - q * w[c] * s.sab[c]) / s.saa[c];
    let mut p = [0.0f64; 3];
    let mut clamped = [false; 3];
    for c in 0..3 {
        p[c] = if s.saa[c] > 0.0 {
            let v = closed_form(p_given(c, q), 1.0, f32::INFINITY, pb[c]);
            clamped[c] = v != p_given(c, q);
            v
        } else {
            let (a, b, sat_min) = fallback(c);
            closed_form(a, b, sat_min, pb[c])
        };
    }
    if qb.1 > 0.0 && informed && clamped.iter().any(|&k| k) {
        let (mut num, mut den) = (0.0, 0.0);
        for c in 0..3 {
            num += w[c] * (s.syb[c] - s.sab[c] * p[c]);
            den += w[c] * w[c] * s.sbb[c];
        }
        if den > 0.0 {
            q = clampq(num / den);
            for c in 0..3 {
                if !clamped[c] {
                    p[c] = closed_form(p_given(c, q), 1.0, f32::INFINITY, pb[c]);
                }
            }
        }
    }
    (p, q)
}

/// The least-squares product `syg / sgg` clamped to `bounds`; without any unsaturated pixel
/// (`sgg == 0`) the dimmest product that saturates every saturated lit pixel (`1 / sat_min`, with
/// `sat_min` their smallest unit-light value), or the lower bound when the object is dark.
pub fn closed_form(syg: f64, sgg: f64, sat_min: f32, (lo, hi): (f64, f64)) -> f64 {
    let v = if sgg > 0.0 {
        syg / sgg
    } else if sat_min.is_finite() && sat_min > 0.0 {
        1.0 / sat_min as f64
    } else {
        lo
    };
    if v.is_finite() {
        v.clamp(lo, hi)
    } else {
        lo
    }
}

/// The normal equations over all of an object's pixels, silhouettes included, and the smallest positive
/// `e` among its saturated pixels: the fallback when no interior pixel informs the solve.
pub fn fallback_sums(e: &[f32], t: &[f32], sat: f32) -> (f64, f64, f32) {
    let (mut syg, mut sgg, mut sat_min) = (0.0f64, 0.0f64, f32::INFINITY);
    for (&ei, &ti) in e.iter().zip(t) {
        if ti < sat {
            syg += (ei * ti) as f64;
            sgg += (ei * ei) as f64;
        } else if ei > 0.0 {
            sat_min = sat_min.min(ei);
        }
    }
    (syg, sgg, sat_min)
}

/// Lanes of the explicit partial sums: float addition is not associative, so the compiler will not
/// vectorise a plain running sum; eight independent accumulators let it (and fix the summation order, so
/// results stay bit-reproducible).
const LANES: usize = 8;

/// Σ penalty(min(a_c + e·k_c, top) - t_c) for the three channels, one loop per norm so each vectorises.
#[inline(always)]
fn rgb_loss(norm: Norm, e: &[f32], t: [&[f32]; 3], a: [f32; 3], k: [f32; 3], top: f32) -> [f32; 3] {
    match norm {
        Norm::L1 => rgb_sum(e, t, a, k, top, |d| d.abs()),
        Norm::L2 => rgb_sum(e, t, a, k, top, |d| d * d),
        Norm::Huber(h) => rgb_sum(e, t, a, k, top, move |d| {
            let ad = d.abs();
            if ad <= h {
                0.5 * d * d / h
            } else {
                ad - 0.5 * h
            }
        }),
    }
}

/// Σ f(min(a_c + e·k_c, top) - t_c) for the three channels in one pass over `e`, in `LANES` partial sums.
#[inline(always)]
fn rgb_sum(
    e: &[f32],
    t: [&[f32]; 3],
    a: [f32; 3],
    k: [f32; 3],
    top: f32,
    f: impl Fn(f32) -> f32,
) -> [f32; 3] {
    let n = e.len();
    let (t0, t1, t2) = (&t[0][..n], &t[1][..n], &t[2][..n]);
    let (mut s0, mut s1, mut s2) = ([0.0f32; LANES], [0.0f32; LANES], [0.0f32; LANES]);
    let full = n - n % LANES;
    let mut i = 0;
    while i < full {
        let (ec, c0, c1, c2) = (
            &e[i..i + LANES],
            &t0[i..i + LANES],
            &t1[i..i + LANES],
            &t2[i..i + LANES],
        );
        for j in 0..LANES {
            let ej = ec[j];
            s0[j] += f((a[0] + ej * k[0]).min(top) - c0[j]);
            s1[j] += f((a[1] + ej * k[1]).min(top) - c1[j]);
            s2[j] += f((a[2] + ej * k[2]).min(top) - c2[j]);
        }
        i += LANES;
    }
    for j in 0..n - full {
        let ej = e[full + j];
        s0[j] += f((a[0] + ej * k[0]).min(top) - t0[full + j]);
        s1[j] += f((a[1] + ej * k[1]).min(top) - t1[full + j]);
        s2[j] += f((a[2] + ej * k[2]).min(top) - t2[full + j]);
    }
    [s0.iter().sum(), s1.iter().sum(), s2.iter().sum()]
}

/// `rgb_loss` in the loss space of `enc`: Σ penalty(enc(min(a_c + e·k_c, top)) - t_c) with `t` already
/// encoded. The linear space ([`Identity`]) is `rgb_loss` itself.
#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn rgb_loss_in<E: Encoding>(
    norm: Norm,
    e: &[f32],
    t: [&[f32]; 3],
    a: [f32; 3],
    k: [f32; 3],
    top: f32,
    enc: E,
) -> [f32; 3] {
    if !E::ENCODES {
        return rgb_loss(norm, e, t, a, k, top);
    }
    match norm {
        Norm::L1 => rgb_sum_encoded(e, t, a, k, top, enc, |d| d.abs()),
        Norm::L2 => rgb_sum_encoded(e, t, a, k, top, enc, |d| d * d),
        Norm::Huber(h) => rgb_sum_encoded(e, t, a, k, top, enc, move |d| {
            let ad = d.abs();
            if ad <= h {
                0.5 * d * d / h
            } else {
                ad - 0.5 * h
            }
        }),
    }
}

/// `rgb_sum` with the model encoded by `enc` (the table lookups are scalar; the rest vectorises). Without
/// a clip (`top` > 1) every value goes through [`Encoding::any`], which branches above 1.
#[inline(always)]
fn rgb_sum_encoded<E: Encoding>(
    e: &[f32],
    t: [&[f32]; 3],
    a: [f32; 3],
    k: [f32; 3],
    top: f32,
    enc: E,
    f: impl Fn(f32) -> f32,
) -> [f32; 3] {
    let n = e.len();
    let (t0, t1, t2) = (&t[0][..n], &t[1][..n], &t[2][..n]);
    let (mut s0, mut s1, mut s2) = ([0.0f32; LANES], [0.0f32; LANES], [0.0f32; LANES]);
    let full = if top <= 1.0 { n - n % LANES } else { 0 };
    let mut i = 0;
    while i < full {
        let (ec, c0, c1, c2) = (
            &e[i..i + LANES],
            &t0[i..i + LANES],
            &t1[i..i + LANES],
            &t2[i..i + LANES],
        );
        for j in 0..LANES {
            let ej = ec[j];
            s0[j] += f(enc.unit((a[0] + ej * k[0]).min(top)) - c0[j]);
            s1[j] += f(enc.unit((a[1] + ej * k[1]).min(top)) - c1[j]);
            s2[j] += f(enc.unit((a[2] + ej * k[2]).min(top)) - c2[j]);
        }
        i += LANES;
    }
    for (j, s) in (full..n).enumerate() {
        let (es, l) = (e[s], j % LANES);
        s0[l] += f(enc.any((a[0] + es * k[0]).min(top)) - t0[s]);
        s1[l] += f(enc.any((a[1] + es * k[1]).min(top)) - t1[s]);
        s2[l] += f(enc.any((a[2] + es * k[2]).min(top)) - t2[s]);
    }
    [s0.iter().sum(), s1.iter().sum(), s2.iter().sum()]
}

/// (Σ e·t, Σ e²) over the pixels with t < `sat`, in `LANES` partial sums each (lane j takes the pixels
/// j, j + LANES, ...; the lanes are added in order). `AVX2` selects the intrinsics form, which the
/// compiler does not find for this masked sum on its own; both forms round alike (no fused multiply-add).
#[inline(always)]
fn normal_equations<const AVX2: bool>(e: &[f32], t: &[f32], sat: f32) -> (f32, f32) {
    let n = e.len().min(t.len());
    let full = n - n % LANES;
    let (mut a, mut b) = ([0.0f32; LANES], [0.0f32; LANES]);
    #[cfg(target_arch = "x86_64")]
    if AVX2 {
        // SAFETY: `AVX2` is only true on the path dispatched after checking the CPU's features.
        (a, b) = unsafe { normal_equation_lanes_avx2(&e[..full], &t[..full], sat) };
    } else {
        normal_equation_lanes(&e[..full], &t[..full], sat, &mut a, &mut b);
    }
    #[cfg(not(target_arch = "x86_64"))]
    normal_equation_lanes(&e[..full], &t[..full], sat, &mut a, &mut b);
    for j in full..n {
        let keep = t[j] < sat;
        a[j - full] += if keep { e[j] * t[j] } else { 0.0 };
        b[j - full] += if keep { e[j] * e[j] } else { 0.0 };
    }
    (a.iter().sum(), b.iter().sum())
}

/// The lane sums of `normal_equations` over whole runs of `LANES` pixels.
#[inline(always)]
fn normal_equation_lanes(
    e: &[f32],
    t: &[f32],
    sat: f32,
    a: &mut [f32; LANES],
    b: &mut [f32; LANES],
) {
    for (x, y) in e.chunks_exact(LANES).zip(t.chunks_exact(LANES)) {
        for j in 0..LANES {
            // Select, not multiply by a 0/1 weight: excluded pixels carry t = +inf.
            let keep = y[j] < sat;
            a[j] += if keep { x[j] * y[j] } else { 0.0 };
            b[j] += if keep { x[j] * x[j] } else { 0.0 };
        }
    }
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
#[inline]
unsafe fn normal_equation_lanes_avx2(
    e: &[f32],
    t: &[f32],
    sat: f32,
) -> ([f32; LANES], [f32; LANES]) {
    use std::arch::x86_64::*;
    let (mut a, mut b) = (_mm256_setzero_ps(), _mm256_setzero_ps());
    let satv = _mm256_set1_ps(sat);
    for (x, y) in e.chunks_exact(LANES).zip(t.chunks_exact(LANES)) {
        let (x, y) = (_mm256_loadu_ps(x.as_ptr()), _mm256_loadu_ps(y.as_ptr()));
        // Where t >= sat (or t = +inf) both factors become 0: the lane adds 0, as the scalar select.
        let keep = _mm256_cmp_ps::<_CMP_LT_OQ>(y, satv);
        let (x, y) = (_mm256_and_ps(x, keep), _mm256_and_ps(y, keep));
        a = _mm256_add_ps(a, _mm256_mul_ps(x, y));
        b = _mm256_add_ps(b, _mm256_mul_ps(x, x));
    }
    let (mut sa, mut sb) = ([0.0f32; LANES], [0.0f32; LANES]);
    _mm256_storeu_ps(sa.as_mut_ptr(), a);
    _mm256_storeu_ps(sb.as_mut_ptr(), b);
    (sa, sb)
}

/// e = max(0, n·l) / d² (unit light), written into `e`; 0 for a light on the surface.
#[inline(always)]
fn irradiance<const AVX2: bool>(
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
            e[i] = (nx[i] * d[0] + ny[i] * d[1] + nz[i] * d[2]).max(0.0);
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

/// AVX2 form of `irradiance`: 1/d³ from the hardware reciprocal square root refined by one Newton step
/// (relative error about 1e-7, the same as the exact `nl / (d2 * sqrt(d2))` in f32), eight pixels at a
/// time; the tail goes through the exact form.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
#[inline]
unsafe fn irradiance_avx2(g: &Group, r: std::ops::Range<usize>, light: &Light, e: &mut [f32]) {
    use std::arch::x86_64::*;
    let n = e.len();
    let full = n - n % 8;
    let s = r.start;
    let (lx, ly, lz) = (
        _mm256_set1_ps(light.pos[0]),
        _mm256_set1_ps(light.pos[1]),
        _mm256_set1_ps(light.pos[2]),
    );
    let (half, three_halves) = (_mm256_set1_ps(0.5), _mm256_set1_ps(1.5));
    let (tiny, big, zero) = (
        _mm256_set1_ps(f32::MIN_POSITIVE),
        _mm256_set1_ps(f32::MAX),
        _mm256_setzero_ps(),
    );
    let mut i = 0;
    while i < full {
        let ld = |v: &Vec<f32>| _mm256_loadu_ps(v.as_ptr().add(s + i));
        let dx = _mm256_sub_ps(lx, ld(&g.p[0]));
        let dy = _mm256_sub_ps(ly, ld(&g.p[1]));
        let dz = _mm256_sub_ps(lz, ld(&g.p[2]));
        let d2 = _mm256_fmadd_ps(dz, dz, _mm256_fmadd_ps(dy, dy, _mm256_mul_ps(dx, dx)));
        let nl = _mm256_fmadd_ps(
            ld(&g.n[2]),
            dz,
            _mm256_fmadd_ps(ld(&g.n[1]), dy, _mm256_mul_ps(ld(&g.n[0]), dx)),
        );
        let nl = _mm256_max_ps(nl, zero);
        // y ~ 1/sqrt(d2), one Newton step: y (1.5 - 0.5 d2 y²).
        let y = _mm256_rsqrt_ps(d2);
        let y = _mm256_mul_ps(
            y,
            _mm256_fnmadd_ps(_mm256_mul_ps(half, d2), _mm256_mul_ps(y, y), three_halves),
        );
        let inv3 = _mm256_mul_ps(_mm256_mul_ps(y, y), y);
        let v = _mm256_min_ps(_mm256_mul_ps(nl, inv3), big);
        let ok = _mm256_cmp_ps::<_CMP_GT_OQ>(d2, tiny);
        _mm256_storeu_ps(e.as_mut_ptr().add(i), _mm256_and_ps(v, ok));
        i += 8;
    }
    irradiance_exact(g, s + full..r.end, light, &mut e[full..]);
}

#[inline(always)]
fn irradiance_exact(g: &Group, r: std::ops::Range<usize>, light: &Light, e: &mut [f32]) {
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
        let dx = lx - px[i];
        let dy = ly - py[i];
        let dz = lz - pz[i];
        let d2 = dx * dx + dy * dy + dz * dz;
        let nl = (nx[i] * dx + ny[i] * dy + nz[i] * dz).max(0.0);
        let v = (nl / (d2 * d2.sqrt())).min(f32::MAX);
        e[i] = if d2 > f32::MIN_POSITIVE { v } else { 0.0 };
    }
}

/// Zero `e` where the segment from the pixel to the light is blocked by another object.
#[inline(always)]
fn shadow(g: &Group, r: std::ops::Range<usize>, light: &Light, e: &mut [f32]) {
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
            let c = cc[i];
            let disc = b * b - a * c;
            // Roots (-b ± √disc)/a: the far one is > 0 and the near one < 1.
            let ab = a + b;
            let far_positive = (b < 0.0) | (c < 0.0);
            let near_below_one = (ab > 0.0) | (disc > ab * ab);
            let hit = (disc >= 0.0) & far_positive & near_below_one;
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
fn shadow_directional(g: &Group, r: std::ops::Range<usize>, d: [f32; 3], e: &mut [f32]) {
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
            // |p - c + t d|² = r² with |d| = 1: t² + 2bt + c = 0; blocked when the far root is positive.
            let b = (px[i] - cx) * d[0] + (py[i] - cy) * d[1] + (pz[i] - cz) * d[2];
            let c = cc[i];
            let hit = (b * b - c >= 0.0) & ((b < 0.0) | (c < 0.0));
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
fn blinn_phong(g: &Group, s: usize, light: &Light, shininess: f32) -> f32 {
    let p = Vec3A::new(g.p[0][s], g.p[1][s], g.p[2][s]);
    let n = Vec3A::new(g.n[0][s], g.n[1][s], g.n[2][s]);
    let v = Vec3A::new(g.v[0][s], g.v[1][s], g.v[2][s]);
    let l = match light.dir {
        Some(d) => Vec3A::from_array(d),
        None => (Vec3A::from_array(light.pos) - p).normalize_or_zero(),
    };
    let h = (l + v).normalize_or_zero();
    n.dot(h).max(0.0).powf(shininess)
}
