//! Property tests (proptest) in bounded time: scene parsing under random mutations of a valid scene, fit
//! parameters (set, get, bounds), the fitness kernel against the renderer, and ray–sphere / ray–plane /
//! ray–triangle intersection against a float64 reference.
//! `PROPTEST_CASES` makes a longer run.

use glam::{DVec3, Vec3A};
use proptest::prelude::*;
use rtloop::params::Target;
use rtloop::render::brdf::specular_scale;
use rtloop::render::shape::PShape;
use rtloop::search::Objective;
use rtloop::search::Rng;
use rtloop::{render, Fitness, FitnessSpec, GBuffer, LossKind, ParamLayout, Projection, Scene};
use serde_json::Value;

const SCENE: &str = r#"{"image": {"width": 16, "height": 12},
  "camera": {"position": [0, 1, -5], "look_at": [0, 0.5, 0], "vfov_deg": 40},
  "light": {"position": [2, 4, -2], "intensity": 50},
  "ambient": [0.02, 0.02, 0.02], "exposure": 1.0,
  "objects": [
    {"name": "ball", "shape": "sphere", "center": [0, 0.5, 0], "radius": 0.5,
     "material": {"albedo": [0.8, 0.3, 0.2], "specular": 0.2, "shininess": 20}},
    {"name": "floor", "shape": "plane", "point": [0, 0, 0], "normal": [0, 1, 0],
     "material": {"albedo": [0.5, 0.5, 0.5]}}],
  "fit": {"light.position": {"min": [-5, 0.5, -5], "max": [5, 8, 5]},
          "objects.ball.albedo": {"min": 0, "max": 1}}}"#;

/// `n` cases, or `PROPTEST_CASES` where set (a longer campaign).
fn cases(n: u32) -> u32 {
    std::env::var("PROPTEST_CASES")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(n)
}

/// Every (path, key) of `v`: the key is the last object key on the way (the field an error must name).
fn paths(v: &Value, at: &mut Vec<Value>, key: &str, out: &mut Vec<(Vec<Value>, String)>) {
    out.push((at.clone(), key.to_string()));
    match v {
        Value::Object(m) => {
            for (k, c) in m {
                at.push(Value::String(k.clone()));
                paths(c, at, k, out);
                at.pop();
            }
        }
        Value::Array(a) => {
            for (i, c) in a.iter().enumerate() {
                at.push(Value::from(i));
                paths(c, at, key, out);
                at.pop();
            }
        }
        _ => {}
    }
}

fn at_mut<'a>(v: &'a mut Value, path: &[Value]) -> &'a mut Value {
    path.iter().fold(v, |v, p| match p {
        Value::String(k) => &mut v[k.as_str()],
        _ => &mut v[p.as_u64().unwrap() as usize],
    })
}

fn odd_value() -> impl Strategy<Value = Value> {
    let leaf = prop_oneof![
        Just(Value::Null),
        any::<bool>().prop_map(Value::from),
        any::<f64>().prop_map(Value::from),
        prop_oneof![Just(0.0), Just(-1.0), Just(1e300), Just(-1e-300), Just(1e9)]
            .prop_map(Value::from),
        any::<i64>().prop_map(Value::from),
        "[a-z. ]{0,12}".prop_map(Value::from),
    ];
    leaf.prop_recursive(2, 8, 4, |inner| {
        prop_oneof![
            prop::collection::vec(inner.clone(), 0..5).prop_map(Value::from),
            prop::collection::btree_map("[a-z]{1,6}", inner, 0..3)
                .prop_map(|m| Value::Object(m.into_iter().collect())),
        ]
    })
}

/// A scene with a `lights` list: a point light, a sphere light and a directional one, each fitted.
const LIGHTS_SCENE: &str = r#"{"image": {"width": 16, "height": 12},
  "camera": {"position": [0, 1, -5], "look_at": [0, 0.5, 0], "vfov_deg": 40},
  "lights": [{"name": "key", "position": [2, 4, -2], "intensity": 50},
             {"name": "fill", "type": "sphere", "position": [-3, 3, -1], "radius": 0.3, "intensity": 10,
              "color": [1, 0.9, 0.8]},
             {"name": "sun", "type": "directional", "direction": [0, 1, 0.2], "intensity": 0.5}],
  "objects": [
    {"name": "ball", "shape": "sphere", "center": [0, 0.5, 0], "radius": 0.5},
    {"name": "floor", "shape": "plane", "point": [0, 0, 0], "normal": [0, 1, 0]}],
  "fit": {"lights.fill.position": {"min": [-5, 0.5, -5], "max": [5, 8, 5]},
          "lights.fill.radius": {"min": 0.01, "max": 1},
          "lights.sun.direction": {"min": -1, "max": 1},
          "lights.key.intensity": {"min": 0, "max": 100}}}"#;

/// A scene with a coated ball (`material.coat`) whose roughness and specular weight are fitted.
const COAT_SCENE: &str = r#"{"image": {"width": 16, "height": 12},
  "camera": {"position": [0, 1, -5], "look_at": [0, 0.5, 0], "vfov_deg": 40},
  "light": {"position": [2, 4, -2], "intensity": 50},
  "objects": [
    {"name": "ball", "shape": "sphere", "center": [0, 0.5, 0], "radius": 0.5,
     "material": {"albedo": [0.8, 0.3, 0.2], "specular": 0.7, "coat": {"roughness": 0.2, "ior": 1.5}}},
    {"name": "floor", "shape": "plane", "point": [0, 0, 0], "normal": [0, 1, 0]}],
  "fit": {"light.position": {"min": [-5, 0.5, -5], "max": [5, 8, 5]},
          "objects.ball.roughness": {"min": 0.05, "max": 0.5},
          "objects.ball.specular": {"min": 0, "max": 2}}}"#;

/// A scene with a rectangle light (a window) beside a lamp, the window's centre, size and intensity fitted.
const WINDOW_SCENE: &str = r#"{"image": {"width": 16, "height": 12},
  "camera": {"position": [0, 1, -5], "look_at": [0, 0.5, 0], "vfov_deg": 40},
  "lights": [{"name": "lamp", "position": [2, 4, -2], "intensity": 50},
             {"name": "window", "type": "rectangle", "position": [-3.5, 2, 1], "size": [1.5, 1],
              "normal": [1, -0.2, -0.1], "up": [0, 1, 0], "intensity": 30, "color": [0.9, 0.95, 1]}],
  "objects": [
    {"name": "ball", "shape": "sphere", "center": [0, 0.5, 0], "radius": 0.5},
    {"name": "floor", "shape": "plane", "point": [0, 0, 0], "normal": [0, 1, 0]}],
  "fit": {"lights.window.position": {"min": [-5, 0.5, -5], "max": [5, 8, 5]},
          "lights.window.size": {"min": [0.5, 0.4], "max": [3, 2]},
          "lights.window.intensity": {"min": 0, "max": 100}}}"#;

/// Replace one value of `text` anywhere (or delete one key): the scene parses, or the error names the
/// field that was changed or one above it, in one line.
fn mutation_is_named(
    text: &str,
    pick: prop::sample::Index,
    value: Value,
    delete: bool,
) -> Result<(), TestCaseError> {
    let mut scene: Value = serde_json::from_str(text).unwrap();
    let mut all = Vec::new();
    paths(&scene, &mut Vec::new(), "", &mut all);
    let (path, key) = all[1 + pick.index(all.len() - 1)].clone();
    let parent_key = all
        .iter()
        .find(|(p, _)| p[..] == path[..path.len() - 1])
        .unwrap()
        .1
        .clone();
    let deleted = delete && matches!(path.last(), Some(Value::String(_)));
    if deleted {
        let (last, up) = path.split_last().unwrap();
        at_mut(&mut scene, up)
            .as_object_mut()
            .unwrap()
            .remove(last.as_str().unwrap());
    } else {
        *at_mut(&mut scene, &path) = value;
    }
    match Scene::from_json(&scene.to_string()) {
        Ok(s) => prop_assert!(s.width > 0 && s.height > 0),
        Err(e) => {
            let msg = e.to_string();
            prop_assert!(!msg.contains('\n'), "{msg}");
            let named = [key.as_str(), parent_key.as_str()]
                .iter()
                .chain(
                    path.iter()
                        .filter_map(|p| p.as_str())
                        .collect::<Vec<_>>()
                        .iter(),
                )
                .any(|k| !k.is_empty() && msg.contains(k));
            prop_assert!(
                named,
                "{path:?} ({}): {msg}",
                if deleted { "deleted" } else { "replaced" }
            );
        }
    }
    Ok(())
}

proptest! {
    #![proptest_config(ProptestConfig { cases: cases(256), ..ProptestConfig::default() })]

    /// Replacing one value anywhere (or deleting one key) never panics: the scene parses, or the error
    /// names the field that was changed or one above it.
    #[test]
    fn mutated_scenes_parse_or_name_a_field(pick in any::<prop::sample::Index>(), value in odd_value(),
                                            delete in any::<bool>()) {
        mutation_is_named(SCENE, pick, value, delete)?;
    }

    /// The same for a scene with a `lights` list (point, sphere and directional lights, fitted).
    #[test]
    fn mutated_light_lists_parse_or_name_a_field(pick in any::<prop::sample::Index>(), value in odd_value(),
                                                 delete in any::<bool>()) {
        mutation_is_named(LIGHTS_SCENE, pick, value, delete)?;
    }

    /// The same for a scene with a coated ball (its coat's fields and its fitted roughness).
    #[test]
    fn mutated_coats_parse_or_name_a_field(pick in any::<prop::sample::Index>(), value in odd_value(),
                                           delete in any::<bool>()) {
        mutation_is_named(COAT_SCENE, pick, value, delete)?;
    }

    /// A parsed coat renders finite, non-negative pixels for any roughness and IOR in range and any light.
    #[test]
    fn coats_render_finite(roughness in 1e-3f64..1.0, ior in 1.01f64..3.0, specular in 0.0f64..4.0,
                           light in [-5.0f64..5.0, 0.6f64..8.0, -5.0f64..5.0]) {
        let mut v: Value = serde_json::from_str(COAT_SCENE).unwrap();
        v["objects"][0]["material"]["coat"] = serde_json::json!({"roughness": roughness, "ior": ior});
        v["objects"][0]["material"]["specular"] = specular.into();
        v["light"]["position"] = serde_json::json!(light);
        let scene = Scene::from_json(&v.to_string()).unwrap();
        let img = render::render(&scene, None, None, 1).unwrap();
        prop_assert!(img.rgb.iter().all(|p| p.is_finite() && *p >= 0.0));
    }

    /// The same for a scene with a rectangle light.
    #[test]
    fn mutated_window_scenes_parse_or_name_a_field(pick in any::<prop::sample::Index>(), value in odd_value(),
                                                   delete in any::<bool>()) {
        mutation_is_named(WINDOW_SCENE, pick, value, delete)?;
    }
}

fn v3() -> impl Strategy<Value = [f32; 3]> {
    [-1e3f32..1e3, -1e3f32..1e3, -1e3f32..1e3]
}

fn unit(d: [f32; 3]) -> Option<Vec3A> {
    let v = Vec3A::from_array(d);
    (v.length() > 1e-3).then(|| v.normalize())
}

fn f64v(v: Vec3A) -> DVec3 {
    v.as_dvec3()
}

proptest! {
    #![proptest_config(ProptestConfig { cases: cases(2000), ..ProptestConfig::default() })]

    /// A sphere hit lies on the sphere (to f32 rounding of the scene's coordinates) at t > 0 with a unit
    /// outward normal; against float64, a clear hit is found at the same t and a clear miss is a miss.
    #[test]
    fn sphere_hits_lie_on_the_sphere(c in v3(), r in 1e-2f32..1e2, o in v3(), d in v3(), aim in any::<bool>()) {
        let (center, origin) = (Vec3A::from_array(c), Vec3A::from_array(o));
        // Half the rays aim near the sphere so that hits are common.
        let dir = if aim { unit((center + Vec3A::from_array(d) * (r / 1e3) - origin).to_array()) } else { unit(d) };
        let Some(dir) = dir else { return Ok(()) };
        let s = PShape::Sphere { center, radius: r };
        // float64 reference from the same (f32) inputs.
        let (oc, dd) = (f64v(origin) - f64v(center), f64v(dir));
        let b = oc.dot(dd);
        let dist2 = (oc - b * dd).length_squared();
        let (r64, disc) = (r as f64, (r as f64).powi(2) - (oc - b * dd).length_squared());
        let scale = (oc.length() + r64) as f32;
        let tol = 1e-5 * scale.max(1.0) + 1e-6 * center.abs().max_element();
        let reference = (disc >= 0.0).then(|| {
            let h = disc.sqrt();
            [-b - h, -b + h].into_iter().find(|&t| t > 1e-4 * scale as f64)
        }).flatten();
        match s.intersect(origin, dir, 1e-4 * scale, f32::INFINITY) {
            Some(hit) => {
                prop_assert!(hit.t > 0.0 && hit.t.is_finite());
                prop_assert!(hit.position.is_finite() && hit.normal.is_finite());
                let on = (f64v(hit.position) - f64v(center)).length() - r64;
                prop_assert!(on.abs() <= tol as f64, "off the surface by {on}, tol {tol}");
                prop_assert!((hit.normal.length() - 1.0).abs() < 1e-5);
                // A clear hit agrees with float64 on t.
                if let Some(t) = reference {
                    if r64 * r64 - dist2 > (tol as f64 * r64) {
                        prop_assert!((hit.t as f64 - t).abs() <= 4.0 * tol as f64, "t {} vs {t}", hit.t);
                    }
                }
            }
            None => {
                // A miss must be a real miss, or a graze within the tolerance.
                if let Some(t) = reference {
                    let graze = disc.sqrt() <= 4.0 * tol as f64 || t <= 2e-4 * scale as f64 + tol as f64;
                    prop_assert!(graze, "missed a float64 hit at t {t} (disc {disc}, tol {tol})");
                }
            }
        }
    }

    /// A plane hit lies on the plane at t > 0; a miss is a ray parallel to it or pointing away.
    #[test]
    fn plane_hits_lie_on_the_plane(p in v3(), n in v3(), o in v3(), d in v3()) {
        let (Some(normal), Some(dir)) = (unit(n), unit(d)) else { return Ok(()) };
        let (point, origin) = (Vec3A::from_array(p), Vec3A::from_array(o));
        let s = PShape::Plane { point, normal };
        let (nn, dd) = (f64v(normal), f64v(dir));
        let denom = nn.dot(dd);
        let t_ref = nn.dot(f64v(point) - f64v(origin)) / denom;
        let scale = 1.0 + point.abs().max_element() + origin.abs().max_element();
        let tol = 1e-5 * scale;
        match s.intersect(origin, dir, 1e-4 * scale, f32::INFINITY) {
            Some(hit) => {
                prop_assert!(hit.t > 0.0 && hit.t.is_finite() && hit.position.is_finite());
                let off = nn.dot(f64v(hit.position) - f64v(point));
                prop_assert!(off.abs() <= (tol + 1e-6 * hit.t) as f64, "off the plane by {off}");
            }
            None => {
                let clear = t_ref.is_finite() && t_ref > 1e-3 * scale as f64 && denom.abs() > 1e-3;
                prop_assert!(!clear, "missed a float64 hit at t {t_ref}");
            }
        }
    }
}

// ---------------------------------------------------------------- fit parameters

/// A random valid scene (1-3 spheres on a floor, a point or directional light) as JSON, its fit section
/// holding every fittable path with random valid bounds (one number or one per component; min == max at
/// times: a fixed parameter).
fn random_params_scene(rng: &mut Rng) -> (String, Vec<String>) {
    let mut u = |lo: f64, hi: f64| lo + (hi - lo) * rng.uniform();
    let spheres = 1 + (u(0.0, 3.0) as usize).min(2);
    let directional = u(0.0, 1.0) < 0.5;
    let mut objects = Vec::new();
    let mut paths = vec![
        if directional {
            "light.direction"
        } else {
            "light.position"
        }
        .to_string(),
        "light.intensity".into(),
        "light.color".into(),
        "ambient".into(),
        "environment".into(),
        "exposure".into(),
    ];
    for k in 0..=spheres {
        let name = if k == spheres {
            "floor".to_string()
        } else {
            format!("s{k}")
        };
        let material = format!(
            r#"{{"albedo": [{}, {}, {}], "specular": {}, "shininess": {}}}"#,
            u(0.0, 1.0),
            u(0.0, 1.0),
            u(0.0, 1.0),
            u(0.0, 1.0),
            u(0.0, 100.0)
        );
        objects.push(if k == spheres {
            format!(r#"{{"name": "{name}", "shape": "plane", "point": [0, 0, 0], "normal": [0, 1, 0], "material": {material}}}"#)
        } else {
            format!(
                r#"{{"name": "{name}", "shape": "sphere", "center": [{}, 0.5, {}], "radius": {}, "material": {material}}}"#,
                u(-2.0, 2.0),
                u(-2.0, 2.0),
                u(0.1, 1.0)
            )
        });
        for m in ["albedo", "specular", "shininess"] {
            paths.push(format!("objects.{name}.{m}"));
        }
    }
    let light = if directional {
        format!(
            r#""type": "directional", "direction": [{}, {}, {}]"#,
            u(-1.0, 1.0),
            u(0.1, 1.0),
            u(-1.0, 1.0)
        )
    } else {
        format!(
            r#""position": [{}, {}, {}]"#,
            u(-5.0, 5.0),
            u(1.0, 8.0),
            u(-5.0, 5.0)
        )
    };
    let mut fit = Vec::new();
    for p in &paths {
        let len = if p.ends_with("specular")
            || p.ends_with("shininess")
            || p == "light.intensity"
            || p == "exposure"
        {
            1
        } else {
            3
        };
        let geometric = p.starts_with("light.position") || p.starts_with("light.direction");
        let single = len == 1 || u(0.0, 1.0) < 0.3;
        let mut one = || {
            let lo = if geometric {
                u(-10.0, 10.0)
            } else if p == "exposure" {
                u(1e-3, 2.0)
            } else {
                u(0.0, 2.0)
            };
            let hi = if u(0.0, 1.0) < 0.1 {
                lo
            } else {
                lo + u(0.0, 10.0)
            };
            (lo, hi)
        };
        let (lo, hi): (Vec<f64>, Vec<f64>) = if single {
            let (lo, hi) = one();
            (vec![lo], vec![hi])
        } else {
            (0..len).map(|_| one()).unzip()
        };
        let side = |v: &[f64]| {
            if v.len() == 1 {
                format!("{}", v[0])
            } else {
                format!("{v:?}")
            }
        };
        fit.push(format!(
            r#""{p}": {{"min": {}, "max": {}}}"#,
            side(&lo),
            side(&hi)
        ));
    }
    let text = format!(
        r#"{{"image": {{"width": 8, "height": 6}},
            "camera": {{"position": [0, 1, -5], "look_at": [0, 0.5, 0], "vfov_deg": 40}},
            "light": {{{light}, "intensity": {}, "color": [{}, {}, {}]}},
            "ambient": [{}, {}, {}], "environment": [{}, {}, {}], "exposure": {},
            "objects": [{}], "fit": {{{}}}}}"#,
        u(0.0, 100.0),
        u(0.0, 1.0),
        u(0.0, 1.0),
        u(0.0, 1.0),
        u(0.0, 0.2),
        u(0.0, 0.2),
        u(0.0, 0.2),
        u(0.0, 0.2),
        u(0.0, 0.2),
        u(0.0, 0.2),
        u(0.1, 3.0),
        objects.join(","),
        fit.join(",")
    );
    (text, paths)
}

/// The suffix of component `k`'s name for `target`, as `ParamLayout` names it.
fn suffix(target: Target, k: usize) -> &'static str {
    match target.len() {
        1 => "",
        _ if matches!(target, Target::LightPosition | Target::LightDirection) => {
            [".x", ".y", ".z"][k]
        }
        _ => [".r", ".g", ".b"][k],
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: cases(256), ..ProptestConfig::default() })]

    /// For a random subset of a random scene's fit paths (in any order): the layout's names, bounds and
    /// entries agree with the fit section, in canonical order; writing values and reading them back gives
    /// them bit for bit (values outside the bounds too: `apply` does no bounds check, the bounds are the
    /// search's), except `light.direction`, which is documented to be stored normalised: it reads back as
    /// the unit vector along what was written (to 4 ulps), `[0, 1, 0]` for a zero vector. Nothing else in
    /// the scene changes; values within the bounds survive a JSON round trip (the direction to 4 ulps).
    #[test]
    fn params_set_then_get_gives_the_values_back(seed in any::<u64>(), pick in any::<u32>(),
                                                 outside in 0u32..4) {
        let mut rng = Rng::new(seed);
        let (text, paths) = random_params_scene(&mut rng);
        let scene = Scene::from_json(&text).unwrap();
        let mut subset: Vec<String> = paths.iter().enumerate()
            .filter(|(i, _)| pick >> (i % 32) & 1 == 1).map(|(_, p)| p.clone()).collect();
        // any order: the layout sorts
        for i in (1..subset.len()).rev() {
            subset.swap(i, rng.below(i + 1));
        }
        let layout = ParamLayout::new(&scene, &subset).unwrap();
        let dim: usize = layout.entries.iter().map(|e| e.1.len()).sum();
        prop_assert_eq!(layout.dim(), dim);
        prop_assert_eq!(layout.names.len(), dim);
        prop_assert_eq!(layout.entries.len(), subset.len());
        let mut next = 0;
        for (w, (path, target, offset)) in layout.entries.iter().enumerate() {
            prop_assert!(subset.contains(path));
            prop_assert_eq!(*offset, next);
            if w > 0 {
                prop_assert!(layout.entries[w - 1].1.order_key() < target.order_key());
            }
            let f = scene.fit.iter().find(|f| &f.path == path).unwrap();
            prop_assert_eq!(f.target, *target);
            for k in 0..target.len() {
                prop_assert_eq!(layout.bounds[offset + k], (f.min[k], f.max[k]));
                prop_assert_eq!(&layout.names[offset + k], &format!("{path}{}", suffix(*target, k)));
            }
            next += target.len();
        }
        // Values: within the bounds (ends included), or with `outside` == 0 anywhere in +-1e6.
        let x: Vec<f64> = layout.bounds.iter().map(|&(lo, hi)| match rng.below(8) {
            0 => lo,
            1 => hi,
            2 if outside == 0 => (rng.uniform() - 0.5) * 2e6,
            3 if outside == 0 => 0.0,
            _ => lo + (hi - lo) * rng.uniform(),
        }).collect();
        let within = x.iter().zip(&layout.bounds).all(|(v, b)| b.0 <= *v && *v <= b.1);
        let mut set = scene.clone();
        layout.apply(&mut set, &x);
        let got = layout.read(&set);
        prop_assert_eq!(got.len(), dim);
        let expected = |t: Target, v: &[f64]| -> Vec<f64> {
            if t != Target::LightDirection {
                return v.to_vec();
            }
            let d = DVec3::from_slice(v);
            if d == DVec3::ZERO { vec![0.0, 1.0, 0.0] } else { d.normalize().to_array().to_vec() }
        };
        for (path, target, offset) in &layout.entries {
            let (x, got) = (&x[*offset..][..target.len()], &got[*offset..][..target.len()]);
            let want = expected(*target, x);
            if *target == Target::LightDirection {
                let len = DVec3::from_slice(got).length();
                prop_assert!((len - 1.0).abs() <= 4.0 * f64::EPSILON, "{path}: |{got:?}| = {len}");
                for k in 0..3 {
                    prop_assert!((got[k] - want[k]).abs() <= 4.0 * f64::EPSILON, "{path}: {got:?} vs {want:?}");
                }
            } else {
                let bits = |v: &[f64]| v.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
                prop_assert_eq!(bits(got), bits(x), "{}", path);
            }
        }
        // Nothing else changed: the other fittable values, the geometry, camera, fit section.
        let all = ParamLayout::all(&scene);
        let (before, after) = (all.read(&scene), all.read(&set));
        for (path, target, offset) in &all.entries {
            if !subset.contains(path) {
                let r = *offset..*offset + target.len();
                prop_assert_eq!(&before[r.clone()], &after[r], "{} changed", path);
            }
        }
        prop_assert_eq!(&set.camera, &scene.camera);
        prop_assert_eq!(&set.fit, &scene.fit);
        for (a, b) in set.objects.iter().zip(&scene.objects) {
            prop_assert_eq!(&a.shape, &b.shape);
        }
        // In bounds, the scene saves and loads with the same values.
        let zero_direction = layout.entries.iter().any(|(_, t, o)| {
            *t == Target::LightDirection && x[*o..*o + 3].iter().all(|v| *v == 0.0)
        });
        if within && !zero_direction {
            let back = Scene::from_json(&set.to_value().to_string());
            prop_assert!(back.is_ok(), "in-bounds values do not load back: {:?}", back.err());
            let again = layout.read(&back.unwrap());
            for (path, target, offset) in &layout.entries {
                for k in *offset..*offset + target.len() {
                    let tol = if *target == Target::LightDirection { 4.0 * f64::EPSILON } else { 0.0 };
                    prop_assert!((again[k] - got[k]).abs() <= tol, "{path}: {} vs {}", again[k], got[k]);
                }
            }
        }
    }

    /// A fit entry's bounds are accepted exactly when they are valid (finite, within the magnitude limit,
    /// min <= max, min >= 0 for every path but the light's position and direction, min > 0 for exposure);
    /// a refusal names the entry. A path outside the fit section is refused by `ParamLayout::new`, named.
    #[test]
    fn fit_bounds_are_accepted_exactly_when_valid(seed in any::<u64>(), which in any::<prop::sample::Index>(),
                                                   lo in bound_value(), hi in bound_value()) {
        let mut rng = Rng::new(seed);
        let (text, paths) = random_params_scene(&mut rng);
        let path = which.get(&paths).clone();
        let mut v: Value = serde_json::from_str(&text).unwrap();
        v["fit"][path.as_str()] = serde_json::json!({"min": lo, "max": hi});
        let geometric = path == "light.position" || path == "light.direction";
        let limit = if path == "light.intensity" { 1e20 } else { 1e8 };
        let valid = lo <= hi && lo.abs() <= limit && hi.abs() <= limit
            && (geometric || lo >= 0.0) && (path != "exposure" || lo > 0.0);
        match Scene::from_json(&v.to_string()) {
            Ok(s) => {
                prop_assert!(valid, "{path}: accepted min {lo} max {hi}");
                let f = s.fit.iter().find(|f| f.path == path).unwrap();
                prop_assert!(f.min.iter().all(|m| *m == lo) && f.max.iter().all(|m| *m == hi));
                let unknown = format!("{path}x");
                let e = ParamLayout::new(&s, &[unknown.clone()]).unwrap_err().to_string();
                prop_assert!(e.contains(&unknown), "{e}");
            }
            Err(e) => {
                prop_assert!(!valid, "{path}: refused valid min {lo} max {hi}: {e}");
                let field = format!("fit[{path:?}]");
                prop_assert!(e.to_string().contains(&field), "{e}");
            }
        }
    }
}

/// A fit bound: ordinary, at the edges of what is allowed, or beyond them.
fn bound_value() -> impl Strategy<Value = f64> {
    prop_oneof![
        -20.0f64..20.0,
        Just(0.0),
        Just(-0.0),
        Just(1e8),
        Just(-1e8),
        Just(1.5e8),
        Just(1e20),
        Just(2e20),
        Just(-1e-300),
        Just(1e-300),
    ]
}

// ---------------------------------------------------------------- the kernel against the plain path

/// The constant term of a random kernel scene.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Sky {
    None,
    Ambient,
    Environment,
}

/// A random 16x12 scene: 1-3 spheres on a slightly tilted floor, a random point light, albedo, specular
/// and shininess (none with `matte`), ambient light or an occluded environment, exposure; its fit section
/// holds every fittable path.
fn random_kernel_scene(rng: &mut Rng, matte: bool, sky: Sky) -> (Scene, Vec<String>) {
    let mut u = |lo: f64, hi: f64| lo + (hi - lo) * rng.uniform();
    let spheres = 1 + (u(0.0, 3.0) as usize).min(2);
    let mut objects = Vec::new();
    let mut paths = vec![
        "light.position",
        "light.intensity",
        "light.color",
        "exposure",
    ]
    .into_iter()
    .map(String::from)
    .collect::<Vec<_>>();
    paths.push(
        if sky == Sky::Environment {
            "environment"
        } else {
            "ambient"
        }
        .into(),
    );
    for k in 0..=spheres {
        let (ks, sh) = if matte {
            (0.0, 0.0)
        } else {
            (u(0.0, 0.5), u(1.0, 60.0))
        };
        let material = format!(
            r#"{{"albedo": [{}, {}, {}], "specular": {ks}, "shininess": {sh}}}"#,
            u(0.05, 1.0),
            u(0.05, 1.0),
            u(0.05, 1.0)
        );
        let name = if k == spheres {
            "floor".to_string()
        } else {
            format!("s{k}")
        };
        objects.push(if k == spheres {
            format!(
                r#"{{"name": "floor", "shape": "plane", "point": [0, 0, 0], "normal": [{}, 1, {}], "material": {material}}}"#,
                u(-0.05, 0.05),
                u(-0.05, 0.05)
            )
        } else {
            let r = u(0.3, 1.0);
            format!(
                r#"{{"name": "{name}", "shape": "sphere", "center": [{}, {r}, {}], "radius": {r}, "material": {material}}}"#,
                u(-2.0, 2.0),
                u(-1.5, 1.5)
            )
        });
        paths.push(format!("objects.{name}.albedo"));
        if !matte {
            paths.push(format!("objects.{name}.specular"));
            paths.push(format!("objects.{name}.shininess"));
        }
    }
    let (amb, env) = match sky {
        Sky::None => (0.0, 0.0),
        Sky::Ambient => (u(0.01, 0.2), 0.0),
        Sky::Environment => (0.0, u(0.01, 0.5)),
    };
    let bounds = |p: &str| match p {
        "light.position" => r#"{"min": [-6, 0.5, -6], "max": [6, 8, 6]}"#,
        "light.intensity" => r#"{"min": 1, "max": 200}"#,
        "exposure" => r#"{"min": 0.5, "max": 2}"#,
        _ if p.ends_with("shininess") => r#"{"min": 1, "max": 80}"#,
        _ => r#"{"min": 0, "max": 1}"#,
    };
    let fit: serde_json::Map<String, Value> = paths
        .iter()
        .map(|p| (p.clone(), serde_json::from_str(bounds(p)).unwrap()))
        .collect();
    let objects: Vec<Value> = objects
        .iter()
        .map(|o| serde_json::from_str(o).unwrap())
        .collect();
    let text = serde_json::json!({
        "image": {"width": 16, "height": 12},
        "camera": {"position": [u(-1.0, 1.0), u(1.0, 3.0), -7], "look_at": [0, 0.7, 0], "vfov_deg": 40},
        "light": {"position": [u(-4.0, 4.0), u(1.0, 6.0), u(-4.0, 4.0)], "intensity": u(20.0, 120.0),
                  "color": [u(0.5, 1.0), u(0.5, 1.0), u(0.5, 1.0)]},
        "ambient": [amb, amb, amb], "environment": [env, env * 0.8, env], "exposure": u(0.7, 1.5),
        "objects": objects, "fit": fit,
    })
    .to_string();
    (Scene::from_json(&text).unwrap(), paths)
}

/// The pixels whose shadow test is decided by a margin: for every other sphere the segment to `scene`'s
/// light passes farther than 1e-4 (relative) from its surface, and the pixel and the light are farther
/// than that from every other plane (in float64). The kernel's shadow test and the renderer's are
/// different formulas; at a shadow's edge they may disagree by rounding, a whole pixel either way.
fn decided_pixels(scene: &Scene) -> Vec<u32> {
    let geometry = rtloop::render::Geometry::new(scene);
    let g = GBuffer::new(&geometry, scene.width, scene.height);
    let light = DVec3::from_array(scene.light.position);
    let near = |x: f64, scale: f64| x.abs() <= 1e-4 * (1.0 + scale);
    (0..g.surfels.len() as u32)
        .filter(|&i| {
            let s = &g.surfels[i as usize];
            let p = f64v(s.position);
            scene.objects.iter().enumerate().all(|(k, o)| {
                if k as u32 == s.object || s.object == u32::MAX {
                    return true;
                }
                match &o.shape {
                    rtloop::scene::Shape::Sphere { center, radius } => {
                        let (c, v) = (DVec3::from_array(*center), light - p);
                        let t = ((c - p).dot(v) / v.length_squared()).clamp(0.0, 1.0);
                        !near(
                            (c - (p + t * v)).length() - radius,
                            c.abs().max_element() + radius,
                        )
                    }
                    rtloop::scene::Shape::Plane { point, normal } => {
                        let (q, n) = (
                            DVec3::from_array(*point),
                            DVec3::from_array(*normal).normalize(),
                        );
                        let scale = q.abs().max_element()
                            + p.abs().max_element()
                            + light.abs().max_element();
                        !near(n.dot(p - q), scale) && !near(n.dot(light - q), scale)
                    }
                    _ => true,
                }
            })
        })
        .collect()
}

proptest! {
    #![proptest_config(ProptestConfig { cases: cases(64), ..ProptestConfig::default() })]

    /// The fused kernel's whole-image L1 loss (`LossKind::L1`, over a random subset of the fit paths, at a
    /// random candidate, clipped at 1 or not) equals the L1 distance between `render` of the candidate's
    /// scene and the objective, summed here in f64 over the same pixels (those whose shadow test is
    /// decided, see `decided_pixels`). Tolerance, from f32 rounding: each path computes a pixel value in
    /// at most ~32 rounded f32 operations, and the lobe's power n.h^s multiplies n.h's relative error by
    /// s, so one value differs by at most (64 + 4 s) eps |v|, plus n.l's absolute rounding (8 eps) times
    /// the light's term at n.l = 1 (a pixel lit at grazing light by one path, unlit by the other); the
    /// kernel then sums each 64-pixel block in f32, at most 64 eps x the sum of |difference| <= |v| + |t|.
    #[test]
    fn kernel_l1_is_the_l1_of_the_render(seed in any::<u64>(), pick in any::<u32>(), matte in any::<bool>(),
                                         sky in prop_oneof![Just(Sky::None), Just(Sky::Ambient), Just(Sky::Environment)],
                                         clip in any::<bool>()) {
        let mut rng = Rng::new(seed);
        let (scene, paths) = random_kernel_scene(&mut rng, matte, sky);
        let subset: Vec<String> = paths.iter().enumerate()
            .filter(|(i, _)| pick >> (i % 32) & 1 == 1).map(|(_, p)| p.clone()).collect();
        prop_assume!(!subset.is_empty());
        let layout = ParamLayout::new(&scene, &subset).unwrap();
        // The objective: the scene's own render, each value scaled by a random factor in [0.5, 1.5).
        let target: Vec<f32> = render(&scene, None, None, 1).unwrap().rgb.iter()
            .map(|v| v * (0.5 + rng.uniform()) as f32).collect();
        let x: Vec<f64> = layout.bounds.iter().map(|&(lo, hi)| lo + (hi - lo) * rng.uniform()).collect();
        let mut candidate = scene.clone();
        layout.apply(&mut candidate, &x);
        let pixels = decided_pixels(&candidate);
        let f = Fitness::new(&scene, layout, &target, FitnessSpec { pixels: Some(pixels.clone()), loss: LossKind::L1, clip, ..Default::default() }).unwrap();
        let mut out = [0.0];
        f.evaluate(&x, &mut out);
        let image = render(&candidate, None, None, 1).unwrap().rgb;
        let s_max = candidate.objects.iter().map(|o| o.material.shininess).fold(0.0, f64::max);
        let g = GBuffer::new(&rtloop::render::Geometry::new(&candidate), scene.width, scene.height);
        let light = DVec3::from_array(candidate.light.position);
        let (mut plain, mut tol) = (0.0f64, 0.0f64);
        for &i in &pixels {
            let s = &g.surfels[i as usize];
            for c in 0..3 {
                let k = 3 * i as usize + c;
                let v = if clip { image[k].min(1.0) } else { image[k] } as f64;
                let t = target[k] as f64;
                plain += (v - t).abs();
                // The light's term at n.l = 1 (and n.h = 1): n.l's absolute rounding, 8 eps, scales it.
                let unlit = match candidate.objects.get(s.object as usize) {
                    Some(o) => {
                        let m = &o.material;
                        let d2 = (light - f64v(s.position)).length_squared();
                        let scale = specular_scale(m.specular as f32, m.shininess as f32) as f64;
                        candidate.exposure * candidate.light.intensity * candidate.light.color[c] / d2
                            * (m.albedo[c] / std::f64::consts::PI + scale)
                    }
                    None => 0.0,
                };
                tol += f32::EPSILON as f64
                    * ((64.0 + 4.0 * s_max) * v.abs() + 64.0 * (v.abs() + t.abs()) + 8.0 * unlit);
            }
        }
        prop_assert!((out[0] - plain).abs() <= tol,
            "kernel {} vs render {plain} (tol {tol}, {} of {} pixels)", out[0], pixels.len(), image.len() / 3);
    }

    /// At the true light of a clean render of a matte scene (no constant term, ambient light, or an
    /// occluded environment), the projected loss over the pixels off every silhouette (those that inform
    /// the closed form) vanishes: the products fit the render's pixels up to the f32 rounding of both. A
    /// value's relative rounding is at most rho = 64 eps + 8 eps / n.l (n.l's absolute rounding over n.l);
    /// the box least squares (the truth inside the box) leaves a residual no larger in L2 than the true
    /// products do, |rho t|_2, so the L1 loss is at most sqrt(values) x |rho t|_2. Without a constant term
    /// the one-column solve P = sum(a t) / sum(a a) recovers P = exposure x intensity x colour x albedo of
    /// every object lit in view to the largest rho of its pixels.
    #[test]
    fn projected_loss_vanishes_at_the_true_light(seed in any::<u64>(),
                                                 sky in prop_oneof![Just(Sky::None), Just(Sky::Ambient), Just(Sky::Environment)]) {
        let mut rng = Rng::new(seed);
        let (scene, _) = random_kernel_scene(&mut rng, true, sky);
        // Only the light is searched; the constant term's column comes from the scene's own values.
        let bounds = serde_json::json!({"min": [-6, 0.5, -6], "max": [6, 8, 6]});
        let scene = scene.without_fit().with_bounds(&[("light.position".to_string(), bounds)]).unwrap();
        let layout = ParamLayout::new(&scene, &["light.position".to_string()]).unwrap();
        let target = render(&scene, None, None, 1).unwrap().rgb;
        let n = scene.objects.len();
        let mut proj = Projection::matte(vec![[(0.0, 1e4); 3]; n]);
        if sky != Sky::None {
            proj.environment = vec![[(0.0, 1e4); 3]; n];
        }
        // Off the silhouettes only: every pixel of the loss then informs the closed form.
        let g = GBuffer::new(&rtloop::render::Geometry::new(&scene), scene.width, scene.height);
        let pixels: Vec<u32> = decided_pixels(&scene).into_iter()
            .filter(|&i| rtloop::fitness::interior(&g, i as usize)).collect();
        let f = Fitness::new(&scene, layout, &target, FitnessSpec { pixels: Some(pixels.clone()), loss: LossKind::L1Projected, clip: false, projection: Some(proj), ..Default::default() })
            .unwrap();
        let truth = scene.light.position;
        let loss: f64 = f.channel_losses(&truth).iter().sum();
        // Relative rounding of a pixel's value: 64 eps, plus n.l's absolute rounding (8 eps for unit
        // vectors) relative to n.l itself, large at grazing light.
        let light = DVec3::from_array(truth);
        let rho = |i: u32| {
            let s = &g.surfels[i as usize];
            let (p, n) = (f64v(s.position), f64v(s.normal));
            let cos = n.dot((light - p).normalize());
            let eps = f32::EPSILON as f64;
            if cos > 0.0 { 64.0 * eps + 8.0 * eps / cos } else { 64.0 * eps }
        };
        let r2: f64 = pixels.iter().flat_map(|&i| (0..3).map(move |c| (i, 3 * i as usize + c)))
            .map(|(i, k)| (rho(i) * target[k] as f64).powi(2)).sum();
        let tol = (3.0 * pixels.len() as f64).sqrt() * r2.sqrt();
        prop_assert!(loss <= tol, "loss at the truth {loss} > {tol}");
        if sky == Sky::None {
            let solved = f.solved(&truth);
            let ids = rtloop::render::object_ids(&scene, None, None);
            for (k, o) in scene.objects.iter().enumerate() {
                // its lit pixels (a shadowed one has no light to scale)
                let lit: Vec<u32> = pixels.iter().copied()
                    .filter(|&i| ids[i as usize] == k as i32 && target[3 * i as usize..][..3].iter().any(|v| *v > 0.0))
                    .collect();
                if lit.is_empty() {
                    continue;
                }
                let rel = lit.iter().map(|&i| rho(i)).fold(0.0, f64::max);
                for c in 0..3 {
                    let p = scene.exposure * scene.light.intensity * scene.light.color[c] * o.material.albedo[c];
                    let got = solved.products[k][c];
                    prop_assert!((got - p).abs() <= rel * p, "{}: P[{c}] {got} vs {p} ({} px)", o.name, lit.len());
                }
            }
        }
    }
}

// ---------------------------------------------------------------- ray–mesh intersection

/// A point of a cube of side `scale` around `offset`.
fn point(scale: f64, offset: [f64; 3]) -> impl Strategy<Value = DVec3> {
    [-1.0f64..1.0, -1.0f64..1.0, -1.0f64..1.0]
        .prop_map(move |p| DVec3::from_array(offset) + scale * DVec3::from_array(p))
}

/// A triangle of a cube of random size (1e-2 to 1e3) and place, f32-representable vertices, and whether
/// it is well shaped (twice its area at least 1e-3 x its longest edge squared, so it is far from
/// degenerate).
fn triangle3() -> impl Strategy<Value = [DVec3; 3]> {
    (-2.0f64..3.0, [-1e3f64..1e3, -1e3f64..1e3, -1e3f64..1e3]).prop_flat_map(|(e, offset)| {
        let scale = 10f64.powf(e);
        [
            point(scale, offset),
            point(scale, offset),
            point(scale, offset),
        ]
        .prop_map(|v| v.map(|p| p.as_vec3a().as_dvec3()))
    })
}

fn well_shaped(v: &[DVec3; 3]) -> bool {
    let edge = [v[1] - v[0], v[2] - v[1], v[0] - v[2]]
        .iter()
        .map(|e| e.length())
        .fold(0.0, f64::max);
    (v[1] - v[0]).cross(v[2] - v[0]).length() >= 1e-3 * edge * edge
}

fn mesh_of(tris: &[[DVec3; 3]]) -> Option<rtloop::geometry::mesh::Mesh> {
    rtloop::geometry::mesh::Mesh::new(tris, None)
}

proptest! {
    #![proptest_config(ProptestConfig { cases: cases(2000), max_global_rejects: cases(2000), ..ProptestConfig::default() })]

    /// A ray from a random origin aimed at a random point inside a well-shaped triangle (barycentric
    /// coordinates >= 1e-3) hits it at the float64 plane-equation t of the same f32 ray, to f32 rounding:
    /// Möller–Trumbore's products carry 64 eps x (|o - v0| + |e1| + |e2|), over the cosine to the normal
    /// and over the sine of the angle between the edges (|e1||e2| / |e1 x e2|, a thin triangle's
    /// determinant).
    #[test]
    fn a_ray_aimed_inside_a_triangle_hits_it(v in triangle3(), bary in (1e-3f64..1.0, 1e-3f64..1.0),
                                             from in [-1.0f64..1.0, -1.0f64..1.0, -1.0f64..1.0], far in 0.1f64..10.0) {
        prop_assume!(well_shaped(&v));
        let (mut a, mut b) = bary;
        if a + b > 1.0 - 1e-3 {
            (a, b) = (1.0 - a, 1.0 - b); // reflect into the triangle
        }
        prop_assume!(a >= 1e-3 && b >= 1e-3 && a + b <= 1.0 - 1e-3);
        let aim = v[0] + a * (v[1] - v[0]) + b * (v[2] - v[0]);
        let size = (v[1] - v[0]).length().max((v[2] - v[0]).length());
        let origin = (aim + far * size * DVec3::from_array(from)).as_vec3a();
        let Some(dir) = unit((aim - origin.as_dvec3()).as_vec3a().to_array()) else { return Ok(()) };
        let n = (v[1] - v[0]).cross(v[2] - v[0]).normalize();
        let cos = n.dot(dir.as_dvec3()).abs();
        prop_assume!(cos > 1e-2);
        // float64 reference of the f32 ray: the plane equation.
        let (o, d) = (origin.as_dvec3(), dir.as_dvec3());
        let t_ref = n.dot(v[0] - o) / n.dot(d);
        let e = f32::EPSILON as f64;
        // 1 / sin of the angle between the edges: Möller–Trumbore's determinant loses that much.
        let thin = (v[1] - v[0]).length() * (v[2] - v[0]).length() / (v[1] - v[0]).cross(v[2] - v[0]).length();
        let tol = 64.0 * e * ((o - v[0]).length() + 2.0 * size) * thin / cos;
        let mesh = mesh_of(&[v]).expect("a well-shaped triangle is kept");
        let hit = mesh.intersect(origin, dir, 0.0, f32::INFINITY);
        prop_assert!(hit.is_some(), "missed: t_ref {t_ref}, cos {cos}");
        let hit = hit.unwrap();
        prop_assert!((hit.t as f64 - t_ref).abs() <= tol, "t {} vs {t_ref} (tol {tol})", hit.t);
        prop_assert!((hit.normal.length() - 1.0).abs() < 1e-5 && hit.normal.dot(dir) <= 0.0);
        prop_assert!(mesh.hits_segment(origin, dir, 0.0, (t_ref + tol) as f32));
    }

    /// A ray that stays on the far side of a plane bounding the triangle's box (by 1e-3 of its size)
    /// misses it, both as a camera ray and as a shadow segment.
    #[test]
    fn a_ray_beside_the_box_misses(v in triangle3(), axis in 0usize..3, above in any::<bool>(),
                                   o in [-1.0f64..1.0, -1.0f64..1.0, -1.0f64..1.0], d in v3()) {
        let Some(mesh) = mesh_of(&[v]) else { return Ok(()) };
        let (lo, hi) = (v[0].min(v[1]).min(v[2]), v[0].max(v[1]).max(v[2]));
        let size = (hi - lo).max_element().max(1e-30);
        let Some(dir) = unit(d) else { return Ok(()) };
        let mut origin = (lo + hi) / 2.0 + size * DVec3::from_array(o);
        let mut dir = dir.as_dvec3();
        // Put the origin beyond the box on `axis` and point the ray away (or along) that face.
        if above {
            origin[axis] = hi[axis] + 1e-3 * size + origin[axis].abs() * 1e-6;
            dir[axis] = dir[axis].abs();
        } else {
            origin[axis] = lo[axis] - 1e-3 * size - origin[axis].abs() * 1e-6;
            dir[axis] = -dir[axis].abs();
        }
        let (origin, dir) = (origin.as_vec3a(), dir.normalize().as_vec3a());
        let beyond = if above { origin[axis] as f64 > hi[axis] } else { (origin[axis] as f64) < lo[axis] };
        prop_assume!(beyond);
        prop_assert!(mesh.intersect(origin, dir, 0.0, f32::INFINITY).is_none());
        prop_assert!(!mesh.hits_segment(origin, dir, 0.0, f32::MAX));
    }

    /// Degenerate triangles (a repeated vertex, or three collinear ones) are dropped and never hit: a
    /// mesh of them alone is refused, and beside a good triangle a ray aimed at one hits only the good one
    /// (where the float64 reference says it does).
    #[test]
    fn degenerate_triangles_are_never_hit(good in triangle3(), k in prop::sample::select(vec![-2.0f64, -1.0, -0.5, 0.5, 2.0, 4.0]), repeated in any::<bool>(),
                                          along in 0.0f64..1.0, from in [-1.0f64..1.0, -1.0f64..1.0, -1.0f64..1.0]) {
        prop_assume!(well_shaped(&good));
        let [a, b, _] = good;
        // Beside the good triangle: shifted by twice its size.
        let size = (b - a).length().max((good[2] - a).length());
        let shift = DVec3::new(2.0 * size, 0.0, 0.0);
        let (a, b) = (a + shift, b + shift);
        let (a, b) = (a.as_vec3a().as_dvec3(), b.as_vec3a().as_dvec3());
        // Collinear exactly, in f64 and in f32: the third vertex a power of two along the first edge.
        let c = if repeated { b } else { a + k * (b - a) };
        let bad = [a, b, c];
        prop_assert!(mesh_of(&[bad]).is_none());
        let mesh = mesh_of(&[good, bad]).unwrap();
        prop_assert_eq!(mesh.triangle_count(), 1);
        let aim = bad[0] + along * (bad[1] - bad[0]);
        let origin = (aim + size * DVec3::from_array(from)).as_vec3a();
        let Some(dir) = unit((aim - origin.as_dvec3()).as_vec3a().to_array()) else { return Ok(()) };
        if let Some(hit) = mesh.intersect(origin, dir, 0.0, f32::INFINITY) {
            let n = (good[1] - good[0]).cross(good[2] - good[0]).normalize();
            let off = n.dot(hit.position.as_dvec3() - good[0]);
            prop_assert!(off.abs() <= 1e-4 * (size + good[0].abs().max_element()), "hit off the good triangle's plane by {off}");
        }
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: cases(32), ..ProptestConfig::default() })]

    /// `render_pixels` is the whole render's values at the pixels asked for, bit for bit, with the footprint
    /// or at pixel centres, in any order and with repeats; a pixel outside the image is an error naming it.
    #[test]
    fn rendered_pixels_are_the_renders_pixels(seed in any::<u64>(), matte in any::<bool>(), footprint in any::<bool>(),
                                              sky in prop_oneof![Just(Sky::None), Just(Sky::Ambient), Just(Sky::Environment)],
                                              picks in prop::collection::vec(any::<u32>(), 0..200)) {
        let mut rng = Rng::new(seed);
        let (scene, _) = random_kernel_scene(&mut rng, matte, sky);
        let whole = render::render_with(&scene, None, None, 1, footprint).unwrap().rgb;
        let n = scene.width * scene.height;
        let idx: Vec<u32> = picks.iter().map(|p| p % n).collect();
        let some = render::render_pixels(&scene, &idx, footprint).unwrap();
        prop_assert_eq!(some.len(), 3 * idx.len());
        for (k, &p) in idx.iter().enumerate() {
            let p = p as usize;
            prop_assert_eq!(&some[3 * k..3 * k + 3], &whole[3 * p..3 * p + 3], "pixel {}", p);
        }
        let err = render::render_pixels(&scene, &[n], footprint).unwrap_err().to_string();
        prop_assert!(err.contains(&format!("pixel {n} is outside")), "{}", err);
    }
}
