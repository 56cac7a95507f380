//! Property tests (proptest) in bounded time: scene parsing under random mutations of a valid scene, and
//! ray–sphere / ray–plane intersection against a float64 reference. `PROPTEST_CASES` makes a longer run.

use glam::{DVec3, Vec3A};
use proptest::prelude::*;
use rtloop::render::shape::PShape;
use rtloop::Scene;
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

proptest! {
    #![proptest_config(ProptestConfig { cases: cases(256), ..ProptestConfig::default() })]

    /// Replacing one value anywhere (or deleting one key) never panics: the scene parses, or the error
    /// names the field that was changed or one above it.
    #[test]
    fn mutated_scenes_parse_or_name_a_field(pick in any::<prop::sample::Index>(), value in odd_value(),
                                            delete in any::<bool>()) {
        let mut scene: Value = serde_json::from_str(SCENE).unwrap();
        let mut all = Vec::new();
        paths(&scene, &mut Vec::new(), "", &mut all);
        let (path, key) = all[1 + pick.index(all.len() - 1)].clone();
        let parent_key = all.iter().find(|(p, _)| p[..] == path[..path.len() - 1]).unwrap().1.clone();
        let deleted = delete && matches!(path.last(), Some(Value::String(_)));
        if deleted {
            let (last, up) = path.split_last().unwrap();
            at_mut(&mut scene, up).as_object_mut().unwrap().remove(last.as_str().unwrap());
        } else {
            *at_mut(&mut scene, &path) = value;
        }
        match Scene::from_json(&scene.to_string()) {
            Ok(s) => prop_assert!(s.width > 0 && s.height > 0),
            Err(e) => {
                let msg = e.to_string();
                let named = [key.as_str(), parent_key.as_str()]
                    .iter()
                    .chain(path.iter().filter_map(|p| p.as_str()).collect::<Vec<_>>().iter())
                    .any(|k| !k.is_empty() && msg.contains(k));
                prop_assert!(named, "{path:?} ({}): {msg}", if deleted { "deleted" } else { "replaced" });
            }
        }
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
