//! The per-object least squares of the closed form: the normal-equation sums a pixel pass gathers
//! (`SolveSums`), and the products from them within their bounds (`solve_object`, with an environment
//! column `solve_object_env`, the 2 x 2 box least squares `box_ls2`).

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

/// The partial sums of a run's normal equations (f64 each).
pub(crate) const SUM_LANES: usize = 4;

/// The nine sums of [`SolveSums::add_environment`] over one run (`col` the diffuse factor, `b` the
/// specular factor, `v` the sky view, `t` the objective; pixels at or above `sat` left out), `SUM_LANES` at
/// a time in f64 (their order fixed: the same values on any machine and either path), in the order saa,
/// sab, sbb, sya, syb, sav, svv, syv, svb. `specular` false: `b` is all 0 and its four sums are 0 (not
/// summed). With `AVX2` the whole runs of four go through `environment_lanes_avx2`.
#[inline(always)]
pub(crate) fn environment_lane_sums<const AVX2: bool>(
    col: &[f32],
    b: &[f32],
    v: &[f32],
    t: &[f32],
    sat: f32,
    specular: bool,
) -> [f64; 9] {
    let n = col.len();
    let (b, v, t) = (&b[..n], &v[..n], &t[..n]);
    let full = n - n % SUM_LANES;
    let mut s = [[0.0f64; SUM_LANES]; 9];
    let mut i = 0;
    #[cfg(target_arch = "x86_64")]
    if AVX2 {
        // SAFETY: `AVX2` is only true on the path dispatched after checking the CPU's features.
        s = unsafe { environment_lanes_avx2([&col[..full], b, v, t], sat, specular) };
        i = full;
    }
    let mut add = |l: usize, i: usize| {
        let on = t[i] < sat;
        let a = if on { col[i] as f64 } else { 0.0 };
        let y = if on { t[i] as f64 } else { 0.0 };
        let vi = if on { v[i] as f64 } else { 0.0 };
        let bi = if on { b[i] as f64 } else { 0.0 };
        s[0][l] += a * a;
        s[3][l] += y * a;
        s[5][l] += a * vi;
        s[6][l] += vi * vi;
        s[7][l] += y * vi;
        if specular {
            s[1][l] += a * bi;
            s[2][l] += bi * bi;
            s[4][l] += y * bi;
            s[8][l] += vi * bi;
        }
    };
    while i < full {
        for l in 0..SUM_LANES {
            add(l, i + l);
        }
        i += SUM_LANES;
    }
    for (l, i) in (full..n).enumerate() {
        add(l, i);
    }
    std::array::from_fn(|k| (s[k][0] + s[k][1]) + (s[k][2] + s[k][3]))
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

    /// Channel `c`'s nine sums of one run ([`environment_lane_sums`]) added in.
    #[inline(always)]
    pub(crate) fn add_lanes(&mut self, c: usize, s: [f64; 9]) {
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

    /// Every sum of channel `c` over one run with an environment column: factors `a`, `b` (zero for a
    /// matte object), sky view `v`, objective `t` (pixels at or above `sat` left out), one pixel after
    /// another: the reference the tests hold [`environment_lane_sums`] to (the kernels use that).
    #[cfg(test)]
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
        self.add_lanes(c, s);
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
/// more. A channel with no lit informing pixel takes P_c from `fallback(c)` and E_c = Σyv / Σvv within
/// its bounds (its lower bound when no pixel informs at all).
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
                // No lit informing pixel (a = 0 on all of them): E_c alone fits them, Σyv / Σvv.
                let (a, b, sat_min) = fallback(c);
                let ec = s.syv[c] / s.svv[c];
                let ec = if ec.is_finite() {
                    ec.clamp(eb[c].0, eb[c].1)
                } else {
                    eb[c].0
                };
                (p[c], e[c]) = (closed_form(a, b, sat_min, pb[c]), ec);
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
    fn environment_lane_sums_are_the_nine_sums_on_either_path() {
        // 203 pixels (not a multiple of the lanes), some saturated or excluded (t = +inf)
        let mut rng = Lcg(11);
        let n = 203;
        let mut draw =
            |scale: f64| -> Vec<f32> { (0..n).map(|_| (rng.next() * scale) as f32).collect() };
        let (a, b, v) = (draw(2.0), draw(0.5), draw(1.0));
        let mut t = draw(1.1);
        t[5] = f32::INFINITY;
        let sat = 1.0;
        let mut seq = SolveSums::default();
        seq.add_environment(1, &a, Some(&b), &v, &t, sat);
        let want = [
            seq.saa[1], seq.sab[1], seq.sbb[1], seq.sya[1], seq.syb[1], seq.sav[1], seq.svv[1],
            seq.syv[1], seq.svb[1],
        ];
        let scalar = environment_lane_sums::<false>(&a, &b, &v, &t, sat, true);
        for (k, (&x, &w)) in scalar.iter().zip(&want).enumerate() {
            assert!(
                (x - w).abs() <= 1e-12 * w.abs().max(1e-300),
                "sum {k}: {x} vs {w}"
            );
        }
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx2") && std::arch::is_x86_feature_detected!("fma")
        {
            assert_eq!(
                environment_lane_sums::<true>(&a, &b, &v, &t, sat, true),
                scalar,
                "bit for bit"
            );
            let zeros = vec![0.0f32; n];
            assert_eq!(
                environment_lane_sums::<true>(&a, &zeros, &v, &t, sat, false),
                environment_lane_sums::<false>(&a, &zeros, &v, &t, sat, true)
            );
        }
        // matte: the lobe's four sums stay 0, the others are those with b = 0
        let matte = environment_lane_sums::<false>(&a, &b, &v, &t, sat, false);
        assert_eq!([matte[1], matte[2], matte[4], matte[8]], [0.0; 4]);
        assert_eq!(
            [matte[0], matte[3], matte[5], matte[6], matte[7]],
            [scalar[0], scalar[3], scalar[5], scalar[6], scalar[7]]
        );
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

    #[test]
    fn an_object_in_shadow_gets_its_environment_product() {
        // Every informing pixel unlit (a = 0): y = E v determines E; P is the fallback's (was: E at 0).
        let v: Vec<f32> = (0..6).map(|i| 0.4 + 0.1 * i as f32).collect();
        let (a, e) = (vec![0.0f32; 6], [0.03, 0.05, 0.02]);
        let mut s = SolveSums::default();
        for c in 0..3 {
            let y: Vec<f32> = v.iter().map(|&vi| (e[c] * vi as f64) as f32).collect();
            s.add_environment(c, &a, None, &v, &y, f32::INFINITY);
        }
        let wide = [(0.0, 10.0); 3];
        let (pk, _, ek) =
            solve_object_env(&s, [1.0; 3], &wide, (0.0, 0.0), &wide, |_| (0.0, 0.0, 0.0));
        for c in 0..3 {
            assert!(
                (ek[c] - e[c]).abs() < 1e-7 * e[c] && pk[c] == 0.0,
                "{pk:?} {ek:?}"
            );
        }
        // No informing pixel at all: E at its lower bound.
        let lo = [(0.01, 10.0); 3];
        let (_, _, ek) = solve_object_env(
            &SolveSums::default(),
            [1.0; 3],
            &wide,
            (0.0, 0.0),
            &lo,
            |_| (0.0, 0.0, 0.0),
        );
        assert_eq!(ek, [0.01; 3]);
    }
}

/// The lane sums of [`environment_lane_sums`] (its `col`, `b`, `v` and `t` in that order) over whole runs of `SUM_LANES` (4) pixels, in f64, each
/// lane and each sum the scalar loop's operations in its order (so the same values); with `specular` false
/// the lobe's four sums (whose factor is 0) are left at 0.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
#[inline]
pub(crate) unsafe fn environment_lanes_avx2(
    [col, b, v, t]: [&[f32]; 4],
    sat: f32,
    specular: bool,
) -> [[f64; 4]; 9] {
    use std::arch::x86_64::*;
    let mut s = [_mm256_setzero_pd(); 9];
    let satv = _mm_set1_ps(sat);
    let n = col.len() - col.len() % 4;
    let mut i = 0;
    while i < n {
        let y = _mm_loadu_ps(t[i..i + 4].as_ptr());
        // Where t >= sat (or t = +inf) every value becomes 0, as the scalar select.
        let keep = _mm_cmplt_ps(y, satv);
        let a = _mm256_cvtps_pd(_mm_and_ps(_mm_loadu_ps(col[i..i + 4].as_ptr()), keep));
        let yv = _mm256_cvtps_pd(_mm_and_ps(y, keep));
        let vv = _mm256_cvtps_pd(_mm_and_ps(_mm_loadu_ps(v[i..i + 4].as_ptr()), keep));
        s[0] = _mm256_add_pd(s[0], _mm256_mul_pd(a, a));
        s[3] = _mm256_add_pd(s[3], _mm256_mul_pd(yv, a));
        s[5] = _mm256_add_pd(s[5], _mm256_mul_pd(a, vv));
        s[6] = _mm256_add_pd(s[6], _mm256_mul_pd(vv, vv));
        s[7] = _mm256_add_pd(s[7], _mm256_mul_pd(yv, vv));
        if specular {
            let bv = _mm256_cvtps_pd(_mm_and_ps(_mm_loadu_ps(b[i..i + 4].as_ptr()), keep));
            s[1] = _mm256_add_pd(s[1], _mm256_mul_pd(a, bv));
            s[2] = _mm256_add_pd(s[2], _mm256_mul_pd(bv, bv));
            s[4] = _mm256_add_pd(s[4], _mm256_mul_pd(yv, bv));
            s[8] = _mm256_add_pd(s[8], _mm256_mul_pd(vv, bv));
        }
        i += 4;
    }
    let mut out = [[0.0f64; 4]; 9];
    for (o, v) in out.iter_mut().zip(s) {
        _mm256_storeu_pd(o.as_mut_ptr(), v);
    }
    out
}
