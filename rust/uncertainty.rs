//! Kernels of the Gauss-Newton uncertainty (python/rtloop/uncertainty): one finite-difference column of
//! the Jacobian over the used pixels, and the block sums of the score contributions for the sandwich.
//! Each repeats, operation for operation, the numpy it replaces (the same numbers to the last bit).

use crate::error::{Error, Result};
use crate::render::render;
use crate::scene::Scene;

/// What one side of a difference is: a scene to render, or the optimum's used values `f0`.
pub enum Side<'a> {
    Render(&'a Scene),
    Optimum,
}

/// The used pixels' values of `img` (flat H x W x 3) in `out` (3 per used pixel), min(value, 1) with
/// `clip`; a pixel crossing 1 (against `clipped0`) in a `free` channel is marked in `kink`.
fn used_values(
    img: &[f32],
    idx: &[u32],
    clipped0: &[bool],
    free: &[bool],
    clip: bool,
    kink: &mut [bool],
    out: &mut [f32],
) {
    for (i, &p) in idx.iter().enumerate() {
        let mut crossed = false;
        for c in 0..3 {
            let g = img[3 * p as usize + c];
            let j = 3 * i + c;
            if clip {
                crossed |= ((g >= 1.0) != clipped0[j]) && free[j];
                out[j] = if g > 1.0 { 1.0 } else { g }; // np.minimum(g, 1): NaN stays NaN
            } else {
                out[j] = g;
            }
        }
        if crossed {
            kink[i] = true;
        }
    }
}

/// d f / d theta_k over the used pixels' channels: (f(up) - f(down)) / `denom` in f64 from the f32
/// values, a side at the optimum taken from `f0`. Renders at spp 1 and the scene's size; pixels whose
/// value crosses 1 inside the step (with `clip`) are marked in `kink`.
#[allow(clippy::too_many_arguments)]
pub fn fd_column(
    up: Side<'_>,
    down: Side<'_>,
    f0: &[f32],
    idx: &[u32],
    clipped0: &[bool],
    free: &[bool],
    clip: bool,
    denom: f64,
    kink: &mut [bool],
    out: &mut [f64],
) -> Result<()> {
    let n = 3 * idx.len();
    if f0.len() != n
        || clipped0.len() != n
        || free.len() != n
        || out.len() != n
        || kink.len() != idx.len()
    {
        return Err(Error::Invalid(format!(
            "fd_column: {} used pixels need f0, clipped0, free and out of {n} values and kink of {} \
             (got {}, {}, {}, {}, {})",
            idx.len(), idx.len(), f0.len(), clipped0.len(), free.len(), out.len(), kink.len()
        )));
    }
    let values = |side: Side<'_>, kink: &mut [bool]| -> Result<Vec<f32>> {
        Ok(match side {
            Side::Optimum => f0.to_vec(),
            Side::Render(scene) => {
                let img = render(scene, None, None, 1)?;
                let pixels = img.rgb.len() / 3;
                if let Some(&p) = idx.iter().find(|&&p| p as usize >= pixels) {
                    return Err(Error::Invalid(format!(
                        "fd_column: pixel {p} is outside the {pixels} rendered"
                    )));
                }
                let mut v = vec![0f32; n];
                used_values(&img.rgb, idx, clipped0, free, clip, kink, &mut v);
                v
            }
        })
    };
    let fp = values(up, kink)?;
    let fm = values(down, kink)?;
    for j in 0..n {
        out[j] = (f64::from(fp[j]) - f64::from(fm[j])) / denom;
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
    for (a, &k) in rows.iter().enumerate() {
        let row = &jt[k * m..(k + 1) * m];
        let acc = &mut g[a * blocks..(a + 1) * blocks];
        for i in 0..m {
            acc[block_of[i / 3]] += row[i] * r[i];
        }
    }
    Ok(g)
}

#[cfg(test)]
mod tests {
    use super::*;

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
        let (mut kink, mut out) = (vec![false], vec![9.0; 3]);
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
            &mut out,
        )
        .unwrap();
        assert_eq!(out, vec![0.0; 3]);
        assert!(!kink[0]);
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
            &mut out
        )
        .is_err());
    }
}
