//! The one-dimensional minimisers of [`super::kernel::Kernel::refine`]: the exact L1 line minimum over a
//! coefficient (the weighted median of the pixels' break points) and the sRGB-encoded line minimum (a
//! branch-and-bound over intervals with a lower bound each), with the bisection they share.

use super::loss::{Norm, SrgbLut};

/// One pixel's term in a line search of [`super::kernel::Kernel::refine`] in the sRGB space: the model k x + o (k > 0)
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
