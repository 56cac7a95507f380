//! The material model: Lambert plus normalised Blinn–Phong, f = ρ/π + k_s·(s+8)/(8π)·max(0, n·h)^s.
//!
//! The only place the lobe and its normalisation live; `shade` and the fitness kernel both call these
//! (each function keeps the exact order of operations its callers had, so results are bit for bit).

use std::ops::Mul;

use glam::Vec3A;

/// 1/π, Lambert's normalisation.
pub const INV_PI: f32 = std::f32::consts::FRAC_1_PI;

/// Lambert's ρ/π, for a scalar or an RGB albedo (or any factor linear in it).
#[inline(always)]
pub fn lambert<T: Mul<f32, Output = T>>(rho: T) -> T {
    rho * INV_PI
}

/// The lobe's scale k_s·(s+8)/(8π), evaluated as (k_s·(s+8))·(1/(8π)); `ks` may carry linear factors
/// (exposure, light) in front.
#[inline(always)]
pub fn specular_scale(ks: f32, shininess: f32) -> f32 {
    ks * (shininess + 8.0) * (INV_PI / 8.0)
}

/// The same normalisation relative to Lambert's 1/π: (s+8)/8 (the projected fit scales the diffuse
/// factor by it).
#[inline(always)]
pub fn specular_per_lambert(shininess: f32) -> f32 {
    (shininess + 8.0) / 8.0
}

/// max(0, n·h)^s with h the half vector of the unit directions to the light `l` and to the eye `v`.
#[inline(always)]
pub fn blinn_phong(n: Vec3A, l: Vec3A, v: Vec3A, shininess: f32) -> f32 {
    half_cos(n.to_array(), l.to_array(), v.to_array()).powf(shininess)
}

/// max(0, n·h), the lobe's cosine before its power: h the half vector of the unit directions to the
/// light `l` and to the eye `v`, n·h summed as (x + y) + z. The fitness kernel calls it per pixel in its
/// lane loops.
#[inline(always)]
pub fn half_cos(n: [f32; 3], l: [f32; 3], v: [f32; 3]) -> f32 {
    let h = unit_or_zero(l[0] + v[0], l[1] + v[1], l[2] + v[2]);
    ((n[0] * h[0] + n[1] * h[1]) + n[2] * h[2]).max(0.0)
}

/// (x, y, z) over its length, the length as (x² + y²) + z² and its reciprocal 1/sqrt; zero where that
/// reciprocal is not finite and positive (no length, or too short to divide by).
#[inline(always)]
pub fn unit_or_zero(x: f32, y: f32, z: f32) -> [f32; 3] {
    let rcp = 1.0 / ((x * x + y * y) + z * z).sqrt();
    if rcp.is_finite() && rcp > 0.0 {
        [x * rcp, y * rcp, z * rcp]
    } else {
        [0.0; 3]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lobe_peaks_at_its_normalisation() {
        let n = Vec3A::Y;
        assert_eq!(blinn_phong(n, n, n, 20.0), 1.0);
        let want = 0.5 * 28.0 / (8.0 * std::f32::consts::PI);
        assert!((specular_scale(0.5, 20.0) - want).abs() < 1e-7);
        assert!((lambert(1.0f32) * specular_per_lambert(20.0) - 28.0 * INV_PI / 8.0).abs() < 1e-7);
        // Light below the horizon of the half vector: no lobe, no NaN.
        assert_eq!(blinn_phong(n, -n, -n, 5.0), 0.0);
    }
}
