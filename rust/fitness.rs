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
}

impl LossKind {
    pub fn parse(s: &str) -> Result<LossKind> {
        match s {
            "l1" => Ok(LossKind::L1),
            "l1_rgb" => Ok(LossKind::L1PerChannel),
            _ => Err(Error::Invalid(format!(
                "unknown loss {s:?} (known: \"l1\", \"l1_rgb\")"
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
        let base = ShadeParams::new(scene);
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
        })
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
            LossKind::L1 => 1,
            LossKind::L1PerChannel => 3,
        }
    }

    fn evaluate(&self, x: &[f64], out: &mut [f64]) {
        let c = self.channel_losses(x);
        match self.kind {
            LossKind::L1 => out[0] = c[0] + c[1] + c[2],
            LossKind::L1PerChannel => out.copy_from_slice(&c),
        }
    }
}
