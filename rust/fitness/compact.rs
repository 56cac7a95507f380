//! One gather's light for one candidate, summed per receiving pixel ([`Compact`]), and its lookups into
//! a sphere sender's bounce table folded per pixel ([`Fold`]): what a round of the bounce's fixed point
//! (`bounce`) adds up.

use super::light_terms::Receive;
use super::pixels::{Gather, Light};
use crate::render::coat::Coat;

/// Adds p·a[j] + e·s[j] to `col` at each receiving pixel `pixels[j]`, for `(p, a)` and `(e, s)`.
#[inline(always)]
pub(crate) fn add_terms(
    col: &mut [f32],
    pixels: &[u32],
    (p, a): (f32, &[f32]),
    (e, s): (f32, &[f32]),
) {
    for (j, &i) in pixels.iter().enumerate() {
        col[i as usize] += p * a[j] + e * s[j];
    }
}

/// One gather for one candidate, summed per receiving pixel: Σ form·e (the unit light the sender's points
/// send) and Σ form·S (their sky view), and for a sphere sender the (pixel, table point, Σ form) of its
/// table lookups; a round of the fixed point then costs per pixel, not per point. The forms are as the
/// receiver's coat weighs them, and a table lookup's as the sender's coat lets its own bounce out
/// (`Gather::received_form`, `Gather::leaving`).
pub(crate) struct Compact {
    pub(crate) pixels: Vec<u32>,
    pub(crate) a: Vec<f32>,
    pub(crate) s: Vec<f32>,
    table: Vec<(u32, u32, f32)>,
}

/// The coats a gather's light passes: its receiver's (taken as `how` says) and its sender's.
#[derive(Clone, Copy)]
pub(crate) struct Coats<'a> {
    pub(crate) receiver: Option<&'a Coat>,
    pub(crate) how: Receive<'a>,
    pub(crate) sender: Option<&'a Coat>,
}

impl Compact {
    /// [`Compact::new`] of `gth` with the unit light `light` gives its points (`Gather::light`).
    pub(crate) fn lit<const AVX2: bool>(
        gth: &Gather,
        light: &Light,
        coats: Coats,
        parallel: bool,
    ) -> Compact {
        let mut e = Vec::new();
        gth.light::<AVX2>(light, coats.sender, &mut e, parallel);
        Compact::new(gth, &e, coats)
    }

    fn new(gth: &Gather, e: &[f32], coats: Coats) -> Compact {
        let sky = &gth.points.sky;
        let mut c = Compact {
            pixels: Vec::new(),
            a: Vec::new(),
            s: Vec::new(),
            table: Vec::new(),
        };
        for (j, &i) in gth.pixel.iter().enumerate() {
            // The gather's points come in pixel order: a new pixel starts a new entry.
            if c.pixels.last() != Some(&i) {
                c.pixels.push(i);
                c.a.push(0.0);
                c.s.push(0.0);
            }
            let k = c.pixels.len() - 1;
            let f = gth.received_form(j, coats.receiver, coats.how);
            c.a[k] += f * e[j];
            if !sky.is_empty() {
                c.s[k] += f * sky[j];
            }
            if let Some(&t) = gth.table.get(j) {
                let f = gth.leaving(j, coats.sender, f);
                match c.table.last_mut() {
                    Some(last) if last.0 == k as u32 && last.1 == t => last.2 += f,
                    _ => c.table.push((k as u32, t, f)),
                }
            }
        }
        c
    }
}

/// One receiving gather's lookups into a sphere sender's table, summed per receiving pixel for one of the
/// table's own senders: Σ form·e and Σ form·S over the table points each pixel looks up.
pub(crate) struct Fold {
    pub(crate) sender: usize,
    pub(crate) a: Vec<f32>,
    pub(crate) s: Vec<f32>,
}

impl Fold {
    /// Per table sender (`table_gathers[m]`, lit as `table_light[m]`), the folded lookups of `cg`; none
    /// for a plane sender (no table) or a gather with no lookups.
    pub(crate) fn of(cg: &Compact, table_gathers: &[Gather], table_light: &[Compact]) -> Vec<Fold> {
        if cg.table.is_empty() {
            return Vec::new();
        }
        table_gathers
            .iter()
            .zip(table_light)
            .map(|(gth, tl)| {
                let (mut at, mut st) = (
                    vec![0.0f32; crate::render::bounce::TABLE],
                    vec![0.0f32; crate::render::bounce::TABLE],
                );
                for (j, &t) in tl.pixels.iter().enumerate() {
                    at[t as usize] += tl.a[j];
                    st[t as usize] += tl.s[j];
                }
                let mut fold = Fold {
                    sender: gth.sender,
                    a: vec![0.0; cg.pixels.len()],
                    s: vec![0.0; cg.pixels.len()],
                };
                for &(j, t, f) in &cg.table {
                    fold.a[j as usize] += f * at[t as usize];
                    fold.s[j as usize] += f * st[t as usize];
                }
                fold
            })
            .collect()
    }
}
