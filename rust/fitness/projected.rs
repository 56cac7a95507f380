//! The closed form: per candidate light, the least-squares products of every object (variable
//! projection), and the loss at them.

use rayon::prelude::*;

use super::kernel::{Candidate, Kernel};
use super::light_terms::{irradiance, shadow};
use super::lobe::{coat_factors, half_cos};
use super::loss::{rgb_loss_in, Encoding, Norm, LANES};
use super::pixels::{Group, Light, BLOCK};
use super::simd::{self, Simd};
use super::solve::{
    environment_lane_sums, fallback_sums, solve_object, solve_object_env, SolveSums,
};
use crate::render::brdf::{lambert, specular_per_lambert};

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
    #[inline(always)]
    pub(crate) fn projected_direct<const AVX2: bool, E: Encoding + Send + Sync>(
        &self,
        c: Candidate,
        proj: &Projection,
        out: &mut Solved,
        scratch: &mut Vec<f32>,
        enc: E,
    ) -> [f64; 3] {
        let Candidate {
            params: p,
            clip,
            bound,
            parallel,
        } = c;
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
        let sat = if clip { self.saturated } else { f32::INFINITY };
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
            let run = Run::of(
                g,
                obj,
                &light,
                proj,
                p.materials[obj].shininess,
                p.coat(obj),
                (sat, top),
                self.norm,
            );
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
            let products = self.solve_run(&run, obj, &sums, proj, out, &e_all[..n], sat);
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

    /// Each group's [`Run`] for the light `light` (unit light) and the candidate's shininess (`p`), `None`
    /// for the background.
    pub(crate) fn runs<'a>(
        &'a self,
        light: &'a Light,
        p: &'a crate::render::ShadeParams,
        proj: &'a Projection,
        (sat, top): (f32, f32),
    ) -> Vec<Option<Run<'a>>> {
        self.groups
            .iter()
            .map(|g| {
                g.object.map(|obj| {
                    let shininess = p.materials[obj].shininess;
                    Run::of(
                        g,
                        obj,
                        light,
                        proj,
                        shininess,
                        p.coat(obj),
                        (sat, top),
                        self.norm,
                    )
                })
            })
            .collect()
    }

    /// One object's products from its run's sums into `out` (its environment column's too, where it has
    /// one), and the products as pass 2 takes them. `e_unit`: the run's unit-light factors (a channel
    /// whose normal equations are singular falls back on them).
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn solve_run(
        &self,
        run: &Run,
        obj: usize,
        sums: &SolveSums,
        proj: &Projection,
        out: &mut Solved,
        e_unit: &[f32],
        sat: f32,
    ) -> Products {
        let g = run.group();
        let qb = if run.specular {
            proj.specular[obj]
        } else {
            (0.0, 0.0)
        };
        let fallback = |c: usize| fallback_sums(e_unit, &g.t[c], sat);
        let (pk, q, ek) = if run.sky.is_some() {
            solve_object_env(
                sums,
                proj.weight,
                &proj.diffuse[obj],
                qb,
                &proj.environment[obj],
                fallback,
            )
        } else {
            let (pk, q) = solve_object(sums, proj.weight, &proj.diffuse[obj], qb, fallback);
            (pk, q, [0.0; 3])
        };
        out.products[obj] = pk;
        out.specular[obj] = q;
        if run.sky.is_some() {
            out.environment[obj] = ek;
        }
        Products {
            pk: std::array::from_fn(|c| pk[c] as f32),
            qw: std::array::from_fn(|c| (q * proj.weight[c] as f64) as f32),
            ek: std::array::from_fn(|c| ek[c] as f32),
            on: run.specular && q > 0.0,
        }
    }
}

/// The gauge's bounds for the bounce (`fitness::bounce`): u = 1/intensity from the intensity's range, and
/// each object's largest albedo per channel (ρ = P·u/g_c may not exceed it).
#[derive(Clone, Debug)]
pub struct Gauge {
    pub u: (f64, f64),
    pub albedo_max: Vec<[f64; 3]>,
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

impl Solved {
    /// Object `k`'s environment product in channel `c`; 0 without an environment term.
    #[inline(always)]
    pub(crate) fn environment_at(&self, k: usize, c: usize) -> f64 {
        self.environment.get(k).map_or(0.0, |e| e[c])
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
    /// The object's coat: its diffuse and specular factors replace Lambert's and the lobe's.
    pub(crate) coat: Option<&'a crate::render::coat::Coat>,
    pub(crate) sat: f32,
    pub(crate) top: f32,
    pub(crate) norm: Norm,
}

impl<'a> Run<'a> {
    /// Object `obj`'s run (group `g`) under `light`: specular and sky as the projection says;
    /// `(sat, top)` the saturation test and the clip.
    pub(crate) fn of(
        g: &'a Group,
        obj: usize,
        light: &'a Light,
        proj: &'a Projection,
        shininess: f32,
        coat: Option<&'a crate::render::coat::Coat>,
        (sat, top): (f32, f32),
        norm: Norm,
    ) -> Run<'a> {
        Run {
            g,
            light,
            specular: proj.specular[obj].1 > 0.0,
            sky: proj.sky(obj, g),
            shininess,
            coat,
            sat,
            top,
            norm,
        }
    }

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
            match self.coat {
                // the coat's factors: diffuse per unit albedo and the lobe per unit weight
                Some(coat) => coat_factors(g, r.clone(), self.light, coat, e, &mut b[i0..i0 + len]),
                None => e.iter_mut().for_each(|ei| *ei = lambert(*ei)),
            }
            if self.specular || self.sky.is_some() {
                let b = &mut b[i0..i0 + len];
                let norm = specular_per_lambert(self.shininess);
                if self.specular && self.coat.is_none() {
                    // (s+8)/(8 pi) max(0, n.h)^s cos / d² = e · (s+8)/8 · max(0, n.h)^s: the cosines in
                    // lanes, the power where the light reaches the pixel
                    let mut nh = [0.0f32; BLOCK];
                    half_cos(g, r.clone(), self.light, &mut nh[..len]);
                    for i in 0..len {
                        b[i] = if e[i] > 0.0 {
                            (e[i] * norm * nh[i].powf(self.shininess)).min(f32::MAX)
                        } else {
                            0.0
                        };
                    }
                } else if !self.specular {
                    b.fill(0.0);
                }
                let zeros = [0.0f32; BLOCK];
                let v = self.sky.map_or(&zeros[..len], |v| &v[r.clone()]);
                for c in 0..3 {
                    // the nine sums in SUM_LANES partial sums (a lobe without sky: v = 0, its sums 0)
                    let t = &g.ts[c][r.clone()];
                    sums.add_lanes(
                        c,
                        environment_lane_sums::<AVX2>(e, b, v, t, self.sat, self.specular),
                    );
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
            let sums: [f64; 3] = if self.sky.is_some() || q_on {
                // enc(min(P_c·e + Q·w_c·b + E_c·v, top)), in LANES partial sums as the bounce's pass 2
                ColumnsLoss {
                    cols: [e; 3],
                    b: &b[i0..i0 + len],
                    sky: self.sky.map(|v| &v[r.clone()]),
                    t,
                    pc: pk,
                    qw: if q_on { qw } else { [0.0; 3] },
                    ec: ek,
                    top: self.top,
                    norm: self.norm,
                    enc,
                }
                .run::<AVX2>()
            } else {
                rgb_loss_in(self.norm, e, t, [0.0; 3], pk, self.top, enc).map(f64::from)
            };
            for c in 0..3 {
                part[c] += sums[c];
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
    pub(crate) pk: [f32; 3],
    pub(crate) qw: [f32; 3],
    pub(crate) ek: [f32; 3],
    pub(crate) on: bool,
}

/// Pass 2 over one run where an object has an environment column or a lobe (`cols` its unit-light factor
/// thrice), or a held bounce (`cols` the diffuse columns a'_c, `Kernel::projected_held`), for
/// [`simd::dispatch`]: per channel Σ penalty(enc(min(P_c·a'_c + Q·w_c·b + E_c·v, top)) - t_c), in `LANES`
/// partial sums.
pub(crate) struct ColumnsLoss<'a, E> {
    pub(crate) cols: [&'a [f32]; 3],
    pub(crate) b: &'a [f32],
    pub(crate) sky: Option<&'a [f32]>,
    pub(crate) t: [&'a [f32]; 3],
    pub(crate) pc: [f32; 3],
    pub(crate) qw: [f32; 3],
    pub(crate) ec: [f32; 3],
    pub(crate) top: f32,
    pub(crate) norm: Norm,
    pub(crate) enc: E,
}

impl<E: Encoding> ColumnsLoss<'_, E> {
    #[inline(always)]
    fn sum(&self, f: impl Fn(f32) -> f32) -> [f64; 3] {
        let (b, top, enc) = (self.b, self.top, self.enc);
        let n = b.len();
        let zeros = [0.0f32; CHUNK];
        // no sky: E_c·0 adds +0 to a value >= +0 (products and factors are non-negative): the same value
        let v = self.sky.map_or(&zeros[..n], |v| &v[..n]);
        let full = if !E::ENCODES || top <= 1.0 {
            n - n % LANES
        } else {
            0
        };
        let mut out = [0.0f64; 3];
        for ch in 0..3 {
            let (col, t) = (&self.cols[ch][..n], &self.t[ch][..n]);
            let (pc, qw, ec) = (self.pc[ch], self.qw[ch], self.ec[ch]);
            let mut lanes = [0.0f32; LANES];
            // whole runs of LANES as fixed-size chunks (no bounds checks: the loop vectorises)
            let runs = col[..full]
                .chunks_exact(LANES)
                .zip(b[..full].chunks_exact(LANES))
                .zip(v[..full].chunks_exact(LANES))
                .zip(t[..full].chunks_exact(LANES));
            for (((c8, b8), v8), t8) in runs {
                for l in 0..LANES {
                    let m = pc * c8[l] + qw * b8[l] + ec * v8[l];
                    lanes[l] += f(enc.unit(m.min(top)) - t8[l]);
                }
            }
            for (j, i) in (full..n).enumerate() {
                let m = pc * col[i] + qw * b[i] + ec * v[i];
                lanes[j % LANES] += f(enc.any(m.min(top)) - t[i]);
            }
            out[ch] = lanes.iter().sum::<f32>() as f64;
        }
        out
    }
}

impl<E: Encoding> Simd for ColumnsLoss<'_, E> {
    type Output = [f64; 3];
    #[inline(always)]
    fn run<const AVX2: bool>(self) -> [f64; 3] {
        match self.norm {
            // one closure per norm with the norm a constant, so each loop vectorises on its own
            Norm::L1 => self.sum(|d| Norm::L1.penalty(d)),
            Norm::L2 => self.sum(|d| Norm::L2.penalty(d)),
            Norm::Huber(h) => self.sum(move |d| Norm::Huber(h).penalty(d)),
        }
    }
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

/// The lane sums of [`normal_equations`] over whole runs of `LANES` pixels.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
#[inline]
pub(crate) unsafe fn normal_equation_lanes_avx2(
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
