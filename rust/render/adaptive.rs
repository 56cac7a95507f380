//! Adaptive supersampling in parallel tiles, for full-resolution renders of one or more scenes at once:
//! one sample per pixel, the whole `spp` grid only where a pixel's neighbours see something else.
//!
//! Two neighbouring pixel centres disagree when, in any of the scenes, they see another object, one is
//! in shadow and the other not, the surface normal turns by more than [`CREASE_COS`] (a mesh's edges), or
//! (with [`Sampling::Steps`]) the colour jumps by more than [`CONTRAST`]. With [`Sampling::Curvature`]
//! a colour ramp is left at its centre sample, which is the pixel's average wherever the colour varies
//! linearly; a pixel is refined where the colour bends, when its second differences across the 3x3
//! neighbourhood exceed [`CURVATURE`] (the centre sample then misses the average by about their sum
//! over 24). Every pixel that disagrees with one of its 8 neighbours is
//! supersampled in every scene, so scenes rendered together (an insertion's with and without) share their
//! sample positions. A straight edge that crosses a pixel always separates its centre from a neighbour's
//! (the pixels past the image's border are sampled too), so only features thinner than a pixel between
//! centres can be missed. A refined pixel is exactly the uniform render's (the same grid, summed in the
//! same order); a smooth one is its centre sample.

use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};

use glam::Vec3A;
use rayon::prelude::*;

use super::camera::sample_offsets;
use super::hit::Geometry;
use super::shade::{Pixel, ShadeParams, Shading};
use crate::error::{Error, Result};
use crate::scene::Scene;

/// Tile side in pixels: the unit of work and of progress.
pub const TILE: u32 = 64;
/// Neighbouring normals closer than this cosine (about 8°) are one smooth surface.
pub const CREASE_COS: f32 = 0.99;
/// A colour step larger than this fraction of the brighter value (per channel, plus [`CONTRAST_FLOOR`]).
pub const CONTRAST: f32 = 0.02;
/// The absolute part of the colour step, in exposed linear units: below 8-bit sRGB's darkest codes.
pub const CONTRAST_FLOOR: f32 = 2e-4;
/// [`Sampling::Curvature`]'s limit on `|d2x| + |d2y|` (the second differences of a channel across a pixel's
/// row and column) as a fraction of the brightest of the nine values (plus [`CONTRAST_FLOOR`]): a centre
/// sample stays within a quarter of a percent (about a quarter of an 8-bit sRGB step) of the average.
pub const CURVATURE: f32 = 0.06;

/// Which pixels [`render_layers`] gives the whole `spp` grid.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Sampling {
    /// Every pixel: each image is exactly `render`'s.
    Uniform,
    /// Edges (object, shadow, crease) and colour steps over [`CONTRAST`] between neighbours: for a render
    /// composited onto a photo, where any step shows.
    Steps,
    /// Edges and colour curvature over [`CURVATURE`]: a standalone render (a fit's final.png), where a
    /// smooth ramp's centre samples are its averages.
    Curvature,
}

/// Progress of a tiled render, read from another thread: `done` of `total` tiles; setting `stop` makes
/// the remaining tiles return at once and the render return `None`.
#[derive(Debug, Default)]
pub struct Progress {
    pub done: AtomicUsize,
    pub total: AtomicUsize,
    pub stop: AtomicBool,
}

/// The renders of [`render_layers`]: one image per scene, and the coverage of the last scene's objects
/// from `cover_from` on (the fraction of each pixel's samples that hit them), row-major.
#[derive(Clone, Debug)]
pub struct Layers {
    pub images: Vec<super::Image>,
    pub coverage: Vec<f32>,
    /// Pixels given the whole grid.
    pub refined: usize,
}

/// One scene in working form.
struct Layer {
    geometry: Geometry,
    params: ShadeParams,
    shadows: bool,
}

/// What one camera sample sees in one scene.
#[derive(Clone, Copy, Debug)]
struct Sample {
    rgb: Vec3A,
    normal: Vec3A,
    object: u32,
    shadowed: bool,
}

impl Layer {
    fn new(scene: &Scene) -> Layer {
        let geometry = Geometry::new(scene);
        let mut params = ShadeParams::new(scene);
        params.prepare_bounce(&geometry.shapes);
        Layer {
            geometry,
            params,
            shadows: scene.can_occlude(),
        }
    }

    #[inline]
    fn sample(&self, px: f32, py: f32, width: u32, height: u32) -> Sample {
        let s = self.geometry.primary(px, py, width, height);
        let shading = Shading::new(&self.params, &self.geometry.shapes, self.shadows);
        let (rgb, shadowed) = shading.shade(&s, Pixel::default());
        Sample {
            rgb,
            normal: s.normal,
            object: s.object,
            shadowed,
        }
    }
}

/// Whether the pixels of two neighbouring centre samples see another surface: another object, one in
/// shadow and the other not, or a crease.
#[inline]
fn edge(a: &Sample, b: &Sample) -> bool {
    a.object != b.object
        || a.shadowed != b.shadowed
        || (a.object != u32::MAX && a.normal.dot(b.normal) < CREASE_COS)
}

/// Whether the pixels of two neighbouring centre samples need the whole grid ([`Sampling::Steps`]).
#[inline]
fn differ(a: &Sample, b: &Sample) -> bool {
    edge(a, b)
        || (a.rgb - b.rgb)
            .abs()
            .cmpgt(CONTRAST * a.rgb.max(b.rgb) + Vec3A::splat(CONTRAST_FLOOR))
            .any()
}

/// Whether a pixel whose 3x3 centre samples are `n` (row-major, `n[4]` its own) bends by more than
/// [`CURVATURE`] allows ([`Sampling::Curvature`]; edges are tested apart).
#[inline]
fn bends(n: [&Sample; 9]) -> bool {
    let c = n[4].rgb;
    let d2 = (n[3].rgb + n[5].rgb - 2.0 * c).abs() + (n[1].rgb + n[7].rgb - 2.0 * c).abs();
    let top = n.iter().fold(Vec3A::ZERO, |m, s| m.max(s.rgb));
    d2.cmpgt(CURVATURE * top + Vec3A::splat(CONTRAST_FLOOR))
        .any()
}

/// Render every scene of `scenes` (the same camera and size, or not: each is rendered as given) at
/// `width` x `height`, supersampling with `spp` samples (see `camera::sample_offsets`) the pixels
/// `sampling` picks in any of them (every pixel with [`Sampling::Uniform`]: then each image is exactly
/// `render`'s). `None` when `progress.stop` was set before the end. Same result on any thread count.
pub fn render_layers(
    scenes: &[&Scene],
    cover_from: usize,
    width: u32,
    height: u32,
    spp: u32,
    sampling: Sampling,
    progress: &Progress,
) -> Result<Option<Layers>> {
    if width == 0 || height == 0 || width > 16384 || height > 16384 {
        return Err(Error::Invalid(format!(
            "image size must be 1..16384 pixels per side (got {width}x{height})"
        )));
    }
    if spp == 0 || spp > 4096 {
        return Err(Error::Invalid(format!("spp must be 1..4096 (got {spp})")));
    }
    if scenes.is_empty() {
        return Err(Error::Value("render_layers: no scenes given".into()));
    }
    let layers: Vec<Layer> = scenes.iter().map(|s| Layer::new(s)).collect();
    let offsets = sample_offsets(spp);
    let (w, h) = (width as usize, height as usize);
    let tiles_x = w.div_ceil(TILE as usize);
    let tiles_y = h.div_ceil(TILE as usize);
    progress.done.store(0, Ordering::Relaxed);
    progress.total.store(tiles_x * tiles_y, Ordering::Relaxed);

    let band = TILE as usize * w;
    let mut images: Vec<Vec<f32>> = layers.iter().map(|_| vec![0.0f32; w * h * 3]).collect();
    let mut coverage = vec![0.0f32; w * h];
    let mut bands: Vec<Band> = coverage
        .chunks_mut(band)
        .enumerate()
        .map(|(b, c)| (b, Vec::with_capacity(layers.len()), c))
        .collect();
    for image in images.iter_mut() {
        for (b, chunk) in bands.iter_mut().zip(image.chunks_mut(3 * band)) {
            b.1.push(chunk);
        }
    }
    let job = Job {
        layers: &layers,
        offsets: &offsets,
        cover_from: cover_from as u32,
        width,
        height,
        sampling,
        progress,
    };
    let refined: usize = bands
        .into_par_iter()
        .map(|(b, mut rgb, cov)| {
            let y0 = b * TILE as usize;
            let y1 = (y0 + TILE as usize).min(h);
            (0..tiles_x)
                .map(|t| {
                    if progress.stop.load(Ordering::Relaxed) {
                        return 0;
                    }
                    let x0 = t * TILE as usize;
                    let n = job.tile(x0, (x0 + TILE as usize).min(w), y0, y1, &mut rgb, cov);
                    progress.done.fetch_add(1, Ordering::Relaxed);
                    n
                })
                .sum::<usize>()
        })
        .sum();
    if progress.stop.load(Ordering::Relaxed) {
        return Ok(None);
    }
    Ok(Some(Layers {
        images: images
            .into_iter()
            .map(|rgb| super::Image { width, height, rgb })
            .collect(),
        coverage,
        refined,
    }))
}

/// A band of [`TILE`] rows: its index, those rows of each image and of the coverage.
type Band<'a> = (usize, Vec<&'a mut [f32]>, &'a mut [f32]);

/// What every tile shares.
struct Job<'a> {
    layers: &'a [Layer],
    offsets: &'a [(f32, f32)],
    cover_from: u32,
    width: u32,
    height: u32,
    sampling: Sampling,
    progress: &'a Progress,
}

impl Job<'_> {
    /// Render pixels `x0..x1` of rows `y0..y1` into the band's buffers (whose row 0 is `y0`); returns
    /// how many were given the whole grid.
    fn tile(
        &self,
        x0: usize,
        x1: usize,
        y0: usize,
        y1: usize,
        rgb: &mut [&mut [f32]],
        cov: &mut [f32],
    ) -> usize {
        let w = self.width as usize;
        let n_layers = self.layers.len();
        // Centre samples of the tile and a one-pixel halo, past the image's border too (the camera's rays
        // go on beyond it), so an edge between a border pixel's centre and the border is seen.
        let hw = x1 - x0 + 2;
        let mut centres = Vec::new();
        let adaptive = self.sampling != Sampling::Uniform;
        if adaptive {
            centres.reserve(hw * (y1 - y0 + 2) * n_layers);
            for y in y0..y1 + 2 {
                for x in x0..x1 + 2 {
                    for l in self.layers {
                        // The centre of pixel (x - 1, y - 1).
                        let (px, py) = (x as f32 - 0.5, y as f32 - 0.5);
                        centres.push(l.sample(px, py, self.width, self.height));
                    }
                }
            }
        }
        // The centre sample of pixel (x - 1, y - 1).
        let at = |x: usize, y: usize, l: usize| &centres[((y - y0) * hw + (x - x0)) * n_layers + l];
        let covered = |object: u32| object != u32::MAX && object >= self.cover_from;
        let mut refined = 0;
        let mut sums = vec![Vec3A::ZERO; n_layers];
        let inv = 1.0 / self.offsets.len() as f32;
        for y in y0..y1 {
            for x in x0..x1 {
                let edge = match self.sampling {
                    Sampling::Uniform => true,
                    Sampling::Steps => (y..y + 3).any(|ny| {
                        (x..x + 3).any(|nx| {
                            (0..n_layers).any(|l| differ(at(x + 1, y + 1, l), at(nx, ny, l)))
                        })
                    }),
                    Sampling::Curvature => (0..n_layers).any(|l| {
                        let n: [&Sample; 9] = std::array::from_fn(|i| at(x + i % 3, y + i / 3, l));
                        n.iter().any(|s| edge(n[4], s)) || bends(n)
                    }),
                };
                let p = (y - y0) * w + x;
                if edge {
                    refined += 1;
                    sums.fill(Vec3A::ZERO);
                    let mut hits = 0u32;
                    for &(dx, dy) in self.offsets {
                        let (px, py) = (x as f32 + dx, y as f32 + dy);
                        for (l, layer) in self.layers.iter().enumerate() {
                            let s = layer.sample(px, py, self.width, self.height);
                            sums[l] += s.rgb;
                            if l == n_layers - 1 && covered(s.object) {
                                hits += 1;
                            }
                        }
                    }
                    for (l, out) in rgb.iter_mut().enumerate() {
                        let v = (sums[l] * inv).min(Vec3A::splat(f32::MAX));
                        out[3 * p..3 * p + 3].copy_from_slice(&v.to_array());
                    }
                    cov[p] = hits as f32 * inv;
                } else {
                    for (l, out) in rgb.iter_mut().enumerate() {
                        out[3 * p..3 * p + 3].copy_from_slice(&at(x + 1, y + 1, l).rgb.to_array());
                    }
                    cov[p] = if covered(at(x + 1, y + 1, n_layers - 1).object) {
                        1.0
                    } else {
                        0.0
                    };
                }
            }
            if self.progress.stop.load(Ordering::Relaxed) {
                break;
            }
        }
        refined
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::render::{render, to_srgb8};

    fn scene(extra: &str) -> Scene {
        let text = format!(
            r#"{{"image": {{"width": 64, "height": 48}},
            "camera": {{"position": [0, 1.6, -6], "look_at": [0, 0.8, 0], "up": [0, 1, 0], "vfov_deg": 35}},
            "light": {{"position": [2, 5, -3], "intensity": 60, "color": [1, 1, 1]}},
            "ambient": [0.02, 0.02, 0.02], "background": [0.1, 0.1, 0.1], "exposure": 1,
            "objects": [
              {{"name": "floor", "shape": "plane", "point": [0, 0, 0], "normal": [0, 1, 0],
               "material": {{"albedo": [0.6, 0.6, 0.6], "specular": 0, "shininess": 1}}}},
              {{"name": "ball", "shape": "sphere", "center": [0, 0.8, 0], "radius": 0.8,
               "material": {{"albedo": [0.8, 0.7, 0.1], "specular": 0.3, "shininess": 40}}}}{extra}]}}"#
        );
        Scene::from_json(&text).unwrap()
    }

    #[test]
    fn uniform_layers_are_the_uniform_render_bit_for_bit() {
        let s = scene("");
        let want = render(&s, Some(70), Some(50), 4).unwrap();
        let got = render_layers(&[&s], 1, 70, 50, 4, Sampling::Uniform, &Progress::default())
            .unwrap()
            .unwrap();
        assert_eq!(got.images[0].rgb, want.rgb);
        assert_eq!(got.refined, 70 * 50);
    }

    #[test]
    fn adaptive_refines_only_edges_and_stays_close_to_uniform() {
        let s = scene("");
        let (w, h) = (160, 120);
        let want = render(&s, Some(w), Some(h), 16).unwrap();
        let got = render_layers(&[&s], 1, w, h, 16, Sampling::Steps, &Progress::default())
            .unwrap()
            .unwrap();
        // At this size the floor's shading steps by more than 2% between many neighbours; at 12 MP by few.
        assert!(
            got.refined > 100 && got.refined < (w * h / 2) as usize,
            "{}",
            got.refined
        );
        let worst = want
            .rgb
            .iter()
            .zip(&got.images[0].rgb)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0f32, f32::max);
        assert!(worst < 0.01, "{worst}");
        // The ball's coverage (objects from index 1): its visible disc, in pixels.
        let area: f32 = got.coverage.iter().sum();
        assert!(area > 1000.0 && area < 4000.0, "{area}");
    }

    #[test]
    fn curvature_refines_fewer_than_steps_and_stays_close_to_many_samples() {
        let s = scene("");
        let (w, h) = (160, 120);
        let reference = to_srgb8(&render(&s, Some(w), Some(h), 256).unwrap().rgb);
        let run = |sampling| {
            render_layers(&[&s], 1, w, h, 16, sampling, &Progress::default())
                .unwrap()
                .unwrap()
        };
        let (steps, curved) = (run(Sampling::Steps), run(Sampling::Curvature));
        assert!(
            curved.refined * 2 < steps.refined,
            "{} {}",
            curved.refined,
            steps.refined
        );
        // 8-bit sRGB steps off the 256-sample render: (mean, share off by more than 2).
        let off = |rgb: &[f32]| {
            let d: Vec<i32> = to_srgb8(rgb)
                .iter()
                .zip(&reference)
                .map(|(a, b)| (*a as i32 - *b as i32).abs())
                .collect();
            let n = d.len() as f64;
            (
                d.iter().sum::<i32>() as f64 / n,
                d.iter().filter(|&&v| v > 2).count() as f64 / n,
            )
        };
        let uniform = off(&render(&s, Some(w), Some(h), 16).unwrap().rgb);
        let got = off(&curved.images[0].rgb);
        assert!(
            got.0 <= uniform.0 + 0.01 && got.1 <= uniform.1 + 0.001,
            "{got:?} {uniform:?}"
        );
    }

    #[test]
    fn same_result_on_any_thread_count_and_stop_returns_none() {
        let s = scene("");
        let run = |threads| {
            rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap()
                .install(|| {
                    render_layers(
                        &[&s, &s],
                        1,
                        130,
                        97,
                        9,
                        Sampling::Curvature,
                        &Progress::default(),
                    )
                })
                .unwrap()
                .unwrap()
        };
        let (a, b) = (run(1), run(3));
        assert_eq!(a.images[1].rgb, b.images[1].rgb);
        assert_eq!(a.coverage, b.coverage);
        let stopped = Progress::default();
        stopped.stop.store(true, Ordering::Relaxed);
        assert!(
            render_layers(&[&s], 1, 64, 48, 4, Sampling::Steps, &stopped)
                .unwrap()
                .is_none()
        );
    }
}
