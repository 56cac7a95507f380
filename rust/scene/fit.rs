//! The scene's `fit` section: each entry's path, its bounds (one number or one per component, within the
//! input limits) and its public form.

use serde_json::{json, Value};

use super::{FitParam, Scene, Target, MAX_INTENSITY, MAX_MAGNITUDE};
use crate::error::{Error, Result};

impl FitParam {
    /// The entry in the public format: `{"min": ..., "max": ...}` (numbers for one component, else lists).
    pub(super) fn to_value(&self) -> Value {
        let (min, max) = if self.min.len() == 1 {
            (json!(self.min[0]), json!(self.max[0]))
        } else {
            (json!(self.min), json!(self.max))
        };
        json!({"min": min, "max": max})
    }
}

fn bound_values(field: &str, v: Option<&Value>, len: usize, limit: f64) -> Result<Vec<f64>> {
    let v = v.ok_or_else(|| Error::scene(field, "missing"))?;
    let nums: Vec<Option<f64>> = match v {
        Value::Number(n) => vec![n.as_f64(); len],
        Value::Array(a) if a.len() == len => a.iter().map(|x| x.as_f64()).collect(),
        Value::Array(a) => {
            return Err(Error::scene(
                field,
                format!("expected {len} numbers or one number, got {}", a.len()),
            ))
        }
        _ => {
            return Err(Error::scene(
                field,
                format!("expected a number or a list of {len} numbers, got {v}"),
            ))
        }
    };
    nums.into_iter()
        .map(|x| match x {
            Some(x) if x.is_finite() && x.abs() <= limit => Ok(x),
            Some(x) if x.is_finite() => Err(Error::scene(
                field,
                format!("every bound must be within +-{limit:e} (got {x:e})"),
            )),
            _ => Err(Error::scene(
                field,
                format!("every bound must be a finite number (got {v})"),
            )),
        })
        .collect()
}

/// The largest rectangle light side a fit may search (metres): a wall of windows, not a sky.
pub const MAX_SIZE: f64 = 100.0;

pub(super) fn parse_fit_entry(scene: &Scene, path: &str, bounds: &Value) -> Result<FitParam> {
    let field = format!("fit[{path:?}]");
    let target = Target::parse(path, scene).map_err(|m| Error::scene(&field, m))?;
    let obj = bounds.as_object().ok_or_else(|| {
        Error::scene(
            &field,
            format!("expected {{\"min\": ..., \"max\": ...}}, got {bounds}"),
        )
    })?;
    if let Some(k) = obj.keys().find(|k| *k != "min" && *k != "max") {
        return Err(Error::scene(
            &field,
            format!("unknown key {k:?} (expected \"min\" and \"max\")"),
        ));
    }
    let len = target.len();
    let limit = if target.is_intensity() {
        MAX_INTENSITY
    } else {
        MAX_MAGNITUDE
    };
    let min = bound_values(&format!("{field}.min"), obj.get("min"), len, limit)?;
    let max = bound_values(&format!("{field}.max"), obj.get("max"), len, limit)?;
    for k in 0..len {
        if min[k] > max[k] {
            return Err(Error::scene(
                &field,
                format!("min > max in component {k} ({} > {})", min[k], max[k]),
            ));
        }
        if target == Target::Exposure && min[k] <= 0.0 {
            return Err(Error::scene(
                format!("{field}.min"),
                format!("must be > 0 for exposure (got {})", min[k]),
            ));
        }
        if matches!(target, Target::Size(_)) && !(min[k] > 0.0 && max[k] <= MAX_SIZE) {
            return Err(Error::scene(
                &field,
                format!(
                    "a rectangle light's width and height must be within (0, {MAX_SIZE}] m (got {} to {})",
                    min[k], max[k]
                ),
            ));
        }
        if let Some(lo) = target.lower_limit() {
            if min[k] < lo {
                return Err(Error::scene(
                    format!("{field}.min"),
                    format!("must be >= {lo} for {path} (got {})", min[k]),
                ));
            }
        }
    }
    // The first light's own parameters keep their single-light names: a list of one light is the light.
    let path = match target {
        Target::LightPosition => "light.position",
        Target::LightDirection => "light.direction",
        Target::LightIntensity => "light.intensity",
        Target::LightColor => "light.color",
        _ => path,
    };
    Ok(FitParam {
        path: path.to_string(),
        target,
        min,
        max,
    })
}
