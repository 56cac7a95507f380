//! The closed form with one diffuse bounce between the objects (`render::bounce`).
//!
//! With interreflection a pixel of object o is, per channel c,
//!   y = P_o,c·(a + (u/g_c)·B_o,c) + E_o,c·v + Q_o·w_c·b,   B_o,c = Σ_k F_k·(P_k,c·a_k(y_k) + E_k,c·S(y_k)),
//! where the bounce B is gathered from the senders' products at their representative points, g_c =
//! exposure x colour_c, and u = 1 / intensity: the receiver's albedo ρ = P·u/g_c enters absolutely (a
//! bounce is as bright as the albedos are, not only their products with the light). The solve is a fixed
//! point: the products without the bounce, then twice the gauge u (least squares given the products, inside
//! the intensity's and the albedos' bounds) and the products given u. Pass 2 is the loss at the result.
//! The full fixed point is serial and without early exit (a fit solves it only where a pass starts and
//! ends); the search's candidates, with the bounce held ([`Frozen`]), are spread over the pool for a lone
//! candidate and stop early above their bound, as direct candidates do.

use super::kernel::{Candidate, Kernel};
use super::loss::{Encoding, Norm, LANES};
use super::pixels::{Light, BLOCK};
use super::projected::{Projection, Run, Solved, CHUNK};
use super::simd::{self, Simd};
use super::solve::{
    environment_lane_sums, fallback_sums, solve_object, solve_object_env, SolveSums, SUM_LANES,
};
use rayon::prelude::*;

/// The gauge's bounds for the bounce: u = 1/intensity from the intensity's range, and each object's
/// largest albedo per channel (ρ = P·u/g_c may not exceed it).
#[derive(Clone, Debug)]
pub struct Gauge {
    pub u: (f64, f64),
    pub albedo_max: Vec<[f64; 3]>,
    /// Fixed-point rounds of (gauge, products) after the bounce-free solve: [`SEARCH_ROUNDS`] while the
    /// search ranks lights, [`FINAL_ROUNDS`] for the reported products.
    pub rounds: usize,
    /// The bounce held while the search ranks lights ([`Frozen`]); `None`: solved per candidate.
    pub frozen: Option<std::sync::Arc<Frozen>>,
}

/// The bounce solved once, at a reference candidate (the full fixed point, [`FINAL_ROUNDS`]), and held:
/// per pixel and channel the term (u/g_c)·B_c that [`Kernel::projected_bounce`] adds to the diffuse factor
/// a, so that a candidate costs a direct one's factors and one solve of its products given a + that term.
/// Near the reference the bounce changes far less than the direct light (it is a few per cent of a
/// pixel, and its light comes from the whole floor): a search from a bounce-free fit's light ranks
/// lights by this, and the result's products (and loss) are the full bounce's at the found light.
#[derive(Clone, Debug)]
pub struct Frozen {
    /// (u/g_c)·B_c at pixel i (in the kernel's pixel order): `bounce[c * pixels + i]`.
    pub bounce: Vec<f32>,
    /// The gauge solved at the reference.
    pub u: f64,
}

/// The gauge converges linearly (the products first absorb part of the bounce); every third round
/// extrapolates it (Aitken's Δ²). Six rounds reach the fixed point of rtloop's own renders to about 1e-3
/// (the light within 0.5 mm; three leave it 10 mm off, plain iteration needs ~20), nine to 1e-4.
pub const SEARCH_ROUNDS: usize = 6;
pub const FINAL_ROUNDS: usize = 9;

/// One object's pixels in one channel for [`gauge_sums`]: the objective (`t`, at or above `sat` left
/// out), the bounce B_c, the unit-light diffuse and specular factors and the sky view.
struct GaugeTerms<'a> {
    t: &'a [f32],
    bounce: &'a [f32],
    a: &'a [f32],
    b: &'a [f32],
    sky: Option<&'a [f32]>,
}

/// Lanes of [`gauge_sums`].
const GAUGE_LANES: usize = 4;

/// The fixed point's gauge sums over one object's channel: Σ r·m and Σ m² with m = P_c·B_c/g_c and r the
/// residual without the bounce, y − P_c·a − Q·w_c·b − E_c·v, at products `[P_c, Q·w_c, E_c]` (g_c =
/// `w`). Taken in [`GAUGE_LANES`] partial sums (pixel i in lane i mod 4, the tail in lane 0), added in
/// lane order: independent chains of additions, the same value on any pool.
fn gauge_sums(px: GaugeTerms, [pc, qw, ec]: [f64; 3], w: f64, sat: f32) -> (f64, f64) {
    let n = px.t.len();
    let (t, bounce, a, b) = (px.t, &px.bounce[..n], &px.a[..n], &px.b[..n]);
    let term = |i: usize| -> (f64, f64) {
        if t[i] < sat {
            let m = pc * bounce[i] as f64 / w;
            let mut r = t[i] as f64 - pc * a[i] as f64 - qw * b[i] as f64;
            if let Some(v) = px.sky {
                r -= ec * v[i] as f64;
            }
            (r * m, m * m)
        } else {
            (0.0, 0.0)
        }
    };
    let (mut num, mut den) = ([0.0f64; GAUGE_LANES], [0.0f64; GAUGE_LANES]);
    let full = n - n % GAUGE_LANES;
    for i in (0..full).step_by(GAUGE_LANES) {
        for l in 0..GAUGE_LANES {
            let (rm, mm) = term(i + l);
            num[l] += rm;
            den[l] += mm;
        }
    }
    for i in full..n {
        let (rm, mm) = term(i);
        num[0] += rm;
        den[0] += mm;
    }
    (
        num.iter().fold(0.0, |s, v| s + v),
        den.iter().fold(0.0, |s, v| s + v),
    )
}

impl Kernel {
    /// [`Kernel::projected`] with the bounce (`proj.gauge` set). `scratch` ends as
    /// [a | b | a'_r | a'_g | a'_b] per pixel: unit-light diffuse and specular factors, and the diffuse
    /// columns with the bounce folded in, which [`Kernel::refine`] uses.
    pub(crate) fn projected_bounce<const AVX2: bool, E: Encoding + Send + Sync>(
        &self,
        c: Candidate,
        proj: &Projection,
        gauge: &Gauge,
        out: &mut Solved,
        scratch: &mut Vec<f32>,
        enc: E,
    ) -> [f64; 3] {
        let p = c.params;
        let light = Light {
            pos: p.light_position.to_array(),
            dir: p.light_direction.map(|d| d.to_array()),
            rgb: [1.0; 3],
        };
        let n_px = self.pixels;
        scratch.resize(5 * n_px, 0.0);
        let (a_all, rest) = scratch.split_at_mut(n_px);
        let (b_all, ab_all) = rest.split_at_mut(n_px);
        let sat = if c.clip {
            self.saturated
        } else {
            f32::INFINITY
        };
        let top = if c.clip { 1.0 } else { f32::INFINITY };
        out.products = proj
            .diffuse
            .iter()
            .map(|b| [b[0].0, b[1].0, b[2].0])
            .collect();
        out.specular = proj.specular.iter().map(|b| b.0).collect();
        out.environment = proj
            .environment
            .iter()
            .map(|b| [b[0].0, b[1].0, b[2].0])
            .collect();
        let w: [f64; 3] = std::array::from_fn(|c| proj.weight[c] as f64);
        let runs: Vec<Option<Run>> = self
            .groups
            .iter()
            .map(|g| {
                g.object.map(|obj| {
                    let shininess = p.materials[obj].shininess;
                    Run::of(g, obj, &light, proj, shininess, (sat, top), self.norm)
                })
            })
            .collect();
        if let Some(f) = &gauge.frozen {
            return self.projected_held::<AVX2, E>(c, proj, f, &runs, out, scratch, enc);
        }
        // Pass 1: each sender's light at its points (every gather at once), the factors (runs of blocks
        // over the pool, their sums added in order) and the bounce-free products.
        let mut offsets = Vec::with_capacity(self.groups.len());
        let mut offset = 0;
        for g in &self.groups {
            offsets.push(offset);
            offset += g.len();
        }
        let gathered: Vec<Vec<Compact>> = self
            .groups
            .par_iter()
            .map(|g| {
                g.gathers
                    .par_iter()
                    .map(|gth| {
                        let mut e = Vec::new();
                        gth.light::<AVX2>(&light, &mut e, c.parallel);
                        Compact::new(gth, &e)
                    })
                    .collect()
            })
            .collect();
        for (gi, (g, run)) in self.groups.iter().zip(&runs).enumerate() {
            let (o0, n) = (offsets[gi], g.len());
            let (Some(run), Some(obj)) = (run, g.object) else {
                continue;
            };
            let parts: Vec<SolveSums> = a_all[o0..o0 + n]
                .par_chunks_mut(BLOCK * 8)
                .zip(b_all[o0..o0 + n].par_chunks_mut(BLOCK * 8))
                .enumerate()
                .map(|(k, (e, b))| run.factors::<AVX2>(k * BLOCK * 8, e, b))
                .collect();
            let mut sums = SolveSums::default();
            for part in &parts {
                sums.add(part);
            }
            self.solve_into(run, obj, &sums, proj, out, &a_all[o0..o0 + n], sat);
        }
        // Each sphere's table points: their senders' light (unit light), for the second bounce.
        let table_light: Vec<Vec<Compact>> = self
            .tables
            .iter()
            .map(|gths| {
                gths.iter()
                    .map(|gth| {
                        let mut e = Vec::new();
                        gth.light::<AVX2>(&light, &mut e, c.parallel);
                        Compact::new(gth, &e)
                    })
                    .collect()
            })
            .collect();
        // The senders' own bounce, folded per receiving pixel: for a sphere sender k and each of its
        // table's senders k', Σ form·(light on k's table from k') and Σ form·(sky of k's table from k') over
        // the pixel's lookups. A round then costs per pixel and k', not per lookup.
        let folded: Vec<Vec<Vec<Fold>>> = self
            .groups
            .iter()
            .zip(&gathered)
            .map(|(g, cgs)| {
                g.gathers
                    .iter()
                    .zip(cgs)
                    .map(|(gth, cg)| {
                        Fold::of(cg, &self.tables[gth.sender], &table_light[gth.sender])
                    })
                    .collect()
            })
            .collect();
        // The fixed point: the bounce columns from the senders' products, the gauge, the products.
        // From the brightest lamp the bounds allow (the dimmest bounce): converges faster than from the
        // scene's own intensity.
        let mut u = gauge.u.0;
        let mut history: Vec<f64> = Vec::with_capacity(3);
        // A group's channels side by side in the bounce columns' rounds: (group, channel, its column).
        fn columns<'a>(
            ab: &'a mut [f32],
            lens: &[usize],
            n_px: usize,
        ) -> Vec<(usize, usize, &'a mut [f32])> {
            let mut cols = Vec::with_capacity(3 * lens.len());
            for (c, mut rest) in ab.chunks_mut(n_px.max(1)).take(3).enumerate() {
                for (gi, &n) in lens.iter().enumerate() {
                    let (col, tail) = rest.split_at_mut(n);
                    cols.push((gi, c, col));
                    rest = tail;
                }
            }
            cols
        }
        let lens: Vec<usize> = self.groups.iter().map(|g| g.len()).collect();
        let no_sky = vec![0.0f32; lens.iter().copied().max().unwrap_or(0)];
        for round in 0..gauge.rounds {
            // B_o,c per pixel into a'_c (as B for now) and, while it is at hand, the gauge's sums over the
            // object's channel ([`gauge_sums`]), every (group, channel) at once.
            let solved = &*out;
            let (a_in, b_in) = (&*a_all, &*b_all);
            let gauge_parts: Vec<(usize, usize, (f64, f64))> = columns(ab_all, &lens, n_px)
                .into_par_iter()
                .filter_map(|(gi, c, col)| {
                    let g = &self.groups[gi];
                    col.fill(0.0);
                    for ((gth, cg), folds) in g.gathers.iter().zip(&gathered[gi]).zip(&folded[gi]) {
                        let pk = solved.products[gth.sender][c] as f32;
                        let ek = solved
                            .environment
                            .get(gth.sender)
                            .map_or(0.0, |e| e[c] as f32);
                        for (j, &i) in cg.pixels.iter().enumerate() {
                            col[i as usize] += pk * cg.a[j] + ek * cg.s[j];
                        }
                        // The sender's own bounce: its albedo P_k·u/g_c times the light on its table.
                        let second = (u / w[c]) as f32 * pk;
                        for fold in folds {
                            let pt = second * solved.products[fold.sender][c] as f32;
                            let et = second
                                * solved
                                    .environment
                                    .get(fold.sender)
                                    .map_or(0.0, |e| e[c] as f32);
                            for (j, &i) in cg.pixels.iter().enumerate() {
                                col[i as usize] += pt * fold.a[j] + et * fold.s[j];
                            }
                        }
                    }
                    let obj = g.object?;
                    let (o0, n) = (offsets[gi], col.len());
                    let sums = gauge_sums(
                        GaugeTerms {
                            t: &g.ts[c],
                            bounce: col,
                            a: &a_in[o0..o0 + n],
                            b: &b_in[o0..o0 + n],
                            sky: proj.sky(obj, g),
                        },
                        [
                            solved.products[obj][c],
                            solved.specular[obj] * w[c],
                            solved.environment.get(obj).map_or(0.0, |e| e[c]),
                        ],
                        w[c],
                        sat,
                    );
                    Some((gi, c, sums))
                })
                .collect();
            // u: least squares of the residual without the bounce against P_c·B_c/g_c, its sums added per
            // object and channel in that order.
            let (mut num, mut den) = (0.0f64, 0.0f64);
            let mut u_max = gauge.u.1;
            for (gi, g) in self.groups.iter().enumerate() {
                let Some(obj) = g.object else { continue };
                for c in 0..3 {
                    let pc = out.products[obj][c];
                    if pc > 0.0 && w[c] > 0.0 {
                        u_max = u_max.min(gauge.albedo_max[obj][c] * w[c] / pc);
                    }
                    for &(gj, cj, (nc, dc)) in &gauge_parts {
                        if (gj, cj) == (gi, c) {
                            num += nc;
                            den += dc;
                        }
                    }
                }
            }
            let lo = gauge.u.0.min(u_max);
            let hi = u_max.max(lo);
            u = if den > 0.0 && num.is_finite() {
                (num / den).clamp(lo, hi)
            } else {
                lo
            };
            history.push(u);
            if round % 3 == 2 {
                let (u0, u1, u2) = (history[0], history[1], history[2]);
                let d2 = u2 - 2.0 * u1 + u0;
                if d2.abs() > 1e-12 * u2.abs() {
                    let x = u2 - (u2 - u1) * (u2 - u1) / d2;
                    if x.is_finite() {
                        u = x.clamp(lo, hi);
                    }
                }
                history.clear();
            }
            // a'_c = a + (u/g_c)·B_c and its normal-equation sums, every (group, channel) at once; then
            // each object's products given them, in group order.
            let (a_all, b_all) = (&*a_all, &*b_all);
            let lanes: Vec<(usize, usize, Option<[f64; 9]>)> = columns(ab_all, &lens, n_px)
                .into_par_iter()
                .map(|(gi, c, col)| {
                    let (g, o0) = (&self.groups[gi], offsets[gi]);
                    let n = col.len();
                    let k = if w[c] > 0.0 { (u / w[c]) as f32 } else { 0.0 };
                    for i in 0..n {
                        col[i] = a_all[o0 + i] + k * col[i];
                    }
                    let sums = match (&runs[gi], g.object) {
                        (Some(run), Some(_)) => {
                            let v = run.sky().unwrap_or(&no_sky[..n]);
                            let specular = run.is_specular();
                            // (without a lobe `b` is not read: any slice of the run's length serves)
                            let b = if specular { &b_all[o0..o0 + n] } else { v };
                            Some(environment_lane_sums::<AVX2>(
                                col, b, v, &g.ts[c], sat, specular,
                            ))
                        }
                        _ => None,
                    };
                    (gi, c, sums)
                })
                .collect();
            for (gi, g) in self.groups.iter().enumerate() {
                let (Some(run), Some(obj)) = (&runs[gi], g.object) else {
                    continue;
                };
                let mut sums = SolveSums::default();
                for &(gj, c, l) in &lanes {
                    if let (true, Some(l)) = (gj == gi, l) {
                        sums.add_lanes(c, l);
                    }
                }
                let (o0, n) = (offsets[gi], g.len());
                self.solve_into(run, obj, &sums, proj, out, &a_all[o0..o0 + n], sat);
            }
        }
        out.gauge = Some(u);
        // Pass 2: the loss at the products, every object's channel at once, added in group order.
        let solved = &*out;
        let ab_all = &*ab_all;
        let sums: Vec<f32> = (0..3 * self.groups.len())
            .into_par_iter()
            .map(|gc| {
                let (gi, c) = (gc / 3, gc % 3);
                let (g, o0, n) = (&self.groups[gi], offsets[gi], self.groups[gi].len());
                let Some(obj) = g.object else { return 0.0 };
                let gt = if E::ENCODES { &g.te } else { &g.t };
                let sky = proj.sky(obj, g);
                let pc = solved.products[obj][c] as f32;
                let ec = solved.environment.get(obj).map_or(0.0, |e| e[c]) as f32;
                let qw = (solved.specular[obj] * w[c]) as f32;
                let ac = &ab_all[c * n_px + o0..][..n];
                let mut sum = 0.0f32;
                for i in 0..n {
                    let mut v = pc * ac[i] + qw * b_all[o0 + i];
                    if let Some(sv) = sky {
                        v += ec * sv[i];
                    }
                    sum += self.norm.penalty(enc.any(v.min(top)) - gt[c][i]);
                }
                sum
            })
            .collect();
        let mut acc = [0.0f64; 3];
        for (gi, g) in self.groups.iter().enumerate() {
            let gt = if E::ENCODES { &g.te } else { &g.t };
            if g.object.is_none() {
                for s in 0..g.len() {
                    for c in 0..3 {
                        acc[c] += self.norm.penalty(gt[c][s]) as f64;
                    }
                }
                continue;
            }
            for c in 0..3 {
                acc[c] += sums[3 * gi + c] as f64;
            }
        }
        acc
    }

    /// [`Kernel::projected_bounce`] with the bounce held ([`Frozen`]): per object, its unit-light factors,
    /// a'_c = a + the held (u/g_c)·B_c, the products given a'_c and the loss at them. The sums are taken
    /// per run of [`CHUNK`] pixels and added in order, so the value is the same serial or spread over the
    /// pool (`c.parallel`, a polish's lone candidate) on any number of threads; serially the sum stops
    /// once it exceeds `c.bound` (as the direct kernel's).
    #[allow(clippy::too_many_arguments)]
    fn projected_held<const AVX2: bool, E: Encoding + Send + Sync>(
        &self,
        c: Candidate,
        proj: &Projection,
        frozen: &Frozen,
        runs: &[Option<Run>],
        out: &mut Solved,
        scratch: &mut [f32],
        enc: E,
    ) -> [f64; 3] {
        let n_px = self.pixels;
        let sat = if c.clip {
            self.saturated
        } else {
            f32::INFINITY
        };
        let top = if c.clip { 1.0 } else { f32::INFINITY };
        let w: [f64; 3] = std::array::from_fn(|c| proj.weight[c] as f64);
        let (a_all, rest) = scratch.split_at_mut(n_px);
        let (b_all, rest) = rest.split_at_mut(n_px);
        let (ar_all, rest) = rest.split_at_mut(n_px);
        let (ag_all, ab_all) = rest.split_at_mut(n_px);
        out.gauge = Some(frozen.u);
        // (on a pool of one thread the serial loop below is the same value, without the jobs' set-up)
        if c.parallel && rayon::current_num_threads() > 1 {
            let slices = [a_all, b_all, ar_all, ag_all, ab_all];
            return self.held_pooled::<AVX2, E>(proj, frozen, runs, out, slices, (sat, top), enc);
        }
        let mut acc = [0.0f64; 3];
        let mut o0 = 0;
        for (g, run) in self.groups.iter().zip(runs) {
            let n = g.len();
            let range = o0..o0 + n;
            o0 += n;
            let gt = if E::ENCODES { &g.te } else { &g.t };
            let (Some(run), Some(obj)) = (run, g.object) else {
                for s in 0..n {
                    for c in 0..3 {
                        acc[c] += self.norm.penalty(gt[c][s]) as f64;
                    }
                }
                continue;
            };
            let held: [&[f32]; 3] =
                std::array::from_fn(|ch| &frozen.bounce[ch * n_px + range.start..][..n]);
            let sky = run.sky();
            let specular = run.is_specular();
            // Pass 1, one run: the factors, a'_c, and the normal equations given a'_c.
            let pass1 = |k: usize, a: &mut [f32], b: &mut [f32], ap: [&mut [f32]; 3]| {
                let start = k * CHUNK;
                let len = a.len();
                simd::dispatch(
                    HeldRun {
                        run,
                        start,
                        e: a,
                        b,
                        held: std::array::from_fn(|ch| &held[ch][start..start + len]),
                        cols: ap,
                        ts: std::array::from_fn(|ch| &g.ts[ch][start..start + len]),
                        sky: sky.map(|v| &v[start..start + len]),
                        specular,
                        sat,
                    },
                    AVX2,
                )
            };
            let (a, b) = (&mut a_all[range.clone()], &mut b_all[range.clone()]);
            let (ar, ag, ab) = (
                &mut ar_all[range.clone()],
                &mut ag_all[range.clone()],
                &mut ab_all[range.clone()],
            );
            let parts: Vec<SolveSums> = a
                .chunks_mut(CHUNK)
                .zip(b.chunks_mut(CHUNK))
                .zip(ar.chunks_mut(CHUNK))
                .zip(ag.chunks_mut(CHUNK))
                .zip(ab.chunks_mut(CHUNK))
                .enumerate()
                .map(|(k, ((((a, b), r), gg), bb))| pass1(k, a, b, [r, gg, bb]))
                .collect();
            let mut sums = SolveSums::default();
            for part in &parts {
                sums.add(part);
            }
            self.solve_into(run, obj, &sums, proj, out, &a_all[range.clone()], sat);
            // Pass 2, one run: the loss at the products.
            let pc: [f32; 3] = std::array::from_fn(|ch| out.products[obj][ch] as f32);
            let ec: [f32; 3] =
                std::array::from_fn(|ch| out.environment.get(obj).map_or(0.0, |e| e[ch]) as f32);
            let qw: [f32; 3] = std::array::from_fn(|ch| (out.specular[obj] * w[ch]) as f32);
            let sky = proj.sky(obj, g);
            let (b, cols) = (
                &b_all[range.clone()],
                [
                    &ar_all[range.clone()],
                    &ag_all[range.clone()],
                    &ab_all[range.clone()],
                ],
            );
            let pass2 = |k: usize| {
                let r = k * CHUNK..((k + 1) * CHUNK).min(n);
                simd::dispatch(
                    HeldLoss {
                        cols: std::array::from_fn(|ch| &cols[ch][r.clone()]),
                        b: &b[r.clone()],
                        sky: sky.map(|v| &v[r.clone()]),
                        t: std::array::from_fn(|ch| &gt[ch][r.clone()]),
                        pc,
                        qw,
                        ec,
                        top,
                        norm: self.norm,
                        enc,
                    },
                    AVX2,
                )
            };
            for k in 0..n.div_ceil(CHUNK) {
                let part = pass2(k);
                for ch in 0..3 {
                    acc[ch] += part[ch];
                }
                if acc[0] + acc[1] + acc[2] > c.bound {
                    return acc;
                }
            }
        }
        acc
    }

    /// [`Kernel::projected_held`] for one candidate over the pool (`c.parallel`): pass 1 over the runs of
    /// [`CHUNK`] pixels of every object at once, each object's products from its runs' sums added in
    /// order, pass 2 over every object's runs at once, the losses added per object in run order and the
    /// objects in group order: the serial value bit for bit, in two joins per candidate (not two per
    /// object). `slices`: the scratch's a, b, a'_r, a'_g and a'_b.
    #[allow(clippy::too_many_arguments)]
    fn held_pooled<const AVX2: bool, E: Encoding + Send + Sync>(
        &self,
        proj: &Projection,
        frozen: &Frozen,
        runs: &[Option<Run>],
        out: &mut Solved,
        slices: [&mut [f32]; 5],
        (sat, top): (f32, f32),
        enc: E,
    ) -> [f64; 3] {
        fn take<'a>(rest: &mut &'a mut [f32], n: usize) -> &'a mut [f32] {
            let (head, tail) = std::mem::take(rest).split_at_mut(n);
            *rest = tail;
            head
        }
        let n_px = self.pixels;
        let w: [f64; 3] = std::array::from_fn(|c| proj.weight[c] as f64);
        let [a_all, b_all, ar_all, ag_all, ab_all] = slices;
        // Pass 1: (group, run) jobs over disjoint slices of the factors and columns.
        let mut jobs: Vec<(usize, HeldRun)> = Vec::new();
        let mut rest = [
            &mut *a_all,
            &mut *b_all,
            &mut *ar_all,
            &mut *ag_all,
            &mut *ab_all,
        ];
        let mut o0 = 0;
        for (gi, (g, run)) in self.groups.iter().zip(runs).enumerate() {
            let n = g.len();
            let [a, b, ar, ag, ab] = rest.each_mut().map(|r| take(r, n));
            let range = o0..o0 + n;
            o0 += n;
            let (Some(run), Some(_)) = (run, g.object) else {
                continue;
            };
            let (sky, specular) = (run.sky(), run.is_specular());
            let chunks = a
                .chunks_mut(CHUNK)
                .zip(b.chunks_mut(CHUNK))
                .zip(ar.chunks_mut(CHUNK))
                .zip(ag.chunks_mut(CHUNK))
                .zip(ab.chunks_mut(CHUNK))
                .enumerate();
            for (k, ((((e, b), r), gg), bb)) in chunks {
                let (start, len) = (k * CHUNK, e.len());
                let at = start..start + len;
                jobs.push((
                    gi,
                    HeldRun {
                        run,
                        start,
                        e,
                        b,
                        held: std::array::from_fn(|ch| {
                            &frozen.bounce[ch * n_px + range.start..][at.clone()]
                        }),
                        cols: [r, gg, bb],
                        ts: std::array::from_fn(|ch| &g.ts[ch][at.clone()]),
                        sky: sky.map(|v| &v[at.clone()]),
                        specular,
                        sat,
                    },
                ));
            }
        }
        let sums: Vec<(usize, SolveSums)> = jobs
            .into_par_iter()
            .map(|(gi, job)| (gi, simd::dispatch(job, AVX2)))
            .collect();
        let mut o0 = 0;
        for (gi, (g, run)) in self.groups.iter().zip(runs).enumerate() {
            let range = o0..o0 + g.len();
            o0 += g.len();
            let (Some(run), Some(obj)) = (run, g.object) else {
                continue;
            };
            let mut total = SolveSums::default();
            for (_, part) in sums.iter().filter(|(gj, _)| *gj == gi) {
                total.add(part);
            }
            self.solve_into(run, obj, &total, proj, out, &a_all[range], sat);
        }
        // Pass 2: the loss of every (group, run) at its object's products.
        let (b_all, cols_all) = (&*b_all, [&*ar_all, &*ag_all, &*ab_all]);
        let mut jobs: Vec<(usize, HeldLoss<E>)> = Vec::new();
        let mut o0 = 0;
        for (gi, (g, run)) in self.groups.iter().zip(runs).enumerate() {
            let (n, start) = (g.len(), o0);
            o0 += n;
            let (Some(_), Some(obj)) = (run, g.object) else {
                continue;
            };
            let gt = if E::ENCODES { &g.te } else { &g.t };
            let pc: [f32; 3] = std::array::from_fn(|ch| out.products[obj][ch] as f32);
            let ec: [f32; 3] =
                std::array::from_fn(|ch| out.environment.get(obj).map_or(0.0, |e| e[ch]) as f32);
            let qw: [f32; 3] = std::array::from_fn(|ch| (out.specular[obj] * w[ch]) as f32);
            let sky = proj.sky(obj, g);
            for k in 0..n.div_ceil(CHUNK) {
                let r = k * CHUNK..((k + 1) * CHUNK).min(n);
                let at = start + r.start..start + r.end;
                jobs.push((
                    gi,
                    HeldLoss {
                        cols: std::array::from_fn(|ch| &cols_all[ch][at.clone()]),
                        b: &b_all[at.clone()],
                        sky: sky.map(|v| &v[r.clone()]),
                        t: std::array::from_fn(|ch| &gt[ch][r.clone()]),
                        pc,
                        qw,
                        ec,
                        top,
                        norm: self.norm,
                        enc,
                    },
                ));
            }
        }
        let losses: Vec<(usize, [f64; 3])> = jobs
            .into_par_iter()
            .map(|(gi, job)| (gi, simd::dispatch(job, AVX2)))
            .collect();
        // The sums in the serial order: groups in order, an object's runs in order.
        let mut acc = [0.0f64; 3];
        for (gi, (g, run)) in self.groups.iter().zip(runs).enumerate() {
            if let (Some(_), Some(_)) = (run, g.object) {
                for (_, part) in losses.iter().filter(|(gj, _)| *gj == gi) {
                    for ch in 0..3 {
                        acc[ch] += part[ch];
                    }
                }
            } else {
                let gt = if E::ENCODES { &g.te } else { &g.t };
                for s in 0..g.len() {
                    for ch in 0..3 {
                        acc[ch] += self.norm.penalty(gt[ch][s]) as f64;
                    }
                }
            }
        }
        acc
    }

    /// One object's products from its sums into `out` (with its environment column if it has one).
    #[allow(clippy::too_many_arguments)]
    fn solve_into(
        &self,
        run: &Run,
        obj: usize,
        sums: &SolveSums,
        proj: &Projection,
        out: &mut Solved,
        e_unit: &[f32],
        sat: f32,
    ) {
        let g = run.group();
        let qb = if run.is_specular() {
            proj.specular[obj]
        } else {
            (0.0, 0.0)
        };
        let fallback = |c: usize| fallback_sums(e_unit, &g.t[c], sat);
        if run.sky().is_some() {
            let (pk, q, ek) = solve_object_env(
                sums,
                proj.weight,
                &proj.diffuse[obj],
                qb,
                &proj.environment[obj],
                fallback,
            );
            out.products[obj] = pk;
            out.specular[obj] = q;
            out.environment[obj] = ek;
        } else {
            let (pk, q) = solve_object(sums, proj.weight, &proj.diffuse[obj], qb, fallback);
            out.products[obj] = pk;
            out.specular[obj] = q;
        }
    }
}

/// Pass 1 of [`Kernel::projected_held`] over one run, for [`simd::dispatch`]: the unit-light factors
/// (`e`, `b`), the diffuse columns a'_c = e + held_c (`cols`) and the normal-equation sums given them,
/// taken in `SUM_LANES` partial sums.
struct HeldRun<'a, 'r> {
    run: &'a Run<'r>,
    start: usize,
    e: &'a mut [f32],
    b: &'a mut [f32],
    held: [&'a [f32]; 3],
    cols: [&'a mut [f32]; 3],
    ts: [&'a [f32]; 3],
    sky: Option<&'a [f32]>,
    specular: bool,
    sat: f32,
}

impl Simd for HeldRun<'_, '_> {
    type Output = SolveSums;
    #[inline(always)]
    fn run<const AVX2: bool>(self) -> SolveSums {
        let HeldRun {
            run,
            start,
            e,
            b,
            held,
            cols,
            ts,
            sky,
            specular,
            sat,
        } = self;
        run.factors::<AVX2>(start, e, b);
        let n = e.len();
        let full = n - n % SUM_LANES;
        let zeros = [0.0f32; CHUNK];
        let mut sums = SolveSums::default();
        for (ch, col) in cols.into_iter().enumerate() {
            let (h, t) = (&held[ch][..n], &ts[ch][..n]);
            for i in 0..n {
                col[i] = e[i] + h[i];
            }
            let col = &col[..n];
            if sky.is_none() && !specular {
                // Σ a'², Σ y·a' over the informing pixels (t < sat), SUM_LANES at a time.
                let (mut aa, mut ya) = ([0.0f64; SUM_LANES], [0.0f64; SUM_LANES]);
                let mut i = 0;
                while i < full {
                    for l in 0..SUM_LANES {
                        let on = t[i + l] < sat;
                        let a = if on { col[i + l] as f64 } else { 0.0 };
                        let y = if on { t[i + l] as f64 } else { 0.0 };
                        aa[l] += a * a;
                        ya[l] += y * a;
                    }
                    i += SUM_LANES;
                }
                for (l, i) in (full..n).enumerate() {
                    let on = t[i] < sat;
                    let a = if on { col[i] as f64 } else { 0.0 };
                    let y = if on { t[i] as f64 } else { 0.0 };
                    aa[l] += a * a;
                    ya[l] += y * a;
                }
                sums.saa[ch] += (aa[0] + aa[1]) + (aa[2] + aa[3]);
                sums.sya[ch] += (ya[0] + ya[1]) + (ya[2] + ya[3]);
            } else {
                let v = sky.map_or(&zeros[..n], |v| &v[..n]);
                let bb: &[f32] = if specular { &b[..n] } else { v }; // not read without a lobe
                                                                     // the nine sums of `SolveSums::add_environment`, SUM_LANES at a time
                sums.add_lanes(
                    ch,
                    environment_lane_sums::<AVX2>(col, bb, v, t, sat, specular),
                );
            }
        }
        sums
    }
}

/// Pass 2 of [`Kernel::projected_held`] over one run, for [`simd::dispatch`]: per channel
/// Σ penalty(enc(min(P_c·a'_c + Q·w_c·b + E_c·v, top)) - t_c), in `LANES` partial sums.
/// Also the plain closed form's pass 2 where an object has an environment column or a lobe (`cols` its
/// unit-light factor thrice).
pub(crate) struct HeldLoss<'a, E> {
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

impl<E: Encoding> HeldLoss<'_, E> {
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

impl<E: Encoding> Simd for HeldLoss<'_, E> {
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

/// One gather for one candidate, summed per receiving pixel: Σ form·e (the unit light the sender's points
/// get) and Σ form·S (their sky view), and for a sphere sender the (pixel, table point, Σ form) of its
/// table lookups; a round of the fixed point then costs per pixel, not per point.
struct Compact {
    pixels: Vec<u32>,
    a: Vec<f32>,
    s: Vec<f32>,
    table: Vec<(u32, u32, f32)>,
}

impl Compact {
    fn new(gth: &super::pixels::Gather, e: &[f32]) -> Compact {
        let sky = &gth.points.sky;
        let mut c = Compact {
            pixels: Vec::new(),
            a: Vec::new(),
            s: Vec::new(),
            table: Vec::new(),
        };
        for (j, &i) in gth.pixel.iter().enumerate() {
            // The gather's points come in pixel order: a new pixel starts a new entry.
            if c.pixels.last() != Some(&i) {
                c.pixels.push(i);
                c.a.push(0.0);
                c.s.push(0.0);
            }
            let k = c.pixels.len() - 1;
            let f = gth.form[j];
            c.a[k] += f * e[j];
            if !sky.is_empty() {
                c.s[k] += f * sky[j];
            }
            if let Some(&t) = gth.table.get(j) {
                match c.table.last_mut() {
                    Some(last) if last.0 == k as u32 && last.1 == t => last.2 += f,
                    _ => c.table.push((k as u32, t, f)),
                }
            }
        }
        c
    }
}

/// One receiving gather's lookups into a sphere sender's table, summed per receiving pixel for one of the
/// table's own senders: Σ form·e and Σ form·S over the table points each pixel looks up.
struct Fold {
    sender: usize,
    a: Vec<f32>,
    s: Vec<f32>,
}

impl Fold {
    /// Per table sender (`table_gathers[m]`, lit as `table_light[m]`), the folded lookups of `cg`; none
    /// for a plane sender (no table) or a gather with no lookups.
    fn of(
        cg: &Compact,
        table_gathers: &[super::pixels::Gather],
        table_light: &[Compact],
    ) -> Vec<Fold> {
        if cg.table.is_empty() {
            return Vec::new();
        }
        table_gathers
            .iter()
            .zip(table_light)
            .map(|(gth, tl)| {
                let (mut at, mut st) = (
                    vec![0.0f32; crate::render::bounce::TABLE],
                    vec![0.0f32; crate::render::bounce::TABLE],
                );
                for (j, &t) in tl.pixels.iter().enumerate() {
                    at[t as usize] += tl.a[j];
                    st[t as usize] += tl.s[j];
                }
                let mut fold = Fold {
                    sender: gth.sender,
                    a: vec![0.0; cg.pixels.len()],
                    s: vec![0.0; cg.pixels.len()],
                };
                for &(j, t, f) in &cg.table {
                    fold.a[j as usize] += f * at[t as usize];
                    fold.s[j as usize] += f * st[t as usize];
                }
                fold
            })
            .collect()
    }
}
