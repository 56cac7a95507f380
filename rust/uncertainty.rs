//! Kernels of the Gauss-Newton uncertainty (python/rtloop/uncertainty): one finite-difference column of
//! the Jacobian over the used pixels, and the block sums of the score contributions for the sandwich.
//! Each repeats, operation for operation, the numpy it replaces (the same numbers to the last bit).

use crate::error::{Error, Result};
use crate::render::render_pixels_many;
use crate::scene::Scene;

/// What one side of a difference is: its used pixels' rendered values, or the optimum's used values `f0`.
pub enum Side {
    Rendered(Vec<f32>),
    Optimum,
}

/// The used pixels' rendered values `v` (3 per used pixel) made min(value, 1) in place with `clip`; a
/// pixel crossing 1 (against `clipped0`) in a `free` channel is marked in `kink`.
fn clip_used(v: &mut [f32], clipped0: &[bool], free: &[bool], clip: bool, kink: &mut [bool]) {
    if !clip {
        return;
    }
    for (i, px) in v.chunks_exact_mut(3).enumerate() {
        let mut crossed = false;
        for (c, g) in px.iter_mut().enumerate() {
            let j = 3 * i + c;
            crossed |= ((*g >= 1.0) != clipped0[j]) && free[j];
            if *g > 1.0 {
                *g = 1.0; // np.minimum(g, 1): NaN stays NaN
            }
        }
        if crossed {
            kink[i] = true;
        }
    }
}

/// The least jump, as a fraction of a pixel's value, that [`one_sided_disagree`] counts: a smooth f's two
/// sides differ by |f''| h^2, about (h / d)^2 ~ 1e-6 of f at steps of 1e-3 of the range (d the light's
/// distance), a thousand times below; a jump of this size makes a central difference jump / 2h, about
/// half a smooth derivative's 2 f / d, and a larger one more.
pub const JUMP_FRACTION: f64 = 1e-3;

/// Whether a step's two sides disagree like a jump, not like a smooth function: the forward change
/// `up - at` and the backward `at - down` (values, f64 from f32) differ by more than half their sizes
/// together and by more than [`JUMP_FRACTION`] of the largest of the three values. A shadow edge or the
/// terminator crossing the pixel inside one side makes that side's change the pixel's direct light and
/// the other's a smooth one's, and the central difference there a jump / 2h that the Gauss-Newton model
/// cannot represent. A smooth f's sides differ by f'' h^2 against |f'| h each: not a jump, also where f'
/// vanishes (a floor under a sun the step turns about its symmetry axis), by the second condition.
pub fn one_sided_disagree(up: f64, at: f64, down: f64) -> bool {
    let (forward, backward) = (up - at, at - down);
    let gap = (forward - backward).abs();
    gap > 0.5 * (forward.abs() + backward.abs())
        && gap > JUMP_FRACTION * up.abs().max(at.abs()).max(down.abs())
}

/// d f / d theta_k over the used pixels' channels: (f(up) - f(down)) / `denom` in f64 from the f32
/// values (the used pixels' renders at spp 1), a side at the optimum taken from `f0`; pixels whose
/// value crosses 1 inside the step (with `clip`) are marked in `kink`. With both sides rendered, a pixel
/// whose forward and backward changes in a `free` channel disagree like a jump
/// ([`one_sided_disagree`]: a shadow edge or the terminator crossed inside the step) is marked in `jump`.
#[allow(clippy::too_many_arguments)]
pub fn fd_column(
    up: Side,
    down: Side,
    f0: &[f32],
    idx: &[u32],
    clipped0: &[bool],
    free: &[bool],
    clip: bool,
    denom: f64,
    kink: &mut [bool],
    jump: &mut [bool],
    out: &mut [f64],
) -> Result<()> {
    let n = 3 * idx.len();
    if f0.len() != n
        || clipped0.len() != n
        || free.len() != n
        || out.len() != n
        || kink.len() != idx.len()
        || jump.len() != idx.len()
    {
        return Err(Error::Invalid(format!(
            "fd_column: {} used pixels need f0, clipped0, free and out of {n} values and kink and jump of \
             {} (got {}, {}, {}, {}, {}, {})",
            idx.len(), idx.len(), f0.len(), clipped0.len(), free.len(), out.len(), kink.len(), jump.len()
        )));
    }
    let rendered = |s: &Side| !matches!(s, Side::Optimum);
    let both = rendered(&up) && rendered(&down);
    let values = |side: Side, kink: &mut [bool]| -> Result<Vec<f32>> {
        Ok(match side {
            Side::Optimum => f0.to_vec(),
            Side::Rendered(values) => {
                if values.len() != n {
                    return Err(Error::Invalid(format!(
                        "fd_column: {} rendered values for {n}",
                        values.len()
                    )));
                }
                let mut v = values;
                clip_used(&mut v, clipped0, free, clip, kink);
                v
            }
        })
    };
    let fp = values(up, kink)?;
    let fm = values(down, kink)?;
    for j in 0..n {
        out[j] = (f64::from(fp[j]) - f64::from(fm[j])) / denom;
    }
    if both {
        for (i, hit) in jump.iter_mut().enumerate() {
            *hit |= (3 * i..3 * i + 3).any(|j| {
                free[j] && one_sided_disagree(f64::from(fp[j]), f64::from(f0[j]), f64::from(fm[j]))
            });
        }
    }
    Ok(())
}

/// One rendered column of [`fd_columns`]: its two sides (None: the optimum) and the difference's divisor.
pub struct Column<'a> {
    pub up: Option<&'a Scene>,
    pub down: Option<&'a Scene>,
    pub denom: f64,
}

/// [`fd_column`] of each of `columns` into `out[k]`, the sides of all rendered in one pass
/// ([`render_pixels_many`]: scenes with the same first hits find them once); the same values bit for bit
/// as the columns one by one.
#[allow(clippy::too_many_arguments)]
pub fn fd_columns(
    columns: &[Column<'_>],
    f0: &[f32],
    idx: &[u32],
    clipped0: &[bool],
    free: &[bool],
    clip: bool,
    kink: &mut [bool],
    jump: &mut [bool],
    out: &mut [&mut [f64]],
) -> Result<()> {
    if out.len() != columns.len() {
        return Err(Error::Invalid(format!(
            "fd_columns: {} columns need as many rows (got {})",
            columns.len(),
            out.len()
        )));
    }
    let scenes: Vec<&Scene> = columns
        .iter()
        .flat_map(|c| [c.up, c.down])
        .flatten()
        .collect();
    let values = render_pixels_many(&scenes, idx)?;
    let mut next = values.into_iter();
    for (c, row) in columns.iter().zip(out.iter_mut()) {
        let mut side = |s: Option<&Scene>| match s {
            Some(_) => next.next().map_or(Side::Optimum, Side::Rendered),
            None => Side::Optimum,
        };
        let (up, down) = (side(c.up), side(c.down));
        fd_column(
            up, down, f0, idx, clipped0, free, clip, c.denom, kink, jump, row,
        )?;
    }
    Ok(())
}

/// g[a][b] = sum over the residuals i of block `block_of[i / 3]` == b of jt[rows[a]][i] * r[i], summed
/// in the order of i (as np.bincount does); `jt` is row-major with `r.len()` columns.
pub fn block_scores(
    jt: &[f64],
    rows: &[usize],
    r: &[f64],
    block_of: &[usize],
    blocks: usize,
) -> Result<Vec<f64>> {
    let m = r.len();
    if m != 3 * block_of.len()
        || rows.iter().any(|&k| (k + 1) * m > jt.len())
        || block_of.iter().any(|&b| b >= blocks)
    {
        return Err(Error::Invalid(format!(
            "block_scores: {m} residuals need {} block numbers below {blocks} and rows of {m} in jt",
            m / 3
        )));
    }
    let mut g = vec![0f64; rows.len() * blocks];
    if blocks == 0 {
        return Ok(g);
    }
    // Pixel by pixel, every row's sum at once (independent chains of additions, one block lookup per
    // pixel); each (row, block) sum still adds its terms in the order of i, so the values are those of
    // a row-by-row sum on any number of threads (this runs on one: it takes well under a millisecond).
    let row_of: Vec<&[f64]> = rows.iter().map(|&k| &jt[k * m..(k + 1) * m]).collect();
    for (p, (rp, &b)) in r.chunks_exact(3).zip(block_of).enumerate() {
        for (a, row) in row_of.iter().enumerate() {
            let jp = &row[3 * p..3 * p + 3];
            let acc = &mut g[a * blocks + b];
            *acc += jp[0] * rp[0];
            *acc += jp[1] * rp[1];
            *acc += jp[2] * rp[2];
        }
    }
    Ok(g)
}

/// The pixel footprint's Δ per used residual (3 per used pixel `idx`, flat indices into the `width` x
/// `height` image `centre`, RGB float32 pixel-centre values): a pixel's area average less its centre value,
/// (f_xx + f_yy) / 24 from the 4-neighbour Laplacian, (((up + down) + left) + right) - 4 centre in f64 from
/// the f32 values, divided by 24. 0 for a pixel on the image border, where any of the five values is not
/// below 1 (clipped, or NaN), and where the centre value clipped at 1 is not `f0`'s (the fit compared
/// another value there: a footprint render's). As python/rtloop/uncertainty's numpy did, to the last bit.
pub fn footprint_delta(
    centre: &[f32],
    (width, height): (usize, usize),
    idx: &[u32],
    f0: &[f32],
) -> Result<Vec<f64>> {
    if centre.len() != 3 * width * height || f0.len() != 3 * idx.len() {
        return Err(Error::Invalid(format!(
            "footprint_delta: a {width} x {height} image needs {} values (got {}), {} used pixels {} \
             values of f0 (got {})",
            3 * width * height,
            centre.len(),
            idx.len(),
            3 * idx.len(),
            f0.len()
        )));
    }
    let mut out = vec![0f64; 3 * idx.len()];
    for (i, &p) in idx.iter().enumerate() {
        let p = p as usize;
        let (y, x) = (p / width, p % width);
        if y >= height || x == 0 || x + 1 >= width || y == 0 || y + 1 >= height {
            continue;
        }
        for c in 0..3 {
            let at = 3 * p + c;
            let c32 = centre[at];
            let [up, down, left, right] =
                [at - 3 * width, at + 3 * width, at - 3, at + 3].map(|j| f64::from(centre[j]));
            let mid = f64::from(c32);
            let below = [up, down, left, right, mid].iter().all(|&v| v < 1.0);
            let clipped = if c32 > 1.0 { 1.0 } else { c32 }; // NaN stays NaN: never equal
            if below && clipped == f0[3 * i + c] {
                out[3 * i + c] = (up + down + left + right - 4.0 * mid) / 24.0;
            }
        }
    }
    Ok(out)
}

/// The `ks`-th smallest values of `values` (0-based; what `np.partition(values, ks)[ks]` holds: exact
/// elements, no interpolation), by selection on a copy. Errors on a NaN or a `k` out of range.
pub fn order_statistics(values: &[f64], ks: &[usize]) -> Result<Vec<f64>> {
    if values.iter().any(|v| v.is_nan()) {
        return Err(Error::Invalid(
            "order_statistics: the values hold a NaN".into(),
        ));
    }
    if let Some(&k) = ks.iter().find(|&&k| k >= values.len()) {
        return Err(Error::Invalid(format!(
            "order_statistics: k = {k} of {} values",
            values.len()
        )));
    }
    let mut v = values.to_vec();
    let mut sorted: Vec<usize> = ks.to_vec();
    sorted.sort_unstable();
    sorted.dedup();
    // select the largest k first, then each smaller one within the part below it
    let mut end = v.len();
    let mut got = std::collections::HashMap::new();
    for &k in sorted.iter().rev() {
        let (_, &mut x, _) = v[..end].select_nth_unstable_by(k, f64::total_cmp);
        got.insert(k, x);
        end = k;
    }
    Ok(ks.iter().map(|k| got[k]).collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn order_statistics_are_the_sorted_values() {
        let v = [3.0, -1.0, 2.5, 0.0, 7.0, -4.0, 2.5, 1e-9];
        let mut sorted = v.to_vec();
        sorted.sort_by(f64::total_cmp);
        let ks: Vec<usize> = (0..v.len()).rev().chain([2, 5, 2]).collect();
        let got = order_statistics(&v, &ks).unwrap();
        for (k, x) in ks.iter().zip(got) {
            assert_eq!(x, sorted[*k]);
        }
        assert!(order_statistics(&v, &[8]).is_err());
        assert!(order_statistics(&[1.0, f64::NAN], &[0]).is_err());
    }

    #[test]
    fn footprint_delta_is_the_laplacian_over_24_inside_and_0_elsewhere() {
        // a 4 x 3 image whose red is x^2 + y^2 / 2 (Laplacian 3), green 0.5, blue clipped at one neighbour
        let (w, h) = (4usize, 3usize);
        let mut img = vec![0f32; 3 * w * h];
        for y in 0..h {
            for x in 0..w {
                let p = 3 * (y * w + x);
                img[p] = 0.01 * (x * x) as f32 + 0.005 * (y * y) as f32;
                img[p + 1] = 0.5;
                img[p + 2] = if (x, y) == (2, 0) { 1.0 } else { 0.25 };
            }
        }
        let idx = [5u32, 6, 0];
        let f0: Vec<f32> = idx
            .iter()
            .flat_map(|&p| img[3 * p as usize..3 * p as usize + 3].to_vec())
            .collect();
        let d = footprint_delta(&img, (w, h), &idx, &f0).unwrap();
        assert!((d[0] - 0.03 / 24.0).abs() < 1e-9 && d[1] == 0.0 && d[2] == 0.0);
        assert!((d[3] - 0.03 / 24.0).abs() < 1e-9 && d[4] == 0.0);
        assert_eq!(d[5], 0.0, "a neighbour at 1: clipped");
        assert_eq!(&d[6..], &[0.0; 3], "the border");
        let mut other = f0.clone();
        other[0] += 0.1; // the fit compared another value there
        assert_eq!(footprint_delta(&img, (w, h), &idx, &other).unwrap()[0], 0.0);
        assert!(footprint_delta(&img, (w, h), &idx, &f0[..3]).is_err());
    }

    #[test]
    fn block_scores_sum_each_blocks_products() {
        // two pixels (six residuals) in blocks 1 and 0, one row: the sums by hand
        let jt = [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0, 2.0, 3.0, 4.0, 5.0, 6.0];
        let r = [1.0, 1.0, 1.0, 0.5, 0.5, 0.5];
        let g = block_scores(&jt, &[1], &r, &[1, 0], 2).unwrap();
        assert_eq!(g, vec![7.5, 6.0]);
        assert!(block_scores(&jt, &[2], &r, &[1, 0], 2).is_err()); // no third row
        assert!(block_scores(&jt, &[1], &r, &[2, 0], 2).is_err()); // block out of range
    }

    #[test]
    fn fd_column_of_the_optimum_on_both_sides_is_zero_and_checks_lengths() {
        let f0 = [0.5f32, 0.25, 1.0];
        let (mut kink, mut jump, mut out) = (vec![false], vec![false], vec![9.0; 3]);
        fd_column(
            Side::Optimum,
            Side::Optimum,
            &f0,
            &[0],
            &[false, false, true],
            &[true; 3],
            true,
            2.0,
            &mut kink,
            &mut jump,
            &mut out,
        )
        .unwrap();
        assert_eq!(out, vec![0.0; 3]);
        assert!(!kink[0] && !jump[0]);
        assert!(fd_column(
            Side::Optimum,
            Side::Optimum,
            &f0,
            &[0, 1],
            &[false; 3],
            &[true; 3],
            true,
            1.0,
            &mut kink,
            &mut jump,
            &mut out
        )
        .is_err());
    }

    #[test]
    fn a_jump_on_one_side_disagrees_and_a_smooth_step_does_not() {
        // a lit pixel (0.4) that a shadow edge reaches inside the forward step: 0.0 there
        assert!(one_sided_disagree(0.0, 0.4, 0.401));
        assert!(one_sided_disagree(0.4, 0.0, 0.0)); // the shadow leaves it inside the forward step
                                                    // smooth: 1/d^2 at d = 2.99, 3, 3.01 (curvature h f'' = 1 % of the change)
        let f = |d: f64| 1.0 / (d * d);
        assert!(!one_sided_disagree(f(3.01), f(3.0), f(2.99)));
        // linear, and a pixel the step does not change, float32 rounding aside
        assert!(!one_sided_disagree(0.3, 0.2, 0.1));
        let v = 0.3f32;
        assert!(!one_sided_disagree(
            f64::from(v),
            f64::from(v + f32::EPSILON / 4.0),
            f64::from(v)
        ));
        // a stationary smooth pixel: cos of an angle the step turns by 1e-3 rad either side of 0
        assert!(!one_sided_disagree(1e-3f64.cos(), 1.0, 1e-3f64.cos()));
        // a small jump still counts: 1 % of the value on one side
        assert!(one_sided_disagree(0.396, 0.4, 0.4));
    }
}
