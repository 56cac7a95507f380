//! The scene's number checks: finite values within the input limits, directions, colours, and the small
//! vector helpers the parser uses. Every error names its field.

use super::V3;
use crate::error::{Error, Result};

/// The largest magnitude of any scene number and fit bound but a direction's components
/// (docs/scene-format.md: "Input limits"): metres, colours, intensities and exposures beyond it overflow the
/// f32 renderer's products.
pub const MAX_MAGNITUDE: f64 = 1e8;

/// The largest light intensity: it scales as distance squared, so a light 1e8 m away needs 1e16 and more.
pub const MAX_INTENSITY: f64 = 1e20;

pub(super) fn finite(field: &str, v: f64) -> Result<f64> {
    finite_upto(field, v, MAX_MAGNITUDE)
}

pub(super) fn finite_upto(field: &str, v: f64, limit: f64) -> Result<f64> {
    match out_of_range(v, limit) {
        Some(why) => Err(Error::scene(field, why)),
        None => Ok(v),
    }
}

/// Why `v` is not a finite number within +-`limit`, if it is not.
fn out_of_range(v: f64, limit: f64) -> Option<String> {
    if !v.is_finite() {
        Some(format!("must be a finite number (got {v})"))
    } else if v.abs() > limit {
        Some(format!("must be within +-{limit:e} (got {v:e})"))
    } else {
        None
    }
}

/// Every component finite, then every one within +-`limit`; the error names the first component that
/// is not.
fn components_upto(field: &str, v: V3, limit: f64) -> Result<V3> {
    for bound in [f64::INFINITY, limit] {
        for (k, c) in v.iter().enumerate() {
            if let Some(why) = out_of_range(*c, bound) {
                return Err(Error::scene(field, format!("component {k} {why}")));
            }
        }
    }
    Ok(v)
}

/// Finite components of any size: a direction (only its orientation is used).
pub(super) fn finite_direction(field: &str, v: V3) -> Result<V3> {
    components_upto(field, v, f64::INFINITY)
}

pub(super) fn finite3(field: &str, v: V3) -> Result<V3> {
    components_upto(field, v, MAX_MAGNITUDE)
}

pub(super) fn nonneg3(field: &str, v: V3) -> Result<V3> {
    let v = finite3(field, v)?;
    if v.iter().any(|&c| c < 0.0) {
        return Err(Error::scene(
            field,
            format!("must be >= 0 in every component (got {v:?})"),
        ));
    }
    Ok(v)
}

/// The Euclidean length, computed scaled so that no finite vector overflows (or underflows) to 0 or inf.
pub(crate) fn norm(v: V3) -> f64 {
    let m = v[0].abs().max(v[1].abs()).max(v[2].abs());
    if m == 0.0 || !m.is_finite() {
        return m;
    }
    let (x, y, z) = (v[0] / m, v[1] / m, v[2] / m);
    m * (x * x + y * y + z * z).sqrt()
}

/// `v` normalised in f64 as glam does it, scaled first when its squared length would overflow or
/// underflow (a `[0, 1e300, 0]` normal), so the bits of ordinary vectors are glam's.
pub(crate) fn unit(v: V3) -> glam::DVec3 {
    let d = glam::DVec3::from_array(v);
    let l2 = d.length_squared();
    if l2.is_finite() && l2 > 1e-290 {
        d.normalize()
    } else {
        (d / d.abs().max_element()).normalize()
    }
}

pub(super) fn cross(a: V3, b: V3) -> V3 {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}
