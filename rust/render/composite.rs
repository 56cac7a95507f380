//! The differential-rendering composite (Debevec 1998) of an insertion: the objects' render where the
//! matte covers them, elsewhere the photo plus the difference they make.

use rayon::prelude::*;

use crate::error::{Error, Result};

/// matte·with + (1 - matte)·max(photo + (with - without), 0) per pixel, all linear RGB (3 floats a pixel)
/// but `matte` (1 a pixel); the blend is skipped where the matte is 0, so there the photo's value is kept
/// exactly wherever `with` equals `without`.
pub fn composite(photo: &[f32], with: &[f32], without: &[f32], matte: &[f32]) -> Result<Vec<f32>> {
    let n = matte.len();
    if photo.len() != 3 * n || with.len() != 3 * n || without.len() != 3 * n {
        return Err(Error::Value(format!(
            "composite: expected 3 x {n} values per image (the matte's pixels), got {}, {} and {}",
            photo.len(),
            with.len(),
            without.len()
        )));
    }
    let mut out = vec![0.0f32; 3 * n];
    out.par_chunks_mut(3 * 4096)
        .enumerate()
        .for_each(|(c, chunk)| {
            for (k, o) in chunk.chunks_exact_mut(3).enumerate() {
                let p = c * 4096 + k;
                let m = matte[p];
                for (ch, o) in o.iter_mut().enumerate() {
                    let i = 3 * p + ch;
                    let v = (photo[i] + (with[i] - without[i])).max(0.0);
                    *o = if m > 0.0 {
                        m * with[i] + (1.0 - m) * v
                    } else {
                        v
                    };
                }
            }
        });
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn photo_kept_shadow_added_object_blended() {
        let photo = [0.5, 0.5, 0.5, 0.2, 0.2, 0.2, 0.3, 0.3, 0.3];
        let with = [0.4, 0.4, 0.4, 0.05, 0.05, 0.05, 0.9, 0.8, 0.7];
        let without = [0.4, 0.4, 0.4, 0.1, 0.1, 0.1, 0.2, 0.2, 0.2];
        let out = composite(&photo, &with, &without, &[0.0, 0.0, 0.5]).unwrap();
        assert_eq!(&out[0..3], &photo[0..3]); // nothing changed: the photo
        assert!((out[3] - 0.15).abs() < 1e-6); // shadowed: photo + (with - without)
        assert!((out[6] - (0.5 * 0.9 + 0.5 * 1.0)).abs() < 1e-6); // half covered
        assert!(composite(&photo, &with, &without, &[0.0]).is_err());
    }
}
