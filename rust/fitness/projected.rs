//! The closed form: per candidate light, the least-squares products of every object (variable
//! projection), and the loss at them.

use rayon::prelude::*;

use super::bounce::Gauge;
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
        if let Some(gauge) = &proj.gauge {
            let c = Candidate {
                params: p,
                clip,
                bound,
                parallel,
            };
            return self.projected_bounce::<AVX2, E>(c, proj, gauge, out, scratch, enc);
        }
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
        out.environment.clear();
        out.environment
            .extend(proj.environment.iter().map(|b| [b[0].0, b[1].0, b[2].0]));
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
                sky: proj.sky(obj, g),
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
            let qb = if run.specular {
                proj.specular[obj]
            } else {
                (0.0, 0.0)
            };
            let fallback = |c: usize| fallback_sums(&e_all[..n], &g.t[c], sat);
            let (pk, q, ek) = if run.sky.is_some() {
                solve_object_env(
                    &sums,
                    proj.weight,
                    &proj.diffuse[obj],
                    qb,
                    &proj.environment[obj],
                    fallback,
                )
            } else {
                let (pk, q) = solve_object(&sums, proj.weight, &proj.diffuse[obj], qb, fallback);
                (pk, q, [0.0; 3])
            };
            out.products[obj] = pk;
            out.specular[obj] = q;
            if run.sky.is_some() {
                out.environment[obj] = ek;
            }
            let pk: [f32; 3] = std::array::from_fn(|c| pk[c] as f32);
            let qw: [f32; 3] = std::array::from_fn(|c| (q * proj.weight[c] as f64) as f32);
            let products = Products {
                pk,
                qw,
                ek: std::array::from_fn(|c| ek[c] as f32),
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
        matches!(
            p,
            "light.position" | "light.direction" | "light.intensity" | "environment"
        ) || scene.objects.iter().any(|o| {
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
/// specular bounds are (0, 0) is matte: no specular factor is computed for it at all. `environment`
/// (empty: no environment term) bounds each object's environment products E_c = exposure x env_c x
/// albedo_c, the coefficient of its pixels' sky view factor; an object whose bounds are all (_, 0) gets
/// no environment column.
#[derive(Clone, Debug)]
pub struct Projection {
    pub diffuse: Vec<[(f64, f64); 3]>,
    pub specular: Vec<(f64, f64)>,
    pub environment: Vec<[(f64, f64); 3]>,
    pub weight: [f32; 3],
    /// With interreflection: the bounds of the gauge the bounce needs (`fitness::bounce`).
    pub gauge: Option<Gauge>,
}

impl Projection {
    /// Matte objects only.
    pub fn matte(diffuse: Vec<[(f64, f64); 3]>) -> Projection {
        let n = diffuse.len();
        Projection {
            diffuse,
            specular: vec![(0.0, 0.0); n],
            environment: Vec::new(),
            weight: [1.0; 3],
            gauge: None,
        }
    }

    /// Whether any object has an environment column.
    pub fn has_environment(&self) -> bool {
        self.environment.iter().any(|b| b.iter().any(|c| c.1 > 0.0))
    }

    /// The sky view factors of group `g` (object `obj`) when that object has an environment column.
    pub(crate) fn sky<'g>(&self, obj: usize, g: &'g Group) -> Option<&'g [f32]> {
        let on = self
            .environment
            .get(obj)
            .is_some_and(|b| b.iter().any(|c| c.1 > 0.0));
        (on && !g.sky.is_empty()).then_some(&g.sky[..])
    }
}

/// The closed-form solution for one candidate: per object its diffuse products and specular product
/// (and its environment products, when the projection has an environment term; else empty).
#[derive(Clone, Debug, Default)]
pub struct Solved {
    pub products: Vec<[f64; 3]>,
    pub specular: Vec<f64>,
    pub environment: Vec<[f64; 3]>,
    /// With interreflection: the gauge u = 1 / intensity the bounce was solved with.
    pub gauge: Option<f64>,
    /// Per object: its pixels that receive direct light (filled by `Kernel::refine` only).
    pub lit: Vec<usize>,
}

/// Per-channel sums over an object's informing pixels (t < saturation): diffuse factor a, specular
/// factor b, sky view factor v (objects with an environment column), objective y.
#[derive(Clone, Copy, Debug, Default)]
pub struct SolveSums {
    pub saa: [f64; 3],
    pub sab: [f64; 3],
    pub sbb: [f64; 3],
    pub sya: [f64; 3],
    pub syb: [f64; 3],
    pub sav: [f64; 3],
    pub svv: [f64; 3],
    pub syv: [f64; 3],
    pub svb: [f64; 3],
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
            self.sav[c] += o.sav[c];
            self.svv[c] += o.svv[c];
            self.syv[c] += o.syv[c];
            self.svb[c] += o.svb[c];
        }
    }

    /// Every sum of channel `c` over one run with an environment column: factors `a`, `b` (zero for a
    /// matte object), sky view `v`, objective `t` (pixels at or above `sat` left out).
    #[inline(always)]
    pub(crate) fn add_environment(
        &mut self,
        c: usize,
        a: &[f32],
        b: Option<&[f32]>,
        v: &[f32],
        t: &[f32],
        sat: f32,
    ) {
        let mut s = [0.0f64; 9];
        for i in 0..a.len() {
            if t[i] < sat {
                let (ai, vi, yi) = (a[i] as f64, v[i] as f64, t[i] as f64);
                let bi = b.map_or(0.0, |b| b[i] as f64);
                s[0] += ai * ai;
                s[1] += ai * bi;
                s[2] += bi * bi;
                s[3] += yi * ai;
                s[4] += yi * bi;
                s[5] += ai * vi;
                s[6] += vi * vi;
                s[7] += yi * vi;
                s[8] += vi * bi;
            }
        }
        self.saa[c] += s[0];
        self.sab[c] += s[1];
        self.sbb[c] += s[2];
        self.sya[c] += s[3];
        self.syb[c] += s[4];
        self.sav[c] += s[5];
        self.svv[c] += s[6];
        self.syv[c] += s[7];
        self.svb[c] += s[8];
    }
}

/// Pixels per unit of work of the projected kernel: its sums are taken per run of `CHUNK` pixels and the
/// runs added in order, so that a parallel evaluation gives the serial one's value bit for bit.
pub const CHUNK: usize = 8 * BLOCK;

/// One object's pixels under one candidate light, for the projected kernel's runs of `CHUNK` pixels.
pub(crate) struct Run<'a> {
    pub(crate) g: &'a Group,
    pub(crate) light: &'a Light,
    pub(crate) specular: bool,
    /// The group's sky view factors when the object has an environment column.
    pub(crate) sky: Option<&'a [f32]>,
    pub(crate) shininess: f32,
    pub(crate) sat: f32,
    pub(crate) top: f32,
    pub(crate) norm: Norm,
}

impl<'a> Run<'a> {
    pub(crate) fn group(&self) -> &'a Group {
        self.g
    }

    pub(crate) fn sky(&self) -> Option<&'a [f32]> {
        self.sky
    }

    pub(crate) fn is_specular(&self) -> bool {
        self.specular
    }
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
            if self.specular || self.sky.is_some() {
                let b = &mut b[i0..i0 + len];
                let norm = specular_per_lambert(self.shininess);
                for (i, s) in r.clone().enumerate() {
                    // (s+8)/(8 pi) max(0, n.h)^s cos / d² = e · (s+8)/8 · max(0, n.h)^s
                    b[i] = if e[i] > 0.0 && self.specular {
                        (e[i] * norm * blinn_phong(g, s, self.light, self.shininess)).min(f32::MAX)
                    } else {
                        0.0
                    };
                }
                for c in 0..3 {
                    let t = &g.ts[c][r.clone()];
                    match self.sky {
                        Some(v) => {
                            let bb = self.specular.then_some(&*b);
                            sums.add_environment(c, e, bb, &v[r.clone()], t, self.sat)
                        }
                        None => sums.add_specular(c, e, b, t, self.sat),
                    }
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
        let Products {
            pk,
            qw,
            ek,
            on: q_on,
        } = products;
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
            let sums = if let Some(sky) = self.sky {
                let (b, sky) = (&b[i0..i0 + len], &sky[r.clone()]);
                let mut sums = [0.0f32; 3];
                for c in 0..3 {
                    for i in 0..len {
                        let lobe = if q_on { qw[c] * b[i] } else { 0.0 };
                        let v = (pk[c] * e[i] + ek[c] * sky[i] + lobe).min(self.top);
                        sums[c] += self.norm.penalty(enc.any(v) - t[c][i]);
                    }
                }
                sums
            } else if q_on {
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

/// The solved products of one object as pass 2 uses them: the diffuse `pk` per channel, where `on`
/// the specular product per channel `qw`, and the environment products `ek` (objects with a column).
#[derive(Clone, Copy)]
pub(crate) struct Products {
    pk: [f32; 3],
    qw: [f32; 3],
    ek: [f32; 3],
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

/// [`solve_object`] for an object with an environment column: the least squares (P_c, E_c per channel,
/// Q) of y_c = P_c·a + E_c·v + Q·w_c·b over the informing pixels, within the bounds. Q from the Schur
/// complement of the per-channel 2x2 blocks, then each channel's (P_c, E_c) as a box-constrained 2x2
/// least squares given Q ([`box_ls2`]); if a bound was active, Q again given them and the channels once
/// more. A channel with no informing pixel takes P_c from `fallback(c)` and E_c at its lower bound.
pub fn solve_object_env(
    s: &SolveSums,
    w: [f32; 3],
    pb: &[(f64, f64); 3],
    qb: (f64, f64),
    eb: &[(f64, f64); 3],
    fallback: impl Fn(usize) -> (f64, f64, f32),
) -> ([f64; 3], f64, [f64; 3]) {
    let w: [f64; 3] = std::array::from_fn(|c| w[c] as f64);
    let informed = s.saa.iter().all(|&v| v > 0.0);
    let glossy = qb.1 > 0.0 && informed;
    let clampq = |q: f64| {
        if q.is_finite() {
            q.clamp(qb.0, qb.1)
        } else {
            qb.0
        }
    };
    let gram = |c: usize| [[s.saa[c], s.sav[c]], [s.sav[c], s.svv[c]]];
    let mut q = qb.0;
    if glossy {
        let (mut num, mut den) = (0.0, 0.0);
        for c in 0..3 {
            let g = gram(c);
            let (r, k) = ([s.sya[c], s.syv[c]], [s.sab[c], s.svb[c]]);
            // G^-1 applied through its 2x2 inverse; a singular G (no sky variation) drops v.
            let (gr, gk) = match inverse2(g) {
                Some(inv) => (mul2(inv, r), mul2(inv, k)),
                None => ([r[0] / g[0][0], 0.0], [k[0] / g[0][0], 0.0]),
            };
            num += w[c] * (s.syb[c] - (k[0] * gr[0] + k[1] * gr[1]));
            den += w[c] * w[c] * (s.sbb[c] - (k[0] * gk[0] + k[1] * gk[1]));
        }
        if den > 0.0 && num.is_finite() {
            q = clampq(num / den);
        }
    }
    let channels = |q: f64| -> ([f64; 3], [f64; 3], bool) {
        let (mut p, mut e, mut active) = ([0.0; 3], [0.0; 3], false);
        for c in 0..3 {
            if s.saa[c] > 0.0 {
                let r = [
                    s.sya[c] - q * w[c] * s.sab[c],
                    s.syv[c] - q * w[c] * s.svb[c],
                ];
                let (x, hit) = box_ls2(gram(c), r, pb[c], eb[c]);
                (p[c], e[c], active) = (x[0], x[1], active || hit);
            } else {
                let (a, b, sat_min) = fallback(c);
                (p[c], e[c]) = (closed_form(a, b, sat_min, pb[c]), eb[c].0);
            }
        }
        (p, e, active)
    };
    let (mut p, mut e, active) = channels(q);
    if glossy && active {
        let (mut num, mut den) = (0.0, 0.0);
        for c in 0..3 {
            num += w[c] * (s.syb[c] - s.sab[c] * p[c] - s.svb[c] * e[c]);
            den += w[c] * w[c] * s.sbb[c];
        }
        if den > 0.0 && num.is_finite() {
            q = clampq(num / den);
            (p, e, _) = channels(q);
        }
    }
    (p, q, e)
}

/// The inverse of a symmetric 2x2 matrix, `None` when it is (numerically) singular.
fn inverse2(g: [[f64; 2]; 2]) -> Option<[[f64; 2]; 2]> {
    let det = g[0][0] * g[1][1] - g[0][1] * g[1][0];
    // Relative to the diagonal's scale: collinear columns (Cauchy–Schwarz equality) are singular.
    if !(det > 1e-12 * (g[0][0] * g[1][1]).abs()) || !det.is_finite() {
        return None;
    }
    Some([
        [g[1][1] / det, -g[0][1] / det],
        [-g[1][0] / det, g[0][0] / det],
    ])
}

fn mul2(m: [[f64; 2]; 2], r: [f64; 2]) -> [f64; 2] {
    [
        m[0][0] * r[0] + m[0][1] * r[1],
        m[1][0] * r[0] + m[1][1] * r[1],
    ]
}

/// The minimiser of ½xᵀGx - rᵀx over the box `b0` x `b1` (G symmetric positive semi-definite), and
/// whether a bound is active: the unconstrained optimum when it is inside, else the best of the four
/// edges, each the clamped one-dimensional optimum (a convex quadratic's box minimum lies on an edge
/// when the unconstrained one is outside).
pub fn box_ls2(g: [[f64; 2]; 2], r: [f64; 2], b0: (f64, f64), b1: (f64, f64)) -> ([f64; 2], bool) {
    let inside = |x: [f64; 2]| {
        x[0].is_finite()
            && x[1].is_finite()
            && (b0.0..=b0.1).contains(&x[0])
            && (b1.0..=b1.1).contains(&x[1])
    };
    if let Some(inv) = inverse2(g) {
        let x = mul2(inv, r);
        if inside(x) {
            return (x, false);
        }
    }
    let clamp = |v: f64, (lo, hi): (f64, f64)| if v.is_finite() { v.clamp(lo, hi) } else { lo };
    let f = |x: [f64; 2]| {
        0.5 * (g[0][0] * x[0] * x[0] + 2.0 * g[0][1] * x[0] * x[1] + g[1][1] * x[1] * x[1])
            - r[0] * x[0]
            - r[1] * x[1]
    };
    let opt = |num: f64, den: f64, b: (f64, f64)| {
        if den > 0.0 {
            clamp(num / den, b)
        } else {
            b.0
        }
    };
    let mut best = ([b0.0, b1.0], f64::INFINITY);
    for x0 in [b0.0, b0.1] {
        let x = [x0, opt(r[1] - g[0][1] * x0, g[1][1], b1)];
        let fx = f(x);
        if fx < best.1 {
            best = (x, fx);
        }
    }
    for x1 in [b1.0, b1.1] {
        let x = [opt(r[0] - g[0][1] * x1, g[0][0], b0), x1];
        let fx = f(x);
        if fx < best.1 {
            best = (x, fx);
        }
    }
    (best.0, true)
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

#[cfg(test)]
mod tests {
    use super::*;

    /// A small deterministic generator (the tests need no crate for it).
    struct Lcg(u64);
    impl Lcg {
        fn next(&mut self) -> f64 {
            self.0 = self
                .0
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (self.0 >> 11) as f64 / (1u64 << 53) as f64
        }
    }

    #[test]
    fn box_ls2_is_the_box_minimum() {
        // Against a dense grid: the returned point is never beaten by more than the grid's resolution.
        let mut rng = Lcg(7);
        for trial in 0..300 {
            let (a, b) = (rng.next() * 4.0 - 2.0, rng.next() * 4.0 - 2.0);
            // G = MᵀM for a random 2x2 M (singular every 10th trial: collinear columns).
            let c = if trial % 10 == 0 {
                a
            } else {
                rng.next() * 4.0 - 2.0
            };
            let d = if trial % 10 == 0 {
                b
            } else {
                rng.next() * 4.0 - 2.0
            };
            let g = [
                [a * a + b * b, a * c + b * d],
                [a * c + b * d, c * c + d * d],
            ];
            let r = [rng.next() * 6.0 - 3.0, rng.next() * 6.0 - 3.0];
            let lo0 = rng.next() * 2.0 - 1.0;
            let lo1 = rng.next() * 2.0 - 1.0;
            let b0 = (lo0, lo0 + rng.next() * 2.0);
            let b1 = (lo1, lo1 + rng.next() * 2.0);
            let f = |x: [f64; 2]| {
                0.5 * (g[0][0] * x[0] * x[0] + 2.0 * g[0][1] * x[0] * x[1] + g[1][1] * x[1] * x[1])
                    - r[0] * x[0]
                    - r[1] * x[1]
            };
            let (x, _) = box_ls2(g, r, b0, b1);
            assert!(x[0] >= b0.0 && x[0] <= b0.1 && x[1] >= b1.0 && x[1] <= b1.1);
            let k = 200;
            let mut best = f64::INFINITY;
            for i in 0..=k {
                for j in 0..=k {
                    let p = [
                        b0.0 + (b0.1 - b0.0) * i as f64 / k as f64,
                        b1.0 + (b1.1 - b1.0) * j as f64 / k as f64,
                    ];
                    best = best.min(f(p));
                }
            }
            assert!(
                f(x) <= best + 1e-9 * (1.0 + best.abs()),
                "trial {trial}: {} > {best}",
                f(x)
            );
        }
    }

    #[test]
    fn environment_solve_recovers_exact_products() {
        // y_c = P_c a + E_c v + Q w_c b on synthetic factors: the solve returns (P, E, Q) exactly.
        let mut rng = Lcg(11);
        let n = 400;
        let a: Vec<f32> = (0..n).map(|_| rng.next() as f32).collect();
        let v: Vec<f32> = (0..n).map(|_| rng.next() as f32).collect();
        let b: Vec<f32> = (0..n)
            .map(|i| if i % 3 == 0 { rng.next() as f32 } else { 0.0 })
            .collect();
        let (p, e, q, w) = ([0.3, 0.5, 0.2], [0.05, 0.02, 0.08], 0.7, [1.0f32, 0.9, 1.1]);
        let mut s = SolveSums::default();
        for c in 0..3 {
            let y: Vec<f32> = (0..n)
                .map(|i| {
                    (p[c] * a[i] as f64 + e[c] * v[i] as f64 + q * w[c] as f64 * b[i] as f64) as f32
                })
                .collect();
            s.add_environment(c, &a, Some(&b), &v, &y, f32::INFINITY);
        }
        let wide = [(0.0, 10.0); 3];
        let (pk, qk, ek) = solve_object_env(&s, w, &wide, (0.0, 10.0), &wide, |_| (0.0, 0.0, 0.0));
        for c in 0..3 {
            assert!(
                (pk[c] - p[c]).abs() < 1e-5 && (ek[c] - e[c]).abs() < 1e-5,
                "{pk:?} {ek:?}"
            );
        }
        assert!((qk - q).abs() < 1e-5, "{qk}");
        // E bounded below its truth: it sits at the bound and P absorbs what it can.
        let eb = [(0.0, 0.01); 3];
        let (_, _, ek) = solve_object_env(&s, w, &wide, (0.0, 10.0), &eb, |_| (0.0, 0.0, 0.0));
        assert!(ek.iter().all(|&x| (x - 0.01).abs() < 1e-12), "{ek:?}");
    }
}
