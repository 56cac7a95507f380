//! Statistics of a photo itself, before any model: its pixel noise (Immerkaer's Laplacian difference) and
//! its JPEG blocking's jumps per phase of the 8-pixel grid. `rtloop.fit.goodness` (Python) says what they
//! mean and turns them into the noise sigma and the blocking verdict; these are its loops over the pixels,
//! in the arithmetic numpy did them in (each f32 operation rounded in the same order, the sums in f64 in
//! the same order), so that the numbers are the same to the last bit.

/// Per channel, the median of the absolute response of Immerkaer's kernel [[1, -2, 1], [-2, 4, -2], [1, -2,
/// 1]] over the `h` x `w` interior of `rgb` (row-major, 3 channels, f32; `h`, `w` >= 3): per row the second
/// difference along it, `(a - 2 b) + c` in f32, then that down the columns. The median of an even count is
/// the f32 mean of the middle two, `(a + b) / 2`; NaN where the channel's responses hold a NaN.
pub fn noise_medians(rgb: &[f32], h: usize, w: usize) -> [f32; 3] {
    assert!(
        h >= 3 && w >= 3 && rgb.len() == h * w * 3,
        "noise_medians: an h x w x 3 image, h, w >= 3"
    );
    let (wd, hd) = (w - 2, h - 2);
    // Along the rows: dx[i][j] = (x[i][j] - 2 x[i][j + 1]) + x[i][j + 2].
    let mut dx = vec![0f32; h * wd * 3];
    for i in 0..h {
        let row = &rgb[i * w * 3..(i + 1) * w * 3];
        let out = &mut dx[i * wd * 3..(i + 1) * wd * 3];
        for k in 0..wd * 3 {
            out[k] = (row[k] - 2.0 * row[k + 3]) + row[k + 6];
        }
    }
    // Down the columns, per channel: |(dx[i][j] - 2 dx[i + 1][j]) + dx[i + 2][j]|.
    let mut by_channel = [
        vec![0f32; hd * wd],
        vec![0f32; hd * wd],
        vec![0f32; hd * wd],
    ];
    for i in 0..hd {
        let (a, b, c) = (
            &dx[i * wd * 3..],
            &dx[(i + 1) * wd * 3..],
            &dx[(i + 2) * wd * 3..],
        );
        for j in 0..wd {
            for (ch, out) in by_channel.iter_mut().enumerate() {
                let k = j * 3 + ch;
                out[i * wd + j] = ((a[k] - 2.0 * b[k]) + c[k]).abs();
            }
        }
    }
    by_channel.map(|mut v| median(&mut v))
}

/// numpy's median of `v` (not empty): NaN if any value is NaN; for an even count the f32 mean of the two
/// middle values.
fn median(v: &mut [f32]) -> f32 {
    if v.iter().any(|x| x.is_nan()) {
        return f32::NAN;
    }
    let n = v.len();
    let (below, &mut upper, _) = v.select_nth_unstable_by(n / 2, f32::total_cmp);
    if n % 2 == 1 {
        return upper;
    }
    let lower = below.iter().copied().fold(f32::NEG_INFINITY, f32::max);
    (lower + upper) / 2.0
}

/// The JPEG blocking's mean clipped squared jump per phase of the `block`-pixel grid (block x 3, f64), of
/// `codes` (`h` x `w` x 3 sRGB codes, row-major, f32), along the rows then along the columns, each
/// direction's means halved and added to 0 in that order. Along a line of `n` pixels, pair j (pixels j and
/// j + 1, j = 1 .. n - 3, phase j mod `block`) jumps by `d_j - 0.5 (d_{j-1} + d_{j+1})` in f32 (`d_j =
/// c_{j+1} - c_j`); its square clipped at `edge_sq` (a NaN stays NaN) is summed in f64 per phase over the
/// lines in order and along each line in order, and divided by the phase's count of pairs.
pub fn jpeg_phases(codes: &[f32], h: usize, w: usize, block: usize, edge_sq: f32) -> Vec<[f64; 3]> {
    assert!(
        h >= 4 && w >= 4 && block > 0 && codes.len() == h * w * 3,
        "jpeg_phases: an h x w x 3 image"
    );
    let mut phases = vec![[0f64; 3]; block];
    // Rows: line i is pixels (i, 0 .. w); columns: line x is pixels (0 .. h, x).
    for (lines, n, line_step, pixel_step) in [(h, w, w * 3, 3), (w, h, 3, w * 3)] {
        let mut sums = vec![[0f64; 3]; block];
        let mut counts = vec![0usize; block];
        for j in 1..n - 2 {
            counts[j % block] += lines;
        }
        for line in 0..lines {
            let at = |p: usize, ch: usize| codes[line * line_step + p * pixel_step + ch];
            for j in 1..n - 2 {
                let sum = &mut sums[j % block];
                for (ch, s) in sum.iter_mut().enumerate() {
                    let d0 = at(j, ch) - at(j - 1, ch);
                    let d1 = at(j + 1, ch) - at(j, ch);
                    let d2 = at(j + 2, ch) - at(j + 1, ch);
                    let jump = d1 - 0.5 * (d0 + d2);
                    let sq = jump * jump;
                    *s += f64::from(if sq.is_nan() || sq < edge_sq {
                        sq
                    } else {
                        edge_sq
                    });
                }
            }
        }
        for ((phase, sum), count) in phases.iter_mut().zip(&sums).zip(&counts) {
            for ch in 0..3 {
                phase[ch] += sum[ch] / *count as f64 / 2.0;
            }
        }
    }
    phases
}

/// The 8-bit codes of `values` if each is bit for bit the value of a code in `table` (256 values): the
/// candidate code of a value is `buckets[bits >> shift]` (a bucket past the last reads as the last; each
/// bucket holds at most one code's value); None at the first value that is not its candidate's.
pub fn codes8(values: &[f32], table: &[f32], buckets: &[i16], shift: u32) -> Option<Vec<u8>> {
    let last = buckets.len().checked_sub(1)?;
    let mut codes = Vec::with_capacity(values.len());
    for v in values {
        let bits = v.to_bits();
        let code = usize::try_from(buckets[((bits >> shift) as usize).min(last)]).ok()?;
        if code > 255 || table.get(code)?.to_bits() != bits {
            return None;
        }
        codes.push(code as u8);
    }
    Some(codes)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn codes8_takes_only_the_codes_own_bits() {
        // three "codes" 0, 0.25 and 1, bucketed by sign and exponent (shift 23): 0.25 in bucket 125, 1 in 127
        let table = [0.0f32, 0.25, 1.0];
        let buckets: Vec<i16> = (0..128)
            .map(|b| {
                if b == 0 {
                    0
                } else if b <= 125 {
                    1
                } else {
                    2
                }
            })
            .collect();
        assert_eq!(
            codes8(&[1.0, 0.0, 0.25, 1.0], &table, &buckets, 23),
            Some(vec![2, 0, 1, 2])
        );
        assert_eq!(codes8(&[0.25, 0.2500001], &table, &buckets, 23), None);
        assert_eq!(codes8(&[0.5], &table, &buckets, 23), None);
        assert_eq!(codes8(&[-0.0], &table, &buckets, 23), None);
        assert_eq!(codes8(&[f32::NAN], &table, &buckets, 23), None);
        assert_eq!(codes8(&[], &table, &buckets, 23), Some(vec![]));
    }

    #[test]
    fn median_is_numpys() {
        assert_eq!(median(&mut [3.0, 1.0, 2.0]), 2.0);
        assert_eq!(median(&mut [4.0, 1.0, 3.0, 2.0]), 2.5);
        assert!(median(&mut [1.0, f32::NAN, 2.0]).is_nan());
        // the f32 mean of the middle two, rounded as f32 arithmetic rounds it
        let (a, b) = (1.0f32, 1.0 + f32::EPSILON);
        assert_eq!(median(&mut [b, a]), (a + b) / 2.0);
    }

    #[test]
    fn a_flat_or_linear_image_has_no_noise_and_no_jumps() {
        let (h, w) = (24, 32);
        let ramp: Vec<f32> = (0..h * w * 3)
            .map(|k| ((k / 3) % w) as f32 * 2.0 + ((k / 3) / w) as f32)
            .collect();
        assert_eq!(noise_medians(&ramp, h, w), [0.0; 3]);
        assert!(jpeg_phases(&ramp, h, w, 8, 36.0)
            .iter()
            .all(|p| *p == [0.0; 3]));
    }

    #[test]
    fn a_jump_on_the_grid_line_counts_in_its_phase_only() {
        // one column step between x = 7 and x = 8 (pair 7: phase 7), 10 codes
        let (h, w) = (24, 24);
        let img: Vec<f32> = (0..h * w * 3)
            .map(|k| if (k / 3) % w >= 8 { 10.0 } else { 0.0 })
            .collect();
        let p = jpeg_phases(&img, h, w, 8, 36.0);
        // pair 7 jumps by 10 (clipped to 36 squared); pairs 6 and 8 by -5 (25): phases 6 and 0
        // (each of these phases has 2 pairs per line, 24 lines; the columns add nothing)
        assert_eq!(p[7], [36.0 * 24.0 / (24.0 * 2.0) / 2.0; 3]);
        assert_eq!(p[6], [25.0 * 24.0 / (24.0 * 2.0) / 2.0; 3]);
        assert_eq!(p[0], [25.0 * 24.0 / (24.0 * 2.0) / 2.0; 3]);
        assert_eq!(p[3], [0.0; 3]);
    }
}
