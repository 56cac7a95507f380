//! The refine: the products that minimise the fit's own loss (norm, clip, space) at the found light, by
//! exact line searches per product (`l1_line_min`, `encoded_line_min`, `bisect`).

use rayon::prelude::*;

use super::kernel::Kernel;
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
        let (a_all, rest) = scratch.split_at(self.pixels);
        let b_all = &rest[..self.pixels];
        // With the bounce the diffuse column differs per channel (a'_c, after b in the scratch).
        let bounced = proj.gauge.is_some() && rest.len() >= 4 * self.pixels;
        let sat = if clip { self.saturated } else { f32::INFINITY };
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
            let ac: [&[f32]; 3] = if bounced {
                std::array::from_fn(|c| &rest[(1 + c) * self.pixels + offset..][..n])
            } else {
                [a; 3]
            };
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
                a: ac,
                b,
                specular: proj.specular[obj].1 > 0.0,
                sky: proj.sky(obj, g),
                informed: std::array::from_fn(|c| {
                    (0..n).any(|i| g.ts[c][i].is_finite() && ac[c][i] > 0.0)
                }),
            });
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
        let env = |out: &Solved, o: &RefineObject| {
            if o.sky.is_some() {
                out.environment[o.obj]
            } else {
                [0.0; 3]
            }
        };
        // The loss at the refined products, per object and channel, added in the groups' order.
        let losses: Vec<f64> = (0..objects.len() * 3)
            .into_par_iter()
            .map(|kc| {
                let (o, c) = (&objects[kc / 3], kc % 3);
                let (pc, q, ec) = (out.products[o.obj][c], out.specular[o.obj], env(out, o)[c]);
                let gt = if srgb { &o.g.te[c] } else { &o.g.t[c] };
                (0..o.b.len())
                    .map(|i| {
                        let m = o.model(c, pc, q, ec, proj.weight[c], i).min(top) as f32;
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
    obj: usize,
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
    pub(crate) fn at(&self, top: f64) -> f64 {
        (if self.saturated { top } else { self.y } - self.o) / self.k
    }

    /// g(x) and its right derivative.
    #[inline]
    pub(crate) fn g(&self, x: f64, top: f64, lut: &SrgbLut) -> (f64, f64) {
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
    pub(crate) fn loss(&self, g: f64, g_top: f64, norm: Norm) -> f64 {
        let d = if self.saturated {
            (g - g_top).min(0.0)
        } else {
            g - self.ye as f64
        };
        norm.penalty(d as f32) as f64
    }
}

/// Midpoints evaluated at most by one [`encoded_line_min`] (each one pass over the terms; typically 20-50).
pub(crate) const MAX_SPLITS: usize = 200;

/// The minimiser over [lo, hi] of Σ_j ℓ_j(x) for the sRGB-space terms (each unimodal, their sum not):
/// branch and bound over intervals with a convex minorant per interval, to 1e-8 of the best value, at
/// most `MAX_SPLITS` midpoints, never worse than `start`.
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
pub(crate) struct Point {
    x: f64,
    f: f64,
    g: Vec<[f64; 2]>,
}

/// The slope of penalty(d) for a rising term (d ≥ 0, increasing): L1's is 1 at d = 0 too.
#[inline]
pub(crate) fn rising_slope(norm: Norm, d: f64) -> f64 {
    match norm {
        Norm::L1 => 1.0,
        _ => norm.slope(d.max(0.0)),
    }
}

/// An interval of [`encoded_line_min`] between two points (by index) with its lower bound; the heap pops
/// the lowest bound first.
pub(crate) struct Interval {
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

/// The exact minimiser over [lo, hi] of Σ_j ℓ_j(x) for terms (k > 0, o, y, saturated), ℓ = |min(kx + o,
/// top) - y| (max(0, top - kx - o) when saturated): piecewise linear, so one sweep over the sorted
/// breakpoints finds it, with the clip kept exact.
pub fn l1_line_min(
    terms: impl Iterator<Item = (f64, f64, f64, bool)>,
    (lo, hi): (f64, f64),
    top: f64,
) -> f64 {
    // Breakpoints with the slope change there; the slope left of every breakpoint is -Σk.
    let mut events: Vec<(f64, f64)> = Vec::with_capacity(2 * terms.size_hint().1.unwrap_or(0));
    let mut slope = 0.0;
    let mut push = |at: f64, ds: f64| {
        if !at.is_nan() {
            events.push((at, ds));
        }
    };
    for (k, o, y, saturated) in terms {
        slope -= k;
        if saturated {
            push((top - o) / k, k);
        } else {
            push((y - o) / k, 2.0 * k);
            push((top - o) / k, -k);
        }
    }
    let (mut x, mut f) = (lo, 0.0);
    let (mut best_x, mut best_f) = (lo, 0.0);
    for i in sorted_by_position(&events) {
        let (at, ds) = events[i];
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

/// The indices of (position, slope change) `events` in the order of their positions rounded to f32 (it
/// only merges breakpoints closer than the renderer's precision; a comparison sort cost more), equal ones
/// in index order: an LSD radix sort, three 11-bit digits, of the key and the index packed in one word.
pub(crate) fn sorted_by_position(events: &[(f64, f64)]) -> impl Iterator<Item = usize> {
    let key = |x: f64| {
        let b = (x as f32).to_bits();
        if b >> 31 == 1 {
            !b
        } else {
            b | (1 << 31)
        }
    };
    let mut from: Vec<u64> = events
        .iter()
        .enumerate()
        .map(|(i, e)| (u64::from(key(e.0)) << 32) | i as u64)
        .collect();
    let mut to = vec![0u64; from.len()];
    for shift in [32u32, 43, 54] {
        let mut count = [0u32; 2049];
        for &e in &from {
            count[((e >> shift) & 2047) as usize + 1] += 1;
        }
        for k in 1..count.len() {
            count[k] += count[k - 1];
        }
        for &e in &from {
            let d = ((e >> shift) & 2047) as usize;
            to[count[d] as usize] = e;
            count[d] += 1;
        }
        std::mem::swap(&mut from, &mut to);
    }
    from.into_iter().map(|e| (e & 0xffff_ffff) as usize)
}

/// The zero of a non-decreasing `derivative` on [lo, hi] by bisection (an end when it does not change
/// sign there): the minimiser of a convex function of one variable.
pub(crate) fn bisect((mut lo, mut hi): (f64, f64), derivative: impl Fn(f64) -> f64) -> f64 {
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
