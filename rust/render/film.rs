//! The film: a linear-RGB `Image`, the sRGB transfer curve and 8-bit sRGB output (PNG/BMP).

use std::path::Path;

use crate::error::{Error, Result};

/// A linear-RGB image, row-major, 3 floats per pixel.
#[derive(Clone, Debug)]
pub struct Image {
    pub width: u32,
    pub height: u32,
    pub rgb: Vec<f32>,
}

/// The sRGB transfer curve (linear -> encoded), clamped to [0, 1]; NaN maps to 0.
#[inline]
pub fn linear_to_srgb(x: f32) -> f32 {
    let x = if x.is_nan() { 0.0 } else { x.clamp(0.0, 1.0) };
    if x <= 0.003_130_8 {
        12.92 * x
    } else {
        1.055 * x.powf(1.0 / 2.4) - 0.055
    }
}

/// The sRGB encoding of IEC 61966-2-1: 12.92 x for x <= 0.0031308, else 1.055 x^(1/2.4) - 0.055 (the same
/// formula above 1 and, linearly, below 0).
pub fn srgb_encode_exact(x: f64) -> f64 {
    if x <= 0.003_130_8 {
        12.92 * x
    } else {
        1.055 * x.powf(1.0 / 2.4) - 0.055
    }
}

/// One value's 8-bit sRGB code, by the curve: `round(255 linear_to_srgb(x))`.
#[inline]
pub fn srgb8_by_curve(x: f32) -> u8 {
    (linear_to_srgb(x) * 255.0).round() as u8
}

/// [`Srgb8Table`] splits the floats in (0, 1) into buckets by their bits above this one: a bucket spans at most
/// 2^-10 of its values, over which the code climbs at most 0.3 steps, so that it changes at most once inside.
const SRGB8_SHIFT: u32 = 14;

/// The 8-bit sRGB codes of the floats in (0, 1) by table: per bucket of floats ([`SRGB8_SHIFT`]), the code at
/// its start and the first float inside it with the next code (infinity when none; NaN when the code
/// changes twice, where the curve is asked). Built from the curve's 255 thresholds (each found by bisection
/// over the floats' bits), so that it gives [`srgb8_by_curve`]'s code for every float, bit for bit (the
/// curve's codes never fall as the float rises: tests/film checks the floats around every threshold).
struct Srgb8Table {
    buckets: Vec<(u8, f32)>,
}

impl Srgb8Table {
    fn new() -> Srgb8Table {
        let one = 1.0f32.to_bits();
        // The smallest float whose code is at least c, for c = 1..=255.
        let thresholds: Vec<u32> = (1..=255u32)
            .map(|c| {
                let (mut lo, mut hi) = (0u32, one); // code(lo) < c <= code(hi)
                while hi - lo > 1 {
                    let mid = lo + (hi - lo) / 2;
                    if u32::from(srgb8_by_curve(f32::from_bits(mid))) >= c {
                        hi = mid;
                    } else {
                        lo = mid;
                    }
                }
                hi
            })
            .collect();
        let n = (one >> SRGB8_SHIFT) as usize + 1;
        let mut buckets = Vec::with_capacity(n);
        let mut next = 0; // thresholds[..next] are at or below the bucket's start
        for b in 0..n as u32 {
            let (start, end) = (b << SRGB8_SHIFT, (b + 1) << SRGB8_SHIFT);
            while next < thresholds.len() && thresholds[next] <= start {
                next += 1;
            }
            let inside = thresholds[next..].iter().take_while(|&&t| t < end).count();
            let step = match inside {
                0 => f32::INFINITY,
                1 => f32::from_bits(thresholds[next]),
                _ => f32::NAN,
            };
            buckets.push((next as u8, step));
        }
        Srgb8Table { buckets }
    }

    #[inline]
    fn code(&self, x: f32) -> u8 {
        if !(x > 0.0) {
            return 0; // NaN, zero, negative
        }
        if x >= 1.0 {
            return 255;
        }
        let (code, step) = self.buckets[(x.to_bits() >> SRGB8_SHIFT) as usize];
        if step.is_nan() {
            srgb8_by_curve(x)
        } else {
            code + u8::from(x >= step)
        }
    }
}

fn srgb8_table() -> &'static Srgb8Table {
    static TABLE: std::sync::OnceLock<Srgb8Table> = std::sync::OnceLock::new();
    TABLE.get_or_init(Srgb8Table::new)
}

/// Encode linear RGB as 8-bit sRGB: [`srgb8_by_curve`]'s codes, by table (a few times faster).
pub fn to_srgb8(rgb: &[f32]) -> Vec<u8> {
    let table = srgb8_table();
    rgb.iter().map(|&x| table.code(x)).collect()
}

/// Write linear RGB as an 8-bit sRGB PNG or BMP (chosen by extension), atomically: the image goes to a
/// temporary file beside `path` that is renamed over it only once complete.
pub fn save_srgb8(path: &Path, width: u32, height: u32, rgb: &[f32]) -> Result<()> {
    let io = |m: String| Error::Io {
        path: path.display().to_string(),
        message: m,
    };
    if rgb.len() != (width * height * 3) as usize {
        return Err(io(format!(
            "expected {} values for {width}x{height} RGB, got {}",
            width * height * 3,
            rgb.len()
        )));
    }
    let format = match path
        .extension()
        .and_then(|e| e.to_str())
        .map(|e| e.to_ascii_lowercase())
        .as_deref()
    {
        Some("png") => image::ImageFormat::Png,
        Some("bmp") => image::ImageFormat::Bmp,
        _ => return Err(io("unsupported image extension (use .png or .bmp)".into())),
    };
    let buf = image::RgbImage::from_raw(width, height, to_srgb8(rgb)).expect("size checked above");
    let file_name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    let tmp = path.with_file_name(format!(".{file_name}.tmp{}", std::process::id()));
    buf.save_with_format(&tmp, format).map_err(|e| {
        let _ = std::fs::remove_file(&tmp);
        io(e.to_string())
    })?;
    std::fs::rename(&tmp, path).map_err(|e| {
        let _ = std::fs::remove_file(&tmp);
        io(e.to_string())
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn srgb_curve_endpoints_and_knee() {
        assert_eq!(linear_to_srgb(0.0), 0.0);
        assert!((linear_to_srgb(1.0) - 1.0).abs() < 1e-6);
        assert_eq!(linear_to_srgb(f32::NAN), 0.0);
        assert_eq!(linear_to_srgb(5.0), linear_to_srgb(1.0));
        // Continuity at the knee.
        let a = 0.003_130_8f32;
        assert!((12.92 * a - (1.055 * a.powf(1.0 / 2.4) - 0.055)).abs() < 1e-6);
        assert_eq!(to_srgb8(&[0.5])[0], 188);
    }

    #[test]
    fn the_table_gives_the_curves_codes() {
        let table = srgb8_table();
        assert!(
            table.buckets.iter().all(|&(_, step)| !step.is_nan()),
            "a bucket with two steps"
        );
        let check = |x: f32| {
            assert_eq!(
                table.code(x),
                srgb8_by_curve(x),
                "{x:e} ({:#x})",
                x.to_bits()
            )
        };
        // Around every code's first float, and a sweep of all floats from 0 to 1 in steps of 61 ulps.
        for c in 1..=255u32 {
            let (mut lo, mut hi) = (0u32, 1.0f32.to_bits());
            while hi - lo > 1 {
                let mid = lo + (hi - lo) / 2;
                if u32::from(srgb8_by_curve(f32::from_bits(mid))) < c {
                    lo = mid;
                } else {
                    hi = mid;
                }
            }
            let t = hi;
            for b in t.saturating_sub(4096)..=(t + 4096).min(1.0f32.to_bits()) {
                check(f32::from_bits(b));
            }
        }
        for b in (0..=1.0f32.to_bits()).step_by(61) {
            check(f32::from_bits(b));
        }
        for x in [
            f32::NAN,
            -0.0,
            -1.0,
            f32::NEG_INFINITY,
            0.0,
            1.0,
            1.5,
            f32::INFINITY,
            f32::MIN_POSITIVE,
            1e-45,
        ] {
            check(x);
        }
    }
}
