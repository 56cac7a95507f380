//! The lights fit's loss: any number of lights, point, directional, sphere or rectangle, searched by
//! position (or direction, a sphere's radius, a rectangle's size), each one linear column per object and
//! channel.
//!
//! For a matte scene a pixel of object o is, per channel c,
//! `y = sum_l P[o][c][l] a_l(pixel) + K[o][c]`, with `a_l` light l's unit-intensity irradiance / pi at the
//! pixel (shadowed, a sphere light's soft shadow included: `render::lights::unit_irradiance`, the
//! renderer's own formula) times the exposure, `P = intensity_l x colour_l[c] x albedo_o[c]` and `K` the
//! constant term (ambient and environment light times the albedo). An object with a Blinn–Phong lobe
//! (`specular` > 0) has one more column per light, `b_l` = light l's unit-intensity irradiance times the
//! lobe `render::brdf::specular_scale(1, s) x blinn_phong(n, l, v, s)` (its shininess s as the scene
//! holds it) times the exposure, with the product `S = intensity_l x colour_l[c] x specular_o`. For each
//! candidate the products and constants are the non-negative least-squares fit over the chosen pixels,
//! object by object, so the search runs over the lights' geometry only. The loss is the sum of squared
//! residuals.

use glam::Vec3A;

use crate::error::{Error, Result};
use crate::params::ParamLayout;
use crate::render::brdf::{blinn_phong, specular_scale};
use crate::render::hit::Surfel;
use crate::render::lights::{unit_irradiance, Emitter};
use crate::render::{Geometry, PShape};
use crate::scene::Scene;
use crate::search::Objective;

/// The loss of candidate light geometries against a photo, products solved in closed form.
pub struct LightsFitness {
    pub layout: ParamLayout,
    scene: Scene,
    shapes: Vec<PShape>,
    /// The chosen pixels' first hits, grouped by object (`starts[o]..starts[o + 1]`).
    surfels: Vec<Surfel>,
    starts: Vec<usize>,
    /// The photo's linear values at the chosen pixels, in the order of `surfels`.
    values: Vec<[f32; 3]>,
    /// Per object: its lobe's shininess where it has a Blinn–Phong lobe (specular > 0).
    lobes: Vec<Option<f32>>,
}

/// The most lights the closed form takes with a glossy object: its columns (two per light and the
/// constant) stay within the exhaustive non-negative least squares' reach.
pub const MAX_GLOSSY_LIGHTS: usize = 4;

/// What the closed form found at one candidate.
#[derive(Clone, Debug, PartialEq)]
pub struct LightsSolve {
    /// The sum of squared residuals.
    pub loss: f64,
    /// Per object: per light, the RGB product P (intensity x colour x albedo); then the constant K; then,
    /// where any object is glossy, per light the lobe's product S (intensity x colour x specular; zero
    /// for a matte object).
    pub products: Vec<Vec<[f64; 3]>>,
}

impl LightsFitness {
    /// `target`: the photo's linear RGB (H x W x 3, row-major); `pixels`: the indices of the pixels to
    /// compare (each must see an object; those that see the background are left out).
    pub fn new(
        scene: &Scene,
        layout: ParamLayout,
        target: &[f32],
        pixels: &[u32],
    ) -> Result<LightsFitness> {
        let n = (scene.width * scene.height) as usize;
        if target.len() != 3 * n {
            return Err(Error::Invalid(format!(
                "objective image has {} values; the scene's image is {}x{} (expected {})",
                target.len(),
                scene.width,
                scene.height,
                3 * n
            )));
        }
        if let Some((path, _, _)) = layout.entries.iter().find(|(_, t, _)| t.is_linear()) {
            return Err(Error::Invalid(format!(
                "the lights fit searches the lights' positions, directions, radii and sizes; {path} is solved in \
                 closed form"
            )));
        }
        let lobes: Vec<Option<f32>> = scene
            .objects
            .iter()
            .map(|o| (o.material.specular > 0.0).then_some(o.material.shininess as f32))
            .collect();
        if lobes.iter().any(Option::is_some) && scene.light_count() > MAX_GLOSSY_LIGHTS {
            return Err(Error::Invalid(format!(
                "the lights fit takes a glossy object (specular > 0) under at most {MAX_GLOSSY_LIGHTS} \
                 lights (got {})",
                scene.light_count()
            )));
        }
        let geo = Geometry::new(scene);
        let mut by_object: Vec<Vec<(Surfel, [f32; 3])>> = vec![Vec::new(); scene.objects.len()];
        for &k in pixels {
            let k = k as usize;
            if k >= n {
                return Err(Error::Invalid(format!(
                    "pixel index {k} is outside the {n}-pixel image"
                )));
            }
            let (i, j) = (
                (k % scene.width as usize) as f32,
                (k / scene.width as usize) as f32,
            );
            let s = geo.primary(i + 0.5, j + 0.5, scene.width, scene.height);
            let v = [target[3 * k], target[3 * k + 1], target[3 * k + 2]];
            if s.object != u32::MAX && v.iter().all(|c| c.is_finite()) {
                by_object[s.object as usize].push((s, v));
            }
        }
        let mut starts = vec![0];
        let (mut surfels, mut values) = (Vec::new(), Vec::new());
        for list in by_object {
            for (s, v) in list {
                surfels.push(s);
                values.push(v);
            }
            starts.push(surfels.len());
        }
        Ok(LightsFitness {
            layout,
            scene: scene.clone(),
            shapes: geo.shapes,
            surfels,
            starts,
            values,
            lobes,
        })
    }

    /// The number of pixels compared.
    pub fn pixels(&self) -> usize {
        self.surfels.len()
    }

    /// The lights at the candidate `x`, in working form.
    fn emitters(&self, x: &[f64]) -> Vec<Emitter> {
        let mut scene = self.scene.clone();
        self.layout.apply(&mut scene, x);
        scene.all_lights().map(Emitter::new).collect()
    }

    /// The closed form at candidate `x`: products, constants and the loss.
    pub fn solve(&self, x: &[f64]) -> LightsSolve {
        let lights = self.emitters(x);
        let n = lights.len();
        let glossy = self.lobes.iter().any(Option::is_some);
        let mut products = Vec::with_capacity(self.starts.len() - 1);
        let mut loss = 0.0;
        for o in 0..self.starts.len() - 1 {
            let mut per = self.solve_object(o, &lights, &mut loss);
            if glossy && per.len() == n + 1 {
                per.resize(2 * n + 1, [0.0; 3]);
            }
            products.push(per);
        }
        LightsSolve { loss, products }
    }

    /// Object `o`'s columns at each of its pixels: per light its unit irradiance (/pi, times the
    /// exposure), the constant, and for a glossy object per light its lobe.
    fn columns(&self, p: usize, lights: &[Emitter], shininess: Option<f32>, col: &mut [f64]) {
        let n = lights.len();
        let exposure = self.scene.exposure as f32;
        let s = &self.surfels[p];
        for (l, e) in lights.iter().enumerate() {
            let unit = Emitter {
                intensity: 1.0,
                color: Vec3A::ONE,
                ..*e
            };
            let lit = unit_irradiance(s, &unit, &self.shapes, true);
            col[l] = lit.map_or(0.0, |(_, a)| {
                (a * exposure * std::f32::consts::FRAC_1_PI) as f64
            });
            if let Some(sh) = shininess {
                col[n + 1 + l] = lit.map_or(0.0, |(dir, a)| {
                    let lobe = specular_scale(1.0, sh) * blinn_phong(s.normal, dir, s.view, sh);
                    (a * exposure * lobe) as f64
                });
            }
        }
        col[n] = exposure as f64;
    }

    /// Object `o`'s non-negative least squares, channel by channel: its products (per light, the
    /// constant, then per light the lobe where it is glossy); each channel's residual sum of squares is
    /// added to `loss`.
    fn solve_object(&self, o: usize, lights: &[Emitter], loss: &mut f64) -> Vec<[f64; 3]> {
        let shininess = self.lobes[o];
        let k = lights.len() + 1 + if shininess.is_some() { lights.len() } else { 0 };
        let mut col = vec![0.0f64; k];
        let mut gram = vec![0.0f64; k * k];
        let mut rhs = vec![[0.0f64; 3]; k];
        let mut yy = [0.0f64; 3];
        for p in self.starts[o]..self.starts[o + 1] {
            self.columns(p, lights, shininess, &mut col);
            for a in 0..k {
                for b in 0..k {
                    gram[a * k + b] += col[a] * col[b];
                }
                for c in 0..3 {
                    rhs[a][c] += col[a] * self.values[p][c] as f64;
                }
            }
            for c in 0..3 {
                yy[c] += (self.values[p][c] as f64).powi(2);
            }
        }
        let mut per = vec![[0.0f64; 3]; k];
        for c in 0..3 {
            let b: Vec<f64> = rhs.iter().map(|r| r[c]).collect();
            let (sol, rss) = nnls(&gram, &b, yy[c], k);
            *loss += rss;
            for a in 0..k {
                per[a][c] = sol[a];
            }
        }
        per
    }
}

impl Objective for LightsFitness {
    fn n_objectives(&self) -> usize {
        1
    }

    fn evaluate(&self, x: &[f64], out: &mut [f64]) {
        let v = self.solve(x).loss;
        out[0] = if v.is_finite() { v } else { f64::MAX };
    }
}

/// Solve the `k` x `k` system `g x = b` (Gaussian elimination, partial pivoting); `None` when singular.
fn solve_dense(g: &[f64], b: &[f64], k: usize) -> Option<Vec<f64>> {
    let mut a: Vec<f64> = g.to_vec();
    let mut x: Vec<f64> = b.to_vec();
    let scale = (0..k).map(|i| g[i * k + i].abs()).fold(0.0, f64::max);
    for i in 0..k {
        let piv = (i..k).max_by(|&p, &q| a[p * k + i].abs().total_cmp(&a[q * k + i].abs()))?;
        if !(a[piv * k + i].abs() > 1e-12 * scale) {
            return None;
        }
        for j in 0..k {
            a.swap(i * k + j, piv * k + j);
        }
        x.swap(i, piv);
        for r in i + 1..k {
            let f = a[r * k + i] / a[i * k + i];
            for j in i..k {
                a[r * k + j] -= f * a[i * k + j];
            }
            x[r] -= f * x[i];
        }
    }
    for i in (0..k).rev() {
        let mut v = x[i];
        for j in i + 1..k {
            v -= a[i * k + j] * x[j];
        }
        x[i] = v / a[i * k + i];
    }
    Some(x)
}

/// Non-negative least squares from the normal equations (`gram` = AᵀA, `b` = Aᵀy, `yy` = yᵀy): every
/// subset of the columns is tried (k is at most `MAX_LIGHTS` + 1, or 2 `MAX_GLOSSY_LIGHTS` + 1), the best
/// with all values >= 0 kept.
/// Returns the solution and the residual sum of squares.
pub fn nnls(gram: &[f64], b: &[f64], yy: f64, k: usize) -> (Vec<f64>, f64) {
    let mut best = (vec![0.0; k], yy);
    for mask in 1u32..(1 << k) {
        let idx: Vec<usize> = (0..k).filter(|&i| mask & (1 << i) != 0).collect();
        let m = idx.len();
        let g: Vec<f64> = idx
            .iter()
            .flat_map(|&i| idx.iter().map(move |&j| gram[i * k + j]))
            .collect();
        let bb: Vec<f64> = idx.iter().map(|&i| b[i]).collect();
        let Some(x) = solve_dense(&g, &bb, m) else {
            continue;
        };
        if x.iter().any(|&v| !(v >= 0.0)) {
            continue;
        }
        // rss = yy - 2 bᵀx + xᵀGx = yy - bᵀx at the subset's own least-squares solution
        let rss = (yy - bb.iter().zip(&x).map(|(p, q)| p * q).sum::<f64>()).max(0.0);
        if rss < best.1 {
            let mut full = vec![0.0; k];
            for (n, &i) in idx.iter().enumerate() {
                full[i] = x[n];
            }
            best = (full, rss);
        }
    }
    best
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nnls_matches_a_brute_force_grid_on_a_small_problem() {
        // y = 2 a0 - 1 a1 over four rows: the best non-negative fit drops a1.
        let rows = [[1.0, 0.5], [0.5, 1.0], [1.0, 1.0], [0.2, 0.1]];
        let y: Vec<f64> = rows.iter().map(|r| 2.0 * r[0] - r[1]).collect();
        let mut g = [0.0; 4];
        let mut b = [0.0; 2];
        for (r, &v) in rows.iter().zip(&y) {
            for i in 0..2 {
                b[i] += r[i] * v;
                for j in 0..2 {
                    g[i * 2 + j] += r[i] * r[j];
                }
            }
        }
        let yy: f64 = y.iter().map(|v| v * v).sum();
        let (x, rss) = nnls(&g, &b, yy, 2);
        let mut brute = f64::MAX;
        for i in 0..=400 {
            for j in 0..=400 {
                let (p, q) = (i as f64 * 0.01, j as f64 * 0.01);
                let r: f64 = rows
                    .iter()
                    .zip(&y)
                    .map(|(r, v)| (p * r[0] + q * r[1] - v).powi(2))
                    .sum();
                brute = brute.min(r);
            }
        }
        assert!(x[1] == 0.0 && x[0] > 0.0);
        assert!(
            rss <= brute + 1e-9 && rss >= brute - 1e-3,
            "{rss} vs {brute}"
        );
    }
}
