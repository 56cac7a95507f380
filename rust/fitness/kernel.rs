//! The fused fitness kernel: the grouped pixels of one fit, and the direct (stage-1) loss of a candidate.
//!
//! It models only what the scene needs: no object is its own occluder, one object has no shadow tests,
//! the lobe is compiled out when every specular is 0, and the linear space compiles the encoding away.

use glam::Vec3A;

use super::loss::{rgb_loss_in, Encoding, Identity, Norm, Space, SrgbLut};
use super::pixels::{blinn_phong, group, irradiance, shadow, Group, Light, BLOCK};
use super::simd::{self, Simd};
use crate::render::brdf::{lambert, specular_scale};
use crate::render::{PShape, ShadeParams, Surfel};

pub struct Kernel {
    /// The per-pixel penalty of every loss this kernel computes.
    pub norm: Norm,
    /// Where the penalty compares values (see [`Kernel::set_space`]).
    pub(crate) space: Space,
    pub(crate) groups: Vec<Group>,
    pub(crate) pixels: usize,
}

impl Kernel {
    /// `surfels` and `targets` are the active pixels; `shapes` the scene's shapes.
    /// `solve[i]` says whether pixel i may inform the closed-form products (see `projected`); with
    /// `environment` the kernel models the occluded environment (each pixel's sky view factor is kept).
    pub fn new(
        surfels: &[Surfel],
        targets: &[Vec3A],
        solve: &[bool],
        shapes: &[PShape],
        shadows: bool,
        environment: bool,
    ) -> Kernel {
        let groups = group(surfels, targets, solve, shapes, shadows, environment);
        Kernel {
            norm: Norm::L1,
            space: Space::Linear,
            groups,
            pixels: surfels.len(),
        }
    }

    pub fn pixels(&self) -> usize {
        self.pixels
    }

    /// Compare values in `space` in every loss of this kernel: for sRGB the objective is encoded here,
    /// once, and every model value per evaluation (see [`super::loss`]).
    pub fn set_space(&mut self, space: Space) {
        self.space = space;
        let lut = SrgbLut::get();
        for g in &mut self.groups {
            g.te = match space {
                Space::Linear => Default::default(),
                Space::Srgb => {
                    std::array::from_fn(|c| g.t[c].iter().map(|&t| lut.encode(t)).collect())
                }
            };
        }
    }

    pub fn space(&self) -> Space {
        self.space
    }

    /// Per-channel sums of penalty(enc(min(render, 1)) - enc(objective)) (no clamp without `clip`; enc the
    /// identity in the linear space, the sRGB encoding in [`Space::Srgb`]). Once the running total
    /// exceeds `bound` the sum stops early and the partial sums (already above `bound`) are returned: pass
    /// `f64::INFINITY` for the exact value.
    pub fn l1(&self, c: Candidate) -> [f64; 3] {
        let avx2 = simd::detected();
        match self.space {
            Space::Linear => simd::dispatch(
                L1 {
                    k: self,
                    c,
                    enc: Identity,
                },
                avx2,
            ),
            Space::Srgb => simd::dispatch(
                L1 {
                    k: self,
                    c,
                    enc: SrgbLut::get(),
                },
                avx2,
            ),
        }
    }

    #[inline(always)]
    fn l1_generic<const AVX2: bool, E: Encoding>(&self, cand: Candidate, enc: E) -> [f64; 3] {
        let Candidate {
            params: p,
            clip,
            bound,
            ..
        } = cand;
        let light = Light {
            pos: p.light_position.to_array(),
            dir: p.light_direction.map(|d| d.to_array()),
            rgb: p.light_rgb.to_array(),
        };
        let mut acc = [0.0f64; 3];
        let mut e = [0.0f32; BLOCK];
        for g in &self.groups {
            let n = g.len();
            // The objective in the loss space.
            let gt = if E::ENCODES { &g.te } else { &g.t };
            let Some(obj) = g.object else {
                // Background whose value a free parameter (exposure) changes.
                let bg = p.exposure * p.background;
                for s in 0..n {
                    for c in 0..3 {
                        let m = if clip { bg[c].min(1.0) } else { bg[c] };
                        acc[c] += self.norm.penalty(enc.any(m) - gt[c][s]) as f64;
                    }
                }
                continue;
            };
            let m = &p.materials[obj];
            let specular = p.any_specular && m.specular > 0.0;
            // m_c = exposure * (rho_c * (ambient_c + env_c * sky) + e * I_c * rho_c / pi)  (+ specular lobe)
            let a: [f32; 3] = std::array::from_fn(|c| p.exposure * m.albedo[c] * p.ambient[c]);
            let sky = !g.sky.is_empty() && p.environment != Vec3A::ZERO;
            let ae: [f32; 3] = std::array::from_fn(|c| p.exposure * m.albedo[c] * p.environment[c]);
            let k: [f32; 3] =
                std::array::from_fn(|c| lambert(p.exposure * light.rgb[c] * m.albedo[c]));
            let ks: [f32; 3] = std::array::from_fn(|c| {
                specular_scale(p.exposure * light.rgb[c] * m.specular, m.shininess)
            });
            let mut start = 0;
            while start < n {
                let len = BLOCK.min(n - start);
                let r = start..start + len;
                irradiance::<AVX2>(g, r.clone(), &light, &mut e[..len]);
                shadow(g, r.clone(), &light, &mut e[..len]);
                if specular || sky {
                    for c in 0..3 {
                        let mut sum = 0.0f32;
                        for (i, s) in r.clone().enumerate() {
                            let lobe = if specular {
                                ks[c] * blinn_phong(g, s, &light, m.shininess)
                            } else {
                                0.0
                            };
                            let base = if sky { a[c] + ae[c] * g.sky[s] } else { a[c] };
                            let v = base + e[i] * (k[c] + lobe);
                            let v = if clip { v.min(1.0) } else { v };
                            sum += self.norm.penalty(enc.any(v) - gt[c][s]);
                        }
                        acc[c] += sum as f64;
                    }
                } else {
                    let t = [&gt[0][r.clone()], &gt[1][r.clone()], &gt[2][r.clone()]];
                    let top = if clip { 1.0 } else { f32::INFINITY };
                    let sums = rgb_loss_in(self.norm, &e[..len], t, a, k, top, enc);
                    for c in 0..3 {
                        acc[c] += sums[c] as f64;
                    }
                }
                start += len;
                if acc[0] + acc[1] + acc[2] > bound {
                    return acc;
                }
            }
        }
        acc
    }
}

/// One evaluation: the candidate's shading parameters, whether the model is clipped at 1, the bound
/// above which a sum may stop early (`f64::INFINITY` for the exact value) and whether to spread the
/// pixels over the current rayon pool (the projected loss only; the same value either way).
#[derive(Clone, Copy)]
pub struct Candidate<'a> {
    pub params: &'a ShadeParams,
    pub clip: bool,
    pub bound: f64,
    pub parallel: bool,
}

/// [`Kernel::l1`] for [`simd::dispatch`]: one build per encoding, so the linear space's is exactly the
/// code it was without the option.
struct L1<'a, E> {
    k: &'a Kernel,
    c: Candidate<'a>,
    enc: E,
}

impl<E: Encoding> Simd for L1<'_, E> {
    type Output = [f64; 3];
    #[inline(always)]
    fn run<const AVX2: bool>(self) -> [f64; 3] {
        self.k.l1_generic::<AVX2, E>(self.c, self.enc)
    }
}
