//! What a dotted fit path (`light.position`, `objects.NAME.albedo`, ...) refers to in a scene, and how
//! to read and write it.

use super::Scene;

/// What a dotted fit path refers to.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Target {
    LightPosition,
    /// A directional light's direction (3 components, normalised on use).
    LightDirection,
    LightIntensity,
    LightColor,
    Ambient,
    /// The occluded constant environment radiance (3 components).
    Environment,
    Exposure,
    Albedo(usize),
    Specular(usize),
    Shininess(usize),
    /// A coated object's coat roughness (GGX α).
    Roughness(usize),
    /// A further light's (index >= 1 in the `lights` list) position, direction, intensity and colour.
    ExtraPosition(usize),
    ExtraDirection(usize),
    ExtraIntensity(usize),
    ExtraColor(usize),
    /// A sphere light's radius (any index).
    Radius(usize),
    /// A rectangle light's size, width and height in metres (any index).
    Size(usize),
}

/// The fittable paths, for error messages and documentation.
pub const FITTABLE: &str = "light.position (point light), light.direction (directional light), \
light.intensity, light.color, ambient, environment, exposure, \
objects.NAME.albedo, objects.NAME.specular, objects.NAME.shininess, \
objects.NAME.roughness (coated), lights.NAME.position, lights.NAME.direction, lights.NAME.intensity, lights.NAME.color, \
lights.NAME.radius (sphere light), lights.NAME.size (rectangle light: [width, height]; its position is its centre)";

impl Target {
    /// Parse a dotted path such as `objects.ball.albedo`. The error is a bare reason; the caller adds the field.
    pub fn parse(path: &str, scene: &Scene) -> std::result::Result<Target, String> {
        let directional = scene.light.direction.is_some();
        let t = match path {
            "light.position" if directional => {
                return Err("the light is directional: fit light.direction, not light.position".into())
            }
            "light.direction" if !directional => {
                return Err("the light is a point light: fit light.position (or make it \"type\": \"directional\")".into())
            }
            "light.position" => Target::LightPosition,
            "light.direction" => Target::LightDirection,
            "light.intensity" => Target::LightIntensity,
            "light.color" => Target::LightColor,
            "ambient" => Target::Ambient,
            "environment" => Target::Environment,
            "exposure" => Target::Exposure,
            _ if path.starts_with("lights.") => return parse_light_path(path, scene),
            _ => {
                let parts: Vec<&str> = path.split('.').collect();
                if parts.len() != 3 || parts[0] != "objects" {
                    return Err(format!(
                        "unknown parameter path {path:?} (fittable: {FITTABLE})"
                    ));
                }
                let i = scene.object_index(parts[1]).ok_or_else(|| {
                    let names: Vec<&str> = scene.objects.iter().map(|o| o.name.as_str()).collect();
                    format!(
                        "unknown object {:?} (objects are: {})",
                        parts[1],
                        names.join(", ")
                    )
                })?;
                match parts[2] {
                    "albedo" => Target::Albedo(i),
                    "specular" => Target::Specular(i),
                    "shininess" => Target::Shininess(i),
                    "roughness" if scene.objects[i].material.coat.is_some() => Target::Roughness(i),
                    "roughness" => {
                        return Err(format!(
                            "objects.{}.roughness: the object has no coat (give its material a \"coat\")",
                            parts[1]
                        ))
                    }
                    other => {
                        return Err(format!(
                            "objects.{}.{other} cannot be fitted (fittable per object: albedo, specular, shininess, roughness)",
                            parts[1]
                        ))
                    }
                }
            }
        };
        Ok(t)
    }

    /// Number of scalar components.
    pub fn len(&self) -> usize {
        match self {
            Target::LightPosition
            | Target::LightDirection
            | Target::LightColor
            | Target::Ambient
            | Target::Environment
            | Target::Albedo(_)
            | Target::ExtraPosition(_)
            | Target::ExtraDirection(_)
            | Target::ExtraColor(_) => 3,
            Target::Size(_) => 2,
            Target::ExtraIntensity(_)
            | Target::Radius(_)
            | Target::LightIntensity
            | Target::Exposure
            | Target::Specular(_)
            | Target::Shininess(_)
            | Target::Roughness(_) => 1,
        }
    }

    /// Canonical order: the paper's [light x, y, z, power, objects' RGB...].
    pub fn order_key(&self) -> (usize, usize, usize) {
        match *self {
            Target::LightPosition | Target::LightDirection => (0, 0, 0),
            Target::LightIntensity => (0, 0, 1),
            Target::LightColor => (0, 0, 2),
            Target::Ambient => (1, 0, 0),
            Target::Environment => (1, 0, 1),
            Target::Exposure => (1, 0, 2),
            Target::Albedo(i) => (2, i, 0),
            Target::Specular(i) => (2, i, 1),
            Target::Shininess(i) => (2, i, 2),
            Target::Roughness(i) => (2, i, 3),
            Target::ExtraPosition(i) | Target::ExtraDirection(i) => (0, i, 0),
            Target::ExtraIntensity(i) => (0, i, 1),
            Target::ExtraColor(i) => (0, i, 2),
            Target::Radius(i) => (0, i, 3),
            Target::Size(i) => (0, i, 4),
        }
    }

    /// The smallest physically meaningful value, if any.
    pub fn lower_limit(&self) -> Option<f64> {
        match self {
            Target::LightPosition
            | Target::LightDirection
            | Target::ExtraPosition(_)
            | Target::ExtraDirection(_) => None,
            _ => Some(0.0),
        }
    }

    /// True for parameters the image depends on linearly (albedo, intensity, colour, ambient, exposure, specular).
    pub fn is_linear(&self) -> bool {
        !matches!(
            self,
            Target::LightPosition
                | Target::LightDirection
                | Target::Shininess(_)
                | Target::Roughness(_)
                | Target::ExtraPosition(_)
                | Target::ExtraDirection(_)
                | Target::Radius(_)
                | Target::Size(_)
        )
    }

    /// True for a light's intensity (bounded by `MAX_INTENSITY`, not `MAX_MAGNITUDE`).
    pub fn is_intensity(&self) -> bool {
        matches!(self, Target::LightIntensity | Target::ExtraIntensity(_))
    }

    /// True for a light's position or direction (components x, y, z).
    pub fn is_vector(&self) -> bool {
        matches!(
            self,
            Target::LightPosition
                | Target::LightDirection
                | Target::ExtraPosition(_)
                | Target::ExtraDirection(_)
        )
    }

    /// Current value in `scene`.
    pub fn get(&self, scene: &Scene) -> Vec<f64> {
        match *self {
            Target::LightPosition => scene.light.position.to_vec(),
            Target::LightDirection => scene.light.direction.unwrap_or([0.0, 1.0, 0.0]).to_vec(),
            Target::LightIntensity => vec![scene.light.intensity],
            Target::LightColor => scene.light.color.to_vec(),
            Target::Ambient => scene.ambient.to_vec(),
            Target::Environment => scene.environment.to_vec(),
            Target::Exposure => vec![scene.exposure],
            Target::Albedo(i) => scene.objects[i].material.albedo.to_vec(),
            Target::Specular(i) => vec![scene.objects[i].material.specular],
            Target::Shininess(i) => vec![scene.objects[i].material.shininess],
            Target::Roughness(i) => {
                vec![scene.objects[i].material.coat.map_or(0.0, |c| c.roughness)]
            }
            Target::ExtraPosition(i) => scene.light_at(i).position.to_vec(),
            Target::ExtraDirection(i) => scene
                .light_at(i)
                .direction
                .unwrap_or([0.0, 1.0, 0.0])
                .to_vec(),
            Target::ExtraIntensity(i) => vec![scene.light_at(i).intensity],
            Target::ExtraColor(i) => scene.light_at(i).color.to_vec(),
            Target::Radius(i) => vec![scene.light_at(i).radius],
            Target::Size(i) => scene
                .light_at(i)
                .rect
                .map_or(vec![0.0, 0.0], |r| r.size.to_vec()),
        }
    }

    /// Write `v` (of length `self.len()`) into `scene`.
    pub fn set(&self, scene: &mut Scene, v: &[f64]) {
        let v3 = || [v[0], v[1], v[2]];
        match *self {
            Target::LightPosition => scene.light.position = v3(),
            Target::LightDirection => scene.light.direction = Some(unit_or_up(v)),
            Target::LightIntensity => scene.light.intensity = v[0],
            Target::LightColor => scene.light.color = v3(),
            Target::Ambient => scene.ambient = v3(),
            Target::Environment => scene.environment = v3(),
            Target::Exposure => scene.exposure = v[0],
            Target::Albedo(i) => scene.objects[i].material.albedo = v3(),
            Target::Specular(i) => scene.objects[i].material.specular = v[0],
            Target::Shininess(i) => scene.objects[i].material.shininess = v[0],
            Target::Roughness(i) => {
                if let Some(c) = &mut scene.objects[i].material.coat {
                    let (lo, hi) = crate::render::coat::ALPHA_RANGE;
                    c.roughness = v[0].clamp(lo, hi);
                }
            }
            Target::ExtraPosition(i) => scene.light_at_mut(i).position = v3(),
            Target::ExtraDirection(i) => scene.light_at_mut(i).direction = Some(unit_or_up(v)),
            Target::ExtraIntensity(i) => scene.light_at_mut(i).intensity = v[0],
            Target::ExtraColor(i) => scene.light_at_mut(i).color = v3(),
            Target::Radius(i) => scene.light_at_mut(i).radius = v[0].max(0.0),
            Target::Size(i) => {
                if let Some(r) = &mut scene.light_at_mut(i).rect {
                    r.size = [positive_size(v[0]), positive_size(v[1])];
                }
            }
        }
    }
}

/// The smallest rectangle side a fit writes (metres): a scene's size must stay > 0.
pub const MIN_SIZE: f64 = 1e-6;

/// A rectangle light's side as a fit writes it: at least `MIN_SIZE` (NaN too).
pub fn positive_size(v: f64) -> f64 {
    if v >= MIN_SIZE {
        v
    } else {
        MIN_SIZE
    }
}

/// `v` normalised; straight up for a zero or non-finite vector.
fn unit_or_up(v: &[f64]) -> [f64; 3] {
    let n = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
    if n > 0.0 && n.is_finite() {
        [v[0] / n, v[1] / n, v[2] / n]
    } else {
        [0.0, 1.0, 0.0]
    }
}

/// A `lights.NAME.FIELD` path. The first light's position, direction, intensity and colour are the
/// single light's own targets (`light.position`, ...): a one-light scene fits the same way either way.
fn parse_light_path(path: &str, scene: &Scene) -> std::result::Result<Target, String> {
    let parts: Vec<&str> = path.split('.').collect();
    if parts.len() != 3 {
        return Err(format!(
            "unknown parameter path {path:?} (fittable: {FITTABLE})"
        ));
    }
    let i = scene
        .all_lights()
        .position(|l| l.name == parts[1])
        .ok_or_else(|| {
            let names: Vec<&str> = scene.all_lights().map(|l| l.name.as_str()).collect();
            format!(
                "unknown light {:?} (lights are: {})",
                parts[1],
                names.join(", ")
            )
        })?;
    let l = scene.light_at(i);
    let directional = l.direction.is_some();
    let t = match (parts[2], i) {
        ("position", _) if directional => {
            return Err(format!("light {:?} is directional: fit its direction, not its position", parts[1]))
        }
        ("direction", _) if !directional => {
            return Err(format!("light {:?} has a position, not a direction", parts[1]))
        }
        ("radius", _) if l.radius <= 0.0 => {
            return Err(format!("light {:?} is not a sphere light: it has no radius", parts[1]))
        }
        ("size", _) if l.rect.is_none() => {
            return Err(format!(
                "light {:?} is not a rectangle light: it has no size",
                parts[1]
            ))
        }
        ("position", 0) => Target::LightPosition,
        ("direction", 0) => Target::LightDirection,
        ("intensity", 0) => Target::LightIntensity,
        ("color", 0) => Target::LightColor,
        ("position", _) => Target::ExtraPosition(i),
        ("direction", _) => Target::ExtraDirection(i),
        ("intensity", _) => Target::ExtraIntensity(i),
        ("color", _) => Target::ExtraColor(i),
        ("radius", _) => Target::Radius(i),
        ("size", _) => Target::Size(i),
        (other, _) => {
            return Err(format!(
                "lights.{}.{other} cannot be fitted (fittable per light: position, direction, intensity, color, radius, size)",
                parts[1]
            ))
        }
    };
    Ok(t)
}
