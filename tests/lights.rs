//! Several lights and sphere lights in the renderer, against closed-form references: the irradiance of
//! two point lights on a plane, a one-light `lights` list against the single `light`, and the soft
//! shadow of a ball under a sphere light on the axis through both centres.

use glam::{DVec3, Vec3A};
use rtloop::render::hit::Surfel;
use rtloop::render::lights::{sphere_visibility, SOFT_SAMPLES};
use rtloop::render::{render, Geometry, PShape};
use rtloop::Scene;

fn plane_scene(lights: &str) -> String {
    format!(
        r#"{{"image": {{"width": 24, "height": 18}},
        "camera": {{"position": [0, 4, -0.01], "look_at": [0, 0, 0], "vfov_deg": 60}},
        {lights},
        "objects": [{{"name": "floor", "shape": "plane", "point": [0, 0, 0], "normal": [0, 1, 0],
                      "material": {{"albedo": [0.6, 0.4, 0.2]}}}}]}}"#
    )
}

/// Each pixel of `scene` whose centre sees an object: its index (row-major) and the point seen, in f64.
fn seen_points(scene: &Scene) -> Vec<(usize, DVec3)> {
    let geo = Geometry::new(scene);
    let mut seen = Vec::new();
    for j in 0..scene.height {
        for i in 0..scene.width {
            let s = geo.primary(i as f32 + 0.5, j as f32 + 0.5, scene.width, scene.height);
            if s.object != u32::MAX {
                seen.push(((j * scene.width + i) as usize, s.position.as_dvec3()));
            }
        }
    }
    seen
}

/// Each pixel of a floor lit by a point light, a sphere light (unoccluded: a point light's irradiance)
/// and a directional light is exposure x albedo/pi x the sum of their irradiances, computed here in f64.
#[test]
fn lights_add_up_on_a_plane_as_the_inverse_square_law_says() {
    let text = plane_scene(
        r#""lights": [{"name": "key", "position": [1, 3, 0.5], "intensity": 20, "color": [1, 0.8, 0.6]},
                      {"name": "fill", "type": "sphere", "position": [-2, 2.5, -1], "radius": 0.3,
                       "intensity": 5, "color": [0.5, 0.7, 1]},
                      {"name": "sun", "type": "directional", "direction": [0.3, 1, -0.2], "intensity": 0.7}]"#,
    );
    let scene = Scene::from_json(&text).unwrap();
    assert_eq!(scene.light_count(), 3);
    let img = render(&scene, None, None, 1).unwrap();
    let albedo = DVec3::new(0.6, 0.4, 0.2);
    let n = DVec3::Y;
    let (mut worst, mut count) = (0.0f64, 0);
    for (pixel, p) in seen_points(&scene) {
        let mut e = DVec3::ZERO;
        for l in scene.all_lights() {
            let colour = DVec3::from_array(l.color) * l.intensity;
            e += colour
                * match l.direction {
                    Some(d) => n.dot(DVec3::from_array(d).normalize()).max(0.0),
                    None => {
                        let d = DVec3::from_array(l.position) - p;
                        n.dot(d).max(0.0) / d.length().powi(3)
                    }
                };
        }
        let want = albedo / std::f64::consts::PI * e;
        for c in 0..3 {
            let got = img.rgb[3 * pixel + c] as f64;
            worst = worst.max((got - want[c]).abs() / want[c]);
        }
        count += 1;
    }
    assert!(count > 100);
    assert!(worst < 1e-5, "largest relative error {worst}");
}

/// A `lights` list of one point light renders bit for bit as the same single `light` and is written
/// back as it; its fit paths are the light's.
#[test]
fn a_list_of_one_light_renders_as_the_single_light() {
    let single = Scene::from_json(&plane_scene(
        r#""light": {"position": [1, 3, 0.5], "intensity": 20}"#,
    ))
    .unwrap();
    let listed = Scene::from_json(&plane_scene(
        r#""lights": [{"name": "lamp", "position": [1, 3, 0.5], "intensity": 20}]"#,
    ))
    .unwrap();
    assert_eq!(
        render(&single, None, None, 1).unwrap().rgb,
        render(&listed, None, None, 1).unwrap().rgb
    );
    assert!(single.to_value().get("light").is_some() && single.to_value().get("lights").is_none());
    let back = Scene::from_json(&listed.to_value().to_string()).unwrap();
    assert!(listed.to_value().get("light").is_some());
    assert_eq!(back.light.position, single.light.position);
}

/// The fraction of a sphere light a floor point sees past a ball on the axis through both centres: the
/// ball's silhouette and the light's are concentric discs, the hidden fraction (tan a_ball / tan a_light)^2
/// of the light's disc. The spiral's points each have their own radius: it resolves the fraction to within one of its
/// `SOFT_SAMPLES` points.
#[test]
fn the_soft_shadow_on_the_axis_hides_the_concentric_fraction() {
    let (light_h, light_r, ball_r) = (3.0f64, 0.4f64, 0.25f64);
    let floor = Surfel {
        position: Vec3A::ZERO,
        normal: Vec3A::Y,
        view: Vec3A::Y,
        object: 0,
        eps: 1e-5,
    };
    let mut checked = 0;
    for k in 0..40 {
        let ball_h = 0.3 + k as f64 * 0.06; // ball centre height: from a full umbra to a thin ring
        let shapes = vec![
            PShape::Plane {
                point: Vec3A::ZERO,
                normal: Vec3A::Y,
            },
            PShape::Sphere {
                center: Vec3A::new(0.0, ball_h as f32, 0.0),
                radius: ball_r as f32,
            },
        ];
        let v = sphere_visibility(
            &floor,
            Vec3A::new(0.0, light_h as f32, 0.0),
            light_r as f32,
            &shapes,
        );
        let tan = |r: f64, d: f64| (r / d).asin().tan();
        let hidden = (tan(ball_r, ball_h) / tan(light_r, light_h))
            .powi(2)
            .min(1.0);
        let want = 1.0 - hidden;
        assert!(
            (v as f64 - want).abs() <= 1.0 / SOFT_SAMPLES as f64,
            "ball at {ball_h}: visible {v}, concentric discs say {want}"
        );
        checked += 1;
    }
    assert_eq!(checked, 40);
}

/// A unit-intensity rectangle's irradiance at `x` (normal `n`) in f64 by a fine midpoint rule
/// (`cells` x `cells`), radiance 1/area: the reference for the renderer's coarse fixed grid.
fn rect_reference(
    x: DVec3,
    n: DVec3,
    centre: DVec3,
    u: DVec3,
    v: DVec3,
    normal: DVec3,
    cells: usize,
) -> f64 {
    let (mut sum, area) = (0.0, 4.0 * u.length() * v.length());
    for i in 0..cells {
        for j in 0..cells {
            let a = (2.0 * i as f64 + 1.0) / cells as f64 - 1.0;
            let b = (2.0 * j as f64 + 1.0) / cells as f64 - 1.0;
            let w = centre + a * u + b * v - x;
            let d2 = w.length_squared();
            let dir = w / d2.sqrt();
            sum += (n.dot(dir).max(0.0) * (-normal.dot(dir)).max(0.0)) / d2;
        }
    }
    sum * area / (cells * cells) as f64 / area
}

/// The fine reference itself against the closed form for a point on the axis of a parallel rectangle
/// (four corner view factors: E = 2L [X/sqrt(1+X^2) atan(Y/sqrt(1+X^2)) + Y/sqrt(1+Y^2) atan(X/sqrt(1+Y^2))],
/// X, Y the half-sides over the distance), then the renderer's rectangle light against the reference on a
/// floor lit by a tilted window: within the midpoint rule's error for its grid at these distances.
#[test]
fn a_rectangle_light_gives_the_integrated_irradiance() {
    let (w, h, dist) = (1.5f64, 1.0f64, 2.0f64);
    let (x, y) = (0.5 * w / dist, 0.5 * h / dist);
    let closed = 2.0 / (w * h)
        * (x / (1.0 + x * x).sqrt() * (y / (1.0 + x * x).sqrt()).atan()
            + y / (1.0 + y * y).sqrt() * (x / (1.0 + y * y).sqrt()).atan());
    let fine = rect_reference(
        DVec3::ZERO,
        DVec3::Y,
        DVec3::new(0.0, dist, 0.0),
        DVec3::new(0.5 * w, 0.0, 0.0),
        DVec3::new(0.0, 0.0, 0.5 * h),
        -DVec3::Y,
        600,
    );
    assert!((fine - closed).abs() < 1e-5 * closed, "{fine} vs {closed}");

    let text = plane_scene(
        r#""lights": [{"name": "window", "type": "rectangle", "position": [-3.5, 2, 0.5], "size": [1.5, 1],
                       "normal": [1, -0.3, 0.1], "up": [0, 1, 0], "intensity": 30}]"#,
    );
    let scene = Scene::from_json(&text).unwrap();
    let img = render(&scene, None, None, 1).unwrap();
    let r = scene.light.rect.unwrap();
    let normal = DVec3::from_array(r.normal);
    let up = DVec3::from_array(r.up);
    let (u, v) = (
        up.cross(normal).normalize() * 0.5 * r.size[0],
        up * 0.5 * r.size[1],
    );
    let centre = DVec3::from_array(scene.light.position);
    let (mut worst, mut count) = (0.0f64, 0);
    for (pixel, p) in seen_points(&scene) {
        let e = 30.0 * rect_reference(p, DVec3::Y, centre, u, v, normal, 300);
        let want = 0.6 / std::f64::consts::PI * e;
        let got = img.rgb[3 * pixel] as f64;
        worst = worst.max((got - want).abs() / want);
        count += 1;
    }
    assert!(count > 100);
    assert!(worst < 0.01, "largest relative error {worst}");
}

/// A rectangle light shines one way: a floor behind its plane (the window faces up, away from it) is
/// dark, and turning the window round lights it.
#[test]
fn a_rectangle_light_is_one_sided() {
    let lit = |normal: &str| {
        let text = plane_scene(&format!(
            r#""lights": [{{"name": "w", "type": "rectangle", "position": [0, 2, 0], "size": [1, 1],
                          "normal": {normal}, "intensity": 10}}]"#
        ));
        let img = render(&Scene::from_json(&text).unwrap(), None, None, 1).unwrap();
        img.rgb.iter().map(|&v| v as f64).sum::<f64>()
    };
    assert_eq!(lit("[0, 1, 0]"), 0.0);
    assert!(lit("[0, -1, 0]") > 0.0);
}

/// Bad rectangle fields fail in one line naming the field; a rectangle light is written back as it was
/// read and reads back the same.
#[test]
fn rectangle_fields_are_checked_and_round_trip() {
    let window = |extra: &str| {
        plane_scene(&format!(
            r#""lights": [{{"name": "lamp", "position": [1, 3, 0], "intensity": 20}},
                          {{"name": "w", "type": "rectangle", "position": [0, 2, 3], "intensity": 10{extra}}}]"#
        ))
    };
    let cases = [
        (r#", "size": [1.5, 1]"#, "lights[1].normal"),
        (r#", "normal": [0, 0, -1]"#, "lights[1].size"),
        (
            r#", "size": [0, 1], "normal": [0, 0, -1]"#,
            "lights[1].size",
        ),
        (
            r#", "size": [1, -1], "normal": [0, 0, -1]"#,
            "lights[1].size",
        ),
        (
            r#", "size": [1, 1], "normal": [0, 0, 0]"#,
            "lights[1].normal",
        ),
        (
            r#", "size": [1, 1], "normal": [0, 1, 0], "up": [0, -2, 0]"#,
            "lights[1].up",
        ),
        (
            r#", "size": [1, 1], "normal": [0, 0, -1], "radius": 0.2"#,
            "lights[1].radius",
        ),
        (
            r#", "size": [1, 1], "normal": [0, 0, -1], "direction": [0, 1, 0]"#,
            "lights[1].direction",
        ),
    ];
    for (extra, field) in cases {
        let msg = Scene::from_json(&window(extra)).unwrap_err().to_string();
        assert!(msg.contains(field) && !msg.contains('\n'), "{extra}: {msg}");
    }
    let point = plane_scene(
        r#""lights": [{"name": "p", "position": [1, 3, 0], "intensity": 20, "size": [1, 1]}]"#,
    );
    let msg = Scene::from_json(&point).unwrap_err().to_string();
    assert!(msg.contains("lights[0].size"), "{msg}");
    let single = plane_scene(
        r#""light": {"type": "rectangle", "position": [0, 2, 3], "size": [1, 1], "normal": [0, 0, -1], "intensity": 5}"#,
    );
    let msg = Scene::from_json(&single).unwrap_err().to_string();
    assert!(msg.contains("light.type"), "{msg}");

    let scene = Scene::from_json(&window(
        r#", "size": [1.5, 1], "normal": [0, -0.5, -1], "up": [0, 1, 0]"#,
    ))
    .unwrap();
    let r = scene.extra_lights[0].rect.unwrap();
    assert!((DVec3::from_array(r.up).dot(DVec3::from_array(r.normal))).abs() < 1e-12);
    let back = Scene::from_json(&scene.to_value().to_string()).unwrap();
    assert_eq!(back.extra_lights[0].rect.unwrap().size, [1.5, 1.0]);
    let (a, b) = (
        render(&scene, None, None, 1).unwrap(),
        render(&back, None, None, 1).unwrap(),
    );
    let diff = a
        .rgb
        .iter()
        .zip(&b.rgb)
        .map(|(x, y)| (x - y).abs())
        .fold(0.0f32, f32::max);
    assert!(
        diff <= 1e-6 * a.rgb.iter().fold(0.0f32, |m, &v| m.max(v)),
        "{diff}"
    );
}

/// A rectangle light's size set through a fit path: the working form (`ShadeParams::set`) holds the
/// rectangle the scene with that size written holds (the first light's and a further light's), and the
/// lights fit's closed form at a candidate size is the one at the scene with that size; a size path on
/// a point light, or bounds outside (0, 100] m, is one line naming the fit entry.
#[test]
fn a_fitted_rectangle_size_is_the_written_size() {
    use rtloop::fitness::lights::LightsFitness;
    use rtloop::params::ParamLayout;
    use rtloop::render::ShadeParams;
    use rtloop::scene::Target;
    let window = |size: &str, fit: &str| {
        format!(
            r#"{{"image": {{"width": 24, "height": 18}},
            "camera": {{"position": [0, 3, -4], "look_at": [0, 0.3, 0], "vfov_deg": 50}},
            "lights": [{{"name": "box", "type": "rectangle", "position": [-1.5, 1.5, -0.5], "size": {size},
                         "normal": [1, -0.6, 0.3], "intensity": 8}},
                       {{"name": "w", "type": "rectangle", "position": [1.8, 2, 0.5], "size": {size},
                         "normal": [-1, -0.5, -0.2], "intensity": 10}}],
            "objects": [{{"name": "ball", "shape": "sphere", "center": [0, 0.4, 0], "radius": 0.4}},
                        {{"name": "floor", "shape": "plane", "point": [0, 0, 0], "normal": [0, 1, 0]}}],
            "fit": {fit}}}"#
        )
    };
    let fit =
        r#"{"lights.box.size": {"min": 0.1, "max": 3}, "lights.w.size": {"min": 0.1, "max": 3}}"#;
    let base = Scene::from_json(&window("[1, 1]", fit)).unwrap();
    let want = Scene::from_json(&window("[1.7, 0.4]", fit)).unwrap();
    let mut p = ShadeParams::new(&base);
    p.set(Target::Size(0), &[1.7, 0.4]);
    p.set(Target::Size(1), &[1.7, 0.4]);
    let q = ShadeParams::new(&want);
    for (a, b) in [
        (p.light_rect.unwrap(), q.light_rect.unwrap()),
        (
            p.extra_lights[0].rect.unwrap(),
            q.extra_lights[0].rect.unwrap(),
        ),
    ] {
        for (x, y) in [
            (a.half_u, b.half_u),
            (a.half_v, b.half_v),
            (a.normal, b.normal),
        ] {
            assert!((x - y).length() <= 1e-6 * y.length(), "{x} vs {y}");
        }
    }
    let paths = vec!["lights.box.size".to_string(), "lights.w.size".to_string()];
    let layout = ParamLayout::new(&base, &paths).unwrap();
    let target = render(&want, None, None, 1).unwrap().rgb;
    let pixels: Vec<u32> = (0..24 * 18).collect();
    let f = LightsFitness::new(&base, layout, &target, &pixels).unwrap();
    let at = f.solve(&[1.7, 0.4, 1.7, 0.4]);
    let off = f.solve(&[1.0, 1.0, 1.0, 1.0]);
    assert!(at.loss < 1e-6 * off.loss, "{} vs {}", at.loss, off.loss);
    for (fit, field) in [
        (
            r#"{"lights.box.size": {"min": 0, "max": 3}}"#,
            r#"fit["lights.box.size"]"#,
        ),
        (
            r#"{"lights.w.size": {"min": 0.5, "max": 101}}"#,
            r#"fit["lights.w.size"]"#,
        ),
        (
            r#"{"lights.w.size": {"min": [0.5, 0.5, 0.5], "max": 2}}"#,
            r#"fit["lights.w.size"].min"#,
        ),
        (
            r#"{"lights.w.size": {"min": 2, "max": 1}}"#,
            r#"fit["lights.w.size"]"#,
        ),
    ] {
        let msg = Scene::from_json(&window("[1, 1]", fit))
            .unwrap_err()
            .to_string();
        assert!(msg.contains(field) && !msg.contains('\n'), "{fit}: {msg}");
    }
    let point = plane_scene(
        r#""lights": [{"name": "p", "position": [1, 3, 0], "intensity": 20}],
        "fit": {"lights.p.size": {"min": 0.5, "max": 2}}"#,
    );
    let msg = Scene::from_json(&point).unwrap_err().to_string();
    assert!(
        msg.contains("not a rectangle light") && msg.contains("lights.p.size"),
        "{msg}"
    );
}

/// A glossy ball (Blinn–Phong lobe) under a lamp and a window, rendered by the renderer: the lights
/// fit's closed form at the true geometry explains the render to rounding, its lobe products are
/// intensity x colour x specular per light, and without the lobe columns (the ball made matte in the
/// model) the same pixels are far from explained.
#[test]
fn the_lights_fit_s_lobe_columns_explain_a_glossy_render() {
    use rtloop::fitness::lights::LightsFitness;
    use rtloop::params::ParamLayout;
    let text = |specular: f64| {
        format!(
            r#"{{"image": {{"width": 48, "height": 36}},
            "camera": {{"position": [0, 2, -4], "look_at": [0, 0.5, 0], "vfov_deg": 40}},
            "lights": [{{"name": "lamp", "position": [1.5, 3, -2], "intensity": 20, "color": [1, 0.9, 0.8]}},
                       {{"name": "w", "type": "rectangle", "position": [-2.5, 2, -1], "size": [1.2, 0.8],
                         "normal": [1, -0.4, 0.4], "intensity": 15, "color": [0.8, 0.9, 1]}}],
            "objects": [{{"name": "ball", "shape": "sphere", "center": [0, 0.5, 0], "radius": 0.5,
                          "material": {{"albedo": [0.6, 0.3, 0.2], "specular": {specular}, "shininess": 30}}}},
                        {{"name": "floor", "shape": "plane", "point": [0, 0, 0], "normal": [0, 1, 0],
                          "material": {{"albedo": [0.5, 0.5, 0.5]}}}}],
            "fit": {{"lights.w.position": {{"min": -5, "max": 5}}}}}}"#
        )
    };
    let truth = Scene::from_json(&text(0.5)).unwrap();
    let target = render(&truth, None, None, 1).unwrap().rgb;
    let ids: Vec<u32> = seen_points(&truth).iter().map(|(k, _)| *k as u32).collect();
    let paths = vec!["lights.w.position".to_string()];
    let x = [-2.5, 2.0, -1.0];
    let solve = |scene: &Scene| {
        let layout = ParamLayout::new(scene, &paths).unwrap();
        LightsFitness::new(scene, layout, &target, &ids)
            .unwrap()
            .solve(&x)
    };
    let glossy = solve(&truth);
    let yy: f64 = ids
        .iter()
        .flat_map(|&k| (0..3).map(move |c| k as usize * 3 + c))
        .map(|i| (target[i] as f64).powi(2))
        .sum();
    assert!(glossy.loss < 1e-9 * yy, "{} of {yy}", glossy.loss);
    let ball = &glossy.products[0];
    assert_eq!(ball.len(), 5);
    for (l, rgb) in [(0, [20.0, 18.0, 16.0]), (1, [12.0, 13.5, 15.0])] {
        for c in 0..3 {
            let (want, got) = (rgb[c] * 0.5, ball[3 + l][c]);
            assert!(
                (got - want).abs() < 1e-3 * want,
                "light {l} channel {c}: {got} vs {want}"
            );
            let (want, got) = (rgb[c] * [0.6, 0.3, 0.2][c], ball[l][c]);
            assert!(
                (got - want).abs() < 1e-3 * want,
                "light {l} channel {c}: {got} vs {want}"
            );
        }
    }
    // the floor is matte: its lobe products are zero
    assert!(glossy.products[1][3..].iter().all(|p| *p == [0.0; 3]));
    let matte = solve(&Scene::from_json(&text(0.0)).unwrap());
    assert_eq!(matte.products[0].len(), 3);
    assert!(
        matte.loss > 1e3 * glossy.loss.max(1e-12 * yy),
        "{} vs {}",
        matte.loss,
        glossy.loss
    );
}
