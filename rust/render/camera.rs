//! Pinhole camera: the public pixel-to-ray convention of the scene format, and sub-pixel sample positions.

use glam::{DVec3, Vec3A};

use crate::scene::Camera;

/// The camera's orthonormal frame and image-plane scale, ready to generate rays.
#[derive(Clone, Copy, Debug)]
pub struct CameraFrame {
    pub origin: Vec3A,
    pub forward: Vec3A,
    pub right: Vec3A,
    pub true_up: Vec3A,
    /// tan(vfov / 2).
    pub tan_half: f32,
}

impl CameraFrame {
    pub fn new(c: &Camera) -> CameraFrame {
        // The frame is built in f64 and rounded once, so nearly parallel `up` vectors stay orthonormal.
        let pos = DVec3::from_array(c.position);
        let forward = (DVec3::from_array(c.look_at) - pos).normalize();
        let mut right = forward.cross(DVec3::from_array(c.up));
        let l2 = right.length_squared();
        if !(l2.is_finite() && l2 > 1e-290) {
            right = forward.cross(crate::scene::unit(c.up)); // a huge or tiny `up`: scaled first
        }
        let right = right.normalize();
        let true_up = right.cross(forward);
        CameraFrame {
            origin: pos.as_vec3a(),
            forward: forward.as_vec3a(),
            right: right.as_vec3a(),
            true_up: true_up.as_vec3a(),
            tan_half: (c.vfov_deg.to_radians() * 0.5).tan() as f32,
        }
    }

    /// Unit direction of the ray through image position (`px`, `py`) in pixels: `px` from the left edge,
    /// `py` from the top edge, so the centre of pixel (i, j) is (i + 0.5, j + 0.5).
    #[inline]
    pub fn generate_ray(&self, px: f32, py: f32, width: u32, height: u32) -> Vec3A {
        let (w, h) = (width as f32, height as f32);
        let x = (2.0 * px / w - 1.0) * self.tan_half * (w / h);
        let y = (1.0 - 2.0 * py / h) * self.tan_half;
        (self.forward + x * self.right + y * self.true_up).normalize()
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

#[cfg(test)]
mod tests {
    use super::*;

    fn cam() -> CameraFrame {
        CameraFrame::new(&Camera {
            position: [0.0, 1.6, -6.0],
            look_at: [0.0, 0.8, 0.0],
            up: [0.0, 1.0, 0.0],
            vfov_deg: 35.0,
        })
    }

    #[test]
    fn frame_is_orthonormal_and_right_handed() {
        let c = cam();
        for v in [c.forward, c.right, c.true_up] {
            assert!((v.length() - 1.0).abs() < 1e-6);
        }
        assert!(c.forward.dot(c.right).abs() < 1e-6);
        assert!(c.forward.dot(c.true_up).abs() < 1e-6);
        // Looking down +z with +y up, right-handed: right = forward x up points to -x.
        assert!(c.right.x < -0.99);
        assert!(c.true_up.y > 0.9);
    }

    #[test]
    fn image_edges_span_the_vertical_fov() {
        let c = cam();
        let (w, h) = (128, 96);
        let top = c.generate_ray(64.0, 0.0, w, h);
        let bottom = c.generate_ray(64.0, 96.0, w, h);
        let angle = top.dot(bottom).clamp(-1.0, 1.0).acos().to_degrees();
        assert!((angle - 35.0).abs() < 1e-3, "{angle}");
        let centre = c.generate_ray(64.0, 48.0, w, h);
        assert!((centre - c.forward).length() < 1e-6);
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
