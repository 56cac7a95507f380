//! The outline gate's evidence (`fit::outlines`): a fitness whose outline pixels stay at their centres
//! keeps their sub-pixel samples beside its model, and [`Fitness::outline_gain`] measures at a candidate,
//! at its closed-form products, how much the outline pixels' loss falls when they are averaged over their
//! samples: two passes over the outline pixels' samples, no new set-up.

use glam::Vec3A;

use super::pixels::{ActivePixels, Silhouette, Sky};
use super::silhouette::{unit_light, Linear, Silhouettes};
use super::Fitness;
use crate::render::{CameraFrame, GBuffer, PShape};

/// The outline pixels of a fitness that shades them at their centres: averaged over their sub-pixel
/// samples (`integrated`), and at their centre's first hit alone (`centres`, shaded without the centre's
/// footprint).
#[derive(Clone)]
pub(crate) struct GateOutlines {
    integrated: Silhouettes,
    centres: Silhouettes,
}

impl GateOutlines {
    pub(crate) fn set_space(&mut self, space: super::Space) {
        self.integrated.set_space(space);
        self.centres.set_space(space);
    }
}

/// The outline pixels of `active` (as [`ActivePixels::select`] took them from `pixels` of `gbuffer`, with
/// the fixed `background`) for the gate; `None` where there are none.
pub(crate) fn gate_outlines(
    active: &ActivePixels,
    (gbuffer, pixels, background): (&GBuffer, &[u32], Option<Vec3A>),
    camera: (&CameraFrame, &[PShape]),
    shadows: bool,
    sky: Sky,
) -> Option<Box<GateOutlines>> {
    let (_, _, list, centres) = active.outline_samples(gbuffer, pixels, background, camera);
    let at_centres: Vec<Silhouette> = list
        .iter()
        .zip(centres)
        .map(|(s, c)| Silhouette {
            target: s.target,
            samples: vec![c],
        })
        .collect();
    let shapes = camera.1;
    Some(Box::new(GateOutlines {
        integrated: Silhouettes::new(&list, shapes, shadows, sky)?,
        centres: Silhouettes::new(&at_centres, shapes, shadows, sky)?,
    }))
}

/// What [`Fitness::outline_gain`] measured at a candidate.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct OutlineGain {
    /// The fitness's own loss (its search's, at the least-squares products), summed over the channels.
    pub loss: f64,
    /// The outline pixels' part of it (at their centres).
    pub centres: f64,
    /// Their loss averaged over their sub-pixel samples instead, at the same products.
    pub integrated: f64,
    /// The outline pixels.
    pub pixels: usize,
    /// The largest share, over the objects, of an object's lit pixels that are outline pixels with a lit
    /// sample (a ball lit from behind, lit on its rim alone: near 1).
    pub share: f64,
}

impl Fitness {
    /// For a fitness built with [`super::FitnessSpec::outline_gate`] (the projected loss, the footprint):
    /// at candidate `x` its loss and its outline pixels' loss at their centres and averaged over their
    /// samples, at the closed-form products (the outline pixels inform none: the same products either
    /// way). `None` for other fitnesses, or without outline pixels.
    pub fn outline_gain(&self, x: &[f64]) -> Option<OutlineGain> {
        let (gate, proj) = (self.gate.as_deref()?, self.projection.as_ref()?);
        let p = self.params(x);
        // the loss, the products and each object's lit pixels (a unit light's diffuse factor above 0)
        let (loss, solved, all) = super::with_scratch(|s| {
            let loss = self.fast_losses(x, s, f64::INFINITY, false);
            let mut all = vec![0usize; p.materials.len()];
            let mut offset = 0;
            for g in &self.kernel.groups {
                let a = &s.irradiance[offset..offset + g.len()];
                if let Some(k) = g.object {
                    all[k] += a.iter().filter(|&&v| v > 0.0).count();
                }
                offset += g.len();
            }
            (loss, s.solved.clone(), all)
        });
        let closed = Some((proj, &solved));
        let sum = |l: [f64; 3]| l[0] + l[1] + l[2];
        let centres = sum(gate.centres.loss_of(&self.kernel, &p, closed, self.clip));
        let integrated = sum(gate.integrated.loss_of(&self.kernel, &p, closed, self.clip));
        let model = |obj| Linear::solved(&p, proj, &solved, obj);
        let lit = gate.integrated.lit(&unit_light(&p), model, all.len());
        let share = lit
            .iter()
            .zip(&all)
            .filter(|(&edge, _)| edge > 0)
            .map(|(&edge, &all)| edge as f64 / all.max(edge) as f64)
            .fold(0.0, f64::max);
        Some(OutlineGain {
            loss: loss.iter().sum(),
            centres,
            integrated,
            pixels: gate.integrated.pixels(),
            share,
        })
    }
}
