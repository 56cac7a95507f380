//! The renderer: camera rays -> closest hit -> direct lighting -> linear RGB image.
//!
//! The data flow is split at the first hit: `hit` finds what does not depend on the light or the
//! materials (`Surfel`: hit point, normal, view direction, object), and `shade` turns one into radiance
//! with the `brdf` and `light` formulas. A fit does not call `render`: the fitness evaluates the same
//! `brdf`/`light` formulas over precomputed first hits (see `crate::fitness`).

pub mod adaptive;
pub mod bounce;
pub mod brdf;
pub mod camera;
pub mod coat;
pub mod composite;
pub mod environment;
pub mod film;
pub mod footprint;
pub mod hit;
pub mod light;
pub mod lights;
pub mod shade;
pub mod shape;

use glam::Vec3A;
use rayon::prelude::*;

use crate::error::{Error, Result};
use crate::scene::Scene;
pub use adaptive::{render_layers, Layers, Progress};
pub use camera::{sample_offsets, CameraFrame};
pub use composite::composite;
pub use film::{linear_to_srgb, save_srgb8, to_srgb8, Image};
pub use hit::{closest_hit, occluded, GBuffer, Geometry, Surfel};
pub use shade::{shade, Pixel, ShadeParams, Shading};
pub use shape::PShape;

/// Render `scene` at `width` x `height` (the scene's own size when `None`) with `spp` samples per pixel
/// (one: the pixel centre).
pub fn render(scene: &Scene, width: Option<u32>, height: Option<u32>, spp: u32) -> Result<Image> {
    render_with(scene, width, height, spp, false)
}

/// [`render`], with `footprint` (one sample per pixel): sphere shadow edges and terminators integrated
/// over each pixel's footprint in closed form, as the fitness with the footprint models a photo.
pub fn render_with(
    scene: &Scene,
    width: Option<u32>,
    height: Option<u32>,
    spp: u32,
    footprint: bool,
) -> Result<Image> {
    render_model(scene, (width, height), spp, footprint, false)
}

/// [`render_with`], with `outlines` (and the footprint) the pixels that straddle an object's outline each
/// the mean of their sub-pixel rays (`footprint::silhouette_samples`), as the fitness with
/// `FitnessSpec::outlines` models a photo.
pub fn render_model(
    scene: &Scene,
    (width, height): (Option<u32>, Option<u32>),
    spp: u32,
    footprint: bool,
    outlines: bool,
) -> Result<Image> {
    let frame = Frame::new(scene, width, height, spp, footprint, outlines)?;
    let (width, height) = (frame.width, frame.height);
    let mut rgb = vec![0.0f32; (width * height * 3) as usize];
    rgb.par_chunks_mut(3 * width as usize)
        .enumerate()
        .for_each(|(j, row)| {
            for (i, px) in row.chunks_exact_mut(3).enumerate() {
                px.copy_from_slice(&frame.pixel(i as u32, j as u32).to_array());
            }
        });
    Ok(Image { width, height, rgb })
}

/// The pixel-centre render of `scene` (one sample per pixel, its own size) and the footprint render
/// ([`render_with`] with `footprint`) in one pass, each pixel's light that does not depend on the footprint
/// (ambient, environment, the bounce) shaded once: both images bit for bit (a fit compares the footprint
/// render; its uncertainty differentiates the pixel centres).
/// With `outlines`, the footprint render's outline pixels are integrated too ([`render_model`]).
pub fn render_centre_and_footprint(scene: &Scene, outlines: bool) -> Result<(Image, Image)> {
    let frame = Frame::new(scene, None, None, 1, true, outlines)?;
    let (width, height) = (frame.width, frame.height);
    let mut centre = vec![0.0f32; (width * height * 3) as usize];
    let mut over = vec![0.0f32; (width * height * 3) as usize];
    centre
        .par_chunks_mut(3 * width as usize)
        .zip(over.par_chunks_mut(3 * width as usize))
        .enumerate()
        .for_each(|(j, (row_c, row_f))| {
            for (i, (pc, pf)) in row_c
                .chunks_exact_mut(3)
                .zip(row_f.chunks_exact_mut(3))
                .enumerate()
            {
                let (c, f) = frame.pixel_pair(i as u32, j as u32);
                pc.copy_from_slice(&c.to_array());
                pf.copy_from_slice(&f.to_array());
            }
        });
    Ok((
        Image {
            width,
            height,
            rgb: centre,
        },
        Image {
            width,
            height,
            rgb: over,
        },
    ))
}

/// The pixels `idx` (flat indices `j * width + i` of the scene's own size) of [`render`] at one sample per
/// pixel, of each of `scenes` (three values a pixel, in `idx`'s order), in one pass: scenes that see the
/// same surfaces (the same camera, image size, spheres and planes: only the light, the materials or the
/// environment differ, as the finite differences of a light's position) find each pixel's first hit once
/// and shade it under each scene. The values are those pixels of each scene's whole render bit for bit,
/// for the cost of these pixels alone (a Jacobian column over the used pixels).
pub fn render_pixels_many(scenes: &[&Scene], idx: &[u32]) -> Result<Vec<Vec<f32>>> {
    Ok(shade_many(scenes, idx, false)?.0)
}

/// The pixels `idx` (flat indices `j * width + i` of the scene's own size) of [`render_with`] at one sample
/// per pixel, three values a pixel in `idx`'s order: those pixels of the whole render bit for bit, for the cost
/// of these pixels alone (a fit's tests that read every few pixels of a render).
pub fn render_pixels(scene: &Scene, idx: &[u32], footprint: bool) -> Result<Vec<f32>> {
    let frame = Frame::new(scene, None, None, 1, footprint, false)?;
    check_pixels(&frame, idx)?;
    let mut rgb = vec![0.0f32; 3 * idx.len()];
    rgb.par_chunks_mut(3 * 64)
        .zip(idx.par_chunks(64))
        .for_each(|(out, at)| {
            for (px, &p) in out.chunks_exact_mut(3).zip(at) {
                px.copy_from_slice(&frame.pixel(p % frame.width, p / frame.width).to_array());
            }
        });
    Ok(rgb)
}

/// An error naming the first of `idx` outside `frame`'s image.
fn check_pixels(frame: &Frame, idx: &[u32]) -> Result<()> {
    let pixels = u64::from(frame.width) * u64::from(frame.height);
    match idx.iter().find(|&&p| u64::from(p) >= pixels) {
        Some(&p) => Err(Error::Invalid(format!(
            "render_pixels: pixel {p} is outside the {pixels} of a {}x{} image",
            frame.width, frame.height
        ))),
        None => Ok(()),
    }
}

/// The whole one-sample renders of `scenes`, which must have the same image size, in one pass
/// ([`render_pixels_many`]), and the object index per pixel of the first scene's first hits (-1 for
/// background: [`object_ids`]'s values).
pub fn render_many_with_ids(scenes: &[&Scene]) -> Result<(Vec<Image>, Vec<i32>)> {
    let Some(first) = scenes.first() else {
        return Ok((Vec::new(), Vec::new()));
    };
    let (width, height) = (first.width, first.height);
    if let Some(s) = scenes
        .iter()
        .find(|s| (s.width, s.height) != (width, height))
    {
        return Err(Error::Invalid(format!(
            "render_many: the scenes differ in size ({width}x{height} and {}x{})",
            s.width, s.height
        )));
    }
    let idx: Vec<u32> = (0..width.saturating_mul(height)).collect(); // sizes are checked below 16384
    let (rgb, ids) = shade_many(scenes, &idx, true)?;
    Ok((
        rgb.into_iter()
            .map(|rgb| Image { width, height, rgb })
            .collect(),
        ids,
    ))
}

/// [`render_pixels_many`], with the first scene's object index per pixel when `ids`.
fn shade_many(scenes: &[&Scene], idx: &[u32], ids: bool) -> Result<(Vec<Vec<f32>>, Vec<i32>)> {
    let frames = scenes
        .iter()
        .map(|s| Frame::new(s, None, None, 1, false, false))
        .collect::<Result<Vec<_>>>()?;
    for f in &frames {
        check_pixels(f, idx)?;
    }
    // each scene's leader: the first scene with the same first hits (itself where none is)
    let keys: Vec<_> = frames.iter().map(|f| f.key.clone()).collect();
    let leader: Vec<usize> = (0..frames.len())
        .map(|k| match &keys[k] {
            Some(key) => (0..k).find(|&j| keys[j].as_ref() == Some(key)).unwrap_or(k),
            None => k,
        })
        .collect();
    let n = idx.len();
    const CHUNK: usize = 64; // fixed: each value is computed the same way however the work is split
    let parts: Vec<(Vec<f32>, Vec<i32>)> = idx
        .par_chunks(CHUNK)
        .map(|at| {
            let mut part = vec![0.0f32; 3 * at.len() * frames.len()];
            let mut hit = vec![-1i32; if ids { at.len() } else { 0 }];
            for (q, &p) in at.iter().enumerate() {
                for (k, f) in frames.iter().enumerate() {
                    if leader[k] != k {
                        continue;
                    }
                    let (i, j) = (p % f.width, p / f.width); // a scene's followers share its size
                    let (dx, dy) = f.offsets[0];
                    let s = f
                        .geometry
                        .primary(i as f32 + dx, j as f32 + dy, f.width, f.height);
                    if ids && k == 0 && s.object != u32::MAX {
                        hit[q] = s.object as i32;
                    }
                    let mut sky = None; // the surfel's sky view, once for the scenes sharing it
                    for (m, g) in frames.iter().enumerate().filter(|&(m, _)| leader[m] == k) {
                        let mut sum = Vec3A::ZERO;
                        sum += g.sample_sky(&s, i, j, &mut sky);
                        let v = g.mean(sum).to_array();
                        let at = 3 * (m * at.len() + q);
                        part[at..at + 3].copy_from_slice(&v);
                    }
                }
            }
            (part, hit)
        })
        .collect();
    let mut out = vec![vec![0.0f32; 3 * n]; frames.len()];
    let mut object = Vec::with_capacity(if ids { n } else { 0 });
    for (c, (part, hit)) in parts.iter().enumerate() {
        let len = part.len() / frames.len().max(1);
        for (k, o) in out.iter_mut().enumerate() {
            o[3 * CHUNK * c..3 * CHUNK * c + len].copy_from_slice(&part[k * len..(k + 1) * len]);
        }
        object.extend_from_slice(hit);
    }
    Ok((out, object))
}

/// What every pixel of one render shares: the scene's geometry and shading set-up (the bounce's kept
/// gathers with it), the samples, and whether shadows and the footprint apply.
struct Frame {
    geometry: Geometry,
    key: Option<Vec<u32>>, // bounce::geometry_key: frames with the same key see the same first hits
    params: ShadeParams,
    cache: Option<std::sync::Arc<bounce::Gathered>>,
    shadows: bool,
    footprint: bool,
    /// With the footprint (and no bounce, whose gathers are the pixel centres'): the first hits at the
    /// pixel centres, which tell the pixels on an outline (`footprint::silhouette_samples`).
    outlines: Option<GBuffer>,
    offsets: Vec<(f32, f32)>,
    inv: f32, // 1 / the samples per pixel
    width: u32,
    height: u32,
}

impl Frame {
    fn new(
        scene: &Scene,
        width: Option<u32>,
        height: Option<u32>,
        spp: u32,
        footprint: bool,
        outlines: bool,
    ) -> Result<Self> {
        let width = width.unwrap_or(scene.width);
        let height = height.unwrap_or(scene.height);
        if width == 0 || height == 0 || width > 16384 || height > 16384 {
            return Err(Error::Invalid(format!(
                "image size must be 1..16384 pixels per side (got {width}x{height})"
            )));
        }
        if spp == 0 || spp > 4096 {
            return Err(Error::Invalid(format!("spp must be 1..4096 (got {spp})")));
        }
        let geometry = Geometry::new(scene);
        let mut params = ShadeParams::new(scene);
        // With the bounce, one sample per pixel: the light-independent gathers kept from the last render of
        // this geometry (`bounce::Gathered`; a fit's uncertainty renders it with the light moved).
        let c = &scene.camera;
        let camera_key = [
            c.position[0],
            c.position[1],
            c.position[2],
            c.look_at[0],
            c.look_at[1],
            c.look_at[2],
            c.up[0],
            c.up[1],
            c.up[2],
            c.vfov_deg,
        ];
        let cache = (params.interreflection && spp == 1)
            .then(|| {
                let sky = params.environment != Vec3A::ZERO;
                bounce::Gathered::for_render(&geometry, camera_key, (width, height), sky)
            })
            .flatten();
        match &cache {
            Some(cache) => params.prepare_bounce_cached(&geometry.shapes, cache),
            None => params.prepare_bounce(&geometry.shapes),
        }
        let shadows = scene.can_occlude();
        let offsets = sample_offsets(spp); // spp = 1: the pixel centre
                                           // The footprint (meshes aside, as the fitness refuses them) where the scene can shadow at all.
        if footprint && spp != 1 {
            return Err(Error::Invalid(format!(
                "the footprint render takes one sample per pixel (got spp {spp})"
            )));
        }
        let footprint =
            footprint && shadows && !geometry.shapes.iter().any(|s| matches!(s, PShape::Mesh(_)));
        let key = bounce::geometry_key(&geometry, camera_key, (width, height));
        let outlines = (footprint && outlines && !params.interreflection)
            .then(|| GBuffer::new(&geometry, width, height));
        Ok(Frame {
            outlines,
            geometry,
            key,
            params,
            cache,
            shadows,
            footprint,
            inv: 1.0 / offsets.len() as f32,
            offsets,
            width,
            height,
        })
    }

    /// Pixel (i, j): the mean of its samples, finite.
    #[inline(always)]
    fn pixel(&self, i: u32, j: u32) -> Vec3A {
        if let Some(v) = self.outline(i, j) {
            return v;
        }
        let mut sum = Vec3A::ZERO;
        for &(dx, dy) in &self.offsets {
            let s = self
                .geometry
                .primary(i as f32 + dx, j as f32 + dy, self.width, self.height);
            sum += self.sample(&s, i, j);
        }
        self.mean(sum)
    }

    /// The radiance of one sample of pixel (i, j) whose first hit is `s`.
    #[inline(always)]
    fn sample(&self, s: &Surfel, i: u32, j: u32) -> Vec3A {
        let (width, height) = (self.width, self.height);
        let axes = (self.footprint && s.object != u32::MAX).then(|| {
            let shape = &self.geometry.shapes[s.object as usize];
            footprint::axes(&self.geometry.camera, s, shape, (i, j), (width, height))
        });
        let gathered = self
            .cache
            .as_ref()
            .map(|c| c.pixel(j as usize * width as usize + i as usize));
        let pixel = Pixel {
            footprint: axes.as_ref(),
            gathered,
            sky: None,
        };
        self.shading().shade(s, pixel).0
    }

    /// Pixel (i, j) of a one-sample frame at its centre and over its footprint (the frame's, where it
    /// takes one): [`Frame::pixel`] without and with the footprint.
    fn pixel_pair(&self, i: u32, j: u32) -> (Vec3A, Vec3A) {
        let (dx, dy) = self.offsets[0];
        let s = self
            .geometry
            .primary(i as f32 + dx, j as f32 + dy, self.width, self.height);
        let axes = (self.footprint && s.object != u32::MAX).then(|| {
            let shape = &self.geometry.shapes[s.object as usize];
            footprint::axes(
                &self.geometry.camera,
                &s,
                shape,
                (i, j),
                (self.width, self.height),
            )
        });
        let gathered = self
            .cache
            .as_ref()
            .map(|c| c.pixel(j as usize * self.width as usize + i as usize));
        let pixel = Pixel {
            footprint: axes.as_ref(),
            gathered,
            sky: None,
        };
        let (c, f) = self.shading().shade_pair(&s, pixel);
        // as `pixel` sums its one sample into zero
        let (mut sc, mut sf) = (Vec3A::ZERO, Vec3A::ZERO);
        sc += c;
        sf += f;
        let over = self.outline(i, j).unwrap_or_else(|| self.mean(sf));
        (self.mean(sc), over)
    }

    /// With the footprint, pixel (i, j) where it straddles an outline: the mean of its sub-pixel samples
    /// (`footprint::silhouette_samples`), each shaded as a pixel centre is; `None` elsewhere.
    fn outline(&self, i: u32, j: u32) -> Option<Vec3A> {
        let ids = self.outlines.as_ref()?;
        let at = j as usize * self.width as usize + i as usize;
        let g = &self.geometry;
        let samples = footprint::silhouette_samples(&g.camera, &g.shapes, ids, at)?;
        let mut sum = Vec3A::ZERO;
        for s in &samples {
            sum += self.shading().shade(s, Pixel::default()).0;
        }
        Some((sum * (1.0 / samples.len() as f32)).min(Vec3A::splat(f32::MAX)))
    }

    /// [`Frame::sample`] without the footprint (one sample per pixel), the sky view kept in `sky`
    /// ([`Pixel::sky`]).
    fn sample_sky(&self, s: &Surfel, i: u32, j: u32, sky: &mut Option<f32>) -> Vec3A {
        debug_assert!(!self.footprint);
        let gathered = self
            .cache
            .as_ref()
            .map(|c| c.pixel(j as usize * self.width as usize + i as usize));
        let pixel = Pixel {
            footprint: None,
            gathered,
            sky: Some(sky),
        };
        self.shading().shade(s, pixel).0
    }

    /// How this frame shades its surfels.
    #[inline(always)]
    fn shading(&self) -> Shading<'_> {
        Shading::new(&self.params, &self.geometry.shapes, self.shadows)
    }

    /// A pixel's value from the sum of its samples' radiance: their mean, finite.
    #[inline(always)]
    fn mean(&self, sum: Vec3A) -> Vec3A {
        (sum * self.inv).min(Vec3A::splat(f32::MAX))
    }
}

/// Object index per pixel centre (-1 for background).
pub fn object_ids(scene: &Scene, width: Option<u32>, height: Option<u32>) -> Vec<i32> {
    let geometry = Geometry::new(scene);
    GBuffer::new(
        &geometry,
        width.unwrap_or(scene.width),
        height.unwrap_or(scene.height),
    )
    .object_ids()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn bounce_scene(light_x: f64, ball_y: f64, environment: f64) -> Scene {
        Scene::from_json(&format!(
            r#"{{"image": {{"width": 40, "height": 30}},
                "camera": {{"position": [0, 2, -5], "look_at": [0, 0.6, 0], "vfov_deg": 40}},
                "light": {{"position": [{light_x}, 3, -1], "intensity": 40}},
                "environment": [{environment}, {environment}, {environment}], "interreflection": true,
                "objects": [
                  {{"name": "ball", "shape": "sphere", "center": [0, {ball_y}, 0], "radius": 0.6,
                    "material": {{"albedo": [0.8, 0.2, 0.1]}}}},
                  {{"name": "small", "shape": "sphere", "center": [1.1, 0.3, -0.2], "radius": 0.3,
                    "material": {{"albedo": [0.2, 0.7, 0.3]}}}},
                  {{"name": "floor", "shape": "plane", "point": [0, 0, 0], "normal": [0, 1, 0],
                    "material": {{"albedo": [0.6, 0.6, 0.6]}}}}]}}"#
        ))
        .unwrap()
    }

    #[test]
    fn centre_and_footprint_in_one_pass_are_the_two_renders() {
        // with and without the bounce and the environment, a shadow edge and terminators in view
        for (bounce, env) in [(true, 0.0), (true, 0.3), (false, 0.3), (false, 0.0)] {
            let mut scene = bounce_scene(1.5, 0.6, env);
            scene.interreflection = bounce;
            let (c, f) = render_centre_and_footprint(&scene, false).unwrap();
            let c0 = render_with(&scene, None, None, 1, false).unwrap();
            let f0 = render_with(&scene, None, None, 1, true).unwrap();
            let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
            assert_eq!(
                bits(&c.rgb),
                bits(&c0.rgb),
                "centre, bounce {bounce}, env {env}"
            );
            assert_eq!(
                bits(&f.rgb),
                bits(&f0.rgb),
                "footprint, bounce {bounce}, env {env}"
            );
            assert_ne!(
                bits(&c.rgb),
                bits(&f.rgb),
                "the footprint changes some pixels"
            );
        }
    }

    /// The render as it was before the gathers were kept: every pixel gathers its points itself.
    fn gathering(scene: &Scene, footprint: bool) -> Vec<f32> {
        let geometry = Geometry::new(scene);
        let mut params = ShadeParams::new(scene);
        params.prepare_bounce(&geometry.shapes);
        let (w, h) = (scene.width, scene.height);
        let mut out = Vec::new();
        for j in 0..h {
            for i in 0..w {
                let s = geometry.primary(i as f32 + 0.5, j as f32 + 0.5, w, h);
                let axes = (footprint && s.object != u32::MAX).then(|| {
                    let shape = &geometry.shapes[s.object as usize];
                    footprint::axes(&geometry.camera, &s, shape, (i, j), (w, h))
                });
                let pixel = Pixel {
                    footprint: axes.as_ref(),
                    ..Pixel::default()
                };
                let v = Shading::new(&params, &geometry.shapes, true)
                    .shade(&s, pixel)
                    .0;
                out.extend_from_slice(&v.min(Vec3A::splat(f32::MAX)).to_array());
            }
        }
        out
    }

    /// `render_pixels_many` gives the listed pixels of the whole render bit for bit, in the list's order, with
    /// and without the bounce, and refuses a pixel outside the image.
    #[test]
    fn render_pixels_are_the_renders_pixels() {
        for env in [0.0, 0.3] {
            let mut scene = bounce_scene(1.5, 0.6, env);
            for interreflection in [false, true] {
                scene.interreflection = interreflection;
                let whole = render(&scene, None, None, 1).unwrap();
                let n = scene.width * scene.height;
                let idx: Vec<u32> = (0..n).rev().step_by(7).chain([0, n - 1, 5]).collect();
                let got = render_pixels_many(&[&scene], &idx).unwrap().pop().unwrap();
                assert_eq!(got.len(), 3 * idx.len());
                for (k, &p) in idx.iter().enumerate() {
                    for c in 0..3 {
                        assert_eq!(
                            got[3 * k + c].to_bits(),
                            whole.rgb[3 * p as usize + c].to_bits()
                        );
                    }
                }
                assert!(render_pixels_many(&[&scene], &[n]).is_err());
            }
        }
        // several scenes at once: the light moved, the environment on, the bounce on (the same first hits,
        // shaded each their own way) and the ball moved (other first hits): each its own render's pixels
        let mut scenes = vec![
            bounce_scene(1.5, 0.6, 0.0),
            bounce_scene(-1.0, 0.6, 0.0),
            bounce_scene(1.5, 0.6, 0.3),
            bounce_scene(1.5, 0.65, 0.0),
        ];
        scenes[0].interreflection = false;
        scenes[2].interreflection = false;
        let n = scenes[0].width * scenes[0].height;
        let idx: Vec<u32> = (0..n).step_by(3).collect();
        let refs: Vec<&Scene> = scenes.iter().collect();
        let many = render_pixels_many(&refs, &idx).unwrap();
        for (scene, got) in scenes.iter().zip(&many) {
            let whole = render(scene, None, None, 1).unwrap();
            for (k, &p) in idx.iter().enumerate() {
                for c in 0..3 {
                    assert_eq!(
                        got[3 * k + c].to_bits(),
                        whole.rgb[3 * p as usize + c].to_bits()
                    );
                }
            }
        }
        // whole renders with the object index: the renders and object_ids of the first (the moved ball)
        let refs = [&scenes[3], &scenes[0], &scenes[1]];
        let (images, ids) = render_many_with_ids(&refs).unwrap();
        assert_eq!(ids, object_ids(&scenes[3], None, None));
        assert_ne!(ids, object_ids(&scenes[0], None, None)); // the ball moved: other pixels
        for (scene, img) in refs.iter().zip(&images) {
            let whole = render(scene, None, None, 1).unwrap();
            assert_eq!((img.width, img.height), (whole.width, whole.height));
            assert!(img
                .rgb
                .iter()
                .zip(&whole.rgb)
                .all(|(a, b)| a.to_bits() == b.to_bits()));
        }
        let mut small = scenes[0].clone();
        small.width -= 1;
        assert!(render_many_with_ids(&[&scenes[0], &small]).is_err());
    }

    /// A render with interreflection keeps the light-independent gathers of its geometry
    /// (`bounce::Gathered`): renders that reuse them (the light moved, the environment switched on or
    /// off) and those that must not (the ball moved) give the gathering render's values bit for bit.
    #[test]
    fn kept_gathers_give_the_gathering_render_bit_for_bit() {
        let cases = [
            (0.5, 0.6, 0.0, false),
            (1.5, 0.6, 0.0, false),
            (1.5, 0.6, 0.0, true),
            (1.5, 0.6, 0.3, false),
            (-1.0, 0.6, 0.0, true),
            (-1.0, 0.65, 0.3, false),
            (-1.0, 0.65, 0.0, true),
        ];
        for (x, y, env, footprint) in cases {
            let scene = bounce_scene(x, y, env);
            let img = render_with(&scene, None, None, 1, footprint).unwrap();
            let want = gathering(&scene, footprint);
            assert_eq!(img.rgb.len(), want.len());
            for (k, (a, b)) in img.rgb.iter().zip(&want).enumerate() {
                assert_eq!(
                    a.to_bits(),
                    b.to_bits(),
                    "{x} {y} {env} {footprint}: value {k}"
                );
            }
        }
        // The bounce is in those values: without it the ball's underside is darker.
        let mut off = bounce_scene(0.5, 0.6, 0.0);
        off.interreflection = false;
        let with = render(&bounce_scene(0.5, 0.6, 0.0), None, None, 1).unwrap();
        let without = render(&off, None, None, 1).unwrap();
        assert!(with.rgb.iter().sum::<f32>() > without.rgb.iter().sum::<f32>() * 1.01);
    }
}
