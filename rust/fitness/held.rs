//! Candidates with the bounce held ([`Frozen`]): a direct candidate's unit-light factors, the held bounce
//! folded into its diffuse column, its products and its loss (`bounce` solves the full fixed point that
//! is held).

use super::kernel::{Candidate, Kernel};
use super::loss::Encoding;
use super::projected::{ColumnsLoss, Projection, Run, Solved, CHUNK};
use super::simd::{self, Simd};
use super::solve::{environment_lane_sums, SolveSums, SUM_LANES};
use rayon::prelude::*;

/// The bounce solved once, at a reference candidate (the full fixed point, `bounce::FINAL_ROUNDS`), and held:
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

impl Kernel {
    /// [`Kernel::projected_bounce`] with the bounce held ([`Frozen`]): per object, its unit-light factors,
    /// a'_c = a + the held (u/g_c)·B_c, the products given a'_c and the loss at them. The sums are taken
    /// per run of [`CHUNK`] pixels and added in order, so the value is the same serial or spread over the
    /// pool (`c.parallel`, a polish's lone candidate) on any number of threads; serially the sum stops
    /// once it exceeds `c.bound` (as the direct kernel's).
    #[allow(clippy::too_many_arguments)]
    pub(super) fn projected_held<const AVX2: bool, E: Encoding + Send + Sync>(
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
        let (a_all, rest) = scratch.split_at_mut(n_px);
        let (b_all, rest) = rest.split_at_mut(n_px);
        let (ar_all, rest) = rest.split_at_mut(n_px);
        let (ag_all, ab_all) = rest.split_at_mut(n_px);
        out.gauge = Some(frozen.u);
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
            // Pass 1 over the run's chunks: on the pool (`par_chunks_mut`) or in order (`chunks_mut`).
            macro_rules! pass1_over {
                ($chunks:ident) => {
                    a.$chunks(CHUNK)
                        .zip(b.$chunks(CHUNK))
                        .zip(ar.$chunks(CHUNK))
                        .zip(ag.$chunks(CHUNK))
                        .zip(ab.$chunks(CHUNK))
                        .enumerate()
                        .map(|(k, ((((a, b), r), gg), bb))| pass1(k, a, b, [r, gg, bb]))
                        .collect()
                };
            }
            let parts: Vec<SolveSums> = if c.parallel {
                pass1_over!(par_chunks_mut)
            } else {
                pass1_over!(chunks_mut)
            };
            let mut sums = SolveSums::default();
            for part in &parts {
                sums.add(part);
            }
            self.solve_run(run, obj, &sums, proj, out, &a_all[range.clone()], sat);
            // Pass 2, one run: the loss at the products.
            let cols = [&*ar_all, &*ag_all, &*ab_all];
            let pass2 = |k: usize| {
                let r = k * CHUNK..((k + 1) * CHUNK).min(n);
                let job =
                    self.held_loss(g, obj, range.start, r, (b_all, cols), proj, out, top, enc);
                simd::dispatch(job, AVX2)
            };
            let runs_n = n.div_ceil(CHUNK);
            if c.parallel {
                let parts: Vec<[f64; 3]> = (0..runs_n).into_par_iter().map(pass2).collect();
                for part in &parts {
                    for ch in 0..3 {
                        acc[ch] += part[ch];
                    }
                }
            } else {
                for k in 0..runs_n {
                    let part = pass2(k);
                    for ch in 0..3 {
                        acc[ch] += part[ch];
                    }
                    if acc[0] + acc[1] + acc[2] > c.bound {
                        return acc;
                    }
                }
            }
        }
        acc
    }

    /// Pass 2 of [`Kernel::projected_held`] over pixels `r` of group `g` (object `obj`), whose pixels start
    /// at `o0` in the scratch's `b` and a'_c columns (`scratch`), at the products `out` holds for it.
    #[allow(clippy::too_many_arguments)]
    fn held_loss<'a, E: Encoding>(
        &self,
        g: &'a super::pixels::Group,
        obj: usize,
        o0: usize,
        r: std::ops::Range<usize>,
        (b_all, cols): (&'a [f32], [&'a [f32]; 3]),
        proj: &'a Projection,
        out: &Solved,
        top: f32,
        enc: E,
    ) -> ColumnsLoss<'a, E> {
        let at = o0 + r.start..o0 + r.end;
        let gt = if E::ENCODES { &g.te } else { &g.t };
        let w = |ch: usize| proj.weight[ch] as f64;
        ColumnsLoss {
            cols: std::array::from_fn(|ch| &cols[ch][at.clone()]),
            b: &b_all[at.clone()],
            sky: proj.sky(obj, g).map(|v| &v[r.clone()]),
            t: std::array::from_fn(|ch| &gt[ch][r.clone()]),
            pc: std::array::from_fn(|ch| out.products[obj][ch] as f32),
            qw: std::array::from_fn(|ch| (out.specular[obj] * w(ch)) as f32),
            ec: std::array::from_fn(|ch| out.environment_at(obj, ch) as f32),
            top,
            norm: self.norm,
            enc,
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
