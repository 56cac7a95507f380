//! When the closed form (the projected method) applies to a scene, and which constant term it solves.

use super::lobe::coat_blocker;
use super::pixels::Sky;
use crate::scene::Scene;

/// `None` when the closed form (the projected method) applies to `scene` with the fit section `paths`
/// free, else why not: the one decision of it (Python's fit asks this too).
pub fn projection_blocker(scene: &Scene, paths: &[String]) -> Option<String> {
    let free = |p: &str| paths.iter().any(|q| q == p);
    if !free("light.position") && !free("light.direction") {
        return Some("neither light.position nor light.direction is free".into());
    }
    let ambient = scene.ambient.iter().any(|&v| v != 0.0) || free("ambient");
    if ambient && (scene.environment.iter().any(|&v| v != 0.0) || free("environment")) {
        return Some("the scene has both ambient light and an environment".into());
    }
    if ambient && scene.interreflection {
        return Some("the scene has ambient light and interreflection".into());
    }
    if let Some(why) = coat_blocker(scene) {
        return Some(why);
    }
    let allowed = |p: &str| {
        matches!(
            p,
            "light.position" | "light.direction" | "light.intensity" | "environment" | "ambient"
        ) || scene.objects.iter().any(|o| {
            ["albedo", "specular", "shininess", "roughness"]
                .iter()
                .any(|m| p == format!("objects.{}.{m}", o.name))
        })
    };
    let extra: Vec<&str> = paths
        .iter()
        .map(String::as_str)
        .filter(|p| !allowed(p))
        .collect();
    if !extra.is_empty() {
        return Some(format!(
            "{} cannot be solved in closed form",
            extra.join(", ")
        ));
    }
    if free("light.intensity") {
        let names = |f: &dyn Fn(&crate::scene::Object) -> bool| {
            let v: Vec<&str> = scene
                .objects
                .iter()
                .filter(|o| f(o))
                .map(|o| o.name.as_str())
                .collect();
            v.join(", ")
        };
        let fixed = names(&|o| !free(&format!("objects.{}.albedo", o.name)));
        if !fixed.is_empty() {
            return Some(format!(
                "light.intensity is free but the albedo of {fixed} is fixed"
            ));
        }
    }
    None
}

/// The constant-radiance term the closed form's second column models for `scene`: its occluded
/// environment, or else its ambient light (given or free; unoccluded), or none. The projected method
/// solves one of them (`projection_blocker` refuses both at once).
pub fn constant_term(scene: &Scene) -> Sky {
    let free = |p: &str| scene.fit.iter().any(|f| f.path == p);
    if scene.environment != [0.0; 3] || free("environment") {
        Sky::Occluded
    } else if scene.ambient != [0.0; 3] || free("ambient") {
        Sky::Open
    } else {
        Sky::Occluded
    }
}
