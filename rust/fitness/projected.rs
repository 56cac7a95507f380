//! The closed form: per candidate light, the least-squares products of every object (variable
//! projection), and the loss at them.

use rayon::prelude::*;

use super::kernel::{Candidate, Kernel};
use super::loss::{rgb_loss_in, Encoding, Identity, Norm, Space, SrgbLut, LANES, SATURATED};
use super::pixels::{blinn_phong, irradiance, shadow, Group, Light, BLOCK};
use super::simd::{self, Simd};
use crate::render::brdf::{lambert, specular_per_lambert};
use crate::scene::Scene;

/// [`Kernel::projected`] for [`simd::dispatch`], one build per encoding.
struct Projected<'a, E> {
    k: &'a Kernel,
    c: Candidate<'a>,
    proj: &'a Projection,
    out: &'a mut Solved,
    s: &'a mut Vec<f32>,
    enc: E,
}

impl<E: Encoding + Send + Sync> Simd for Projected<'_, E> {
    type Output = [f64; 3];
    #[inline(always)]
    fn run<const AVX2: bool>(self) -> [f64; 3] {
        self.k.projected_generic::<AVX2, E>(self)
    }
}

impl Kernel {
    /// Variable projection for a scene without ambient light: for the light `p`, the per-object,
    /// per-channel least-squares products P (clamped to their bounds), for objects with a specular term also
    /// the scalar specular product Q (see [`Projection`]), and the resulting per-channel loss.
    /// `scratch` holds the unit-light diffuse and specular factors per pixel between the two passes.
    ///
    /// With `parallel` the pixels of each object are split over the current rayon pool in runs of `CHUNK`
    /// (for one candidate alone, as a local polish evaluates them; the early exit at `bound` is then
    /// skipped). Either way every sum is taken run by run and the runs are added in order, so the result
    /// is the same bit for bit, serial or parallel, on any number of threads.
    pub fn projected(
        &self,
        c: Candidate,
        proj: &Projection,
        out: &mut Solved,
        scratch: &mut Vec<f32>,
    ) -> [f64; 3] {
        let avx2 = simd::detected();
        let (k, s) = (self, scratch);
        match self.space {
            Space::Linear => simd::dispatch(
                Projected {
                    k,
                    c,
                    proj,
                    out,
                    s,
                    enc: Identity,
                },
                avx2,
            ),
            Space::Srgb => {
                let enc = SrgbLut::get();
                simd::dispatch(
                    Projected {
                        k,
                        c,
                        proj,
                        out,
                        s,
                        enc,
                    },
                    avx2,
                )
            }
        }
    }

    #[inline(always)]
    fn projected_generic<const AVX2: bool, E: Encoding + Send + Sync>(
        &self,
        job: Projected<'_, E>,
    ) -> [f64; 3] {
        let Projected {
            c:
                Candidate {
                    params: p,
                    clip,
                    bound,
                    parallel,
                },
            proj,
            out,
            s: scratch,
            enc,
            ..
        } = job;
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
                    .map(|(k, (e, b))| {
                        let start = k * CHUNK;
                        simd::dispatch(
                            Factors {
                                run: &run,
                                start,
                                e,
                                b,
                            },
                            AVX2,
                        )
                    })
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
            let products = Products {
                pk,
                qw,
                on: run.specular && q > 0.0,
            };
            // Pass 2: the loss at those products (serially, stopping once it exceeds `bound`).
            let (e_all, s_all) = (&*e_all, &*s_all);
            if parallel {
                let parts: Vec<[f64; 3]> = e_all
                    .par_chunks(CHUNK)
                    .zip(s_all.par_chunks(CHUNK))
                    .enumerate()
                    .map(|(k, (e, b))| {
                        let (run, start) = (&run, k * CHUNK);
                        simd::dispatch(
                            Loss {
                                run,
                                start,
                                e,
                                b,
                                products,
                                enc,
                            },
                            AVX2,
                        )
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
                        run.loss::<AVX2, E>(k * CHUNK, e, b, products, enc, Some((acc, bound)));
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
}

/// `None` when the closed form (the projected method) applies to `scene` with the fit section `paths`
/// free, else why not: the one decision of it (Python's fit asks this too).
pub fn projection_blocker(scene: &Scene, paths: &[String]) -> Option<String> {
    let free = |p: &str| paths.iter().any(|q| q == p);
    if !free("light.position") && !free("light.direction") {
        return Some("neither light.position nor light.direction is free".into());
    }
    if scene.ambient.iter().any(|&v| v != 0.0) {
        return Some("the scene has ambient light".into());
    }
    let allowed = |p: &str| {
        matches!(p, "light.position" | "light.direction" | "light.intensity")
            || scene.objects.iter().any(|o| {
                ["albedo", "specular", "shininess"]
                    .iter()
                    .any(|m| p == format!("objects.{}.{m}", o.name))
            })
    };
    let extra: Vec<&str> = paths
        .iter()
        .map(String::as_str)
        .filter(|p| !allowed(p))
        .collect();
    if !extra.is_empty() {
        return Some(format!(
            "{} cannot be solved in closed form",
            extra.join(", ")
        ));
    }
    if free("light.intensity") {
        let names = |f: &dyn Fn(&crate::scene::Object) -> bool| {
            let v: Vec<&str> = scene
                .objects
                .iter()
                .filter(|o| f(o))
                .map(|o| o.name.as_str())
                .collect();
            v.join(", ")
        };
        let known = names(&|o| {
            o.material.specular != 0.0 && !free(&format!("objects.{}.specular", o.name))
        });
        if !known.is_empty() {
            return Some(format!(
                "light.intensity is free and the specular of {known} is fixed (the highlight then \
                 measures the intensity, which the closed form does not model)"
            ));
        }
        let fixed = names(&|o| !free(&format!("objects.{}.albedo", o.name)));
        if !fixed.is_empty() {
            return Some(format!(
                "light.intensity is free but the albedo of {fixed} is fixed"
            ));
        }
    }
    None
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
    pub(crate) fn add_specular(&mut self, c: usize, a: &[f32], b: &[f32], t: &[f32], sat: f32) {
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
    pub(crate) fn add(&mut self, o: &SolveSums) {
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
pub(crate) struct Run<'a> {
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
    pub(crate) fn factors<const AVX2: bool>(
        &self,
        start: usize,
        e: &mut [f32],
        b: &mut [f32],
    ) -> SolveSums {
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
                *ei = lambert(*ei);
            }
            if self.specular {
                let b = &mut b[i0..i0 + len];
                let norm = specular_per_lambert(self.shininess);
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

    /// Pass 2 over the run starting at pixel `start`: the per-channel loss at `products`. With `stop = Some((acc, bound))` it returns early once
    /// `acc` plus the run's loss so far exceeds `bound`.
    #[inline(always)]
    pub(crate) fn loss<const AVX2: bool, E: Encoding>(
        &self,
        start: usize,
        e: &[f32],
        b: &[f32],
        products: Products,
        enc: E,
        stop: Option<([f64; 3], f64)>,
    ) -> [f64; 3] {
        let Products { pk, qw, on: q_on } = products;
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
}

/// The solved products of one object as pass 2 uses them: the diffuse `pk` per channel and, where `on`,
/// the specular product per channel `qw`.
#[derive(Clone, Copy)]
pub(crate) struct Products {
    pk: [f32; 3],
    qw: [f32; 3],
    on: bool,
}

/// [`Run::factors`] of one run for [`simd::dispatch`] (a task of the thread pool).
struct Factors<'a, 'r> {
    run: &'a Run<'r>,
    start: usize,
    e: &'a mut [f32],
    b: &'a mut [f32],
}

impl Simd for Factors<'_, '_> {
    type Output = SolveSums;
    #[inline(always)]
    fn run<const AVX2: bool>(self) -> SolveSums {
        self.run.factors::<AVX2>(self.start, self.e, self.b)
    }
}

/// [`Run::loss`] of one run for [`simd::dispatch`] (a task of the thread pool; no early exit).
struct Loss<'a, 'r, E> {
    run: &'a Run<'r>,
    start: usize,
    e: &'a [f32],
    b: &'a [f32],
    products: Products,
    enc: E,
}

impl<E: Encoding> Simd for Loss<'_, '_, E> {
    type Output = [f64; 3];
    #[inline(always)]
    fn run<const AVX2: bool>(self) -> [f64; 3] {
        let Loss {
            run,
            start,
            e,
            b,
            products,
            enc,
        } = self;
        run.loss::<AVX2, E>(start, e, b, products, enc, None)
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

/// (Σ e·t, Σ e²) over the pixels with t < `sat`, in `LANES` partial sums each (lane j takes the pixels
/// j, j + LANES, ...; the lanes are added in order). `AVX2` selects the intrinsics form, which the
/// compiler does not find for this masked sum on its own; both forms round alike (no fused multiply-add).
#[inline(always)]
pub(crate) fn normal_equations<const AVX2: bool>(e: &[f32], t: &[f32], sat: f32) -> (f32, f32) {
    let n = e.len().min(t.len());
    let full = n - n % LANES;
    let (mut a, mut b) = ([0.0f32; LANES], [0.0f32; LANES]);
    #[cfg(target_arch = "x86_64")]
    if AVX2 {
        // SAFETY: `AVX2` is only true on the path dispatched after checking the CPU's features.
        (a, b) = unsafe { super::simd::normal_equation_lanes_avx2(&e[..full], &t[..full], sat) };
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
pub(crate) fn normal_equation_lanes(
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
