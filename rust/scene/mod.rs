//! The scene: the one owner of parsing and validation of rtloop's JSON scene format.
//!
//! Units are metres, right-handed, +y up, linear RGB. Values are kept in `f64` exactly as written;
//! the renderer converts to its own `f32` working form. Every validation error names its field,
//! e.g. `objects[1].normal: zero-length normal`.

use serde::Deserialize;
use serde_json::{json, Map, Value};

use crate::error::{Error, Result};
pub use coat::CoatSpec;
use coat::{coat_spec, RawCoat};

mod checks;
mod coat;
mod fit;
pub mod lights;
mod mesh;
mod target;
use checks::{cross, finite, finite3, finite_direction, finite_upto, nonneg3};
pub(crate) use checks::{norm, unit};
pub use checks::{MAX_INTENSITY, MAX_MAGNITUDE};
use fit::parse_fit_entry;
pub use lights::{PointLight, RectLight};
pub use target::{positive_size, Target, FITTABLE, MIN_SIZE};

use std::path::Path;
use std::sync::Arc;

pub type V3 = [f64; 3];

#[derive(Clone, Debug, PartialEq)]
pub struct Camera {
    pub position: V3,
    pub look_at: V3,
    pub up: V3,
    /// Full vertical field of view in degrees.
    pub vfov_deg: f64,
}

#[derive(Clone, Debug, PartialEq)]
pub struct Material {
    pub albedo: V3,
    pub specular: f64,
    pub shininess: f64,
    /// A clear coat over the base (`render::coat`): the lobe is the coat's GGX one, weighted by
    /// `specular`, and `shininess` is unused.
    pub coat: Option<CoatSpec>,
}

#[derive(Clone, Debug, PartialEq)]
pub enum Shape {
    Sphere {
        center: V3,
        radius: f64,
    },
    /// Infinite, two-sided plane.
    Plane {
        point: V3,
        normal: V3,
    },
    /// A triangle mesh from an OBJ file (two-sided), placed at `position` and scaled by `scale`.
    Mesh {
        /// The file, absolute (resolved against the scene file's folder when read from a file).
        file: String,
        position: V3,
        scale: f64,
        mesh: Arc<crate::geometry::mesh::Mesh>,
    },
}

#[derive(Clone, Debug, PartialEq)]
pub struct Object {
    pub name: String,
    pub shape: Shape,
    pub material: Material,
}

/// One free parameter of the fit section: a dotted path and its bounds (one entry per component).
#[derive(Clone, Debug, PartialEq)]
pub struct FitParam {
    pub path: String,
    pub target: Target,
    pub min: Vec<f64>,
    pub max: Vec<f64>,
}

#[derive(Clone, Debug, PartialEq)]
pub struct Scene {
    pub width: u32,
    pub height: u32,
    pub camera: Camera,
    /// The first light (the only one of a scene with `light`).
    pub light: PointLight,
    /// The `lights` list's further lights, in order (empty for a scene with one light).
    pub extra_lights: Vec<PointLight>,
    pub ambient: V3,
    /// Constant environment radiance per channel (a room's light from every direction), occluded by the
    /// scene's own spheres and planes (`render::environment`); `ambient` is the unoccluded constant term.
    pub environment: V3,
    /// Model one diffuse bounce between the objects (`render::bounce`); off by default.
    pub interreflection: bool,
    pub background: V3,
    pub exposure: f64,
    pub objects: Vec<Object>,
    /// Free parameters in canonical order (light, globals, then objects in scene order).
    pub fit: Vec<FitParam>,
    /// Top-level descriptive keys carried through unchanged (`name`, `description`, `fit_report`, `meta`).
    pub extra: Map<String, Value>,
}

// ---------------------------------------------------------------- raw (serde) form

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawScene {
    image: RawImage,
    camera: RawCamera,
    light: Option<lights::RawLight>,
    lights: Option<Vec<lights::RawLight>>,
    ambient: Option<V3>,
    environment: Option<V3>,
    interreflection: Option<bool>,
    background: Option<V3>,
    exposure: Option<f64>,
    objects: Vec<RawObject>,
    fit: Option<Map<String, Value>>,
    name: Option<Value>,
    description: Option<Value>,
    fit_report: Option<Value>,
    meta: Option<Value>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawImage {
    width: i64,
    height: i64,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawCamera {
    position: V3,
    look_at: V3,
    up: Option<V3>,
    vfov_deg: f64,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawObject {
    name: Option<String>,
    shape: String,
    center: Option<V3>,
    radius: Option<f64>,
    point: Option<V3>,
    normal: Option<V3>,
    file: Option<String>,
    position: Option<V3>,
    scale: Option<f64>,
    material: Option<RawMaterial>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawMaterial {
    albedo: Option<V3>,
    specular: Option<f64>,
    shininess: Option<f64>,
    coat: Option<RawCoat>,
}

impl Scene {
    /// Parse and validate a scene from JSON text; mesh files are resolved against the current directory.
    pub fn from_json(text: &str) -> Result<Scene> {
        Scene::from_json_in(text, None)
    }

    /// Parse and validate a scene from JSON text, resolving relative mesh files against `base` (the
    /// scene file's folder; the current directory when `None`).
    pub fn from_json_in(text: &str, base: Option<&Path>) -> Result<Scene> {
        let de = &mut serde_json::Deserializer::from_str(text);
        let raw: RawScene = serde_path_to_error::deserialize(de).map_err(|e| {
            let path = e.path().to_string();
            let inner = e.into_inner();
            if path.is_empty() || path == "." {
                Error::Scene(format!("scene: {inner}"))
            } else {
                Error::scene(path, inner)
            }
        })?;
        Scene::from_raw(raw, base)
    }

    fn from_raw(raw: RawScene, base: Option<&Path>) -> Result<Scene> {
        let width = raw.image.width;
        let height = raw.image.height;
        for (field, v) in [("image.width", width), ("image.height", height)] {
            if !(1..=16384).contains(&v) {
                return Err(Error::scene(
                    field,
                    format!("must be between 1 and 16384 pixels (got {v})"),
                ));
            }
        }

        let c = &raw.camera;
        let camera = Camera {
            position: finite3("camera.position", c.position)?,
            look_at: finite3("camera.look_at", c.look_at)?,
            up: finite_direction("camera.up", c.up.unwrap_or([0.0, 1.0, 0.0]))?,
            vfov_deg: finite("camera.vfov_deg", c.vfov_deg)?,
        };
        if !(camera.vfov_deg > 0.0 && camera.vfov_deg < 180.0) {
            return Err(Error::scene(
                "camera.vfov_deg",
                format!("must be in (0, 180) degrees (got {})", camera.vfov_deg),
            ));
        }
        let fwd = [
            camera.look_at[0] - camera.position[0],
            camera.look_at[1] - camera.position[1],
            camera.look_at[2] - camera.position[2],
        ];
        let scale = norm(camera.position)
            .max(norm(camera.look_at))
            .max(f64::MIN_POSITIVE);
        if norm(fwd) <= 1e-12 * scale {
            return Err(Error::scene(
                "camera.look_at",
                "coincides with camera.position",
            ));
        }
        if norm(camera.up) == 0.0 {
            return Err(Error::scene("camera.up", "zero-length vector"));
        }
        if norm(cross(unit(fwd).to_array(), unit(camera.up).to_array())) <= 1e-9 {
            return Err(Error::scene(
                "camera.up",
                "is parallel to the viewing direction (look_at - position)",
            ));
        }

        let (light, extra_lights) = lights::parse_lights(raw.light, raw.lights)?;

        let ambient = nonneg3("ambient", raw.ambient.unwrap_or([0.0; 3]))?;
        let environment = nonneg3("environment", raw.environment.unwrap_or([0.0; 3]))?;
        let background = nonneg3("background", raw.background.unwrap_or([0.0; 3]))?;
        let exposure = finite("exposure", raw.exposure.unwrap_or(1.0))?;
        if exposure <= 0.0 {
            return Err(Error::scene(
                "exposure",
                format!("must be > 0 (got {exposure})"),
            ));
        }

        if raw.objects.is_empty() {
            return Err(Error::scene(
                "objects",
                "the scene needs at least one object",
            ));
        }
        let mut objects = Vec::with_capacity(raw.objects.len());
        for (i, o) in raw.objects.into_iter().enumerate() {
            objects.push(parse_object(i, o, &objects, base)?);
        }

        let mut scene = Scene {
            width: width as u32,
            height: height as u32,
            camera,
            light,
            extra_lights,
            ambient,
            environment,
            interreflection: raw.interreflection.unwrap_or(false),
            background,
            exposure,
            objects,
            fit: Vec::new(),
            extra: Map::new(),
        };
        for (key, v) in [
            ("name", raw.name),
            ("description", raw.description),
            ("fit_report", raw.fit_report),
            ("meta", raw.meta),
        ] {
            if let Some(v) = v {
                scene.extra.insert(key.to_string(), v);
            }
        }
        let mut fit = Vec::new();
        for (path, bounds) in raw.fit.unwrap_or_default() {
            let entry = parse_fit_entry(&scene, &path, &bounds)?;
            if fit.iter().any(|f: &FitParam| f.target == entry.target) {
                return Err(Error::scene(
                    format!("fit[{path:?}]"),
                    format!("names the same parameter as another entry ({})", entry.path),
                ));
            }
            fit.push(entry);
        }
        fit.sort_by_key(|p| p.target.order_key());
        scene.fit = fit;
        Ok(scene)
    }

    /// The index of the object called `name`.
    pub fn object_index(&self, name: &str) -> Option<usize> {
        self.objects.iter().position(|o| o.name == name)
    }

    /// The scene as JSON in the public format (defaults written out).
    pub fn to_value(&self) -> Value {
        let objects: Vec<Value> = self
            .objects
            .iter()
            .map(|o| {
                let mut v = match &o.shape {
                    Shape::Sphere { center, radius } => {
                        json!({"name": o.name, "shape": "sphere", "center": center, "radius": radius})
                    }
                    Shape::Plane { point, normal } => {
                        json!({"name": o.name, "shape": "plane", "point": point, "normal": normal})
                    }
                    Shape::Mesh {
                        file,
                        position,
                        scale,
                        ..
                    } => {
                        json!({"name": o.name, "shape": "mesh", "file": file, "position": position,
                               "scale": scale})
                    }
                };
                v["material"] = json!({
                    "albedo": o.material.albedo,
                    "specular": o.material.specular,
                    "shininess": o.material.shininess,
                });
                if let Some(c) = o.material.coat {
                    v["material"]["coat"] = json!({"roughness": c.roughness, "ior": c.ior});
                }
                v
            })
            .collect();
        let mut fit = Map::new();
        for p in &self.fit {
            fit.insert(p.path.clone(), p.to_value());
        }
        let mut out = Map::new();
        for key in ["name", "description"] {
            if let Some(v) = self.extra.get(key) {
                out.insert(key.into(), v.clone());
            }
        }
        out.insert(
            "image".into(),
            json!({"width": self.width, "height": self.height}),
        );
        out.insert(
            "camera".into(),
            json!({"position": self.camera.position, "look_at": self.camera.look_at,
                   "up": self.camera.up, "vfov_deg": self.camera.vfov_deg}),
        );
        if !self.single_point_light() {
            let list: Vec<Value> = self
                .all_lights()
                .map(|l| lights::light_value(l, true))
                .collect();
            out.insert("lights".into(), Value::Array(list));
        } else {
            out.insert("light".into(), lights::light_value(&self.light, false));
        }
        out.insert("ambient".into(), json!(self.ambient));
        if self.environment != [0.0; 3] {
            out.insert("environment".into(), json!(self.environment));
        }
        if self.interreflection {
            out.insert("interreflection".into(), json!(true));
        }
        out.insert("background".into(), json!(self.background));
        out.insert("exposure".into(), json!(self.exposure));
        out.insert("objects".into(), Value::Array(objects));
        out.insert("fit".into(), Value::Object(fit));
        for key in ["meta", "fit_report"] {
            if let Some(v) = self.extra.get(key) {
                out.insert(key.into(), v.clone());
            }
        }
        Value::Object(out)
    }

    /// A copy whose fit section has `bounds` for each `(path, bounds)` (added when the path is new),
    /// validated as [`Scene::from_json`] validates a fit entry. `bounds` is the JSON form
    /// `{"min": ..., "max": ...}`, each a number or one per component.
    pub fn with_bounds(&self, changes: &[(String, Value)]) -> Result<Scene> {
        let mut scene = self.clone();
        for (path, bounds) in changes {
            let entry = parse_fit_entry(&scene, path, bounds)?;
            match scene.fit.iter_mut().find(|f| f.path == *path) {
                Some(f) => *f = entry,
                None => scene.fit.push(entry),
            }
        }
        scene.fit.sort_by_key(|p| p.target.order_key());
        Ok(scene)
    }

    /// A copy with `other`'s fit section, validated against this scene (its objects and light).
    pub fn with_fit(&self, other: &Scene) -> Result<Scene> {
        let mut scene = self.without_fit();
        let mut changes: Vec<(String, Value)> = other
            .fit
            .iter()
            .map(|p| (p.path.clone(), p.to_value()))
            .collect();
        changes.sort_by(|a, b| a.0.cmp(&b.0)); // the order `from_json` checks them in
        let mut fit = Vec::with_capacity(changes.len());
        for (path, bounds) in &changes {
            fit.push(parse_fit_entry(&scene, path, bounds)?);
        }
        fit.sort_by_key(|p| p.target.order_key());
        scene.fit = fit;
        Ok(scene)
    }

    /// A copy with an empty fit section.
    pub fn without_fit(&self) -> Scene {
        Scene {
            fit: Vec::new(),
            ..self.clone()
        }
    }

    /// True when some object sits between a surface and the light for some light position: with one
    /// object (a convex sphere or a plane) nothing can shadow anything; a mesh may shadow itself.
    pub fn can_occlude(&self) -> bool {
        self.objects.len() > 1
            || self
                .objects
                .iter()
                .any(|o| matches!(o.shape, Shape::Mesh { .. }))
    }
}

fn parse_object(
    i: usize,
    o: RawObject,
    previous: &[Object],
    base: Option<&Path>,
) -> Result<Object> {
    let name = o.name.unwrap_or_else(|| format!("object{i}"));
    let f = |field: &str| format!("objects[{i}].{field}");
    if name.is_empty() || name.contains('.') {
        return Err(Error::scene(
            f("name"),
            format!("must be non-empty and contain no '.' (got {name:?})"),
        ));
    }
    if previous.iter().any(|p| p.name == name) {
        return Err(Error::scene(
            f("name"),
            format!("duplicate object name {name:?}"),
        ));
    }
    let need = |v: Option<V3>, field: &str| -> Result<V3> {
        let v =
            v.ok_or_else(|| Error::scene(f(field), format!("missing field for a {}", o.shape)))?;
        if field == "normal" {
            finite_direction(&f(field), v)
        } else {
            finite3(&f(field), v)
        }
    };
    let forbid = |present: bool, field: &str| -> Result<()> {
        if present {
            Err(Error::scene(
                f(field),
                format!("not a field of a {} (a typo for another field?)", o.shape),
            ))
        } else {
            Ok(())
        }
    };
    if o.shape != "mesh" {
        forbid(o.file.is_some(), "file")?;
        forbid(o.position.is_some(), "position")?;
        forbid(o.scale.is_some(), "scale")?;
    }
    let shape = match o.shape.as_str() {
        "sphere" => {
            forbid(o.point.is_some(), "point")?;
            forbid(o.normal.is_some(), "normal")?;
            let center = need(o.center, "center")?;
            let radius = o
                .radius
                .ok_or_else(|| Error::scene(f("radius"), "missing field for a sphere"))?;
            let radius = finite(&f("radius"), radius)?;
            if radius <= 0.0 {
                return Err(Error::scene(
                    f("radius"),
                    format!("must be > 0 (got {radius})"),
                ));
            }
            Shape::Sphere { center, radius }
        }
        "plane" => {
            forbid(o.center.is_some(), "center")?;
            forbid(o.radius.is_some(), "radius")?;
            let point = need(o.point, "point")?;
            let normal = need(o.normal, "normal")?;
            let n = norm(normal);
            if n == 0.0 || !n.is_finite() {
                return Err(Error::scene(f("normal"), "zero-length normal"));
            }
            Shape::Plane { point, normal }
        }
        "mesh" => {
            for (present, field) in [
                (o.center.is_some(), "center"),
                (o.radius.is_some(), "radius"),
                (o.point.is_some(), "point"),
                (o.normal.is_some(), "normal"),
            ] {
                forbid(present, field)?;
            }
            let file = o
                .file
                .as_deref()
                .ok_or_else(|| Error::scene(f("file"), "missing field for a mesh (an OBJ file)"))?;
            let position = finite3(&f("position"), o.position.unwrap_or([0.0; 3]))?;
            let scale = finite(&f("scale"), o.scale.unwrap_or(1.0))?;
            if scale <= 0.0 {
                return Err(Error::scene(
                    f("scale"),
                    format!("must be > 0 (got {scale})"),
                ));
            }
            let path = mesh::resolve(file, base);
            let mesh = mesh::load(&f("file"), &path, position, scale)?;
            Shape::Mesh {
                file: path.to_string_lossy().into_owned(),
                position,
                scale,
                mesh,
            }
        }
        other => {
            return Err(Error::scene(
                f("shape"),
                format!("unknown shape {other:?} (known shapes: \"sphere\", \"plane\", \"mesh\")"),
            ))
        }
    };
    let m = o.material.unwrap_or(RawMaterial {
        albedo: None,
        specular: None,
        shininess: None,
        coat: None,
    });
    let coat = match &m.coat {
        None => None,
        Some(c) => Some(coat_spec(&f("material.coat"), c)?),
    };
    // A coat's lobe weight is 1 (a physical coat, Mitsuba's `specular_reflectance`) unless given.
    let specular_default = if coat.is_some() { 1.0 } else { 0.0 };
    let material = Material {
        albedo: nonneg3(&f("material.albedo"), m.albedo.unwrap_or([0.5; 3]))?,
        specular: finite(
            &f("material.specular"),
            m.specular.unwrap_or(specular_default),
        )?,
        shininess: finite(&f("material.shininess"), m.shininess.unwrap_or(0.0))?,
        coat,
    };
    if material.specular < 0.0 {
        return Err(Error::scene(
            f("material.specular"),
            format!("must be >= 0 (got {})", material.specular),
        ));
    }
    if material.shininess < 0.0 {
        return Err(Error::scene(
            f("material.shininess"),
            format!("must be >= 0 (got {})", material.shininess),
        ));
    }
    Ok(Object {
        name,
        shape,
        material,
    })
}
