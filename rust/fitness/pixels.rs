//! The active pixels in structure-of-arrays form: grouped by object, each group with its objective and
//! its possible occluders' light-independent terms (the per-block light terms an evaluation computes
//! from them are `light_terms`' and `lobe`'s).

use glam::Vec3A;
use rayon::prelude::*;

use crate::render::bounce::{gather, nearest_table};
use crate::render::environment::sky_view;
use crate::render::footprint;
pub use crate::render::footprint::interior;
use crate::render::{CameraFrame, GBuffer, PShape, Surfel};

/// One pixel on an outline: its objective (linear RGB) and the first hits of its sub-pixel rays
/// (`render::footprint::silhouette_samples`).
#[derive(Clone, Debug)]
pub struct Silhouette {
    pub target: Vec3A,
    pub samples: Vec<Surfel>,
}

/// The pixels one fit shades, and the (clipped model, objective) of those no free parameter changes.
#[derive(Clone, Debug, Default)]
pub struct ActivePixels {
    pub surfels: Vec<Surfel>,
    /// The objective per active pixel (linear RGB).
    pub targets: Vec<Vec3A>,
    /// Per active pixel: may it inform the closed-form products (not on a silhouette)?
    pub solve: Vec<bool>,
    /// (clipped model, objective) of the pixels left out: background under a fixed background.
    pub fixed: Vec<(Vec3A, Vec3A)>,
    /// Per active pixel: its footprint on the surface it sees (`render::footprint::axes`), for shadow
    /// edges integrated over the pixel's area; empty when not asked for.
    pub footprint: Vec<[Vec3A; 2]>,
    /// Per active pixel: its index in the image (row-major).
    pub index: Vec<u32>,
    /// With the footprint, the pixels that straddle an object's outline
    /// (`render::footprint::silhouette_samples`): each one's objective and sub-pixel first hits, in pixel
    /// order; empty otherwise.
    pub silhouettes: Vec<Silhouette>,
    /// Per active pixel: is it one of `silhouettes` (then its group leaves it out)? Empty when none is.
    pub outline: Vec<bool>,
    /// Per fixed pair: is it one of `silhouettes` (then the constant loss leaves it out)? Empty when none is.
    pub fixed_outline: Vec<bool>,
}

impl ActivePixels {
    /// Split `pixels` of `gbuffer` (objective `target`, H x W x 3) into active pixels and, where
    /// `background` is the fixed (clipped) background value, the background's fixed pairs.
    /// With `camera` (and the scene's shapes), each active pixel's footprint too. `solve_margin`: a
    /// pixel informs the closed-form products only when every pixel within this Chebyshev distance
    /// shows its own object ([`interior_by`]; 0: its 4-neighbours, [`interior`]); an object with no
    /// such pixel takes its 4-neighbour interior, and one with none of those all its pixels.
    /// With `camera` and `outlines`, the pixels that straddle an outline and inform no product become
    /// [`ActivePixels::silhouettes`].
    #[allow(clippy::too_many_arguments)]
    pub fn select(
        gbuffer: &GBuffer,
        target: &[f32],
        pixels: &[u32],
        background: Option<Vec3A>,
        objects: usize,
        camera: Option<(&CameraFrame, &[PShape])>,
        solve_margin: usize,
        outlines: bool,
    ) -> ActivePixels {
        let mut a = ActivePixels::default();
        let (w, h) = (gbuffer.width, gbuffer.height);
        for &i in pixels {
            let s = gbuffer.surfels[i as usize];
            let t = Vec3A::from_slice(&target[3 * i as usize..3 * i as usize + 3]);
            match background {
                Some(m) if s.object == u32::MAX => a.fixed.push((m, t)),
                _ => {
                    a.surfels.push(s);
                    a.index.push(i);
                    a.solve.push(interior_by(gbuffer, i as usize, solve_margin));
                    a.targets.push(t);
                    if let Some((cam, shapes)) = camera {
                        a.footprint.push(if s.object == u32::MAX {
                            [Vec3A::ZERO; 2]
                        } else {
                            let shape = &shapes[s.object as usize];
                            footprint::axes(cam, &s, shape, (i % w, i / w), (w, h))
                        });
                    }
                }
            }
        }
        // An object with no pixel beyond the margin takes its 4-neighbour interior.
        if solve_margin > 0 {
            let index: Vec<u32> = pixels
                .iter()
                .copied()
                .filter(|&i| !matches!(background, Some(_) if gbuffer.surfels[i as usize].object == u32::MAX))
                .collect();
            for k in 0..objects as u32 {
                let mine: Vec<usize> = (0..a.surfels.len())
                    .filter(|&j| a.surfels[j].object == k)
                    .collect();
                if !mine.iter().any(|&j| a.solve[j]) {
                    for j in mine {
                        a.solve[j] = interior(gbuffer, index[j] as usize);
                    }
                }
            }
        }
        // An object seen only at its silhouette (tiny, or almost hidden) still needs its pixels.
        for k in 0..objects as u32 {
            let mine = || {
                a.surfels
                    .iter()
                    .zip(0..)
                    .filter(move |(s, _)| s.object == k)
            };
            if !mine().any(|(_, i)| a.solve[i]) {
                let all: Vec<usize> = mine().map(|(_, i)| i).collect();
                for i in all {
                    a.solve[i] = true;
                }
            }
        }
        if let (Some(camera), true) = (camera, outlines) {
            a.outlines(gbuffer, pixels, background, camera);
        }
        a
    }

    /// Mark the pixels on an outline (the active ones that inform no product, and the fixed background
    /// ones) whose sub-pixel rays see more than one surface, and keep their samples.
    fn outlines(
        &mut self,
        gbuffer: &GBuffer,
        pixels: &[u32],
        background: Option<Vec3A>,
        camera: (&CameraFrame, &[PShape]),
    ) {
        let (outline, fixed_outline, silhouettes, _) =
            self.outline_samples(gbuffer, pixels, background, camera);
        if !silhouettes.is_empty() {
            self.outline = outline;
            self.fixed_outline = fixed_outline;
        }
        self.silhouettes = silhouettes;
    }

    /// The pixels on an outline among these (as [`ActivePixels::select`] took them from `pixels`): per
    /// active pixel and per fixed pair whether it is one, each one's objective and sub-pixel first hits,
    /// and each one's centre first hit.
    #[allow(clippy::type_complexity)]
    pub(crate) fn outline_samples(
        &self,
        gbuffer: &GBuffer,
        pixels: &[u32],
        background: Option<Vec3A>,
        (camera, shapes): (&CameraFrame, &[PShape]),
    ) -> (Vec<bool>, Vec<bool>, Vec<Silhouette>, Vec<Surfel>) {
        let (mut silhouettes, mut centres) = (Vec::new(), Vec::new());
        let mut outline = vec![false; self.surfels.len()];
        let mut fixed_outline = vec![false; self.fixed.len()];
        let (mut j, mut k) = (0, 0);
        for &i in pixels {
            let fixed = background.is_some() && gbuffer.surfels[i as usize].object == u32::MAX;
            let (slot, target, free) = if fixed {
                k += 1;
                (&mut fixed_outline[k - 1], self.fixed[k - 1].1, true)
            } else {
                j += 1;
                (&mut outline[j - 1], self.targets[j - 1], !self.solve[j - 1])
            };
            if !free {
                continue;
            }
            if let Some(samples) =
                footprint::silhouette_samples(camera, shapes, gbuffer, i as usize)
            {
                *slot = true;
                silhouettes.push(Silhouette { target, samples });
                centres.push(gbuffer.surfels[i as usize]);
            }
        }
        (outline, fixed_outline, silhouettes, centres)
    }

    /// The fixed pairs the constant loss counts: all of them, less those on an outline.
    pub fn counted_fixed(&self) -> Vec<(Vec3A, Vec3A)> {
        if self.fixed_outline.is_empty() {
            return self.fixed.clone();
        }
        self.fixed
            .iter()
            .zip(&self.fixed_outline)
            .filter(|(_, &o)| !o)
            .map(|(f, _)| *f)
            .collect()
    }
}

/// Whether every pixel within Chebyshev distance `margin` of pixel `i` (inside the image) shows its
/// object; `margin` 0 is [`interior`] (its 4-neighbours). A JPEG with 4:2:0 chroma stores one colour
/// sample per 2 x 2 pixels and its decoder interpolates between neighbouring samples, so a pixel's
/// colour mixes those of the pixels up to 2 away: with margin 2 no such mix crosses a silhouette.
pub fn interior_by(gbuffer: &GBuffer, i: usize, margin: usize) -> bool {
    if margin == 0 {
        return interior(gbuffer, i);
    }
    let (w, h) = (gbuffer.width as usize, gbuffer.height as usize);
    let (x, y) = (i % w, i / w);
    let o = gbuffer.surfels[i].object;
    (y.saturating_sub(margin)..(y + margin + 1).min(h)).all(|yy| {
        (x.saturating_sub(margin)..(x + margin + 1).min(w))
            .all(|xx| gbuffer.surfels[yy * w + xx].object == o)
    })
}

/// Pixels per block: the working set of one block stays in L1.
pub const BLOCK: usize = 64;

#[derive(Clone)]
pub(crate) struct SphereOccluder {
    pub(crate) center: [f32; 3],
    pub(crate) radius: f32,
}

#[derive(Clone)]
pub(crate) struct PlaneOccluder {
    pub(crate) normal: [f32; 3],
    pub(crate) point: [f32; 3],
    /// n·(p - q) per pixel of the group: which side of the plane the pixel lies on.
    pub(crate) side: Vec<f32>,
}

/// The pixels of one object (or of the background, `object == None`).
#[derive(Clone)]
pub(crate) struct Group {
    pub(crate) object: Option<usize>,
    pub(crate) p: [Vec<f32>; 3],
    pub(crate) n: [Vec<f32>; 3],
    pub(crate) v: [Vec<f32>; 3],
    pub(crate) t: [Vec<f32>; 3],
    /// The objective in the loss space (its sRGB encoding); empty in the linear space, which uses `t`.
    pub(crate) te: [Vec<f32>; 3],
    /// The objective as the closed-form solve uses it: +inf where a pixel must not inform the products
    /// (a silhouette pixel, which the photo averages over two surfaces), so the saturation test drops it.
    pub(crate) ts: [Vec<f32>; 3],
    pub(crate) spheres: Vec<SphereOccluder>,
    pub(crate) planes: Vec<PlaneOccluder>,
    /// The sky view factor per pixel (`render::environment::sky_view`; light-independent), for a
    /// kernel that models the occluded environment; empty otherwise.
    pub(crate) sky: Vec<f32>,
    /// Where each pixel gathers one bounce from the other objects (`render::bounce::gather`), per
    /// sender; empty unless the kernel models interreflection.
    pub(crate) gathers: Vec<Gather>,
    /// Bounding sphere (centre, radius) of each run of `BLOCK` pixels, for culling shadow tests.
    pub(crate) blocks: Vec<([f32; 3], f32)>,
    /// Each pixel's footprint axes on its surface (x: `du`, y: `dv`), so that a sphere's shadow edge is
    /// integrated over the pixel's area; empty when the group has none (see `shadow`).
    pub(crate) du: [Vec<f32>; 3],
    pub(crate) dv: [Vec<f32>; 3],
    /// Per pixel, half the footprint's |du| + |dv| (no point of the pixel is farther from its centre);
    /// per block the largest.
    pub(crate) spread: Vec<f32>,
    pub(crate) block_spread: Vec<f32>,
    /// With a footprint, the radius of the group's sphere (its own terminator is integrated too).
    pub(crate) own_radius: Option<f32>,
}

impl Group {
    pub(crate) fn len(&self) -> usize {
        self.t[0].len()
    }

    /// This group with its pixels shaded at their centres: no footprint, as `group` builds it without one.
    pub(crate) fn at_pixel_centres(&self) -> Group {
        Group {
            du: Default::default(),
            dv: Default::default(),
            spread: Vec::new(),
            block_spread: Vec::new(),
            own_radius: None,
            ..self.clone()
        }
    }
}

/// One sender's representative points for the pixels of a receiving group (light-independent): the
/// receiving pixels, their configuration factors, and the points as a group of the sender (its
/// occluders and sky view factors), whose light an evaluation computes like a pixel's.
#[derive(Clone)]
pub(crate) struct Gather {
    pub(crate) sender: usize,
    pub(crate) pixel: Vec<u32>,
    pub(crate) form: Vec<f32>,
    pub(crate) points: Group,
    /// For a sphere sender: each point's nearest table point (`render::bounce::TABLE`), whose tabulated
    /// bounce the sender adds to its radiance there; empty for a plane.
    pub(crate) table: Vec<u32>,
}

/// Pixels per parallel run of [`gathers`].
const GATHER_RUN: usize = 256;

/// The gathers of the pixels `idx` of `surfels` (all of object `own`), built over the current pool.
pub(crate) fn gathers(
    surfels: &[Surfel],
    idx: &[usize],
    own: usize,
    shapes: &[PShape],
    shadows: bool,
    sky: Sky,
) -> Vec<Gather> {
    type PerSender = Vec<(Vec<u32>, Vec<f32>, Vec<Surfel>)>;
    // Runs of pixels gathered in parallel, then joined in pixel order: the same lists on any pool (on
    // one thread, one run, nothing to join).
    let run_len = if rayon::current_num_threads() > 1 {
        GATHER_RUN
    } else {
        idx.len().max(1)
    };
    let mut runs: Vec<PerSender> = idx
        .par_chunks(run_len)
        .enumerate()
        .map(|(r, run)| {
            let mut per_sender: PerSender = vec![Default::default(); shapes.len()];
            let mut points = Vec::new();
            for (jj, &i) in run.iter().enumerate() {
                let j = r * run_len + jj;
                let s = &surfels[i];
                gather(s.position, s.normal, own, shapes, &mut points);
                for g in &points {
                    let slot = &mut per_sender[g.sender];
                    slot.0.push(j as u32);
                    slot.1.push(g.form);
                    let scale = g.position.abs().max_element() + shapes[g.sender].scale();
                    slot.2.push(Surfel {
                        position: g.position,
                        normal: g.normal,
                        view: g.normal,
                        object: g.sender as u32,
                        eps: Surfel::eps_at(scale),
                    });
                }
            }
            per_sender
        })
        .collect();
    let mut per_sender: PerSender = if runs.len() == 1 {
        runs.pop().expect("one run")
    } else {
        (0..shapes.len())
            .map(|k| {
                let n = runs.iter().map(|r| r[k].0.len()).sum();
                (
                    Vec::with_capacity(n),
                    Vec::with_capacity(n),
                    Vec::with_capacity(n),
                )
            })
            .collect()
    };
    for run in runs {
        for (to, from) in per_sender.iter_mut().zip(run) {
            to.0.extend(from.0);
            to.1.extend(from.1);
            to.2.extend(from.2);
        }
    }
    per_sender
        .into_par_iter()
        .enumerate()
        .filter(|(_, s)| !s.0.is_empty())
        .map(|(k, (pixel, form, pts))| {
            let zeros = vec![Vec3A::ZERO; pts.len()];
            let solve = vec![false; pts.len()];
            let table = match shapes[k] {
                PShape::Sphere { .. } => pts
                    .par_iter()
                    .map(|s| nearest_table(s.normal) as u32)
                    .collect(),
                PShape::Plane { .. } | PShape::Mesh(_) => Vec::new(),
            };
            let pixels = PixelSet {
                surfels: &pts,
                targets: &zeros,
                solve: &solve,
                footprint: &[],
                outline: &[],
            };
            let mut g = group(pixels, shapes, shadows, sky, false);
            Gather {
                sender: k,
                pixel,
                form,
                points: g.pop().expect("one sender, one group"),
                table,
            }
        })
        .collect()
}

/// The constant-radiance term whose coefficient a kernel's pixels carry: none, the occluded environment
/// (each pixel's sky view factor, `render::environment::sky_view`), or ambient light (unoccluded: 1).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Sky {
    None,
    Occluded,
    Open,
}

/// Per-candidate light terms shared by all groups.
#[derive(Clone, Copy)]
pub(crate) struct Light {
    pub(crate) pos: [f32; 3],
    /// A directional light's unit direction towards the light (then `pos` is unused).
    pub(crate) dir: Option<[f32; 3]>,
    /// intensity x colour.
    pub(crate) rgb: [f32; 3],
}

impl Light {
    /// (position, 1) for a point light, (direction, 0) for a directional one: see [`offset`].
    #[inline(always)]
    pub(crate) fn target(&self) -> ([f32; 3], f32) {
        match self.dir {
            Some(d) => (d, 0.0),
            None => (self.pos, 1.0),
        }
    }
}

/// From `p` towards the light given as [`Light::target`]: L - p, or the direction itself.
#[inline(always)]
pub(super) fn offset(l: [f32; 3], point: f32, p: [f32; 3]) -> [f32; 3] {
    [
        l[0] - point * p[0],
        l[1] - point * p[1],
        l[2] - point * p[2],
    ]
}

/// The pixels a kernel groups: each one's first hit and objective, whether it may inform the closed-form
/// products, and its footprint axes (all pixels, or none: shadow edges at pixel centres); the pixels on
/// an outline (`outline`, all or none) are left out of the groups (`fitness::silhouette` models them).
#[derive(Clone, Copy)]
pub struct PixelSet<'a> {
    pub surfels: &'a [Surfel],
    pub targets: &'a [Vec3A],
    pub solve: &'a [bool],
    pub footprint: &'a [[Vec3A; 2]],
    pub outline: &'a [bool],
}

impl ActivePixels {
    /// These pixels as a kernel groups them.
    pub fn set(&self) -> PixelSet<'_> {
        PixelSet {
            surfels: &self.surfels,
            targets: &self.targets,
            solve: &self.solve,
            footprint: &self.footprint,
            outline: &self.outline,
        }
    }

    /// These pixels each at its centre (no footprint, no silhouette), as `select` picks them without the
    /// footprint.
    pub fn at_pixel_centres(&self) -> ActivePixels {
        ActivePixels {
            footprint: Vec::new(),
            silhouettes: Vec::new(),
            outline: Vec::new(),
            fixed_outline: Vec::new(),
            ..self.clone()
        }
    }
}

/// The `pixels` grouped by object (background last), row-major inside a group, as structures of arrays
/// with their occluders' light-independent terms (`shadows`: the scene can shadow at all); each
/// object's pixels carry the factor of `sky` (none, the sky view, or 1 for ambient light), with
/// `bounce` their gathers.
pub(crate) fn group(
    pixels: PixelSet,
    shapes: &[PShape],
    shadows: bool,
    sky: Sky,
    bounce: bool,
) -> Vec<Group> {
    let PixelSet {
        surfels,
        targets,
        solve,
        footprint,
        outline,
        ..
    } = pixels;
    let runs = object_runs(surfels, outline, shapes.len());
    // One group per object, built in parallel (each in order: the same groups on any pool).
    runs.into_par_iter()
        .map(|(obj, idx)| {
            let idx = &idx[..];
            let col = |f: &dyn Fn(&Surfel) -> f32| {
                idx.iter().map(|&i| f(&surfels[i])).collect::<Vec<f32>>()
            };
            let tcol = |c: usize| idx.iter().map(|&i| targets[i][c]).collect::<Vec<f32>>();
            let object = (obj != u32::MAX).then_some(obj as usize);
            let mut g = Group {
                object,
                p: [
                    col(&|s| s.position.x),
                    col(&|s| s.position.y),
                    col(&|s| s.position.z),
                ],
                n: [
                    col(&|s| s.normal.x),
                    col(&|s| s.normal.y),
                    col(&|s| s.normal.z),
                ],
                v: [col(&|s| s.view.x), col(&|s| s.view.y), col(&|s| s.view.z)],
                t: [tcol(0), tcol(1), tcol(2)],
                te: Default::default(),
                ts: std::array::from_fn(|c| {
                    idx.iter()
                        .map(|&i| {
                            if solve[i] {
                                targets[i][c]
                            } else {
                                f32::INFINITY
                            }
                        })
                        .collect()
                }),
                spheres: Vec::new(),
                planes: Vec::new(),
                sky: match (object, sky) {
                    (Some(o), Sky::Occluded) => idx
                        .iter()
                        .map(|&i| sky_view(surfels[i].position, surfels[i].normal, o, shapes))
                        .collect(),
                    (Some(_), Sky::Open) => vec![1.0; idx.len()],
                    _ => Vec::new(),
                },
                gathers: match object {
                    Some(o) if bounce => gathers(surfels, idx, o, shapes, shadows, sky),
                    _ => Vec::new(),
                },
                blocks: idx
                    .chunks(BLOCK)
                    .map(|chunk| {
                        let pos = |&i: &usize| surfels[i].position;
                        let centre = chunk.iter().map(pos).fold(Vec3A::ZERO, |a, p| a + p)
                            / chunk.len() as f32;
                        let radius = chunk
                            .iter()
                            .map(|i| (pos(i) - centre).length())
                            .fold(0.0f32, f32::max);
                        (centre.to_array(), radius)
                    })
                    .collect(),
                du: Default::default(),
                dv: Default::default(),
                spread: Vec::new(),
                block_spread: Vec::new(),
                own_radius: None,
            };
            if !footprint.is_empty() && shadows && object.is_some() {
                let du: Vec<Vec3A> = idx.iter().map(|&i| footprint[i][0]).collect();
                let dv: Vec<Vec3A> = idx.iter().map(|&i| footprint[i][1]).collect();
                g.spread = idx
                    .iter()
                    .map(|&i| footprint::spread(&footprint[i]))
                    .collect();
                g.du = std::array::from_fn(|c| du.iter().map(|u| u[c]).collect());
                g.dv = std::array::from_fn(|c| dv.iter().map(|v| v[c]).collect());
                g.block_spread = g
                    .spread
                    .chunks(BLOCK)
                    .map(|c| c.iter().copied().fold(0.0, f32::max))
                    .collect();
                if let Some(PShape::Sphere { radius, .. }) = object.map(|o| &shapes[o]) {
                    g.own_radius = Some(*radius);
                }
            }
            if shadows && object.is_some() {
                for (k, shape) in shapes.iter().enumerate() {
                    if Some(k) == object {
                        continue;
                    }
                    match *shape {
                        PShape::Sphere { center, radius } => g.spheres.push(SphereOccluder {
                            center: center.to_array(),
                            radius,
                        }),
                        PShape::Plane { point, normal } => g.planes.push(PlaneOccluder {
                            normal: normal.to_array(),
                            point: point.to_array(),
                            side: idx
                                .iter()
                                .map(|&i| normal.dot(surfels[i].position - point))
                                .collect(),
                        }),
                        PShape::Mesh(_) => {} // `Fitness::new` refuses meshes
                    }
                }
            }
            g
        })
        .collect()
}

/// The pixels `surfels` grouped by object (`shapes` objects; background last), row-major inside a group (a
/// counting sort): per group its object (`u32::MAX`: the background) and its pixels' indices in order, as
/// [`group`] orders the kernel's groups.
pub(crate) fn object_runs(
    surfels: &[Surfel],
    outline: &[bool],
    shapes: usize,
) -> Vec<(u32, Vec<usize>)> {
    let kept = |i: usize| outline.is_empty() || !outline[i];
    let slot = |o: u32| {
        if o == u32::MAX {
            shapes
        } else {
            o as usize
        }
    };
    let mut count = vec![0usize; shapes + 2];
    for (i, s) in surfels.iter().enumerate() {
        if kept(i) {
            count[slot(s.object) + 1] += 1;
        }
    }
    for k in 1..count.len() {
        count[k] += count[k - 1];
    }
    let mut order = vec![0usize; count[count.len() - 1]];
    for (i, s) in surfels.iter().enumerate().filter(|&(i, _)| kept(i)) {
        let k = slot(s.object);
        order[count[k]] = i;
        count[k] += 1;
    }
    let mut runs = Vec::new();
    let mut start = 0;
    while start < order.len() {
        let obj = surfels[order[start]].object;
        let mut end = start;
        while end < order.len() && surfels[order[end]].object == obj {
            end += 1;
        }
        runs.push((obj, order[start..end].to_vec()));
        start = end;
    }
    runs
}
