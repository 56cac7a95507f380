//! The pixels that straddle an object's outline, with the footprint: each one's model value is the mean
//! of its sub-pixel samples (`render::footprint::silhouette_samples`, the renderer's own), every sample
//! shaded as a pixel centre is (its own surface and object; a miss takes the background). A silhouette
//! pixel mixes objects, so it leaves its object's group: its samples form groups of their own, whose
//! values are summed into their pixels after the per-object blocks.

use glam::Vec3A;

use super::kernel::Kernel;
use super::loss::{Encoding, Identity, Norm, Space, SrgbLut};
use super::pixels::{group, Group, Light, PixelSet, Silhouette, Sky};
use super::projected::{Products, Projection, Run, Solved};
use super::simd::{self, Simd};
use super::Fitness;
use crate::render::coat::Coat;

use crate::render::{PShape, ShadeParams, Surfel};

/// One object's value at a sample, linear in its unit-light factors (`projected::Run::factors`): per
/// channel `ambient` + `pc`·a + `qw`·b + `ec`·v (a the diffuse factor, b the lobe's or the coat's, v the
/// sky view factor where `sky`).
#[derive(Clone, Copy)]
pub(crate) struct Linear<'a> {
    pub(crate) ambient: [f32; 3],
    pub(crate) pc: [f32; 3],
    pub(crate) qw: [f32; 3],
    pub(crate) ec: [f32; 3],
    pub(crate) lobe: bool,
    pub(crate) sky: bool,
    pub(crate) shininess: f32,
    pub(crate) coat: Option<&'a Coat>,
}

impl<'a> Linear<'a> {
    /// Object `obj` under the direct model's parameters `p` (`Kernel::l1`).
    pub(crate) fn direct(p: &'a ShadeParams, obj: usize) -> Linear<'a> {
        let m = &p.materials[obj];
        let rgb = p.light_rgb;
        Linear {
            ambient: std::array::from_fn(|c| p.exposure * m.albedo[c] * p.ambient[c]),
            pc: std::array::from_fn(|c| p.exposure * rgb[c] * m.albedo[c]),
            qw: std::array::from_fn(|c| p.exposure * rgb[c] * m.specular),
            ec: std::array::from_fn(|c| p.exposure * m.albedo[c] * p.environment[c]),
            lobe: (p.any_specular && m.specular > 0.0) || p.coat(obj).is_some(),
            sky: p.environment != Vec3A::ZERO,
            shininess: m.shininess,
            coat: p.coat(obj),
        }
    }

    /// Object `obj` at the closed-form products `s` (`Kernel::projected`; no ambient term: it is the
    /// environment column's).
    pub(crate) fn solved(
        p: &'a ShadeParams,
        proj: &Projection,
        s: &Solved,
        obj: usize,
    ) -> Linear<'a> {
        let q = s.specular[obj];
        let on = proj.specular[obj].1 > 0.0;
        Linear {
            ambient: [0.0; 3],
            pc: std::array::from_fn(|c| s.products[obj][c] as f32),
            qw: std::array::from_fn(|c| (q * proj.weight[c] as f64) as f32),
            ec: std::array::from_fn(|c| s.environment_at(obj, c) as f32),
            lobe: on || p.coat(obj).is_some(),
            sky: proj
                .environment
                .get(obj)
                .is_some_and(|b| b.iter().any(|c| c.1 > 0.0)),
            shininess: p.materials[obj].shininess,
            coat: p.coat(obj),
        }
    }
}

/// The silhouette pixels of one fitness: their samples grouped by object, and their objectives.
#[derive(Clone)]
pub(crate) struct Silhouettes {
    groups: Vec<Group>,
    /// Per group, each sample's silhouette pixel.
    pixel: Vec<Vec<u32>>,
    /// Per silhouette pixel, its samples that see the background.
    misses: Vec<f32>,
    /// The samples per pixel (`render::footprint::SILHOUETTE_SAMPLES`; 1 for the outline gate's pixel centres).
    per_pixel: usize,
    t: [Vec<f32>; 3],
    /// The objective in the loss space (sRGB); empty in the linear space.
    te: [Vec<f32>; 3],
    /// Whether the refine's products take the outline pixels' loss too (not where a JPEG's chroma mixes
    /// colours across outlines, `FitnessSpec::solve_margin`).
    refine: bool,
}

impl Silhouettes {
    /// The silhouette pixels `list` among `shapes` (`shadows`: the scene can shadow; `sky`: the constant
    /// term modelled, as for every pixel), each with as many samples as the first; `None` where there are
    /// none.
    pub(crate) fn new(
        list: &[Silhouette],
        shapes: &[PShape],
        shadows: bool,
        sky: Sky,
    ) -> Option<Silhouettes> {
        if list.is_empty() {
            return None;
        }
        let mut misses = vec![0.0f32; list.len()];
        let mut hits: Vec<(u32, u32, Surfel)> = Vec::new();
        for (k, s) in list.iter().enumerate() {
            for sample in &s.samples {
                if sample.object == u32::MAX {
                    misses[k] += 1.0;
                } else {
                    hits.push((sample.object, k as u32, *sample));
                }
            }
        }
        // By object, in pixel order inside one: the order `group` keeps.
        hits.sort_by_key(|h| h.0);
        let surfels: Vec<Surfel> = hits.iter().map(|h| h.2).collect();
        let zeros = vec![Vec3A::ZERO; surfels.len()];
        let solve = vec![false; surfels.len()];
        let samples = PixelSet {
            surfels: &surfels,
            targets: &zeros,
            solve: &solve,
            footprint: &[],
            outline: &[],
        };
        let groups = group(samples, shapes, shadows, sky, false);
        let mut pixel = Vec::with_capacity(groups.len());
        let mut at = 0;
        for g in &groups {
            pixel.push(hits[at..at + g.len()].iter().map(|h| h.1).collect());
            at += g.len();
        }
        Some(Silhouettes {
            groups,
            pixel,
            misses,
            per_pixel: list[0].samples.len(),
            t: std::array::from_fn(|c| list.iter().map(|s| s.target[c]).collect()),
            te: Default::default(),
            refine: true,
        })
    }

    /// Per object (of `objects`), its silhouette pixels with a sample `light` reaches (`model` as for
    /// [`Silhouettes::loss`]).
    pub(crate) fn lit<'m>(
        &self,
        light: &Light,
        model: impl Fn(usize) -> Linear<'m>,
        objects: usize,
    ) -> Vec<usize> {
        let mut lit = vec![0usize; objects];
        self.each_group::<false, _>(light, model, |obj, _, _, pixel, e, _| {
            let mut seen: Vec<u32> = pixel
                .iter()
                .zip(e)
                .filter(|(_, &a)| a > 0.0)
                .map(|(&k, _)| k)
                .collect();
            seen.dedup();
            lit[obj] += seen.len();
        });
        lit
    }

    /// `f(object, model, run, pixels, a, b)` per group of samples: its object's `model`, its run under
    /// `light`, each sample's silhouette pixel and unit-light factors.
    fn each_group<'m, const AVX2: bool, F>(
        &self,
        light: &Light,
        model: impl Fn(usize) -> Linear<'m>,
        mut f: F,
    ) where
        F: FnMut(usize, &Linear, &Run, &[u32], &[f32], &[f32]),
    {
        let (mut e, mut b) = (Vec::new(), Vec::new());
        for (g, pixel) in self.groups.iter().zip(&self.pixel) {
            let Some(obj) = g.object else { continue };
            let m = model(obj);
            e.resize(g.len(), 0.0);
            b.resize(g.len(), 0.0);
            let run = self.run(g, light, &m);
            run.factors::<AVX2>(0, &mut e, &mut b);
            f(obj, &m, &run, pixel, &e, &b);
        }
    }

    /// Group `g`'s [`Run`] for the factors of `m` under `light`.
    fn run<'r>(&self, g: &'r Group, light: &'r Light, m: &Linear<'r>) -> Run<'r> {
        Run {
            g,
            light,
            specular: m.lobe,
            sky: (m.sky && !g.sky.is_empty()).then_some(&g.sky[..]),
            shininess: m.shininess,
            coat: m.coat,
            sat: f32::INFINITY,
            top: f32::INFINITY,
            norm: Norm::L1,
        }
    }

    /// Whether the refine's products minimise the outline pixels' loss too (see [`Silhouettes::refine`]).
    pub(crate) fn products_from_outlines(self, on: bool) -> Silhouettes {
        Silhouettes { refine: on, ..self }
    }

    /// Whether some sample sees object `k`.
    fn has(&self, k: usize) -> bool {
        self.groups.iter().any(|g| g.object == Some(k))
    }

    /// Compare in `space` (see `Kernel::set_space`).
    /// The silhouette pixels.
    pub(crate) fn pixels(&self) -> usize {
        self.misses.len()
    }

    pub(crate) fn set_space(&mut self, space: Space) {
        let lut = SrgbLut::get();
        self.te = match space {
            Space::Linear => Default::default(),
            Space::Srgb => {
                std::array::from_fn(|c| self.t[c].iter().map(|&t| lut.encode(t)).collect())
            }
        };
    }

    /// Per channel Σ penalty(enc(min(mean, `top`)) - enc(objective)) over the silhouette pixels, the mean
    /// over each pixel's samples: `model(object)`'s value under `light` (unit or not, as `model` takes
    /// it) for a sample that sees an object, `background` for a miss.
    pub(crate) fn loss<'m, const AVX2: bool, E: Encoding>(
        &self,
        light: &Light,
        model: impl Fn(usize) -> Linear<'m>,
        background: Vec3A,
        (top, norm): (f32, Norm),
        enc: E,
    ) -> [f64; 3] {
        let mut sum: [Vec<f32>; 3] =
            std::array::from_fn(|c| self.misses.iter().map(|&m| m * background[c]).collect());
        self.each_group::<AVX2, _>(light, model, |_, m, run, pixel, e, b| {
            for c in 0..3 {
                for (j, &k) in pixel.iter().enumerate() {
                    let mut v = m.ambient[c] + m.pc[c] * e[j] + m.qw[c] * b[j];
                    if let Some(sky) = run.sky() {
                        v += m.ec[c] * sky[j];
                    }
                    sum[c][k as usize] += v;
                }
            }
        });
        let w = 1.0 / self.per_pixel as f32;
        let t = if E::ENCODES { &self.te } else { &self.t };
        std::array::from_fn(|c| {
            sum[c]
                .iter()
                .zip(&t[c])
                .map(|(&s, &t)| norm.penalty(enc.any((s * w).min(top)) - t) as f64)
                .sum()
        })
    }
}

/// The unit light at `p`'s light (the factors' light; its colour is the models').
pub(crate) fn unit_light(p: &ShadeParams) -> Light {
    Light {
        pos: p.light_position.to_array(),
        dir: p.light_direction.map(|d| d.to_array()),
        rgb: [1.0; 3],
    }
}

impl Silhouettes {
    /// The silhouette pixels' loss under candidate `p` in `kernel`'s norm and space: the direct model's
    /// (`Kernel::l1`), or at the closed-form products `solved` of `proj` (`Kernel::projected`).
    pub(crate) fn loss_of(
        &self,
        kernel: &Kernel,
        p: &ShadeParams,
        closed: Option<(&Projection, &Solved)>,
        clip: bool,
    ) -> [f64; 3] {
        let top = if clip { 1.0 } else { f32::INFINITY };
        let (light, bg, norm) = (unit_light(p), p.exposure * p.background, kernel.norm);
        let model = |obj| match closed {
            Some((proj, s)) => Linear::solved(p, proj, s, obj),
            None => Linear::direct(p, obj),
        };
        match kernel.space {
            Space::Linear => self.dispatched(&light, model, (bg, top, norm), Identity),
            Space::Srgb => self.dispatched(&light, model, (bg, top, norm), SrgbLut::get()),
        }
    }

    /// [`Silhouettes::loss`] on the CPU's path ([`simd::dispatch`]).
    fn dispatched<'m, E: Encoding>(
        &self,
        light: &Light,
        model: impl Fn(usize) -> Linear<'m>,
        (bg, top, norm): (Vec3A, f32, Norm),
        enc: E,
    ) -> [f64; 3] {
        let s = self;
        simd::dispatch(
            Outline {
                s,
                light,
                model,
                bg,
                top,
                norm,
                enc,
            },
            simd::detected(),
        )
    }

    /// After `kernel`'s refine (`scratch` the unit-light factors of `Kernel::projected`, `loss` the
    /// grouped pixels' loss at `solved`): each object with silhouette samples takes the products that
    /// minimise the whole loss, its grouped pixels' and the silhouette pixels' (each diffuse product in
    /// its channel, then a lobe's over all three, four rounds where it has one: golden-section searches
    /// over the bounds, each kept where it lowers the loss), and its silhouette pixels the light reaches
    /// count as lit. Returns the whole loss.
    pub(crate) fn refine(
        &self,
        kernel: &Kernel,
        (p, proj): (&ShadeParams, &Projection),
        solved: &mut Solved,
        (scratch, clip): (&[f32], bool),
        loss: [f64; 3],
    ) -> [f64; 3] {
        let top = if clip { 1.0 } else { f32::INFINITY };
        let light = unit_light(p);
        let sat = if clip {
            kernel.saturated
        } else {
            f32::INFINITY
        };
        let (mut offset, mut grouped) = (0, loss);
        for g in &kernel.groups {
            let n = g.len();
            let (a, b) = (
                &scratch[offset..offset + n],
                &scratch[kernel.pixels + offset..][..n],
            );
            offset += n;
            let Some(k) = g.object.filter(|&k| self.refine && self.has(k)) else {
                continue;
            };
            let m = &p.materials[k];
            let run = Run::of(
                g,
                k,
                &light,
                proj,
                m.shininess,
                p.coat(k),
                (sat, top),
                kernel.norm,
            );
            let own = |s: &Solved| {
                let products = products(s, proj, k, run.is_specular());
                match kernel.space {
                    Space::Linear => run.loss::<false, _>(0, a, b, products, Identity, None),
                    Space::Srgb => run.loss::<false, _>(0, a, b, products, SrgbLut::get(), None),
                }
            };
            let whole = |s: &Solved| {
                let (o, e) = (own(s), self.loss_of(kernel, p, Some((proj, s)), clip));
                [o[0] + e[0], o[1] + e[1], o[2] + e[2]]
            };
            let before = own(solved);
            let glossy = proj.specular[k].1 > proj.specular[k].0 && run.is_specular();
            for _ in 0..if glossy { 4 } else { 1 } {
                for c in 0..3 {
                    let set = move |s: &mut Solved, v: f64| s.products[k][c] = v;
                    golden(solved, proj.diffuse[k][c], set, |s: &Solved| whole(s)[c]);
                }
                if glossy {
                    let set = move |s: &mut Solved, v: f64| s.specular[k] = v;
                    golden(solved, proj.specular[k], set, |s: &Solved| {
                        whole(s).iter().sum()
                    });
                }
            }
            let after = own(solved);
            for c in 0..3 {
                grouped[c] += after[c] - before[c];
            }
        }
        let lit = self.lit(
            &light,
            |obj| Linear::solved(p, proj, solved, obj),
            solved.products.len(),
        );
        for (l, more) in solved.lit.iter_mut().zip(lit) {
            *l += more;
        }
        let outline = self.loss_of(kernel, p, Some((proj, solved)), clip);
        std::array::from_fn(|c| grouped[c] + outline[c])
    }
}

/// Object `k`'s products in `s` as the projected kernel's pass 2 takes them (`specular`: its run has a
/// lobe).
fn products(s: &Solved, proj: &Projection, k: usize, specular: bool) -> Products {
    let q = s.specular[k];
    Products {
        pk: std::array::from_fn(|c| s.products[k][c] as f32),
        qw: std::array::from_fn(|c| (q * proj.weight[c] as f64) as f32),
        ek: std::array::from_fn(|c| s.environment_at(k, c) as f32),
        on: specular && q > 0.0,
    }
}

/// The value in `bounds` that `set` gives `s` to minimise `loss` (golden-section search), kept where it
/// lowers the loss.
fn golden(
    s: &mut Solved,
    (mut lo, mut hi): (f64, f64),
    set: impl Fn(&mut Solved, f64),
    loss: impl Fn(&Solved) -> f64,
) {
    let before = loss(s);
    let mut probe = s.clone();
    let mut at = |v: f64| {
        set(&mut probe, v);
        loss(&probe)
    };
    // each step keeps one of its two inner points (0.618 of the interval): 48 steps, 1e-10 of it
    let r = 0.5 * (5f64.sqrt() - 1.0);
    let (mut a, mut b) = (hi - r * (hi - lo), lo + r * (hi - lo));
    let (mut fa, mut fb) = (at(a), at(b));
    for _ in 0..48 {
        if fa <= fb {
            (hi, b, fb) = (b, a, fa);
            a = hi - r * (hi - lo);
            fa = at(a);
        } else {
            (lo, a, fa) = (a, b, fb);
            b = lo + r * (hi - lo);
            fb = at(b);
        }
    }
    let best = 0.5 * (lo + hi);
    if at(best) < before {
        set(s, best);
    }
}

/// [`Silhouettes::loss`] for [`simd::dispatch`].
struct Outline<'a, F, E> {
    s: &'a Silhouettes,
    light: &'a Light,
    model: F,
    bg: Vec3A,
    top: f32,
    norm: Norm,
    enc: E,
}

impl<'m, F: Fn(usize) -> Linear<'m>, E: Encoding> Simd for Outline<'_, F, E> {
    type Output = [f64; 3];
    #[inline(always)]
    fn run<const AVX2: bool>(self) -> [f64; 3] {
        let o = self;
        o.s.loss::<AVX2, E>(o.light, o.model, o.bg, (o.top, o.norm), o.enc)
    }
}

impl Fitness {
    /// This fitness with pixels shaded at their centres (as [`Fitness::new`] builds it without
    /// [`super::FitnessSpec::footprint`]) from one built with the footprint, without redoing its geometry: a search
    /// and its polish can then take the two models for the price of one set-up.
    pub fn at_pixel_centres(&self) -> Fitness {
        let active = self.active.at_pixel_centres();
        let kernel = match &self.outlines {
            // the silhouette pixels back in their groups: the groups `new` builds without the footprint
            Some(_) => self
                .kernel
                .regrouped(active.set(), &self.shapes, self.shadows),
            None => self.kernel.at_pixel_centres(),
        };
        Fitness {
            layout: self.layout.clone(),
            early_exit: self.early_exit,
            kernel,
            base: self.base.clone(),
            shapes: self.shapes.clone(),
            constant: super::loss::penalty_sums(&active.fixed, self.norm(), self.space()),
            active,
            kind: self.kind,
            clip: self.clip,
            shadows: self.shadows,
            projection: self.projection.clone(),
            held_solve: None, // solved with the footprint: not this model's
            outlines: None,
            gate: None,
            bounce: self.bounce.clone(),
        }
    }

    /// The pixels on an outline, each the mean of its sub-pixel rays ([`super::FitnessSpec::outlines`]).
    pub fn outline_pixels(&self) -> usize {
        self.active.silhouettes.len()
    }
}
