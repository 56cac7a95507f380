//! A material's `coat` field (`render::coat`): parsed and checked, each error naming the field.

use serde::Deserialize;

use crate::error::{Error, Result};
use crate::render::coat::{ALPHA_RANGE, DEFAULT_IOR, IOR_RANGE};

/// A material's coat: GGX roughness α and the relative index of refraction.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CoatSpec {
    pub roughness: f64,
    pub ior: f64,
}

/// The coat as written in a scene.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawCoat {
    roughness: Option<f64>,
    ior: Option<f64>,
}

/// The default roughness of a coat that does not give one (Mitsuba's `roughplastic` default).
pub const DEFAULT_ROUGHNESS: f64 = 0.1;

/// A coat's fields checked (`field` is the coat's own, `objects[i].material.coat`): `roughness` (GGX α,
/// default 0.1) in `ALPHA_RANGE`, `ior` (default 1.49) in `IOR_RANGE`.
pub(super) fn coat_spec(field: &str, c: &RawCoat) -> Result<CoatSpec> {
    let check = |name: &str, v: f64, (lo, hi): (f64, f64)| -> Result<f64> {
        let at = format!("{field}.{name}");
        if !v.is_finite() || !(lo..=hi).contains(&v) {
            return Err(Error::scene(
                at,
                format!("must be in [{lo}, {hi}] (got {v})"),
            ));
        }
        Ok(v)
    };
    Ok(CoatSpec {
        roughness: check(
            "roughness",
            c.roughness.unwrap_or(DEFAULT_ROUGHNESS),
            ALPHA_RANGE,
        )?,
        ior: check("ior", c.ior.unwrap_or(DEFAULT_IOR), IOR_RANGE)?,
    })
}
