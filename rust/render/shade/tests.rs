//! Shading's unit tests: Lambert, Blinn-Phong, the background, shadows.
use super::*;
use crate::render::Surfel;

fn params(spec: f32, shin: f32) -> ShadeParams {
    ShadeParams {
        light_position: Vec3A::new(0.0, 2.0, 0.0),
        light_direction: None,
        light_intensity: 10.0,
        light_color: Vec3A::ONE,
        light_rgb: Vec3A::splat(10.0),
        light_radius: 0.0,
        light_rect: None,
        extra_lights: Vec::new(),
        ambient: Vec3A::ZERO,
        environment: Vec3A::ZERO,
        interreflection: false,
        coats: Vec::new(),
        tables: Vec::new(),
        background: Vec3A::new(0.1, 0.2, 0.3),
        exposure: 1.0,
        materials: vec![PMaterial {
            albedo: Vec3A::splat(0.5),
            specular: spec,
            shininess: shin,
        }],
        any_specular: spec != 0.0,
    }
}

fn floor_point(x: f32) -> Surfel {
    Surfel {
        position: Vec3A::new(x, 0.0, 0.0),
        normal: Vec3A::Y,
        view: Vec3A::Y,
        object: 0,
        eps: 1e-6,
    }
}

#[test]
fn lambert_inverse_square_and_cosine() {
    let p = params(0.0, 0.0);
    let under = shade(&floor_point(0.0), &p, &[], false);
    assert!((under.x - 10.0 * 0.5 / std::f32::consts::PI / 4.0).abs() < 1e-6);
    // At x = 2 the light is at 45 degrees and sqrt(8) away.
    let side = shade(&floor_point(2.0), &p, &[], false);
    let want = 10.0 * 0.5 / std::f32::consts::PI * (0.5f32.sqrt()) / 8.0;
    assert!((side.x - want).abs() < 1e-6);
}

#[test]
fn light_on_or_below_the_surface_gives_no_direct_light_and_no_nan() {
    let mut p = params(1.0, 10.0);
    p.light_position = Vec3A::ZERO;
    assert_eq!(shade(&floor_point(0.0), &p, &[], false), Vec3A::ZERO);
    p.light_position = Vec3A::new(0.0, -1.0, 0.0);
    assert_eq!(shade(&floor_point(0.0), &p, &[], false), Vec3A::ZERO);
    p.light_position = Vec3A::new(0.0, 1e-30, 0.0);
    let v = shade(&floor_point(0.0), &p, &[], false);
    assert!(v.is_finite(), "{v}");
}

#[test]
fn normalised_blinn_phong_peak() {
    // Eye straight above, light straight above: n.h = 1, lobe = ks (s+8)/(8 pi).
    let p = params(0.5, 20.0);
    let v = shade(&floor_point(0.0), &p, &[], false);
    let e = 10.0 / 4.0;
    let want = e * (0.5 / std::f32::consts::PI + 0.5 * 28.0 / (8.0 * std::f32::consts::PI));
    assert!((v.x - want).abs() < 1e-5, "{} vs {want}", v.x);
}

#[test]
fn miss_returns_exposed_background() {
    let mut p = params(0.0, 0.0);
    p.exposure = 2.0;
    let mut s = floor_point(0.0);
    s.object = u32::MAX;
    assert_eq!(shade(&s, &p, &[], false), Vec3A::new(0.2, 0.4, 0.6));
}

#[test]
fn sphere_shadows_the_floor_but_not_beside_it() {
    let p = params(0.0, 0.0);
    let shapes = crate::render::shape::ball_over_floor(1.0, 0.5);
    // Light at y = 2 straight above a sphere centred at y = 1 with r = 0.5.
    assert_eq!(shade(&floor_point(0.0), &p, &shapes, true), Vec3A::ZERO);
    assert!(shade(&floor_point(3.0), &p, &shapes, true).x > 0.0);
}
