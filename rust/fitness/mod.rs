//! Fitness of candidate parameter vectors against an objective image.
//!
//! Everything that does not depend on the candidate is done once in `Fitness::new`: camera rays, first
//! hits (the scene's geometry and camera are never free parameters), the objective, and the constant
//! loss of pixels no free parameter can change (background under a fixed background). An evaluation
//! shades only the pixels that matter and fuses the loss into the same loop; it never renders an image.

use glam::Vec3A;

use crate::error::{Error, Result};
mod blocker;
pub mod bounce;
mod folds;
mod held;
pub mod kernel;
mod light_terms;
pub mod lights;
pub mod line_min;
mod lobe;
pub mod loss;
pub mod outline_gate;
pub mod pixels;
pub mod projected;
pub mod refine;
pub mod silhouette;
mod simd;
pub mod solve;

use crate::params::{ParamLayout, Target};
use crate::render::{shade, GBuffer, Geometry, PShape, ShadeParams, Surfel};
use crate::scene::Scene;
use crate::search::Objective;
pub use blocker::{constant_term, projection_blocker};
pub use folds::HeldOut;
pub use held::Frozen;
pub use kernel::{Candidate, Kernel};
pub use line_min::{encoded_line_min, l1_line_min, EncodedTerm};
use loss::penalty_sums;
pub use loss::{Norm, Space, SrgbLut, SATURATED};
pub use pixels::Sky;
pub use pixels::{interior, interior_by, ActivePixels, PixelSet, Silhouette};
pub use projected::{Gauge, Projection, Solved};
pub use simd::{path as simd_path, scalar_paths};
pub use solve::{closed_form, fallback_sums, solve_object, SolveSums};

/// How a candidate's image is compared with the objective.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LossKind {
    /// One objective: the sum of absolute differences over all pixels and channels (the paper's stage 1).
    L1,
    /// Three objectives: the sums of absolute differences of R, G and B separately (the paper's stage 2).
    L1PerChannel,
    /// One objective, the whole-image L1 loss after the linear unknowns have been solved in closed form:
    /// for a scene without ambient light every pixel is `P[object][channel] * a(pixel)` (plus
    /// `Q[object] * w[channel] * b(pixel)` for an object with a specular term), with `a` the unit-light
    /// irradiance / pi, `b` the unit-light specular lobe, `P` = exposure x intensity x colour x albedo and
    /// `Q` = intensity x specular. For each candidate light (and shininess), `P` and `Q` are the
    /// least-squares fit over the unsaturated pixels, clamped to their bounds (variable projection), so
    /// the search runs over the light's position (and any free shininess) only.
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

/// How a [`Fitness`] compares a candidate with the objective: which pixels, which loss, and how pixel
/// values are modelled and penalised. `FitnessSpec::default()` is the whole image, the direct loss
/// ([`LossKind::L1`]) on clipped values at pixel centres, L1 in linear space; set the fields that differ
/// with `FitnessSpec { loss: LossKind::L1Projected, projection: Some(..), ..Default::default() }`.
#[derive(Clone, Debug)]
pub struct FitnessSpec {
    /// The pixel indices the loss counts (`None`: all pixels).
    pub pixels: Option<Vec<u32>>,
    pub loss: LossKind,
    /// Rendered values clamped to [0, 1] before comparison, as a camera or an 8/16-bit file would.
    pub clip: bool,
    /// The bounds of the closed-form unknowns: required by [`LossKind::L1Projected`], unused otherwise.
    pub projection: Option<Projection>,
    /// Each pixel integrated over its area where a sphere's shadow edge or its terminator crosses it
    /// (`render::footprint`), as a camera integrates it (`render_with` renders the same model).
    pub footprint: bool,
    /// With the footprint: the pixels that straddle an object's outline are each the mean of their
    /// sub-pixel rays (`silhouette`), not their centre's value. Off by default: a fit takes them only where
    /// the photo shows it needs them (`fit::passes`, the outline gate).
    pub outlines: bool,
    /// With the footprint and outlines at pixel centres: their samples kept beside the model (which they do
    /// not change) for [`Fitness::outline_gain`].
    pub outline_gate: bool,
    /// The closed-form products are informed only by pixels that every pixel within this Chebyshev
    /// distance shows the same object ([`interior_by`]; 0: the 4-neighbours). The loss still counts every
    /// pixel.
    pub solve_margin: usize,
    /// The penalty of a pixel difference ([`Fitness::set_norm`]).
    pub norm: Norm,
    /// Where values are compared ([`Fitness::set_space`]).
    pub space: Space,
    /// The level from which objective values count as possibly clipped ([`Fitness::set_saturated`];
    /// `None`: [`SATURATED`]).
    pub saturated: Option<f32>,
}

impl Default for FitnessSpec {
    fn default() -> FitnessSpec {
        FitnessSpec {
            pixels: None,
            loss: LossKind::L1,
            clip: true,
            projection: None,
            footprint: false,
            outlines: false,
            outline_gate: false,
            solve_margin: 0,
            norm: Norm::L1,
            space: Space::Linear,
            saturated: None,
        }
    }
}

pub struct Fitness {
    pub layout: ParamLayout,
    /// Let `evaluate_bounded` stop early (on by default; off to measure full evaluations).
    pub early_exit: bool,
    kernel: Kernel,
    base: ShadeParams,
    shapes: Vec<PShape>,
    /// The pixels shaded per evaluation, and the fixed ones (kept to recompute `constant` for another
    /// norm or space).
    active: ActivePixels,
    kind: LossKind,
    clip: bool,
    shadows: bool,
    /// Per-channel loss of the pixels left out because no free parameter changes them.
    constant: [f64; 3],
    /// For `L1Projected`: the bounds of the closed-form unknowns.
    projection: Option<Projection>,
    /// The bounce's full fixed point [`Fitness::freeze_bounce`] solved at a candidate: its `x`, the solve
    /// and its scratch. [`Fitness::refined`] at the same `x` refines from it instead of solving it again
    /// (the same inputs: the same values); cleared by every setting that changes the loss.
    held_solve: Option<(Vec<f64>, Solved, Vec<f32>)>,
    /// How the search's candidates take the bounce, where the projection has one.
    bounce: bounce::Mode,
    /// With the footprint, the pixels on an outline (`silhouette`): each the mean of its sub-pixel rays.
    outlines: Option<silhouette::Silhouettes>,
    /// For the outline gate, outlines at their centres: their samples beside the model (`outline_gate`).
    gate: Option<Box<outline_gate::GateOutlines>>,
}

/// Per-thread scratch, reused across evaluations so the hot path never allocates.
#[derive(Default)]
struct Scratch {
    params: Option<ShadeParams>,
    solved: Solved,
    irradiance: Vec<f32>,
}

thread_local! {
    static SCRATCH: std::cell::RefCell<Scratch> = std::cell::RefCell::new(Scratch::default());
}

/// `f` with this thread's scratch, or with a fresh one where the thread's is in use: a thread that waits
/// inside a parallel evaluation may run another job of the pool (another fit's evaluation) meanwhile.
fn with_scratch<R>(f: impl FnOnce(&mut Scratch) -> R) -> R {
    SCRATCH.with(|s| match s.try_borrow_mut() {
        Ok(mut s) => f(&mut s),
        Err(_) => f(&mut Scratch::default()),
    })
}

impl Fitness {
    /// The fitness of `layout`'s parameters against `target`, the objective in linear RGB at the scene's
    /// size (row-major, 3 floats per pixel), compared as `spec` says ([`FitnessSpec`]).
    pub fn new(
        scene: &Scene,
        layout: ParamLayout,
        target: &[f32],
        mut spec: FitnessSpec,
    ) -> Result<Fitness> {
        let (kind, clip, footprint) = (spec.loss, spec.clip, spec.footprint);
        let pixels = spec.pixels.as_deref();
        if !scene.single_point_light() {
            return Err(Error::Invalid(
                "this fitness models one point or directional light; a scene with several lights or a \
                 sphere light is fitted by the lights fit (rtloop.fit(..., lights=N), docs/methods.md)"
                    .into(),
            ));
        }
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
        if let Some(o) = scene
            .objects
            .iter()
            .find(|o| matches!(o.shape, crate::scene::Shape::Mesh { .. }))
        {
            return Err(Error::Invalid(format!(
                "object {:?} is a mesh: meshes can be rendered and inserted, not fitted",
                o.name
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
        let projection = if kind == LossKind::L1Projected {
            let mut proj = spec.projection.take().ok_or_else(|| {
                Error::Invalid("the projected loss needs product bounds for every object".into())
            })?;
            let n = scene.objects.len();
            if proj.diffuse.len() != n
                || proj.specular.len() != n
                || !(proj.environment.is_empty() || proj.environment.len() == n)
            {
                return Err(Error::Invalid(format!(
                    "product bounds given for {} objects ({} specular); the scene has {n}",
                    proj.diffuse.len(),
                    proj.specular.len(),
                )));
            }
            let paths: Vec<String> = layout.entries.iter().map(|e| e.0.clone()).collect();
            if let Some(why) = projection_blocker(scene, &paths) {
                return Err(Error::Invalid(format!(
                    "the projected loss does not apply: {why}"
                )));
            }
            if let Some(o) = scene
                .objects
                .iter()
                .zip(&proj.specular)
                .find(|(o, b)| o.material.specular != 0.0 && b.1 <= 0.0)
            {
                return Err(Error::Invalid(format!(
                    "objects.{}.specular is not 0 but its specular product bounds are (0, 0): the projected \
                     loss would model the object as matte",
                    o.0.name
                )));
            }
            if let Some((path, _, _)) = layout.entries.iter().find(|(_, t, _)| {
                !matches!(
                    t,
                    Target::LightPosition
                        | Target::LightDirection
                        | Target::Shininess(_)
                        | Target::Roughness(_)
                )
            }) {
                return Err(Error::Invalid(format!(
                    "the projected loss searches the light's position or direction and shininess only; {path} \
                     is solved in closed form"
                )));
            }
            // The specular product Q = intensity x specular enters channel c as Q x exposure x colour_c.
            proj.weight = std::array::from_fn(|c| (scene.exposure * scene.light.color[c]) as f32);
            // Unit light, white albedo, no lobe: shading then yields the diffuse factor per pixel.
            base.light_intensity = 1.0;
            base.light_color = Vec3A::ONE;
            base.light_rgb = Vec3A::ONE;
            base.exposure = 1.0;
            for m in &mut base.materials {
                m.albedo = Vec3A::ONE;
                m.specular = 0.0;
            }
            base.any_specular = false;
            // solved in closed form (Projection::environment): the environment, or else the ambient light
            base.environment = Vec3A::ZERO;
            base.ambient = Vec3A::ZERO;
            if constant_term(scene) == Sky::Open && !proj.has_environment() {
                return Err(Error::Invalid(
                    "the scene has ambient light: the projected loss needs its column (product bounds with \
                     rows for exposure x ambient x albedo)"
                        .into(),
                ));
            }
            if scene.interreflection && scene.can_occlude() {
                proj.gauge = Some(bounce::gauge_bounds(scene));
            }
            Some(proj)
        } else {
            None
        };
        let exposure_free = layout
            .entries
            .iter()
            .any(|(_, t, _)| *t == Target::Exposure);
        let background_fixed = !exposure_free || base.background == Vec3A::ZERO;
        let background = background_fixed.then(|| {
            let m = shade(&Surfel::MISS, &base, &[], false);
            if clip {
                m.min(Vec3A::ONE)
            } else {
                m
            }
        });
        // Shadow edges are integrated over each pixel's footprint wherever the scene can shadow.
        let camera =
            (footprint && scene.can_occlude()).then_some((&geometry.camera, &geometry.shapes[..]));
        let active = ActivePixels::select(
            &gbuffer,
            target,
            pixels,
            background,
            scene.objects.len(),
            camera,
            spec.solve_margin,
            // with the bounce each pixel keeps its centre's gathers: no sub-pixel samples
            spec.outlines && !scene.interreflection,
        );
        // The occluded environment costs a sky view factor per pixel only where the model has it.
        let environment = match &projection {
            Some(proj) if proj.has_environment() => constant_term(scene),
            Some(_) => Sky::None,
            None if scene.environment != [0.0; 3]
                || layout.entries.iter().any(|e| e.1 == Target::Environment) =>
            {
                Sky::Occluded
            }
            None => Sky::None,
        };
        let shadows = scene.can_occlude();
        let outlines = silhouette::Silhouettes::new(
            &active.silhouettes,
            &geometry.shapes,
            shadows,
            environment,
        )
        .map(|o| o.products_from_outlines(spec.solve_margin == 0));
        let gate = (spec.outline_gate && !spec.outlines && !scene.interreflection)
            .then(|| camera.map(|c| (c, (&gbuffer, pixels, background))))
            .flatten()
            .and_then(|(c, at)| outline_gate::gate_outlines(&active, at, c, shadows, environment));
        let mut fitness = Fitness {
            outlines,
            gate,
            layout,
            early_exit: true,
            base,
            kernel: Kernel::new(
                active.set(),
                &geometry.shapes,
                scene.can_occlude(),
                environment,
                scene.interreflection && scene.can_occlude(),
            ),
            shapes: geometry.shapes,
            kind,
            clip,
            shadows,
            constant: penalty_sums(&active.counted_fixed(), Norm::L1, Space::Linear),
            active,
            projection,
            held_solve: None,
            bounce: bounce::Mode::SEARCH,
        };
        fitness.set_norm(spec.norm);
        fitness.set_space(spec.space);
        if let Some(level) = spec.saturated {
            fitness.set_saturated(level);
        }
        Ok(fitness)
    }

    /// The closed-form products (object x channel) for candidate light `x` (`L1Projected` only).
    pub fn products(&self, x: &[f64]) -> Vec<[f64; 3]> {
        self.solved(x).products
    }

    /// The closed-form solution for candidate `x`: diffuse products and specular products per object
    /// (`L1Projected` only; empty otherwise).
    pub fn solved(&self, x: &[f64]) -> Solved {
        with_scratch(|s| {
            self.fast_losses(x, s, f64::INFINITY, false);
            s.solved.clone()
        })
    }

    /// For `L1Projected`: the products that minimise this fitness's own loss at candidate `x` (see
    /// [`Kernel::refine`]) and the per-channel loss there; the least-squares products of `solved` are
    /// what the search uses, these are what a fit reports. `None` for other losses.
    pub fn refined(&self, x: &[f64]) -> Option<(Solved, [f64; 3])> {
        let proj = self.projection.as_ref()?;
        // the full bounce at the found light, also where the search held it (`freeze_bounce`)
        let full = &bounce::Mode::FULL;
        let (mut solved, scratch) = match &self.held_solve {
            // the full fixed point already solved here, where the bounce was last held
            Some((at, solved, scratch)) if at.as_slice() == x => (solved.clone(), scratch.clone()),
            _ => {
                let p = self.params(x);
                let (mut solved, mut scratch) = (Solved::default(), Vec::new());
                let c = Candidate {
                    params: &p,
                    clip: self.clip,
                    bound: f64::INFINITY,
                    // the bounce's fixed point over the pool (the same value); a direct solve is too
                    // small for it
                    parallel: proj.gauge.is_some(),
                };
                self.kernel
                    .projected(c, proj, full, &mut solved, &mut scratch);
                (solved, scratch)
            }
        };
        let mut loss = self.kernel.refine(self.clip, proj, &mut solved, &scratch);
        if let Some(o) = &self.outlines {
            let (p, io) = (self.params(x), (&scratch[..], self.clip));
            loss = o.refine(&self.kernel, (&p, proj), &mut solved, io, loss);
        }
        for c in 0..3 {
            loss[c] += self.constant[c];
        }
        Some((solved, loss))
    }

    /// With interreflection (the projected loss): hold the bounce at candidate `x` (`None`: the scene's own
    /// values; the products and gauge solved there, [`bounce::FINAL_ROUNDS`]) while candidates are
    /// ranked ([`Frozen`]): each then costs a direct candidate's factors and one solve of its
    /// products (0.18-0.26 ms on one core against 3.5 ms for the full bounce). [`Fitness::refined`], what
    /// a stage reports, still solves the full bounce at its light. Returns whether there is a bounce to
    /// hold (false: the fitness is unchanged).
    pub fn freeze_bounce(&mut self, x: Option<&[f64]>) -> bool {
        let Some(proj) = &self.projection else {
            return false;
        };
        let Some(g) = &proj.gauge else {
            return false;
        };
        let u_lo = g.u.0;
        let p = match x {
            Some(x) => self.params(x),
            None => self.base.clone(),
        };
        let (mut solved, mut scratch) = (Solved::default(), Vec::new());
        let c = Candidate {
            params: &p,
            clip: self.clip,
            bound: f64::INFINITY,
            parallel: true, // the same value, over the pool
        };
        self.kernel
            .projected(c, proj, &bounce::Mode::FULL, &mut solved, &mut scratch);
        // scratch: [a | b | a'_r | a'_g | a'_b], a'_c = a + (u/g_c)·B_c
        let n = self.kernel.pixels();
        let bounce = (0..3)
            .flat_map(|c| {
                let s = &scratch;
                (0..n).map(move |i| s[(2 + c) * n + i] - s[i])
            })
            .collect();
        let frozen = Frozen {
            bounce,
            u: solved.gauge.unwrap_or(u_lo),
        };
        self.bounce.frozen = Some(std::sync::Arc::new(frozen));
        // `refined` at this candidate (a pass that ends where it started) takes this solve: `proj` is the
        // projection `refined` builds (the full bounce's rounds, nothing held), the candidate the same.
        self.held_solve = x.map(|x| (x.to_vec(), solved, scratch));
        true
    }

    /// The bounce [`Fitness::freeze_bounce`] holds, if any.
    pub fn frozen_bounce(&self) -> Option<std::sync::Arc<Frozen>> {
        self.projection.as_ref()?.gauge.as_ref()?;
        self.bounce.frozen.clone()
    }

    /// Hold `frozen` (another fitness's [`Fitness::frozen_bounce`] over the same pixels, e.g. the
    /// footprint fitness's for the pixel-centre one of the same set-up) while candidates are ranked.
    pub fn hold_bounce(&mut self, frozen: std::sync::Arc<Frozen>) {
        let bounced = self.projection.as_ref().is_some_and(|p| p.gauge.is_some());
        if bounced && frozen.bounce.len() == 3 * self.kernel.pixels() {
            self.bounce.frozen = Some(frozen);
        }
    }

    /// Penalise pixel differences with `norm` (L1 by default) in every loss of this fitness.
    pub fn set_norm(&mut self, norm: Norm) {
        self.held_solve = None;
        self.kernel.norm = norm;
        self.constant = penalty_sums(&self.active.counted_fixed(), norm, self.space());
    }

    pub fn norm(&self) -> Norm {
        self.kernel.norm
    }

    /// Compare values in `space` (linear by default) in every loss of this fitness: in sRGB the
    /// objective is encoded here, once, and the (clipped) model per pixel and evaluation. The
    /// closed-form products of `L1Projected` stay least squares in linear space (that is what makes
    /// them closed form); only the loss that ranks candidates, and the products that [`Fitness::refined`]
    /// reports, are in `space`.
    pub fn set_space(&mut self, space: Space) {
        self.held_solve = None;
        self.kernel.set_space(space);
        if let Some(o) = &mut self.outlines {
            o.set_space(space);
        }
        if let Some(g) = &mut self.gate {
            g.set_space(space);
        }
        self.constant = penalty_sums(&self.active.counted_fixed(), self.norm(), space);
    }

    pub fn space(&self) -> Space {
        self.kernel.space()
    }

    /// Objective values at or above `level` (capped at [`SATURATED`]) count as possibly clipped (see
    /// [`Kernel::set_saturated`]).
    pub fn set_saturated(&mut self, level: f32) {
        self.held_solve = None;
        self.kernel.set_saturated(level);
    }

    pub fn saturated(&self) -> f32 {
        self.kernel.saturated()
    }

    pub fn kind(&self) -> LossKind {
        self.kind
    }

    /// Number of pixels shaded per evaluation.
    pub fn active_pixels(&self) -> usize {
        self.kernel.pixels()
    }

    /// The shading parameters of candidate `x`, written into `p` (reusing its storage).
    fn params_into(&self, x: &[f64], p: &mut ShadeParams) {
        p.clone_from(&self.base);
        for (_, target, offset) in &self.layout.entries {
            p.set(*target, &x[*offset..*offset + target.len()]);
        }
    }

    /// The shading parameters of candidate `x`.
    pub fn params(&self, x: &[f64]) -> ShadeParams {
        let mut p = self.base.clone();
        self.params_into(x, &mut p);
        p
    }

    /// The fused-kernel losses; exact when their total is `<= bound`, otherwise possibly a partial sum
    /// that already exceeds it.
    /// `parallel`: spread the pixels over the current rayon pool (the projected loss only; same value).
    fn fast_losses(&self, x: &[f64], s: &mut Scratch, bound: f64, parallel: bool) -> [f64; 3] {
        let Scratch {
            params,
            solved,
            irradiance,
        } = s;
        let p = params.get_or_insert_with(|| self.base.clone());
        self.params_into(x, p);
        let kernel_bound = bound - (self.constant[0] + self.constant[1] + self.constant[2]);
        let c = Candidate {
            params: p,
            clip: self.clip,
            bound: kernel_bound,
            parallel,
        };
        let mut acc = match &self.projection {
            Some(proj) => self
                .kernel
                .projected(c, proj, &self.bounce, solved, irradiance),
            None => self.kernel.l1(c),
        };
        // (a partial sum already above the bound stays so)
        if let Some(o) = self
            .outlines
            .as_ref()
            .filter(|_| acc.iter().sum::<f64>() <= kernel_bound)
        {
            let closed = self.projection.as_ref().map(|proj| (proj, &*solved));
            let part = o.loss_of(&self.kernel, p, closed, self.clip);
            for c in 0..3 {
                acc[c] += part[c];
            }
        }
        for c in 0..3 {
            acc[c] += self.constant[c];
        }
        acc
    }

    /// Per-channel sums of absolute differences for candidate `x` (the fused kernel).
    pub fn channel_losses(&self, x: &[f64]) -> [f64; 3] {
        with_scratch(|s| self.fast_losses(x, s, f64::INFINITY, false))
    }

    /// The active pixels (first hits, objective, silhouette flags) and the fixed background pairs.
    pub fn active(&self) -> &ActivePixels {
        &self.active
    }

    /// The scene's shapes, and whether any of them can shadow another.
    pub fn shapes(&self) -> (&[PShape], bool) {
        (&self.shapes, self.shadows)
    }

    /// Whether the model is clipped at 1 before comparison.
    pub fn clip(&self) -> bool {
        self.clip
    }

    /// For `L1Projected`: the bounds of the closed-form unknowns.
    pub fn projection(&self) -> Option<&Projection> {
        self.projection.as_ref()
    }
}

impl Fitness {
    fn write(&self, c: [f64; 3], out: &mut [f64]) {
        match self.kind {
            LossKind::L1 | LossKind::L1Projected => out[0] = c[0] + c[1] + c[2],
            LossKind::L1PerChannel => out.copy_from_slice(&c),
        }
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
        self.evaluate_bounded(x, out, f64::INFINITY);
    }

    /// Single-objective losses stop summing once above `bound` (the DE trial's target): the trial loses
    /// either way, so selection is unchanged and most of a losing trial's pixels are never shaded.
    fn evaluate_bounded(&self, x: &[f64], out: &mut [f64], bound: f64) {
        let bound = if self.early_exit {
            bound
        } else {
            f64::INFINITY
        };
        let c = with_scratch(|s| self.fast_losses(x, s, bound, false));
        self.write(c, out);
    }

    /// The projected loss spreads one candidate's pixels over the pool (the same value as `evaluate`).
    fn evaluate_alone(&self, x: &[f64], out: &mut [f64]) {
        let c = with_scratch(|s| self.fast_losses(x, s, f64::INFINITY, true));
        self.write(c, out);
    }
}
