//! The refine: the products that minimise the fit's own loss (norm, clip, space) at the found light, by
//! exact line searches per product (`l1_line_min`, `encoded_line_min`, `bisect`).

use rayon::prelude::*;

use super::kernel::Kernel;
use super::line_min::{bisect, encoded_line_min, l1_line_min, EncodedTerm};
use super::loss::{Norm, Space, SrgbLut};
use super::pixels::Group;
use super::projected::{Projection, Solved};

impl Kernel {
    /// The products that minimise this kernel's own loss (norm, clip, space) at one light, after
    /// `projected` filled `out` and `scratch` for it; a saturated pixel counts one-sidedly, as in the loss
    /// (least squares drops it, which biases bright channels down). Block coordinate descent per object
    /// (each P_c given Q, then Q), each step an exact line search ([`l1_line_min`], bisection on the
    /// derivative, or [`encoded_line_min`] in sRGB). Returns the per-channel loss there.
    pub fn refine(
        &self,
        clip: bool,
        proj: &Projection,
        out: &mut Solved,
        scratch: &[f32],
    ) -> [f64; 3] {
        let sat = if clip { self.saturated } else { f32::INFINITY };
        let top = if clip { 1.0f64 } else { f64::INFINITY };
        let objects = self.refine_objects(proj, scratch);
        out.lit.clear();
        out.lit.resize(proj.diffuse.len(), 0);
        for o in &objects {
            out.lit[o.obj] = o.lit;
        }
        // Block coordinate descent per object: each P_c given Q, then Q given the P's (four rounds for a
        // glossy object; one for a matte one, whose channels are independent). An environment column
        // couples a channel's P_c and E_c: four rounds as for a glossy object. Every line search depends
        // only on its own object's values, and those of an object whose Q stays (matte, or a channel that
        // informs nothing) only on its own channel's: each such (object, channel) runs its rounds as one
        // chain, each glossy object its rounds with its channels' searches side by side, and all the chains
        // at once; the same searches in the same order per chain, so the same values on any number of
        // threads as round by round over every object.
        let rounds = if objects.iter().any(|o| o.specular || o.sky.is_some()) {
            4
        } else {
            1
        };
        let limits = Limits { proj, sat, top };
        let glossy = |o: &RefineObject| o.specular && o.informed.iter().all(|&i| i);
        let chains: Vec<(usize, Option<usize>)> = objects
            .iter()
            .enumerate()
            .flat_map(|(k, o)| {
                let per_channel: Vec<(usize, Option<usize>)> = if glossy(o) {
                    vec![(k, None)]
                } else {
                    (0..3).map(|c| (k, Some(c))).collect()
                };
                per_channel
            })
            .collect();
        let start = &*out;
        let results: Vec<Chain> = chains
            .par_iter()
            .map(|&(k, c)| {
                let o = &objects[k];
                let (p, q, e) = (
                    start.products[o.obj],
                    start.specular[o.obj],
                    if o.sky.is_some() {
                        start.environment[o.obj]
                    } else {
                        [0.0; 3]
                    },
                );
                match c {
                    Some(c) => self.channel_chain(o, c, rounds, (p[c], q, e[c]), limits),
                    None => self.glossy_chain(o, rounds, (p, q, e), limits),
                }
            })
            .collect();
        for (&(k, _), r) in chains.iter().zip(results) {
            let (obj, sky) = (objects[k].obj, objects[k].sky.is_some());
            match r {
                Chain::Channel(c, p, e) => {
                    out.products[obj][c] = p;
                    if sky {
                        out.environment[obj][c] = e;
                    }
                }
                Chain::Glossy(p, q, e) => {
                    out.products[obj] = p;
                    out.specular[obj] = q;
                    if sky {
                        out.environment[obj] = e;
                    }
                }
            }
        }
        self.loss_at(&objects, out, proj, top, None)
    }

    /// The objects' groups with their factors from `scratch` (as [`Kernel::projected`] left it), for
    /// [`Kernel::refine`] and [`Kernel::loss_at`].
    pub(crate) fn refine_objects<'a>(
        &'a self,
        proj: &'a Projection,
        scratch: &'a [f32],
    ) -> Vec<RefineObject<'a>> {
        let (a_all, rest) = scratch.split_at(self.pixels);
        let b_all = &rest[..self.pixels];
        // With the bounce the diffuse column differs per channel (a'_c, after b in the scratch).
        let bounced = proj.gauge.is_some() && rest.len() >= 4 * self.pixels;
        let mut objects: Vec<RefineObject> = Vec::new();
        let mut offset = 0;
        for (index, g) in self.groups.iter().enumerate() {
            let n = g.len();
            let (a, b) = (&a_all[offset..offset + n], &b_all[offset..offset + n]);
            let ac: [&[f32]; 3] = if bounced {
                std::array::from_fn(|c| &rest[(1 + c) * self.pixels + offset..][..n])
            } else {
                [a; 3]
            };
            offset += n;
            let Some(obj) = g.object else {
                continue;
            };
            objects.push(RefineObject {
                g,
                index,
                obj,
                lit: a.iter().filter(|&&v| v > 0.0).count(),
                a: ac,
                b,
                specular: proj.specular[obj].1 > 0.0,
                sky: proj.sky(obj, g),
                informed: std::array::from_fn(|c| {
                    (0..n).any(|i| g.ts[c][i].is_finite() && ac[c][i] > 0.0)
                }),
            });
        }
        objects
    }

    /// The per-channel loss at `out`'s products of the pixels of `objects` (from
    /// [`Kernel::refine_objects`]) and of the background's, in this kernel's norm and space, clipped at
    /// `top`: of every pixel, or (`only`) of those whose entry of `only[group]` is true. Summed per object
    /// and channel in f64, added in the groups' order: the same value on any number of threads.
    pub(crate) fn loss_at(
        &self,
        objects: &[RefineObject],
        out: &Solved,
        proj: &Projection,
        top: f64,
        only: Option<&[Vec<bool>]>,
    ) -> [f64; 3] {
        let srgb = self.space == Space::Srgb;
        let counts = |gi: usize, i: usize| only.is_none_or(|m| m[gi][i]);
        let env = |out: &Solved, o: &RefineObject| {
            if o.sky.is_some() {
                out.environment[o.obj]
            } else {
                [0.0; 3]
            }
        };
        let losses: Vec<f64> = (0..objects.len() * 3)
            .into_par_iter()
            .map(|kc| {
                let (o, c) = (&objects[kc / 3], kc % 3);
                let (pc, q, ec) = (out.products[o.obj][c], out.specular[o.obj], env(out, o)[c]);
                let gt = if srgb { &o.g.te[c] } else { &o.g.t[c] };
                (0..o.b.len())
                    .filter(|&i| counts(o.index, i))
                    .map(|i| {
                        let m = o.model(c, pc, q, ec, proj.weight[c], i).min(top) as f32;
                        let m = if srgb { SrgbLut::get().encode(m) } else { m };
                        self.norm.penalty(m - gt[i]) as f64
                    })
                    .sum::<f64>()
            })
            .collect();
        // The background (an ambient-free scene's: black), after the objects as the groups are ordered.
        let mut acc = [0.0f64; 3];
        for (gi, g) in self.groups.iter().enumerate() {
            if g.object.is_some() {
                continue;
            }
            let gt = if srgb { &g.te } else { &g.t };
            for c in 0..3 {
                acc[c] += (0..g.len())
                    .filter(|&i| counts(gi, i))
                    .map(|i| self.norm.penalty(gt[c][i]) as f64)
                    .sum::<f64>();
            }
        }
        let mut total = [0.0f64; 3];
        for (kc, l) in losses.iter().enumerate() {
            total[kc % 3] += l;
        }
        for c in 0..3 {
            total[c] += acc[c];
        }
        total
    }

    /// The rounds of one channel `c` of an object whose Q stays: P_c (in round 0, and in every round of an
    /// object with a lobe or an environment column, where the channel informs it), then E_c (with an
    /// environment column), from `(P_c, Q, E_c)`.
    fn channel_chain(
        &self,
        o: &RefineObject,
        c: usize,
        rounds: usize,
        (mut p, q, mut e): (f64, f64, f64),
        limits: Limits,
    ) -> Chain {
        for round in 0..rounds {
            if (round == 0 || o.specular || o.sky.is_some()) && o.informed[c] {
                p = self.refine_diffuse(o, c, q, e, p, limits);
            }
            if o.sky.is_some() {
                e = self.refine_environment(o, c, p, q, e, limits);
            }
        }
        Chain::Channel(c, p, e)
    }

    /// The rounds of a glossy object whose every channel informs: per round the three P_c side by side,
    /// then the three E_c (with an environment column), then Q, from `(P, Q, E)`.
    fn glossy_chain(
        &self,
        o: &RefineObject,
        rounds: usize,
        (mut p, mut q, mut e): ([f64; 3], f64, [f64; 3]),
        limits: Limits,
    ) -> Chain {
        for _ in 0..rounds {
            let (pq, pe) = (q, e);
            let ps: Vec<f64> = (0..3)
                .into_par_iter()
                .map(|c| self.refine_diffuse(o, c, pq, pe[c], p[c], limits))
                .collect();
            p.copy_from_slice(&ps);
            if o.sky.is_some() {
                let pp = p;
                let es: Vec<f64> = (0..3)
                    .into_par_iter()
                    .map(|c| self.refine_environment(o, c, pp[c], q, e[c], limits))
                    .collect();
                e.copy_from_slice(&es);
            }
            q = self.refine_specular(o, p, q, e, limits);
        }
        Chain::Glossy(p, q, e)
    }

    /// [`Kernel::refine`]'s line search for P_c of one object given its specular product `q` and
    /// environment product `ec`, starting from `start` (the sRGB branch and bound uses it).
    fn refine_diffuse(
        &self,
        o: &RefineObject,
        c: usize,
        q: f64,
        ec: f64,
        start: f64,
        limits: Limits,
    ) -> f64 {
        let w = limits.proj.weight[c];
        let bounds = limits.proj.diffuse[o.obj][c];
        self.coefficient_line_min(o, c, o.a[c], bounds, start, limits, |pc, i| {
            o.model(c, pc, q, ec, w, i)
        })
    }

    /// [`Kernel::refine`]'s line search for E_c of one object with an environment column, given its
    /// diffuse product `pc` and specular product `q`, starting from `start`.
    fn refine_environment(
        &self,
        o: &RefineObject,
        c: usize,
        pc: f64,
        q: f64,
        start: f64,
        limits: Limits,
    ) -> f64 {
        let Some(v) = o.sky else {
            return start;
        };
        let w = limits.proj.weight[c];
        let bounds = limits.proj.environment[o.obj][c];
        self.coefficient_line_min(o, c, v, bounds, start, limits, |ec, i| {
            o.model(c, pc, q, ec, w, i)
        })
    }

    /// The line search for one linear coefficient x of channel `c` of object `o`, whose column (the
    /// pixel's factor of x) is `col`: `at(x, i)` is pixel i's model value; pixels with a zero factor do
    /// not depend on x and are left out. sRGB: [`encoded_line_min`]; L1: [`l1_line_min`]; otherwise a
    /// bisection on the derivative.
    #[allow(clippy::too_many_arguments)]
    fn coefficient_line_min(
        &self,
        o: &RefineObject,
        c: usize,
        col: &[f32],
        bounds: (f64, f64),
        start: f64,
        limits: Limits,
        at: impl Fn(f64, usize) -> f64,
    ) -> f64 {
        let Limits { sat, top, .. } = limits;
        let (n, t) = (o.b.len(), &o.g.ts[c]);
        if self.space == Space::Srgb {
            // Terms enc(min(k x + s, top)) against the encoded objective.
            let terms: Vec<EncodedTerm> = (0..n)
                .filter(|&i| col[i] > 0.0 && t[i].is_finite())
                .map(|i| EncodedTerm {
                    k: col[i] as f64,
                    o: at(0.0, i),
                    y: t[i] as f64,
                    ye: o.g.te[c][i],
                    saturated: t[i] >= sat,
                })
                .collect();
            encoded_line_min(&terms, self.norm, top, bounds, start)
        } else if self.norm == Norm::L1 {
            // Terms |min(k x + s, top) - y|: coefficient k, offset s (the other terms).
            let terms = (0..n)
                .filter(|&i| col[i] > 0.0 && t[i].is_finite())
                .map(|i| (col[i] as f64, at(0.0, i), t[i] as f64, t[i] >= sat));
            l1_line_min(terms, bounds, top)
        } else {
            bisect(bounds, |x| {
                (0..n)
                    .filter(|&i| col[i] > 0.0)
                    .map(|i| col[i] as f64 * self.refine_slope(at(x, i), t[i], sat, top))
                    .sum()
            })
        }
    }

    /// [`Kernel::refine`]'s line search for Q of one glossy object given its diffuse products `pk` and
    /// environment products `e`.
    fn refine_specular(
        &self,
        o: &RefineObject,
        pk: [f64; 3],
        q: f64,
        e: [f64; 3],
        limits: Limits,
    ) -> f64 {
        let Limits { proj, sat, top } = limits;
        let (n, b, t) = (o.b.len(), o.b, &o.g.ts);
        let bounds = proj.specular[o.obj];
        if self.space == Space::Srgb {
            let terms: Vec<EncodedTerm> = (0..3)
                .flat_map(|c| {
                    (0..n)
                        .filter(move |&i| b[i] > 0.0 && t[c][i].is_finite())
                        .map(move |i| EncodedTerm {
                            k: proj.weight[c] as f64 * b[i] as f64,
                            o: o.model(c, pk[c], 0.0, e[c], proj.weight[c], i),
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
                        let off = o.model(c, pk[c], 0.0, e[c], proj.weight[c], i);
                        (k, off, t[c][i] as f64, t[c][i] >= sat)
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
                                    * self.refine_slope(
                                        o.model(c, pk[c], q, e[c], w, i),
                                        t[c][i],
                                        sat,
                                        top,
                                    )
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

/// What one chain of [`Kernel::refine`] found: channel c's (c, P_c, E_c), or a glossy object's (P, Q, E).
enum Chain {
    Channel(usize, f64, f64),
    Glossy([f64; 3], f64, [f64; 3]),
}

/// What every line search of one [`Kernel::refine`] shares: the products' bounds and the clip.
#[derive(Clone, Copy)]
struct Limits<'a> {
    proj: &'a Projection,
    sat: f32,
    top: f64,
}

/// One object's pixels and unit-light factors, for [`Kernel::refine`].
pub(crate) struct RefineObject<'a> {
    g: &'a Group,
    /// Its group's index in the kernel.
    index: usize,
    obj: usize,
    /// Its pixels the light reaches (unit-light factor > 0).
    lit: usize,
    /// The diffuse column per channel (the same unit-light factors unless a bounce is folded in).
    a: [&'a [f32]; 3],
    b: &'a [f32],
    specular: bool,
    /// The sky view factors, for an object with an environment column.
    sky: Option<&'a [f32]>,
    /// A channel with a pixel that is lit and informs the products.
    informed: [bool; 3],
}

impl RefineObject<'_> {
    /// Model value of pixel `i` in channel `c` of specular weight `w` at products `pc`, `q` and `ec`.
    pub(crate) fn model(&self, c: usize, pc: f64, q: f64, ec: f64, w: f32, i: usize) -> f64 {
        let lit = pc * self.a[c][i] as f64
            + if self.specular {
                q * w as f64 * self.b[i] as f64
            } else {
                0.0
            };
        match self.sky {
            Some(v) => lit + ec * v[i] as f64,
            None => lit,
        }
    }
}
