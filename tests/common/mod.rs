//! The plain per-pixel test oracle of the fitness kernel: the same losses through the renderer's
//! `shade` (Lambert + Blinn-Phong from `render::brdf`, `render::light`) and the exact sRGB encoding,
//! pixel by pixel, from the fitness's public pixels.

use glam::Vec3A;
use rtloop::fitness::{fallback_sums, solve_object, SolveSums, SATURATED};
use rtloop::render::film::srgb_encode_exact;
use rtloop::render::{Pixel, Shading};
use rtloop::{Fitness, Space};

/// `Fitness::reference_channel_losses(x)`: the oracle as a method, so tests read as before.
pub trait Oracle {
    fn reference_channel_losses(&self, x: &[f64]) -> [f64; 3];
}

impl Oracle for Fitness {
    fn reference_channel_losses(&self, x: &[f64]) -> [f64; 3] {
        reference_channel_losses(self, x)
    }
}

/// penalty(enc(m) - enc(t)) per channel for a clipped model `m` and objective `t`, with the exact
/// encoding of this fitness's space (the plain path's; the kernel interpolates a table).
fn exact_penalty(f: &Fitness, m: Vec3A, t: Vec3A) -> [f64; 3] {
    std::array::from_fn(|c| {
        let d = match f.space() {
            Space::Linear => m[c] - t[c],
            Space::Srgb => (srgb_encode_exact(m[c] as f64) - srgb_encode_exact(t[c] as f64)) as f32,
        };
        f.norm().penalty(d) as f64
    })
}

/// The losses of `f` computed the plain way, pixel by pixel through the renderer's `shade` and with the
/// exact sRGB encoding (the reference the kernel is tested against).
pub fn reference_channel_losses(f: &Fitness, x: &[f64]) -> [f64; 3] {
    let p = f.params(x);
    let (active, (shapes, shadows), clip) = (f.active(), f.shapes(), f.clip());
    // Each pixel with its footprint where the fitness has one (the same formulas, pixel by pixel).
    let pixel = |i: usize| Pixel {
        footprint: active.footprint.get(i),
        ..Pixel::default()
    };
    let mut acc = [0.0f64; 3];
    for &(m, t) in &active.fixed {
        let l = exact_penalty(f, m, t);
        for c in 0..3 {
            acc[c] += l[c];
        }
    }
    if let Some(proj) = f.projection() {
        // Unit light, white albedo, no lobe: shade gives the diffuse factor a. Albedo 0 and specular 1
        // give the specular factor b. Sum the normal equations pixel by pixel, solve, then the loss.
        let n = proj.diffuse.len();
        let mut sums = vec![SolveSums::default(); n];
        let a: Vec<f32> = active
            .surfels
            .iter()
            .enumerate()
            .map(|(i, s)| Shading::new(&p, shapes, shadows).shade(s, pixel(i)).0.x)
            .collect();
        let b: Vec<f32> = active
            .surfels
            .iter()
            .enumerate()
            .map(|(i, s)| {
                let k = s.object as usize;
                if s.object == u32::MAX || proj.specular[k].1 <= 0.0 {
                    return 0.0;
                }
                let mut q = p.clone();
                q.materials[k].albedo = Vec3A::ZERO;
                q.materials[k].specular = 1.0;
                q.any_specular = true;
                Shading::new(&q, shapes, shadows).shade(s, pixel(i)).0.x
            })
            .collect();
        let sat = if clip { SATURATED } else { f32::INFINITY };
        for (i, (s, t)) in active.surfels.iter().zip(&active.targets).enumerate() {
            if s.object != u32::MAX && active.solve[i] {
                let (m, ai, bi) = (&mut sums[s.object as usize], a[i] as f64, b[i] as f64);
                for c in 0..3 {
                    if t[c] < sat {
                        let y = t[c] as f64;
                        m.saa[c] += ai * ai;
                        m.sab[c] += ai * bi;
                        m.sbb[c] += bi * bi;
                        m.sya[c] += y * ai;
                        m.syb[c] += y * bi;
                    }
                }
            }
        }
        let solved: Vec<([f64; 3], f64)> = (0..n)
            .map(|k| {
                let fallback = |c: usize| {
                    let (e, t): (Vec<f32>, Vec<f32>) = active
                        .surfels
                        .iter()
                        .zip(&active.targets)
                        .zip(&a)
                        .filter(|((s, _), _)| s.object == k as u32)
                        .map(|((_, t), &ai)| (ai, t[c]))
                        .unzip();
                    fallback_sums(&e, &t, sat)
                };
                solve_object(
                    &sums[k],
                    proj.weight,
                    &proj.diffuse[k],
                    proj.specular[k],
                    fallback,
                )
            })
            .collect();
        for (i, (s, t)) in active.surfels.iter().zip(&active.targets).enumerate() {
            let m = if s.object == u32::MAX {
                Vec3A::ZERO
            } else {
                let (pk, q) = solved[s.object as usize];
                Vec3A::from_array(std::array::from_fn(|c| {
                    (pk[c] * a[i] as f64 + q * proj.weight[c] as f64 * b[i] as f64) as f32
                }))
            };
            let l = exact_penalty(f, if clip { m.min(Vec3A::ONE) } else { m }, *t);
            for c in 0..3 {
                acc[c] += l[c];
            }
        }
        return acc;
    }
    for (i, (s, t)) in active.surfels.iter().zip(&active.targets).enumerate() {
        let m = Shading::new(&p, shapes, shadows).shade(s, pixel(i)).0;
        let l = exact_penalty(f, if clip { m.min(Vec3A::ONE) } else { m }, *t);
        for c in 0..3 {
            acc[c] += l[c];
        }
    }
    acc
}
