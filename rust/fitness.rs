//! Fitness of candidate parameter vectors against an objective image.
//!
//! Everything that does not depend on the candidate is done once in `Fitness::new`: camera rays, first
//! hits (the scene's geometry and camera are never free parameters), the objective, and the constant
//! loss of pixels no free parameter can change (background under a fixed background). An evaluation
//! shades only the pixels that matter and fuses the loss into the same loop; it never renders an image.

use glam::Vec3A;

use crate::de::Objective;
use crate::error::{Error, Result};
use crate::params::{ParamLayout, Target};
use crate::render::{shade, GBuffer, Geometry, PShape, ShadeParams, Surfel};
use crate::scene::Scene;

/// How a candidate's image is compared with the objective.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LossKind {
    /// One objective: the sum of absolute differences over all pixels and channels (the paper's stage 1).
    L1,
    /// Three objectives: the sums of absolute differences of R, G and B separately (the paper's stage 2).
    L1PerChannel,
    /// One objective, the whole-image L1 loss after the linear unknowns have been solved in closed form:
    /// for a matte scene without ambient light every pixel is `P[object][channel] * g(pixel)`, with `g`
    /// the unit-light irradiance / pi and `P` = exposure x intensity x colour x albedo. For each candidate
    /// light, `P` is the least-squares fit over the unsaturated pixels, clamped to its bounds (variable
    /// projection), so the search runs over the light's position only.
    L1Projected,
}

impl LossKind {
    pub fn parse(s: &str) -> Result<LossKind> {
        match s {
            "l1" => Ok(LossKind::L1),
            "l1_rgb" => Ok(LossKind::L1PerChannel),
            "l1_projected" => Ok(LossKind::L1Projected),
            _ => Err(Error::Invalid(format!(
                "unknown loss {s:?} (known: \"l1\", \"l1_rgb\", \"l1_projected\")"
            ))),
        }
    }
}

pub struct Fitness {
    pub layout: ParamLayout,
    base: ShadeParams,
    shapes: Vec<PShape>,
    surfels: Vec<Surfel>,
    target: Vec<Vec3A>,
    kind: LossKind,
    clip: bool,
    shadows: bool,
    /// Per-channel loss of the pixels left out because no free parameter changes them.
    constant: [f64; 3],
    /// For `L1Projected`: (min, max) of each object's product per channel.
    product_bounds: Vec<[(f64, f64); 3]>,
}

/// Objective values at or above this are treated as saturated: they only say "at least this bright".
const SATURATED: f32 = 0.999;

thread_local! {
    /// Per-thread scratch for `L1Projected` (unit-light shading per active pixel): reused, never reallocated
    /// once large enough.
    static SCRATCH: std::cell::RefCell<Vec<f32>> = const { std::cell::RefCell::new(Vec::new()) };
}

impl Fitness {
    /// `target` is the objective in linear RGB at the scene's size (row-major, 3 floats per pixel).
    /// `pixels` restricts the loss to those pixel indices (all pixels when `None`). With `clip`, rendered
    /// values are clamped to [0, 1] before comparison, as a camera or an 8/16-bit file would.
    pub fn new(
        scene: &Scene,
        layout: ParamLayout,
        target: &[f32],
        pixels: Option<&[u32]>,
        kind: LossKind,
        clip: bool,
        product_bounds: Option<Vec<[(f64, f64); 3]>>,
    ) -> Result<Fitness> {
        let n = (scene.width * scene.height) as usize;
        if target.len() != 3 * n {
            return Err(Error::Invalid(format!(
                "objective image has {} values; the scene's image is {}x{} (expected {} = H x W x 3)",
                target.len(),
                scene.width,
                scene.height,
                3 * n
            )));
        }
        if let Some(k) = target.iter().position(|v| !v.is_finite()) {
            return Err(Error::Invalid(format!(
                "objective image value {k} is not finite ({})",
                target[k]
            )));
        }
        let geometry = Geometry::new(scene);
        let gbuffer = GBuffer::new(&geometry, scene.width, scene.height);
        let all: Vec<u32>;
        let pixels = match pixels {
            Some(p) => {
                if let Some(&bad) = p.iter().find(|&&i| i as usize >= n) {
                    return Err(Error::Invalid(format!(
                        "pixel index {bad} is outside the {n}-pixel image"
                    )));
                }
                p
            }
            None => {
                all = (0..n as u32).collect();
                &all
            }
        };
        let mut base = ShadeParams::new(scene);
        let product_bounds = if kind == LossKind::L1Projected {
            let pb = product_bounds.ok_or_else(|| {
                Error::Invalid("the projected loss needs product bounds for every object".into())
            })?;
            if pb.len() != scene.objects.len() {
                return Err(Error::Invalid(format!(
                    "product bounds given for {} objects; the scene has {}",
                    pb.len(),
                    scene.objects.len()
                )));
            }
            if base.ambient != Vec3A::ZERO || base.any_specular {
                return Err(Error::Invalid(
                    "the projected loss models matte scenes without ambient light (ambient 0, specular 0)".into(),
                ));
            }
            if let Some((path, _, _)) = layout
                .entries
                .iter()
                .find(|(_, t, _)| *t != Target::LightPosition)
            {
                return Err(Error::Invalid(format!(
                    "the projected loss searches light.position only; {path} is solved in closed form"
                )));
            }
            // Unit light and white albedo: shading then yields g per pixel.
            base.light_intensity = 1.0;
            base.light_color = Vec3A::ONE;
            base.light_rgb = Vec3A::ONE;
            base.exposure = 1.0;
            for m in &mut base.materials {
                m.albedo = Vec3A::ONE;
            }
            pb
        } else {
            Vec::new()
        };
        let exposure_free = layout
            .entries
            .iter()
            .any(|(_, t, _)| *t == Target::Exposure);
        let background_fixed = !exposure_free || base.background == Vec3A::ZERO;
        let (mut surfels, mut tgt, mut constant) = (Vec::new(), Vec::new(), [0.0f64; 3]);
        for &i in pixels {
            let s = gbuffer.surfels[i as usize];
            let t = Vec3A::from_slice(&target[3 * i as usize..3 * i as usize + 3]);
            if s.object == u32::MAX && background_fixed {
                let m = shade(&s, &base, &[], false);
                let m = if clip { m.min(Vec3A::ONE) } else { m };
                let d = (m - t).abs();
                for c in 0..3 {
                    constant[c] += d[c] as f64;
                }
            } else {
                surfels.push(s);
                tgt.push(t);
            }
        }
        Ok(Fitness {
            layout,
            base,
            shapes: geometry.shapes,
            surfels,
            target: tgt,
            kind,
            clip,
            shadows: scene.can_occlude(),
            constant,
            product_bounds,
        })
    }

    /// For `L1Projected`: the least-squares products (per object and channel) for the light of `x`, and
    /// the unit-light shading of every active pixel in `g`.
    fn solve_products(&self, x: &[f64], g: &mut Vec<f32>) -> Vec<[f64; 3]> {
        let p = self.params(x);
        let n = self.product_bounds.len();
        let mut syg = vec![[0.0f64; 3]; n];
        let mut sgg = vec![[0.0f64; 3]; n];
        g.clear();
        for (s, t) in self.surfels.iter().zip(&self.target) {
            let gi = shade(s, &p, &self.shapes, self.shadows).x;
            g.push(gi);
            if s.object == u32::MAX || gi <= 0.0 {
                continue;
            }
            let k = s.object as usize;
            let gd = gi as f64;
            for c in 0..3 {
                if !self.clip || t[c] < SATURATED {
                    syg[k][c] += t[c] as f64 * gd;
                    sgg[k][c] += gd * gd;
                }
            }
        }
        (0..n)
            .map(|k| {
                let mut out = [0.0; 3];
                for c in 0..3 {
                    let (lo, hi) = self.product_bounds[k][c];
                    let v = if sgg[k][c] > 0.0 {
                        syg[k][c] / sgg[k][c]
                    } else {
                        lo
                    };
                    out[c] = if v.is_finite() { v.clamp(lo, hi) } else { lo };
                }
                out
            })
            .collect()
    }

    /// The closed-form products (object x channel) for candidate light `x` (`L1Projected` only).
    pub fn products(&self, x: &[f64]) -> Vec<[f64; 3]> {
        SCRATCH.with(|g| self.solve_products(x, &mut g.borrow_mut()))
    }

    fn projected_losses(&self, x: &[f64]) -> [f64; 3] {
        SCRATCH.with(|g| {
            let mut g = g.borrow_mut();
            let prods = self.solve_products(x, &mut g);
            let mut acc = self.constant;
            for ((s, t), &gi) in self.surfels.iter().zip(&self.target).zip(g.iter()) {
                let m = if s.object == u32::MAX {
                    Vec3A::ZERO
                } else {
                    let pk = prods[s.object as usize];
                    Vec3A::new(pk[0] as f32, pk[1] as f32, pk[2] as f32) * gi
                };
                let m = if self.clip { m.min(Vec3A::ONE) } else { m };
                let d = (m - *t).abs();
                acc[0] += d.x as f64;
                acc[1] += d.y as f64;
                acc[2] += d.z as f64;
            }
            acc
        })
    }

    pub fn kind(&self) -> LossKind {
        self.kind
    }

    /// Number of pixels shaded per evaluation.
    pub fn active_pixels(&self) -> usize {
        self.surfels.len()
    }

    /// The shading parameters of candidate `x`.
    pub fn params(&self, x: &[f64]) -> ShadeParams {
        let mut p = self.base.clone();
        for (_, target, offset) in &self.layout.entries {
            p.set(*target, &x[*offset..*offset + target.len()]);
        }
        p
    }

    /// Per-channel sums of absolute differences for candidate `x`.
    pub fn channel_losses(&self, x: &[f64]) -> [f64; 3] {
        if self.kind == LossKind::L1Projected {
            return self.projected_losses(x);
        }
        let p = self.params(x);
        let mut acc = [0.0f64; 3];
        for (s, t) in self.surfels.iter().zip(&self.target) {
            let m = shade(s, &p, &self.shapes, self.shadows);
            let m = if self.clip { m.min(Vec3A::ONE) } else { m };
            let d = (m - *t).abs();
            acc[0] += d.x as f64;
            acc[1] += d.y as f64;
            acc[2] += d.z as f64;
        }
        for c in 0..3 {
            acc[c] += self.constant[c];
        }
        acc
    }
}

impl Objective for Fitness {
    fn n_objectives(&self) -> usize {
        match self.kind {
            LossKind::L1 | LossKind::L1Projected => 1,
            LossKind::L1PerChannel => 3,
        }
    }

    fn evaluate(&self, x: &[f64], out: &mut [f64]) {
        let c = self.channel_losses(x);
        match self.kind {
            LossKind::L1 | LossKind::L1Projected => out[0] = c[0] + c[1] + c[2],
            LossKind::L1PerChannel => out.copy_from_slice(&c),
        }
    }
}
