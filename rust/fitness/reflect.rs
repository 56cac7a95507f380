//! A coated object's reflection of the other objects, with interreflection: the coat's specular lobe
//! (`render::coat::Coat::lobe`) sees the lit floor below a glossy ball, which `render::shade::reflected`
//! adds to the ball's light. Per pixel of a coated object, the lobe's directions that meet another object
//! are kept as gathers (light-independent: their points' occluders and sky views), each of the weight its
//! direction has in the lobe of the coat they were built for; a candidate with another coat (the coat's
//! roughness tried) rescales them by the two coats' directional albedos (`light_terms::Receive::Lobe`).

use super::bounce::Lit;
use super::compact::{Coats, Compact, Fold};
use super::kernel::Kernel;
use super::light_terms::Receive;
use super::pixels::{gathers_of, Gather, Light, Reflections};
use crate::render::bounce::{mirror, GatherPoint};
use crate::render::coat::Coat;
use crate::render::{PShape, ShadeParams, Surfel};
use glam::Vec3A;
use rayon::prelude::*;

impl Kernel {
    /// Builds the [`Reflections`] of every group whose object has a coat in `coats` (per object; empty:
    /// none), among `shapes` with shadow tests where `shadows`; every other group keeps none.
    pub(crate) fn set_reflections(
        &mut self,
        shapes: &[PShape],
        shadows: bool,
        coats: &[Option<Coat>],
    ) {
        let sky = self.sky;
        for g in &mut self.groups {
            g.reflections = None;
            let Some(o) = g.object else { continue };
            let Some(Some(coat)) = coats.get(o) else {
                continue;
            };
            let at = |v: &[Vec<f32>; 3], i: usize| Vec3A::new(v[0][i], v[1][i], v[2][i]);
            let surfels: Vec<Surfel> = (0..g.len())
                .map(|i| Surfel {
                    position: at(&g.p, i),
                    normal: at(&g.n, i),
                    view: at(&g.v, i),
                    object: o as u32,
                    eps: 0.0,
                })
                .collect();
            let idx: Vec<usize> = (0..surfels.len()).collect();
            let points = |s: &Surfel, out: &mut Vec<GatherPoint>| {
                let mut lobe = Vec::new();
                coat.lobe(s.normal, s.view, &mut lobe);
                out.clear();
                out.extend(
                    lobe.into_iter()
                        .filter_map(|d| mirror(s.position, d, o, shapes)),
                );
            };
            let gathers = gathers_of(&surfels, &idx, shapes, (shadows, sky), points);
            g.reflections = Some(Reflections {
                coat: coat.clone(),
                gathers,
            });
        }
    }
}

/// A coated group's lobe points lit for one candidate, with their table lookups folded (`bounce`).
pub(crate) struct Mirrored<'g> {
    gathers: &'g [Gather],
    lit: Vec<Compact>,
    folds: Vec<Vec<Fold>>,
}

impl Mirrored<'_> {
    pub(crate) fn lit(&self) -> Lit<'_> {
        Lit {
            gathers: self.gathers,
            lit: &self.lit,
            folds: &self.folds,
        }
    }
}

impl Kernel {
    /// Each sphere's table points' light from each of their senders (unit light `light`), as the second
    /// bounce reads it (`bounce`).
    pub(crate) fn table_light<const AVX2: bool>(
        &self,
        p: &ShadeParams,
        light: &Light,
        parallel: bool,
    ) -> Vec<Vec<Compact>> {
        self.tables
            .iter()
            .enumerate()
            .map(|(k, gths)| {
                let coats = |gth: &Gather| Coats {
                    receiver: p.coat(k),
                    how: Receive::Table,
                    sender: p.coat(gth.sender),
                };
                gths.iter()
                    .map(|gth| Compact::lit::<AVX2>(gth, light, coats(gth), parallel))
                    .collect()
            })
            .collect()
    }

    /// Per group, its reflections lit at the unit light `light` (and folded into `table_light`) where its
    /// object has a coat in `p`; `None` elsewhere.
    pub(crate) fn mirrored<const AVX2: bool>(
        &self,
        p: &ShadeParams,
        light: &Light,
        table_light: &[Vec<Compact>],
        parallel: bool,
    ) -> Vec<Option<Mirrored<'_>>> {
        self.groups
            .iter()
            .map(|g| {
                let r = g.reflections.as_ref()?;
                let receiver = p.coat(g.object?)?;
                let lit: Vec<Compact> = r
                    .gathers
                    .par_iter()
                    .map(|gth| {
                        let coats = Coats {
                            receiver: Some(receiver),
                            how: Receive::Lobe(&r.coat),
                            sender: p.coat(gth.sender),
                        };
                        Compact::lit::<AVX2>(gth, light, coats, parallel)
                    })
                    .collect();
                let folds = r
                    .gathers
                    .iter()
                    .zip(&lit)
                    .map(|(gth, cg)| {
                        Fold::of(cg, &self.tables[gth.sender], &table_light[gth.sender])
                    })
                    .collect();
                Some(Mirrored {
                    gathers: &r.gathers,
                    lit,
                    folds,
                })
            })
            .collect()
    }
}
