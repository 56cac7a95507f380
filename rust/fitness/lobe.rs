//! The Blinn-Phong lobe's cosine, max(0, n·h), over a block of a group's pixels in lanes: the part of
//! the renderer's `brdf::blinn_phong` before its power, for the closed form's specular column and the
//! two-stage kernel.

use super::pixels::{Group, Light};
use crate::render::brdf::{self, unit_or_zero};
use crate::render::coat::Coat;
use crate::render::light::incidence;
use glam::Vec3A;

/// Why the closed form cannot take a scene's coat, if it cannot: the bounce's closed form does not model
/// a coated object.
pub fn coat_blocker(scene: &crate::scene::Scene) -> Option<String> {
    let o = scene.objects.iter().find(|o| o.material.coat.is_some())?;
    scene.interreflection.then(|| {
        format!(
            "objects.{} has a coat and the scene has interreflection",
            o.name
        )
    })
}

/// The coat's factors over the block `r`: `e` holds each pixel's unit-light irradiance (cos/d², shadowed)
/// and becomes the diffuse factor per unit albedo, e·`Coat::diffuse`; `b` gets the lobe's, e·`Coat::specular`
/// (the renderer's `Coat` calls, on the same directions as `shade`'s).
pub(crate) fn coat_factors(
    g: &Group,
    r: std::ops::Range<usize>,
    light: &Light,
    coat: &Coat,
    e: &mut [f32],
    b: &mut [f32],
) {
    let pos = Vec3A::from_array(light.pos);
    let dir = light.dir.map(Vec3A::from_array);
    for (i, s) in r.enumerate() {
        if e[i] <= 0.0 {
            e[i] = 0.0;
            b[i] = 0.0;
            continue;
        }
        let at = |v: &[Vec<f32>; 3]| Vec3A::new(v[0][s], v[1][s], v[2][s]);
        let (n, v, p) = (at(&g.n), at(&g.v), at(&g.p));
        let Some((l, _, _)) = incidence(pos, dir, p) else {
            e[i] = 0.0;
            b[i] = 0.0;
            continue;
        };
        b[i] = (e[i] * coat.specular(n, l, v)).min(f32::MAX);
        e[i] *= coat.diffuse(n.dot(l), n.dot(v));
    }
}

/// max(0, n·h) for each pixel of the block `r` into `out` (h the half vector of the unit directions to
/// the light, `light::toward`, and to the eye): `brdf::half_cos`, the cosine whose power is
/// `brdf::blinn_phong`, over the block in lanes; the direction to a point light is `brdf::unit_or_zero`,
/// as glam's `normalize_or_zero` in `light::toward` (x² + y², then + z²; the reciprocal length 1 / sqrt).
#[inline(always)]
pub(crate) fn half_cos<'a>(
    g: &'a Group,
    r: std::ops::Range<usize>,
    light: &Light,
    out: &mut [f32],
) {
    let n = out.len();
    let col = |v: &'a [Vec<f32>; 3], c: usize| -> &'a [f32] { &v[c][r.start..][..n] };
    let (nx, ny, nz) = (col(&g.n, 0), col(&g.n, 1), col(&g.n, 2));
    let (vx, vy, vz) = (col(&g.v, 0), col(&g.v, 1), col(&g.v, 2));
    match light.dir {
        Some(l) => {
            for i in 0..n {
                out[i] = brdf::half_cos([nx[i], ny[i], nz[i]], l, [vx[i], vy[i], vz[i]]);
            }
        }
        None => {
            let (px, py, pz) = (col(&g.p, 0), col(&g.p, 1), col(&g.p, 2));
            let [lx, ly, lz] = light.pos;
            for i in 0..n {
                let l = unit_or_zero(lx - px[i], ly - py[i], lz - pz[i]);
                out[i] = brdf::half_cos([nx[i], ny[i], nz[i]], l, [vx[i], vy[i], vz[i]]);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fitness::pixels::BLOCK;
    use crate::render::light::toward;

    /// A group of the given pixels (position, normal, view); nothing else set.
    fn pixels_of(px: &[([f32; 3], [f32; 3], [f32; 3])]) -> Group {
        let col = |k: usize, c: usize| {
            px.iter()
                .map(|t| [t.0, t.1, t.2][k][c])
                .collect::<Vec<f32>>()
        };
        let cols = |k: usize| [col(k, 0), col(k, 1), col(k, 2)];
        Group {
            object: Some(0),
            p: cols(0),
            n: cols(1),
            v: cols(2),
            t: Default::default(),
            te: Default::default(),
            ts: Default::default(),
            spheres: Vec::new(),
            planes: Vec::new(),
            sky: Vec::new(),
            gathers: Vec::new(),
            blocks: Vec::new(),
            du: Default::default(),
            dv: Default::default(),
            spread: Vec::new(),
            block_spread: Vec::new(),
            own_radius: None,
        }
    }

    fn unit_or_any(v: [f32; 3]) -> [f32; 3] {
        Vec3A::from_array(v).normalize_or(Vec3A::Y).to_array()
    }

    proptest::proptest! {
        /// `half_cos` in lanes, to the power, is the renderer's Blinn-Phong lobe bit for bit (the fitness
        /// and the render must agree), for point and directional lights, pixels at or beside the light,
        /// and an eye direction opposite the light's (the half vector zero).
        #[test]
        fn half_cos_is_the_renderers_lobe_to_the_bit(
            raw in proptest::collection::vec(
                (proptest::array::uniform3(-4.0f32..4.0), proptest::array::uniform3(-1.0f32..1.0),
                 proptest::array::uniform3(-1.0f32..1.0)), 1..=BLOCK),
            light in proptest::array::uniform3(-4.0f32..4.0),
            directional in proptest::bool::ANY,
            shininess in 0.5f32..2000.0,
        ) {
            let mut px: Vec<([f32; 3], [f32; 3], [f32; 3])> =
                raw.iter().map(|&(p, n, v)| (p, unit_or_any(n), unit_or_any(v))).collect();
            let dir = directional.then(|| unit_or_any(light));
            // the hard cases: a pixel at the light, and an eye looking from exactly where the light is
            px[0].0 = light;
            let last = px.len() - 1;
            let to_light = toward(Vec3A::from_array(light), dir.map(Vec3A::from_array),
                                  Vec3A::from_array(px[last].0));
            px[last].2 = (-to_light).to_array();
            let g = pixels_of(&px);
            let mut out = vec![0.0f32; px.len()];
            half_cos(&g, 0..px.len(), &Light { pos: light, dir, rgb: [1.0; 3] }, &mut out);
            for (i, &(p, n, v)) in px.iter().enumerate() {
                let l = toward(Vec3A::from_array(light), dir.map(Vec3A::from_array), Vec3A::from_array(p));
                let want = crate::render::brdf::blinn_phong(Vec3A::from_array(n), l, Vec3A::from_array(v),
                                                            shininess);
                let got = out[i].powf(shininess);
                proptest::prop_assert_eq!(got.to_bits(), want.to_bits(), "pixel {}: {} against {}", i, got, want);
            }
        }
    }
}
