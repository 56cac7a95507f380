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
    let geo = Geometry::new(&scene);
    let albedo = DVec3::new(0.6, 0.4, 0.2);
    let n = DVec3::Y;
    let (mut worst, mut count) = (0.0f64, 0);
    for j in 0..scene.height {
        for i in 0..scene.width {
            let s = geo.primary(i as f32 + 0.5, j as f32 + 0.5, scene.width, scene.height);
            if s.object == u32::MAX {
                continue;
            }
            let p = DVec3::new(
                s.position.x as f64,
                s.position.y as f64,
                s.position.z as f64,
            );
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
            let k = 3 * (j * scene.width + i) as usize;
            for c in 0..3 {
                let got = img.rgb[k + c] as f64;
                worst = worst.max((got - want[c]).abs() / want[c]);
            }
            count += 1;
        }
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
