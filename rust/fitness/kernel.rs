//! The fused fitness kernel: the grouped pixels of one fit, and the direct (stage-1) loss of a candidate.
//!
//! It models only what the scene needs: no object is its own occluder, one object has no shadow tests,
//! the lobe is compiled out when every specular is 0, and the linear space compiles the encoding away.

use glam::Vec3A;

use super::light_terms::{irradiance, shadow};
use super::lobe::{coat_factors, half_cos};
use super::loss::{rgb_loss_in, Encoding, Identity, Norm, Space, SrgbLut, SATURATED};
use super::pixels::{gathers, group, Gather, Group, Light, PixelSet, Sky, BLOCK};
use super::simd::{self, Simd};
use crate::render::bounce::{table_points, TABLE};
use crate::render::brdf::{lambert, specular_scale};
use crate::render::{PShape, ShadeParams, Surfel};

pub struct Kernel {
    /// The per-pixel penalty of every loss this kernel computes.
    pub norm: Norm,
    /// Where the penalty compares values (see [`Kernel::set_space`]).
    pub(crate) space: Space,
    pub(crate) groups: Vec<Group>,
    pub(crate) pixels: usize,
    /// With interreflection, per object: for a sphere the gathers of its table points (the light the
    /// others bounce onto it, `render::bounce::TABLE`); empty otherwise.
    pub(crate) tables: Vec<Vec<Gather>>,
    /// Objective values at or above this may be clipped (with `clip`): the closed-form solve leaves them
    /// out and the refine counts them one-sidedly. [`SATURATED`] unless the photo's noise puts a clipped
    /// pixel's value further below 1 ([`Kernel::set_saturated`]).
    pub(crate) saturated: f32,
    /// The constant-radiance term its pixels carry.
    pub(crate) sky: Sky,
}

impl Kernel {
    /// `pixels` are the active pixels ([`PixelSet`]); `shapes` the scene's shapes; `sky` is the
    /// constant-radiance term modelled (see [`Sky`]: each pixel's factor for it is kept).
    pub fn new(
        pixels: PixelSet,
        shapes: &[PShape],
        shadows: bool,
        sky: Sky,
        bounce: bool,
    ) -> Kernel {
        let groups = group(pixels, shapes, shadows, sky, bounce);
        let tables = if bounce {
            shapes
                .iter()
                .enumerate()
                .map(|(k, shape)| match *shape {
                    PShape::Sphere { center, radius } => {
                        let at: Vec<Surfel> = table_points(center, radius)
                            .into_iter()
                            .map(|(position, normal)| Surfel {
                                position,
                                normal,
                                view: normal,
                                object: k as u32,
                                eps: Surfel::eps_at(position.abs().max_element() + shape.scale()),
                            })
                            .collect();
                        let idx: Vec<usize> = (0..at.len()).collect();
                        gathers(&at, &idx, k, shapes, shadows, sky)
                    }
                    PShape::Plane { .. } | PShape::Mesh(_) => Vec::new(),
                })
                .collect()
        } else {
            Vec::new()
        };
        Kernel {
            tables,
            norm: Norm::L1,
            space: Space::Linear,
            groups,
            pixels: pixels.surfels.len(),
            saturated: SATURATED,
            sky,
        }
    }

    /// This kernel with every pixel shaded at its centre: the kernel `new` builds without a footprint,
    /// without redoing its geometry (one with silhouettes lacks their pixels' centres: see
    /// `Fitness::at_pixel_centres`).
    pub fn at_pixel_centres(&self) -> Kernel {
        Kernel {
            norm: self.norm,
            space: self.space,
            groups: self.groups.iter().map(Group::at_pixel_centres).collect(),
            pixels: self.pixels,
            tables: self.tables.clone(),
            saturated: self.saturated,
            sky: self.sky,
        }
    }

    /// A kernel with this one's settings (norm, space, saturation level, constant term; no bounce) over
    /// `pixels` of `shapes`.
    pub fn regrouped(&self, pixels: PixelSet, shapes: &[PShape], shadows: bool) -> Kernel {
        let mut k = Kernel::new(pixels, shapes, shadows, self.sky, false);
        k.norm = self.norm;
        k.set_space(self.space);
        k.saturated = self.saturated;
        k
    }

    /// Treat objective values at or above `level` (at most [`SATURATED`]) as possibly clipped: a noisy or
    /// JPEG photo's clipped pixels scatter below 1 by its error, and taken as measurements they pull the
    /// least-squares products down (their model is far above 1).
    pub fn set_saturated(&mut self, level: f32) {
        self.saturated = if level.is_nan() {
            SATURATED
        } else {
            level.min(SATURATED)
        };
    }

    pub fn saturated(&self) -> f32 {
        self.saturated
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
        let tables = if p.interreflection {
            self.bounce_tables::<AVX2>(p, &light)
        } else {
            Vec::new()
        };
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
            // One bounce from the other objects, per pixel (exposure applied; times the albedo below).
            let bounce = (p.interreflection && !g.gathers.is_empty())
                .then(|| gathered::<AVX2>(g, p, &light, &tables));
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
                if let Some(coat) = p.coat(obj) {
                    // the coat: diffuse and lobe factors per pixel (`lobe::coat_factors`)
                    let mut lobes = [0.0f32; BLOCK];
                    coat_factors(g, r.clone(), &light, coat, &mut e[..len], &mut lobes[..len]);
                    for c in 0..3 {
                        let kd = p.exposure * light.rgb[c] * m.albedo[c];
                        let ks = p.exposure * light.rgb[c] * m.specular;
                        let mut sum = 0.0f32;
                        for (i, s) in r.clone().enumerate() {
                            let mut base = if sky { a[c] + ae[c] * g.sky[s] } else { a[c] };
                            if let Some(b) = &bounce {
                                base += m.albedo[c] * b[c][s];
                            }
                            let v = base + kd * e[i] + ks * lobes[i];
                            let v = if clip { v.min(1.0) } else { v };
                            sum += self.norm.penalty(enc.any(v) - gt[c][s]);
                        }
                        acc[c] += sum as f64;
                    }
                } else if specular || sky || bounce.is_some() {
                    // max(0, n·h)^s per pixel, once for the three channels (the cosines in lanes)
                    let mut lobes = [0.0f32; BLOCK];
                    if specular {
                        half_cos(g, r.clone(), &light, &mut lobes[..len]);
                        for v in &mut lobes[..len] {
                            *v = v.powf(m.shininess);
                        }
                    }
                    for c in 0..3 {
                        let mut sum = 0.0f32;
                        for (i, s) in r.clone().enumerate() {
                            let lobe = if specular { ks[c] * lobes[i] } else { 0.0 };
                            let mut base = if sky { a[c] + ae[c] * g.sky[s] } else { a[c] };
                            if let Some(b) = &bounce {
                                base += m.albedo[c] * b[c][s];
                            }
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

impl Kernel {
    /// Per object and channel, the light the others bounce onto each table point of a sphere (radiance
    /// before its albedo, no exposure) under shading parameters `p`; empty for a plane.
    pub(crate) fn bounce_tables<const AVX2: bool>(
        &self,
        p: &ShadeParams,
        light: &Light,
    ) -> Vec<[Vec<f32>; 3]> {
        let mut e = Vec::new();
        self.tables
            .iter()
            .map(|gths| {
                let mut out: [Vec<f32>; 3] = std::array::from_fn(|_| {
                    if gths.is_empty() {
                        Vec::new()
                    } else {
                        vec![0.0; TABLE]
                    }
                });
                for gth in gths {
                    gth.light::<AVX2>(light, &mut e, false);
                    let rho = p.materials[gth.sender].albedo;
                    let sky = &gth.points.sky;
                    for c in 0..3 {
                        for (j, &i) in gth.pixel.iter().enumerate() {
                            let mut l = light.rgb[c] * e[j] + p.ambient[c];
                            if !sky.is_empty() {
                                l += p.environment[c] * sky[j];
                            }
                            out[c][i as usize] += gth.form[j] * rho[c] * l;
                        }
                    }
                }
                out
            })
            .collect()
    }
}

/// Per channel and pixel of group `g`: Σ over its gathers of form factor x the sender's radiance at its
/// representative point (direct, environment, ambient; exposure applied), under shading parameters `p`.
/// `render::shade` adds the same (times the receiver's albedo) with `render::bounce`.
#[inline(always)]
pub(crate) fn gathered<const AVX2: bool>(
    g: &Group,
    p: &ShadeParams,
    light: &Light,
    tables: &[[Vec<f32>; 3]],
) -> [Vec<f32>; 3] {
    let n = g.len();
    let mut out: [Vec<f32>; 3] = std::array::from_fn(|_| vec![0.0f32; n]);
    let mut e = Vec::new();
    for gth in &g.gathers {
        gth.light::<AVX2>(light, &mut e, false);
        let rho = p.materials[gth.sender].albedo;
        let sky = &gth.points.sky;
        for c in 0..3 {
            let k = p.exposure * rho[c];
            for (j, &i) in gth.pixel.iter().enumerate() {
                let mut l = light.rgb[c] * e[j] + p.ambient[c];
                if !sky.is_empty() {
                    l += p.environment[c] * sky[j];
                }
                if !gth.table.is_empty() {
                    l += tables[gth.sender][c][gth.table[j] as usize];
                }
                out[c][i as usize] += gth.form[j] * k * l;
            }
        }
    }
    out
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
