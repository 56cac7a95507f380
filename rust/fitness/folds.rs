//! Held-out losses of the closed form: the products solved on some of the pixels and the loss measured on
//! the others ([`Fitness::held_out`]), for choosing image terms by how well they predict pixels they were
//! not fitted to.

use rayon::prelude::*;

use super::kernel::{Candidate, Kernel};
use super::pixels::object_runs;
use super::projected::Solved;
use super::Fitness;
use crate::error::{Error, Result};

impl Kernel {
    /// This kernel with the pixels whose entry of `leave[group]` is true left out of the closed-form solve
    /// (their solve objective +inf, as a silhouette pixel's): the same geometry, factors and loss.
    fn leaving_out(&self, leave: &[Vec<bool>]) -> Kernel {
        let mut groups = self.groups.clone();
        for (g, leave) in groups.iter_mut().zip(leave) {
            for ts in g.ts.iter_mut() {
                for (t, &out) in ts.iter_mut().zip(leave) {
                    if out {
                        *t = f32::INFINITY;
                    }
                }
            }
        }
        Kernel {
            norm: self.norm,
            space: self.space,
            groups,
            pixels: self.pixels,
            tables: self.tables.clone(),
            saturated: self.saturated,
            sky: self.sky,
        }
    }
}

/// One fold's held-out result ([`Fitness::held_out`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct HeldOut {
    /// The loss of the fold's pixels at the products solved without them (summed over the channels).
    pub loss: f64,
    /// The fold's active pixels.
    pub pixels: usize,
}

impl Fitness {
    /// For the projected loss: per fold k of `folds` (one label per image pixel, row-major; a label
    /// >= `count` puts a pixel in no fold, so that it always informs the products), the closed-form
    /// products at candidate `x` solved on the active pixels outside fold k (with the pixels the solve
    /// always leaves out, silhouettes and saturated ones, left out as ever) and the loss of fold k's pixels
    /// at them, in this fitness's norm and space. `refine`: the products that minimise the fit's own loss on
    /// those pixels (as [`Fitness::refined`] refines them), else the least-squares products
    /// ([`Fitness::solved`]'s); with a bounce, its fixed point as the search solves it. The folds are solved side by side, each in a fixed order: the same values on
    /// any number of threads. The fixed background pixels (no parameter changes them) are left out.
    pub fn held_out(
        &self,
        x: &[f64],
        folds: &[u8],
        count: usize,
        refine: bool,
    ) -> Result<Vec<HeldOut>> {
        let Some(proj) = &self.projection else {
            return Err(Error::Invalid(
                "held-out losses need the projected loss (loss=\"l1_projected\")".into(),
            ));
        };
        let runs = object_runs(
            &self.active.surfels,
            &self.active.outline,
            self.shapes.len(),
        );
        let label = |j: usize| folds.get(self.active.index[j] as usize).copied();
        if let Some(j) = (0..self.active.index.len()).find(|&j| label(j).is_none()) {
            return Err(Error::Invalid(format!(
                "folds has {} labels; pixel {} of the image needs one",
                folds.len(),
                self.active.index[j]
            )));
        }
        let p = self.params(x);
        // the bounce's fixed point as the search solves it (its rounds, or held where the search holds it)
        let mode = &self.bounce;
        let clip = self.clip;
        let top = if clip { 1.0 } else { f64::INFINITY };
        Ok((0..count)
            .into_par_iter()
            .map(|k| {
                let leave: Vec<Vec<bool>> = runs
                    .iter()
                    .map(|(_, idx)| idx.iter().map(|&j| label(j) == Some(k as u8)).collect())
                    .collect();
                let kernel = self.kernel.leaving_out(&leave);
                let (mut solved, mut scratch) = (Solved::default(), Vec::new());
                let c = Candidate {
                    params: &p,
                    clip,
                    bound: f64::INFINITY,
                    parallel: false,
                };
                kernel.projected(c, proj, mode, &mut solved, &mut scratch);
                if refine {
                    kernel.refine(clip, proj, &mut solved, &scratch);
                }
                let objects = kernel.refine_objects(proj, &scratch);
                let loss = kernel.loss_at(&objects, &solved, proj, top, Some(&leave));
                HeldOut {
                    loss: loss[0] + loss[1] + loss[2],
                    pixels: leave.iter().flatten().filter(|&&l| l).count(),
                }
            })
            .collect())
    }
}
