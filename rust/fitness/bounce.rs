//! The closed form with one diffuse bounce between the objects (`render::bounce`).
//!
//! With interreflection a pixel of object o is, per channel c,
//!   y = P_o,c·(a + (u/g_c)·B_o,c) + E_o,c·v + Q_o·w_c·b,   B_o,c = Σ_k F_k·(P_k,c·a_k(y_k) + E_k,c·S(y_k)),
//! where the bounce B is gathered from the senders' products at their representative points, g_c =
//! exposure x colour_c, and u = 1 / intensity: the receiver's albedo ρ = P·u/g_c enters absolutely (a
//! bounce is as bright as the albedos are, not only their products with the light). The solve is a fixed
//! point: the products without the bounce, then twice the gauge u (least squares given the products, inside
//! the intensity's and the albedos' bounds) and the products given u. Pass 2 is the loss at the result.
//! The full fixed point runs without early exit (a fit solves it only where a pass starts and ends), over
//! the pool; the search's candidates, with the bounce held ([`Frozen`], `held`), are spread over the pool
//! for a lone candidate and stop early above their bound, as direct candidates do.

use super::held::Frozen;
use super::kernel::{Candidate, Kernel};
use super::loss::{Encoding, Identity, Space, SrgbLut};
use super::pixels::{Light, BLOCK};
use super::projected::{Gauge, Projection, Solved};
use super::simd::{self, Simd};
use super::solve::{environment_lane_sums, SolveSums};
use rayon::prelude::*;

/// [`Kernel::projected`] for [`simd::dispatch`], one build per encoding.
struct Projected<'a, E> {
    k: &'a Kernel,
    c: Candidate<'a>,
    proj: &'a Projection,
    mode: &'a Mode,
    out: &'a mut Solved,
    s: &'a mut Vec<f32>,
    enc: E,
}

impl<E: Encoding + Send + Sync> Simd for Projected<'_, E> {
    type Output = [f64; 3];
    #[inline(always)]
    fn run<const AVX2: bool>(self) -> [f64; 3] {
        let (k, proj) = (self.k, self.proj);
        match &proj.gauge {
            Some(gauge) => k.projected_bounce::<AVX2, E>(
                self.c, proj, gauge, self.mode, self.out, self.s, self.enc,
            ),
            None => k.projected_direct::<AVX2, E>(self.c, proj, self.out, self.s, self.enc),
        }
    }
}

/// How the bounce is solved per candidate: the fixed point's rounds of (gauge, products) after the
/// bounce-free solve ([`SEARCH_ROUNDS`] while the search ranks lights, [`FINAL_ROUNDS`] for the reported
/// products), or the bounce held ([`Frozen`]) while the search ranks lights.
#[derive(Clone, Debug)]
pub struct Mode {
    pub rounds: usize,
    /// The bounce held while the search ranks lights; `None`: solved per candidate.
    pub frozen: Option<std::sync::Arc<Frozen>>,
}

impl Mode {
    /// The search's fixed point, solved per candidate.
    pub const SEARCH: Mode = Mode {
        rounds: SEARCH_ROUNDS,
        frozen: None,
    };
    /// The full fixed point (what a fit reports), solved per candidate.
    pub const FULL: Mode = Mode {
        rounds: FINAL_ROUNDS,
        frozen: None,
    };
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
    /// The closed form for candidate `c`: per object the products within `proj`'s bounds and the
    /// per-channel loss at them ([`Kernel::projected_direct`]); with the bounce (`proj.gauge` set) as
    /// `mode` says ([`Kernel::projected_bounce`]). `scratch` holds the per-pixel factors between the
    /// passes.
    pub fn projected(
        &self,
        c: Candidate,
        proj: &Projection,
        mode: &Mode,
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
                    mode,
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
                        mode,
                        out,
                        s,
                        enc,
                    },
                    avx2,
                )
            }
        }
    }

    /// The closed form with the bounce (`proj.gauge` set). `scratch` ends as
    /// [a | b | a'_r | a'_g | a'_b] per pixel: unit-light diffuse and specular factors, and the diffuse
    /// columns with the bounce folded in, which [`Kernel::refine`] uses.
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn projected_bounce<const AVX2: bool, E: Encoding + Send + Sync>(
        &self,
        c: Candidate,
        proj: &Projection,
        gauge: &Gauge,
        mode: &Mode,
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
        let runs = self.runs(&light, p, proj, (sat, top));
        if let Some(f) = &mode.frozen {
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
                    .map(|gth| Compact::lit::<AVX2>(gth, &light, c.parallel))
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
            self.solve_run(run, obj, &sums, proj, out, &a_all[o0..o0 + n], sat);
        }
        // Each sphere's table points: their senders' light (unit light), for the second bounce.
        let table_light: Vec<Vec<Compact>> = self
            .tables
            .iter()
            .map(|gths| {
                gths.iter()
                    .map(|gth| Compact::lit::<AVX2>(gth, &light, c.parallel))
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
        for round in 0..mode.rounds {
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
                        let ek = solved.environment_at(gth.sender, c) as f32;
                        add_terms(col, &cg.pixels, (pk, &cg.a), (ek, &cg.s));
                        // The sender's own bounce: its albedo P_k·u/g_c times the light on its table.
                        let second = (u / w[c]) as f32 * pk;
                        for fold in folds {
                            let pt = second * solved.products[fold.sender][c] as f32;
                            let et = second * solved.environment_at(fold.sender, c) as f32;
                            add_terms(col, &cg.pixels, (pt, &fold.a), (et, &fold.s));
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
                            solved.environment_at(obj, c),
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
                self.solve_run(run, obj, &sums, proj, out, &a_all[o0..o0 + n], sat);
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
                let ec = solved.environment_at(obj, c) as f32;
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
}

/// Adds p·a[j] + e·s[j] to `col` at each receiving pixel `pixels[j]`, for `(p, a)` and `(e, s)`.
#[inline(always)]
fn add_terms(col: &mut [f32], pixels: &[u32], (p, a): (f32, &[f32]), (e, s): (f32, &[f32])) {
    for (j, &i) in pixels.iter().enumerate() {
        col[i as usize] += p * a[j] + e * s[j];
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
    /// [`Compact::new`] of `gth` with the unit light `light` gives its points (`Gather::light`).
    fn lit<const AVX2: bool>(
        gth: &super::pixels::Gather,
        light: &Light,
        parallel: bool,
    ) -> Compact {
        let mut e = Vec::new();
        gth.light::<AVX2>(light, &mut e, parallel);
        Compact::new(gth, &e)
    }

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

/// The gauge bounds of the bounce from the scene's fit section: u = 1/intensity over the intensity's
/// bounds (its value when fixed), and each object's largest albedo (its value when fixed).
pub(crate) fn gauge_bounds(scene: &crate::scene::Scene) -> super::projected::Gauge {
    let bounds = |t: crate::params::Target| scene.fit.iter().find(|f| f.target == t);
    let (ilo, ihi) = match bounds(crate::params::Target::LightIntensity) {
        Some(f) => (f.min[0], f.max[0]),
        None => (scene.light.intensity, scene.light.intensity),
    };
    let inv = |i: f64| if i > 0.0 { 1.0 / i } else { f64::MAX };
    super::projected::Gauge {
        u: (inv(ihi), inv(ilo)),
        albedo_max: (0..scene.objects.len())
            .map(|k| match bounds(crate::params::Target::Albedo(k)) {
                Some(f) => [f.max[0], f.max[1], f.max[2]],
                None => scene.objects[k].material.albedo,
            })
            .collect(),
    }
}
