//! Property tests (proptest) in bounded time: scene parsing under random mutations of a valid scene, fit
//! parameters (set, get, bounds), and ray–sphere / ray–plane intersection against a float64 reference.
//! `PROPTEST_CASES` makes a longer run.

use glam::{DVec3, Vec3A};
use proptest::prelude::*;
use rtloop::params::Target;
use rtloop::render::shape::PShape;
use rtloop::search::Rng;
use rtloop::{ParamLayout, Scene};
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
