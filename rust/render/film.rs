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

/// Encode linear RGB as 8-bit sRGB.
pub fn to_srgb8(rgb: &[f32]) -> Vec<u8> {
    rgb.iter()
        .map(|&x| (linear_to_srgb(x) * 255.0).round() as u8)
        .collect()
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
}
