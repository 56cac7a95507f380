//! The scene's lights: the single `light` object or the `lights` list (point, directional, sphere and
//! rectangle lights, each named), parsed and validated in one place. A scene is written back with `light` when it
//! has one point or directional light (a list of one such light is that light), else with `lights`.

use serde::Deserialize;
use serde_json::{json, Value};

use super::{
    finite, finite3, finite_direction, finite_upto, nonneg3, norm, Scene, MAX_INTENSITY, V3,
};
use crate::error::{Error, Result};

/// A light: a point light at `position`, a sphere light (`radius` > 0) centred there, a rectangle light
/// (`rect`: a window) centred there, or a directional light (a sun, a lamp far away) shining from
/// `direction`.
#[derive(Clone, Debug, PartialEq)]
pub struct PointLight {
    /// Its name in a `lights` list (`light0` for the single `light`).
    pub name: String,
    /// Point, sphere or rectangle light: its position (centre). Unused (zero) for a directional light.
    pub position: V3,
    /// Point light: radiant intensity in W/sr; directional: irradiance at normal incidence in W/m²
    /// (times `color` in both cases).
    pub intensity: f64,
    pub color: V3,
    /// Directional light: the unit direction from the scene towards the light (normalised when set).
    pub direction: Option<V3>,
    /// Sphere light: its radius in metres (0 for a point or directional light). Its intensity is that of
    /// the point light it looks like from afar: radiance = intensity x colour / (pi r^2).
    pub radius: f64,
    /// Rectangle light: its size and orientation (`None` for the other kinds). Its intensity is its
    /// radiant intensity along its normal: radiance = intensity x colour / (width x height).
    pub rect: Option<RectLight>,
}

/// A rectangle light's shape: `size` = (width, height) in metres, the unit `normal` it emits towards
/// (one-sided), and the unit `up` its height runs along (orthogonal to `normal`; its width runs along
/// up x normal).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RectLight {
    pub size: [f64; 2],
    pub normal: V3,
    pub up: V3,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawLight {
    name: Option<String>,
    #[serde(rename = "type")]
    kind: Option<String>,
    position: Option<V3>,
    direction: Option<V3>,
    radius: Option<f64>,
    size: Option<[f64; 2]>,
    normal: Option<V3>,
    up: Option<V3>,
    intensity: f64,
    color: Option<V3>,
}

/// Validate one light; `field` is its prefix in messages (`light` or `lights[1]`), `index` its place
/// in the list (its default name is `light{index}`).
pub(super) fn parse_light(
    field: &str,
    index: usize,
    l: &RawLight,
    listed: bool,
) -> Result<PointLight> {
    let f = |k: &str| format!("{field}.{k}");
    if !listed && l.name.is_some() {
        return Err(Error::scene(
            f("name"),
            "a single `light` has no name (name lights in a `lights` list)",
        ));
    }
    let name = l.name.clone().unwrap_or_else(|| format!("light{index}"));
    if name.is_empty() || name.contains('.') {
        return Err(Error::scene(
            f("name"),
            format!("must be non-empty and contain no '.' (got {name:?})"),
        ));
    }
    let kind = l.kind.as_deref().unwrap_or("point");
    if !listed && matches!(kind, "sphere" | "rectangle") {
        return Err(Error::scene(
            f("type"),
            format!("a {kind} light goes in a `lights` list"),
        ));
    }
    if kind != "rectangle" {
        for (key, given) in [
            ("size", l.size.is_some()),
            ("normal", l.normal.is_some()),
            ("up", l.up.is_some()),
        ] {
            if given {
                return Err(Error::scene(
                    f(key),
                    format!("a {kind} light has no {key} (set \"type\": \"rectangle\")"),
                ));
            }
        }
    }
    let (position, direction, radius) = match kind {
        "point" | "sphere" | "rectangle" => {
            if l.direction.is_some() {
                return Err(Error::scene(f("direction"), format!("a {kind} light has a position, not a direction (or set \"type\": \"directional\")")));
            }
            let p = l.position.ok_or_else(|| {
                Error::scene(f("position"), format!("missing field for a {kind} light"))
            })?;
            let radius = match (kind, l.radius) {
                ("point", Some(_)) => {
                    return Err(Error::scene(
                        f("radius"),
                        "a point light has no radius (set \"type\": \"sphere\")",
                    ))
                }
                ("point", None) | ("rectangle", None) => 0.0,
                ("rectangle", Some(_)) => {
                    return Err(Error::scene(
                        f("radius"),
                        "a rectangle light has no radius (its extent is `size`)",
                    ))
                }
                (_, None) => {
                    return Err(Error::scene(
                        f("radius"),
                        "missing field for a sphere light",
                    ))
                }
                (_, Some(r)) => {
                    let r = finite(&f("radius"), r)?;
                    if r <= 0.0 {
                        return Err(Error::scene(f("radius"), format!("must be > 0 (got {r})")));
                    }
                    r
                }
            };
            (finite3(&f("position"), p)?, None, radius)
        }
        "directional" => {
            if l.position.is_some() {
                return Err(Error::scene(
                    f("position"),
                    "a directional light has a direction, not a position",
                ));
            }
            if l.radius.is_some() {
                return Err(Error::scene(
                    f("radius"),
                    "a directional light has no radius",
                ));
            }
            let d = l.direction.ok_or_else(|| {
                Error::scene(f("direction"), "missing field for a directional light")
            })?;
            let d = finite_direction(&f("direction"), d)?;
            let n = norm(d);
            if n == 0.0 || !n.is_finite() {
                return Err(Error::scene(f("direction"), "zero-length direction"));
            }
            ([0.0; 3], Some([d[0] / n, d[1] / n, d[2] / n]), 0.0) // stored as a unit vector
        }
        other => {
            let known = if listed {
                "\"point\", \"directional\", \"sphere\", \"rectangle\""
            } else {
                "\"point\", \"directional\""
            };
            return Err(Error::scene(
                f("type"),
                format!("unknown light type {other:?} (known: {known})"),
            ));
        }
    };
    let intensity = finite_upto(&f("intensity"), l.intensity, MAX_INTENSITY)?;
    if intensity < 0.0 {
        return Err(Error::scene(
            f("intensity"),
            format!("must be >= 0 (got {intensity})"),
        ));
    }
    let rect = if kind == "rectangle" {
        Some(parse_rect(&f, l)?)
    } else {
        None
    };
    Ok(PointLight {
        name,
        position,
        intensity,
        color: nonneg3(&f("color"), l.color.unwrap_or([1.0; 3]))?,
        direction,
        radius,
        rect,
    })
}

/// A finite, non-zero vector scaled to unit length.
fn unit(field: &str, v: V3) -> Result<V3> {
    let v = finite_direction(field, v)?;
    let n = norm(v);
    if n == 0.0 || !n.is_finite() {
        return Err(Error::scene(field, "zero-length vector"));
    }
    Ok([v[0] / n, v[1] / n, v[2] / n])
}

/// A rectangle light's size, normal and up (`up` made orthogonal to the normal; by default the world's
/// +y, or +z for a rectangle facing up or down).
fn parse_rect(f: &dyn Fn(&str) -> String, l: &RawLight) -> Result<RectLight> {
    let size = l.size.ok_or_else(|| {
        Error::scene(
            f("size"),
            "missing field for a rectangle light: [width, height] in metres",
        )
    })?;
    for v in size {
        if finite(&f("size"), v)? <= 0.0 {
            return Err(Error::scene(
                f("size"),
                format!("width and height must be > 0 (got {size:?})"),
            ));
        }
    }
    let normal = l.normal.ok_or_else(|| {
        Error::scene(
            f("normal"),
            "missing field for a rectangle light: the direction it shines towards",
        )
    })?;
    let normal = unit(&f("normal"), normal)?;
    let up = match l.up {
        Some(u) => unit(&f("up"), u)?,
        None if normal[1].abs() > 0.9 => [0.0, 0.0, 1.0],
        None => [0.0, 1.0, 0.0],
    };
    let d = up[0] * normal[0] + up[1] * normal[1] + up[2] * normal[2];
    let u = [
        up[0] - d * normal[0],
        up[1] - d * normal[1],
        up[2] - d * normal[2],
    ];
    let n = norm(u);
    if !(n > 1e-6) {
        return Err(Error::scene(
            f("up"),
            "is parallel to the normal: give the direction the rectangle's height runs along",
        ));
    }
    Ok(RectLight {
        size,
        normal,
        up: [u[0] / n, u[1] / n, u[2] / n],
    })
}

/// The scene's lights from its `light` or `lights` field (exactly one of the two).
pub(super) fn parse_lights(
    light: Option<RawLight>,
    lights: Option<Vec<RawLight>>,
) -> Result<(PointLight, Vec<PointLight>)> {
    match (light, lights) {
        (Some(_), Some(_)) => Err(Error::scene(
            "lights",
            "give either `light` or `lights`, not both",
        )),
        (None, None) => Err(Error::scene(
            "lights",
            "missing: the scene needs a `light` or a `lights` list",
        )),
        (Some(l), None) => Ok((parse_light("light", 0, &l, false)?, Vec::new())),
        (None, Some(list)) => {
            if list.is_empty() {
                return Err(Error::scene("lights", "the list needs at least one light"));
            }
            if list.len() > MAX_LIGHTS {
                return Err(Error::scene(
                    "lights",
                    format!("at most {MAX_LIGHTS} lights (got {})", list.len()),
                ));
            }
            let mut out: Vec<PointLight> = Vec::with_capacity(list.len());
            for (i, l) in list.iter().enumerate() {
                let light = parse_light(&format!("lights[{i}]"), i, l, true)?;
                if out.iter().any(|o| o.name == light.name) {
                    return Err(Error::scene(
                        format!("lights[{i}].name"),
                        format!("duplicate light name {:?}", light.name),
                    ));
                }
                out.push(light);
            }
            let first = out.remove(0);
            Ok((first, out))
        }
    }
}

/// The most lights a scene may hold (each costs a shadow ray per pixel, a sphere light several).
pub const MAX_LIGHTS: usize = 8;

/// One light in the public format.
pub(super) fn light_value(l: &PointLight, listed: bool) -> Value {
    let mut v = match (l.direction, l.radius > 0.0, l.rect) {
        (_, _, Some(r)) => {
            json!({"type": "rectangle", "position": l.position, "size": r.size, "normal": r.normal,
                   "up": r.up, "intensity": l.intensity, "color": l.color})
        }
        (Some(d), _, _) => {
            json!({"type": "directional", "direction": d, "intensity": l.intensity, "color": l.color})
        }
        (None, true, _) => json!({"type": "sphere", "position": l.position, "radius": l.radius,
                               "intensity": l.intensity, "color": l.color}),
        (None, false, _) => {
            json!({"position": l.position, "intensity": l.intensity, "color": l.color})
        }
    };
    if listed {
        v["name"] = json!(l.name);
    }
    v
}

impl Scene {
    /// Every light: the first, then the `lights` list's others.
    pub fn all_lights(&self) -> impl Iterator<Item = &PointLight> {
        std::iter::once(&self.light).chain(self.extra_lights.iter())
    }

    /// The number of lights.
    pub fn light_count(&self) -> usize {
        1 + self.extra_lights.len()
    }

    /// The light at `index` in the list (0: the first).
    pub fn light_at(&self, index: usize) -> &PointLight {
        if index == 0 {
            &self.light
        } else {
            &self.extra_lights[index - 1]
        }
    }

    /// The light at `index` in the list, to change it.
    pub fn light_at_mut(&mut self, index: usize) -> &mut PointLight {
        if index == 0 {
            &mut self.light
        } else {
            &mut self.extra_lights[index - 1]
        }
    }

    /// True when the one-light fitness models the scene's lighting exactly: one point or directional light.
    pub fn single_point_light(&self) -> bool {
        self.extra_lights.is_empty() && self.light.radius == 0.0 && self.light.rect.is_none()
    }
}
