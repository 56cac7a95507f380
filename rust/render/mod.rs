//! The renderer: camera rays -> closest hit -> direct lighting -> linear RGB image.
//!
//! The data flow is split at the first hit: `GBuffer` holds what does not depend on the light or the
//! materials (hit point, normal, view direction, object per sample), and `shade` turns one such `Surfel`
//! into radiance. `render` and the fitness evaluation share both halves, so a fit measures exactly the
//! image `render` would produce.

pub mod camera;
pub mod shade;
pub mod shape;

use std::path::Path;

use glam::Vec3A;
use rayon::prelude::*;

use crate::error::{Error, Result};
use crate::scene::Scene;
pub use camera::CameraFrame;
pub use shade::{shade, ShadeParams};
pub use shape::PShape;

/// The first hit of one camera sample: everything shading needs that the light and materials don't change.
#[derive(Clone, Copy, Debug)]
pub struct Surfel {
    pub position: Vec3A,
    /// Unit normal facing the viewer for planes (two-sided), outward for spheres.
    pub normal: Vec3A,
    /// Unit direction from the hit towards the eye.
    pub view: Vec3A,
    /// Index of the object hit, `u32::MAX` for a miss.
    pub object: u32,
    /// Scale-aware minimum distance for the shadow ray, from the hit point's rounding error.
    pub eps: f32,
}

impl Surfel {
    pub const MISS: Surfel = Surfel {
        position: Vec3A::ZERO,
        normal: Vec3A::ZERO,
        view: Vec3A::ZERO,
        object: u32::MAX,
        eps: 0.0,
    };
}

/// The scene's fixed geometry in working form.
#[derive(Clone, Debug)]
pub struct Geometry {
    pub camera: CameraFrame,
    pub shapes: Vec<PShape>,
}

impl Geometry {
    pub fn new(scene: &Scene) -> Geometry {
        Geometry {
            camera: CameraFrame::new(&scene.camera),
            shapes: scene
                .objects
                .iter()
                .map(|o| PShape::new(&o.shape))
                .collect(),
        }
    }

    /// Closest hit along the camera ray through image position (`px`, `py`).
    pub fn primary(&self, px: f32, py: f32, width: u32, height: u32) -> Surfel {
        let origin = self.camera.origin;
        let dir = self.camera.generate_ray(px, py, width, height);
        let mut best: Option<(usize, shape::ShapeHit)> = None;
        for (k, s) in self.shapes.iter().enumerate() {
            let tmax = best.map_or(f32::INFINITY, |(_, h)| h.t);
            if let Some(h) = s.intersect(origin, dir, 0.0, tmax) {
                best = Some((k, h));
            }
        }
        match best {
            None => Surfel::MISS,
            Some((k, h)) => {
                let mut normal = h.normal;
                if matches!(self.shapes[k], PShape::Plane { .. }) && normal.dot(dir) > 0.0 {
                    normal = -normal;
                }
                // Rounding error of the hit point grows with the coordinates involved.
                let scale = h.position.abs().max_element()
                    + self.shapes[k].scale()
                    + origin.abs().max_element();
                Surfel {
                    position: h.position,
                    normal,
                    view: -dir,
                    object: k as u32,
                    eps: 64.0 * f32::EPSILON * scale,
                }
            }
        }
    }
}

/// Sub-pixel sample positions in [0, 1)²: a stratified grid when `spp` is a square, otherwise the R2
/// low-discrepancy sequence. One sample is the pixel centre.
pub fn sample_offsets(spp: u32) -> Vec<(f32, f32)> {
    let spp = spp.max(1);
    let k = (spp as f64).sqrt().round() as u32;
    if k * k == spp {
        (0..spp)
            .map(|s| {
                (
                    ((s % k) as f32 + 0.5) / k as f32,
                    ((s / k) as f32 + 0.5) / k as f32,
                )
            })
            .collect()
    } else {
        let g = 1.324_717_957_244_746_f64;
        let (a1, a2) = (1.0 / g, 1.0 / (g * g));
        (0..spp)
            .map(|n| {
                (
                    ((0.5 + a1 * n as f64).fract()) as f32,
                    ((0.5 + a2 * n as f64).fract()) as f32,
                )
            })
            .collect()
    }
}

/// Camera-ray first hits at pixel centres for a `width` x `height` image, row-major.
#[derive(Clone, Debug)]
pub struct GBuffer {
    pub width: u32,
    pub height: u32,
    pub surfels: Vec<Surfel>,
}

impl GBuffer {
    pub fn new(geometry: &Geometry, width: u32, height: u32) -> GBuffer {
        let mut surfels = vec![Surfel::MISS; (width * height) as usize];
        surfels
            .par_chunks_mut(width as usize)
            .enumerate()
            .for_each(|(j, row)| {
                for (i, s) in row.iter_mut().enumerate() {
                    *s = geometry.primary(i as f32 + 0.5, j as f32 + 0.5, width, height);
                }
            });
        GBuffer {
            width,
            height,
            surfels,
        }
    }

    /// Object index per pixel, -1 for background.
    pub fn object_ids(&self) -> Vec<i32> {
        self.surfels
            .iter()
            .map(|s| {
                if s.object == u32::MAX {
                    -1
                } else {
                    s.object as i32
                }
            })
            .collect()
    }
}

/// A linear-RGB image, row-major, 3 floats per pixel.
#[derive(Clone, Debug)]
pub struct Image {
    pub width: u32,
    pub height: u32,
    pub rgb: Vec<f32>,
}

/// Render `scene` at `width` x `height` (the scene's own size when `None`) with `spp` samples per pixel.
pub fn render(scene: &Scene, width: Option<u32>, height: Option<u32>, spp: u32) -> Result<Image> {
    let width = width.unwrap_or(scene.width);
    let height = height.unwrap_or(scene.height);
    if width == 0 || height == 0 || width > 16384 || height > 16384 {
        return Err(Error::Invalid(format!(
            "image size must be 1..16384 pixels per side (got {width}x{height})"
        )));
    }
    if spp == 0 || spp > 4096 {
        return Err(Error::Invalid(format!("spp must be 1..4096 (got {spp})")));
    }
    let geometry = Geometry::new(scene);
    let params = ShadeParams::new(scene);
    let shadows = scene.can_occlude();
    let offsets = sample_offsets(spp); // spp = 1: the pixel centre
    let inv = 1.0 / offsets.len() as f32;
    let mut rgb = vec![0.0f32; (width * height * 3) as usize];
    rgb.par_chunks_mut(3 * width as usize)
        .enumerate()
        .for_each(|(j, row)| {
            for (i, px) in row.chunks_exact_mut(3).enumerate() {
                let mut sum = Vec3A::ZERO;
                for &(dx, dy) in &offsets {
                    let s = geometry.primary(i as f32 + dx, j as f32 + dy, width, height);
                    sum += shade(&s, &params, &geometry.shapes, shadows);
                }
                let v = (sum * inv).min(Vec3A::splat(f32::MAX));
                px.copy_from_slice(&v.to_array());
            }
        });
    Ok(Image { width, height, rgb })
}

/// Object index per pixel centre (-1 for background).
pub fn object_ids(scene: &Scene, width: Option<u32>, height: Option<u32>) -> Vec<i32> {
    let geometry = Geometry::new(scene);
    GBuffer::new(
        &geometry,
        width.unwrap_or(scene.width),
        height.unwrap_or(scene.height),
    )
    .object_ids()
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

    #[test]
    fn sample_patterns_are_inside_the_pixel_and_balanced() {
        for spp in [1, 2, 3, 4, 5, 16] {
            let o = sample_offsets(spp);
            assert_eq!(o.len(), spp as usize);
            let mean = o.iter().fold((0.0, 0.0), |a, b| (a.0 + b.0, a.1 + b.1));
            for &(x, y) in &o {
                assert!((0.0..1.0).contains(&x) && (0.0..1.0).contains(&y));
            }
            assert!(
                (mean.0 / spp as f32 - 0.5).abs() < 0.25
                    && (mean.1 / spp as f32 - 0.5).abs() < 0.25
            );
        }
    }
}
