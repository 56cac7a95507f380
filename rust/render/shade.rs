//! Render's per-pixel shading: direct light from one light (`light`) through the material (`brdf`),
//! with a shadow ray (`hit::occluded`), plus ambient and the occluded environment (`environment`).
//!
//! L = ρ·(ambient + env·S) + V·I·color·max(0, n·l)/d² · [ρ/π + k_s·(s+8)/(8π)·max(0, n·h)^s]
//!     (+ ρ·Σ_k F_k·L_k, one bounce from the other objects, with `interreflection`: `bounce`),
//! pixel = exposure·L, with V the light's visibility and S the sky view factor.

use glam::Vec3A;

use super::bounce::{gather, nearest_table, table_points, CachedPoint, GatherPoint, Gathered};
use super::brdf::{blinn_phong, lambert, specular_scale};
use super::coat::Coat;
use super::environment::sky_view;
use super::footprint::{edge_between, sphere_edge_lit, terminator_cos};
use super::hit::{occluded, Surfel};
use super::light::{incidence, irradiance, unit_or_up};
use super::lights::{sphere_visibility, unit_irradiance, Emitter, RectAxes};
use super::shape::PShape;
use crate::params::Target;
use crate::scene::Scene;

/// A material in working form.
#[derive(Clone, Copy, Debug)]
pub struct PMaterial {
    pub albedo: Vec3A,
    pub specular: f32,
    pub shininess: f32,
}

/// Everything shading needs that a fit may change: the light, global terms and the materials.
#[derive(Debug)]
pub struct ShadeParams {
    pub light_position: Vec3A,
    /// `Some(unit vector towards the light)` for a directional light: no fall-off, shadow rays to infinity.
    pub light_direction: Option<Vec3A>,
    pub light_intensity: f32,
    pub light_color: Vec3A,
    /// I · color, in W/sr per channel (kept in step by `set`).
    pub light_rgb: Vec3A,
    /// The first light's radius: a sphere light when > 0 (soft shadows, `lights::sphere_visibility`).
    pub light_radius: f32,
    /// The first light's shape when it is a rectangle light (`lights::rect_irradiance`).
    pub light_rect: Option<RectAxes>,
    /// The scene's further lights, each added through the same BRDF (`lights`); empty for one light.
    pub extra_lights: Vec<Emitter>,
    pub ambient: Vec3A,
    /// The environment radiance, occluded by the scene's shapes (see `environment`).
    pub environment: Vec3A,
    /// One diffuse bounce between the objects (see `bounce`).
    pub interreflection: bool,
    /// With `interreflection`, per sphere its table points and the light bounced onto each (radiance
    /// before its albedo), made by [`ShadeParams::prepare_bounce`]; empty otherwise.
    pub tables: Vec<(Vec<(Vec3A, Vec3A)>, Vec<Vec3A>)>,
    pub background: Vec3A,
    pub exposure: f32,
    pub materials: Vec<PMaterial>,
    /// False when every specular is 0: the Blinn–Phong lobe is skipped entirely.
    pub any_specular: bool,
    /// Per object its coat (`coat`), or empty when no object has one: a coated object's direct light
    /// goes through the coat's BRDF instead of Lambert plus Blinn–Phong.
    pub coats: Vec<Option<Coat>>,
}

impl Clone for ShadeParams {
    fn clone(&self) -> Self {
        let mut p = ShadeParams {
            materials: Vec::with_capacity(self.materials.len()),
            tables: self.tables.clone(),
            extra_lights: self.extra_lights.clone(),
            coats: self.coats.clone(),
            ..*self
        };
        p.materials.extend_from_slice(&self.materials);
        p
    }

    /// Reuses the vectors' allocations: the fitness hot path calls this once per candidate.
    fn clone_from(&mut self, source: &Self) {
        *self = ShadeParams {
            materials: refill(std::mem::take(&mut self.materials), &source.materials),
            tables: refill(std::mem::take(&mut self.tables), &source.tables),
            extra_lights: refill(std::mem::take(&mut self.extra_lights), &source.extra_lights),
            coats: refill(std::mem::take(&mut self.coats), &source.coats),
            ..*source
        };
    }
}

/// `into` made a copy of `from` in `into`'s allocation (nothing to do when both are empty).
fn refill<T: Clone>(mut into: Vec<T>, from: &Vec<T>) -> Vec<T> {
    if !from.is_empty() || !into.is_empty() {
        into.clone_from(from);
    }
    into
}

/// Per object its coat, or empty when no object has one.
fn coats_of(scene: &Scene) -> Vec<Option<Coat>> {
    if scene.objects.iter().all(|o| o.material.coat.is_none()) {
        return Vec::new();
    }
    scene
        .objects
        .iter()
        .map(|o| o.material.coat.map(|c| Coat::new(c.roughness, c.ior)))
        .collect()
}

fn v3(a: [f64; 3]) -> Vec3A {
    glam::DVec3::from_array(a).as_vec3a()
}

impl ShadeParams {
    pub fn new(scene: &Scene) -> ShadeParams {
        let materials: Vec<PMaterial> = scene
            .objects
            .iter()
            .map(|o| PMaterial {
                albedo: v3(o.material.albedo),
                specular: o.material.specular as f32,
                shininess: o.material.shininess as f32,
            })
            .collect();
        let mut p = ShadeParams {
            light_position: v3(scene.light.position),
            light_direction: scene.light.direction.map(|d| unit_or_up(v3(d))),
            light_intensity: scene.light.intensity as f32,
            light_color: v3(scene.light.color),
            light_rgb: v3(scene.light.color) * scene.light.intensity as f32,
            light_radius: scene.light.radius as f32,
            light_rect: scene.light.rect.as_ref().map(RectAxes::new),
            extra_lights: scene.extra_lights.iter().map(Emitter::new).collect(),
            ambient: v3(scene.ambient),
            environment: v3(scene.environment),
            interreflection: scene.interreflection,
            tables: Vec::new(),
            background: v3(scene.background),
            exposure: scene.exposure as f32,
            any_specular: false,
            materials,
            coats: coats_of(scene),
        };
        p.update_flags();
        p
    }

    /// Tabulate, for every sphere, the light the other objects bounce onto it (see `bounce::TABLE`), for
    /// the current parameters: the senders' second bounce that `shade` adds.
    pub fn prepare_bounce(&mut self, shapes: &[PShape]) {
        let mut points = Vec::new();
        self.prepare_tables(shapes, |p, k, at| {
            at.iter()
                .map(|&(y, n)| {
                    gather(y, n, k, shapes, &mut points);
                    points
                        .iter()
                        .map(|g| g.form * sender_radiance(g, p, shapes))
                        .fold(Vec3A::ZERO, |a, b| a + b)
                })
                .collect()
        });
    }

    /// [`ShadeParams::prepare_bounce`] from a render's cached gathers (`bounce::Gathered`, built for
    /// `shapes`): the same tables.
    pub fn prepare_bounce_cached(&mut self, shapes: &[PShape], cache: &Gathered) {
        self.prepare_tables(shapes, |p, k, _| {
            cache
                .table(k)
                .iter()
                .map(|points| {
                    points
                        .iter()
                        .map(|c| c.point.form * sender_radiance_cached(c, p, shapes))
                        .fold(Vec3A::ZERO, |a, b| a + b)
                })
                .collect()
        });
    }

    /// Rebuild `tables` (emptied first; left empty without interreflection): for every sphere `k`, its
    /// table points and the light `light(self, k, points)` gives at each; nothing for other shapes.
    fn prepare_tables(
        &mut self,
        shapes: &[PShape],
        mut light: impl FnMut(&Self, usize, &[(Vec3A, Vec3A)]) -> Vec<Vec3A>,
    ) {
        self.tables.clear();
        if !self.interreflection {
            return;
        }
        let tables: Vec<_> = shapes
            .iter()
            .enumerate()
            .map(|(k, shape)| match *shape {
                PShape::Sphere { center, radius } => {
                    let at = table_points(center, radius);
                    let light = light(self, k, &at);
                    (at, light)
                }
                PShape::Plane { .. } | PShape::Mesh(_) => (Vec::new(), Vec::new()),
            })
            .collect();
        self.tables = tables;
    }

    /// The coat of object `i`, if it has one.
    #[inline(always)]
    pub fn coat(&self, i: usize) -> Option<&Coat> {
        self.coats.get(i).and_then(|c| c.as_ref())
    }

    fn update_flags(&mut self) {
        self.any_specular = self.materials.iter().any(|m| m.specular != 0.0);
    }

    /// Apply one free parameter directly to the working form.
    pub fn set(&mut self, target: Target, v: &[f64]) {
        let v3 = || Vec3A::new(v[0] as f32, v[1] as f32, v[2] as f32);
        match target {
            Target::LightPosition => self.light_position = v3(),
            Target::LightDirection => self.light_direction = Some(unit_or_up(v3())),
            Target::LightIntensity => self.light_intensity = v[0] as f32,
            Target::LightColor => self.light_color = v3(),
            Target::Ambient => self.ambient = v3(),
            Target::Environment => self.environment = v3(),
            Target::Exposure => self.exposure = v[0] as f32,
            Target::Albedo(i) => self.materials[i].albedo = v3(),
            Target::Specular(i) => {
                self.materials[i].specular = v[0] as f32;
                self.update_flags();
            }
            Target::Shininess(i) => self.materials[i].shininess = v[0] as f32,
            Target::Roughness(i) => {
                if let Some(Some(c)) = self.coats.get_mut(i) {
                    *c = Coat::new(v[0], c.eta as f64);
                }
            }
            Target::ExtraPosition(i) => self.extra_lights[i - 1].position = v3(),
            Target::ExtraDirection(i) => {
                self.extra_lights[i - 1].direction = Some(unit_or_up(v3()))
            }
            Target::ExtraIntensity(i) => self.extra_lights[i - 1].intensity = v[0] as f32,
            Target::ExtraColor(i) => self.extra_lights[i - 1].color = v3(),
            Target::Radius(0) => self.light_radius = v[0].max(0.0) as f32,
            Target::Radius(i) => self.extra_lights[i - 1].radius = v[0].max(0.0) as f32,
            Target::Size(i) => {
                let rect = match i {
                    0 => &mut self.light_rect,
                    _ => &mut self.extra_lights[i - 1].rect,
                };
                if let Some(r) = rect {
                    *r = r.resized([v[0], v[1]]);
                }
            }
        }
        self.light_rgb = self.light_color * self.light_intensity;
    }
}

thread_local! {
    static GATHER: std::cell::RefCell<Vec<GatherPoint>> = const { std::cell::RefCell::new(Vec::new()) };
}

/// The radiance (before exposure) that the sender of `g` leaves at its representative point: its direct
/// light (shadowed), environment and ambient, diffusely; not its own bounce.
pub fn sender_radiance(g: &GatherPoint, p: &ShadeParams, shapes: &[PShape]) -> Vec3A {
    sender_radiance_with(
        g,
        || sky_view(g.position, g.normal, g.sender, shapes),
        || nearest_table(g.normal),
        p,
        shapes,
    )
}

/// [`sender_radiance`] from a render's cached gather point (`bounce::Gathered`): its sky view and table
/// point as kept, the same value.
#[inline]
pub fn sender_radiance_cached(c: &CachedPoint, p: &ShadeParams, shapes: &[PShape]) -> Vec3A {
    sender_radiance_with(&c.point, || c.sky, || c.table as usize, p, shapes)
}

/// [`sender_radiance`] with the point's sky view (`sky`, called only with environment light) and its
/// sender's nearest table point (`table`, called only for a sphere sender once tables are prepared).
#[inline(always)]
fn sender_radiance_with(
    g: &GatherPoint,
    sky: impl Fn() -> f32,
    table: impl Fn() -> usize,
    p: &ShadeParams,
    shapes: &[PShape],
) -> Vec3A {
    let m = &p.materials[g.sender];
    let mut l = m.albedo * p.ambient;
    if p.environment != Vec3A::ZERO {
        l += m.albedo * p.environment * sky();
    }
    if let Some((dir, dist, falloff)) = incidence(p.light_position, p.light_direction, g.position) {
        let ndotl = g.normal.dot(dir);
        let at = Surfel {
            position: g.position,
            normal: g.normal,
            view: g.normal,
            object: g.sender as u32,
            eps: Surfel::eps_at(g.position.abs().max_element() + shapes[g.sender].scale()),
        };
        if ndotl > 0.0 && !occluded(&at, dir, dist, shapes) {
            l += (p.light_rgb * lambert(m.albedo) * irradiance(ndotl, falloff))
                .min(Vec3A::splat(f32::MAX));
        }
    }
    // A sphere sender's own bounce (the second bounce), from its table once prepared.
    if let Some((at, light)) = p.tables.get(g.sender) {
        if !at.is_empty() {
            l += m.albedo * light[table()];
        }
    }
    l
}

/// Exposure-scaled radiance towards the eye at surfel `s` (the background for a miss).
#[inline]
pub fn shade(s: &Surfel, p: &ShadeParams, shapes: &[PShape], shadows: bool) -> Vec3A {
    Shading::new(p, shapes, shadows)
        .shade(s, Pixel::default())
        .0
}

/// What shading a scene's surfels takes: its parameters, its shapes, and whether shadow rays are traced.
#[derive(Clone, Copy)]
pub struct Shading<'a> {
    pub params: &'a ShadeParams,
    pub shapes: &'a [PShape],
    pub shadows: bool,
}

/// What a pixel adds to the shading of its surfel, each part optional: `Pixel::default()` shades the
/// surfel alone, as [`shade`] does.
#[derive(Default)]
pub struct Pixel<'a> {
    /// The pixel's footprint on the surface (`footprint::axes`): a sphere's shadow edge and a sphere's own
    /// terminator are averaged over the pixel (`footprint::sphere_edge_lit`, `footprint::terminator_cos`),
    /// as the fitness does.
    pub footprint: Option<&'a [Vec3A; 2]>,
    /// The pixel's gather points from a render's cache (`bounce::Gathered::pixel`); `None` gathers them:
    /// the same value.
    pub gathered: Option<&'a [CachedPoint]>,
    /// Where the surfel's sky view (`environment::sky_view`, which depends on the surfaces alone) is kept:
    /// computed where the environment needs it and the kept value is None, else taken from it, so that
    /// scenes sharing a surfel compute it once (the same values bit for bit); `None` keeps it nowhere.
    pub sky: Option<&'a mut Option<f32>>,
}

impl<'a> Shading<'a> {
    /// Shading with `params` among `shapes`, tracing shadow rays where `shadows`.
    #[inline(always)]
    pub fn new(params: &'a ShadeParams, shapes: &'a [PShape], shadows: bool) -> Self {
        Shading {
            params,
            shapes,
            shadows,
        }
    }

    /// [`shade`] at a `pixel` (its footprint, its cached gathers, its kept sky view), and whether the light
    /// faces the point but a shadow ray found it (partly) blocked.
    #[inline(always)]
    pub fn shade(&self, s: &Surfel, pixel: Pixel<'_>) -> (Vec3A, bool) {
        let footprint = pixel.footprint;
        match self.indirect_at(s, pixel) {
            Ok(l) => direct(s, footprint, self.params, self.shapes, self.shadows, l),
            Err(background) => (background, false),
        }
    }

    /// [`Shading::shade`] of one surfel at its pixel centre and over the `pixel`'s footprint, the light
    /// that does not depend on the footprint (ambient, environment, the bounce) gathered once: the same two
    /// values, bit for bit, as the two calls.
    pub fn shade_pair(&self, s: &Surfel, pixel: Pixel<'_>) -> (Vec3A, Vec3A) {
        let footprint = pixel.footprint;
        let l = match self.indirect_at(s, pixel) {
            Ok(l) => l,
            Err(background) => return (background, background),
        };
        let (p, shapes, shadows) = (self.params, self.shapes, self.shadows);
        let centre = direct(s, None, p, shapes, shadows, l).0;
        let over = match footprint {
            Some(_) => direct(s, footprint, p, shapes, shadows, l).0,
            None => centre,
        };
        (centre, over)
    }

    /// The `indirect` light at `s` (the `pixel`'s gathers and kept sky view used), or `Err` with the
    /// exposure-scaled background for a miss.
    #[inline(always)]
    fn indirect_at(&self, s: &Surfel, pixel: Pixel<'_>) -> Result<Vec3A, Vec3A> {
        let p = self.params;
        if s.object == u32::MAX {
            return Err(p.exposure * p.background);
        }
        let mut sky = None;
        let sky = pixel.sky.unwrap_or(&mut sky);
        Ok(indirect(s, p, self.shapes, pixel.gathered, sky))
    }
}

/// The light at an object's surfel (not the background) that does not come straight from the light:
/// ambient, environment (its sky view kept in `sky`) and, with interreflection, the bounce; before exposure.
#[inline(always)]
fn indirect(
    s: &Surfel,
    p: &ShadeParams,
    shapes: &[PShape],
    gathered: Option<&[CachedPoint]>,
    sky: &mut Option<f32>,
) -> Vec3A {
    let m = &p.materials[s.object as usize];
    let mut l = m.albedo * p.ambient;
    if p.environment != Vec3A::ZERO {
        let sky =
            *sky.get_or_insert_with(|| sky_view(s.position, s.normal, s.object as usize, shapes));
        l += m.albedo * p.environment * sky;
    }
    if let (true, Some(points)) = (p.interreflection, gathered) {
        for c in points {
            l += m.albedo * c.point.form * sender_radiance_cached(c, p, shapes);
        }
    } else if p.interreflection {
        GATHER.with_borrow_mut(|points| {
            gather(s.position, s.normal, s.object as usize, shapes, points);
            for g in points.iter() {
                l += m.albedo * g.form * sender_radiance(g, p, shapes);
            }
        });
    }
    l
}

/// The exposure-scaled radiance at an object's surfel: the `indirect` light `l` plus the light's own
/// (over the pixel's `footprint` where given), and whether the light faces the point but is (partly)
/// blocked.
#[inline(always)]
fn direct(
    s: &Surfel,
    footprint: Option<&[Vec3A; 2]>,
    p: &ShadeParams,
    shapes: &[PShape],
    shadows: bool,
    mut l: Vec3A,
) -> (Vec3A, bool) {
    let m = &p.materials[s.object as usize];
    for e in &p.extra_lights {
        if let Some((dir, e_unit)) = unit_irradiance(s, e, shapes, shadows) {
            l += (e.rgb() * brdf(s, m, p, dir) * e_unit).min(Vec3A::splat(f32::MAX));
        }
    }
    if let Some(r) = &p.light_rect {
        let e = Emitter {
            position: p.light_position,
            direction: None,
            intensity: p.light_intensity,
            color: p.light_color,
            radius: 0.0,
            rect: Some(*r),
        };
        if let Some((dir, e_unit)) = unit_irradiance(s, &e, shapes, shadows) {
            l += (e.rgb() * brdf(s, m, p, dir) * e_unit).min(Vec3A::splat(f32::MAX));
        }
        return ((p.exposure * l).min(Vec3A::splat(f32::MAX)), false);
    }
    let Some((dir, dist, falloff)) = incidence(p.light_position, p.light_direction, s.position)
    else {
        return ((p.exposure * l).min(Vec3A::splat(f32::MAX)), false);
    };
    let mut ndotl = s.normal.dot(dir);
    let axes = footprint.map(|f| [f[0].to_array(), f[1].to_array()]);
    if let Some(axes) = axes {
        if let Some(PShape::Sphere { radius, .. }) = shapes.get(s.object as usize) {
            ndotl = terminator_cos(s.normal.to_array(), dir.to_array(), axes, *radius);
        }
    }
    let visible = match (shadows, axes) {
        (false, _) => 1.0,
        (true, _) if ndotl <= 0.0 => 1.0, // unlit anyway: no shadow ray
        (true, _) if p.light_radius > 0.0 && p.light_direction.is_none() => {
            sphere_visibility(s, p.light_position, p.light_radius, shapes)
        }
        (true, None) => f32::from(u8::from(!occluded(s, dir, dist, shapes))),
        (true, Some(axes)) => visible_fraction(s, axes, p, dir, dist, shapes),
    };
    let shadowed = ndotl > 0.0 && visible < 1.0;
    if ndotl > 0.0 && visible > 0.0 {
        let brdf = brdf(s, m, p, dir);
        l +=
            (p.light_rgb * brdf * irradiance(ndotl, falloff) * visible).min(Vec3A::splat(f32::MAX));
    }
    ((p.exposure * l).min(Vec3A::splat(f32::MAX)), shadowed)
}

/// The material's BRDF at `s` for light from `dir`: Lambert plus the Blinn–Phong lobe where specular,
/// or the coat's (`coat::Coat`) where the object has one.
#[inline(always)]
fn brdf(s: &Surfel, m: &PMaterial, p: &ShadeParams, dir: Vec3A) -> Vec3A {
    if let Some(c) = p.coat(s.object as usize) {
        let mut brdf = m.albedo * c.diffuse(s.normal.dot(dir), s.normal.dot(s.view));
        if m.specular > 0.0 {
            brdf += Vec3A::splat(m.specular * c.specular(s.normal, dir, s.view));
        }
        return brdf;
    }
    let mut brdf = lambert(m.albedo);
    if p.any_specular && m.specular > 0.0 {
        let lobe = specular_scale(m.specular, m.shininess)
            * blinn_phong(s.normal, dir, s.view, m.shininess);
        brdf += Vec3A::splat(lobe);
    }
    brdf
}

/// The fraction of the pixel at `s` (footprint `axes`) the light reaches: each other sphere's shadow
/// edge straight across the pixel where the line to the light passes it between the two, any other
/// occluder as `occluded` tests it.
fn visible_fraction(
    s: &Surfel,
    axes: [[f32; 3]; 2],
    p: &ShadeParams,
    dir: Vec3A,
    dist: f32,
    shapes: &[PShape],
) -> f32 {
    let (to, point) = match p.light_direction {
        Some(d) => (d, 0.0),
        None => (p.light_position, 1.0),
    };
    let (tmin, tmax) = s.shadow_range(dist);
    let mut lit = 1.0;
    for (k, sh) in shapes.iter().enumerate() {
        if k as u32 == s.object && !matches!(sh, PShape::Mesh(_)) {
            continue;
        }
        if let PShape::Sphere { center, radius } = *sh {
            // Where the closest approach of the line to the centre lies between point and light.
            let d = to - point * s.position;
            let (a, b) = (d.length_squared(), (s.position - center).dot(d));
            let between = if point == 0.0 {
                edge_between::<false>(a, b)
            } else {
                edge_between::<true>(a, b)
            };
            if between {
                let (pa, ta, ca) = (s.position.to_array(), to.to_array(), center.to_array());
                lit *= sphere_edge_lit(pa, axes, ta, point, ca, radius);
                continue;
            }
        }
        if sh.hits_segment(s.position, dir, tmin, tmax) {
            return 0.0;
        }
    }
    lit
}

#[cfg(test)]
mod tests {
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
}
