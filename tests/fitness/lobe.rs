//! The specular lobe in the closed form: the kernel and the dense least-squares solve.

use super::*;

/// A glossy sphere beside a matte one on a floor: the projected loss with the specular product solved in
/// closed form and the shininess searched.
pub(crate) fn glossy_scene(light: [f64; 3], ks: f64, shininess: f64, intensity: f64) -> Scene {
    Scene::from_json(&format!(
        r#"{{"image": {{"width": 96, "height": 72}},
            "camera": {{"position": [0.3, 1.8, -6], "look_at": [0, 0.6, 0], "vfov_deg": 40}},
            "light": {{"position": {light:?}, "intensity": {intensity}, "color": [1.0, 0.9, 0.8]}},
            "exposure": 1.2,
            "objects": [
              {{"name": "glossy", "shape": "sphere", "center": [-0.7, 0.6, 0], "radius": 0.6,
                "material": {{"albedo": [0.7, 0.4, 0.2], "specular": {ks}, "shininess": {shininess}}}}},
              {{"name": "matte", "shape": "sphere", "center": [0.9, 0.5, 0.4], "radius": 0.5,
                "material": {{"albedo": [0.2, 0.5, 0.6]}}}},
              {{"name": "floor", "shape": "plane", "point": [0, 0, 0], "normal": [0, 1, 0],
                "material": {{"albedo": [0.5, 0.5, 0.5]}}}}],
            "fit": {{"light.position": {{"min": [-5, 1, -5], "max": [5, 7, 5]}},
                     "objects.glossy.shininess": {{"min": 1, "max": 200}}}}}}"#
    ))
    .unwrap()
}

pub(crate) fn glossy_fitness(scene: &Scene, target: &[f32]) -> (Fitness, ParamLayout) {
    let paths = ["light.position", "objects.glossy.shininess"].map(String::from);
    let layout = ParamLayout::new(scene, &paths).unwrap();
    let mut proj = Projection::matte(vec![[(0.0, 500.0); 3]; 3]);
    proj.specular[0] = (0.0, 500.0);
    let f = projected(scene, layout.clone(), target, proj, true);
    (f, layout)
}

/// A random trial of [`glossy_scene`]: its light position, specular `ks`, shininess `s` and intensity, the
/// scene's clipped render (`target`) and the projected fitness against it ([`glossy_fitness`]).
pub(crate) struct GlossyTrial {
    pub light: [f64; 3],
    pub ks: f64,
    pub s: f64,
    pub intensity: f64,
    pub target: Vec<f32>,
    pub f: Fitness,
    pub layout: ParamLayout,
}

pub(crate) fn glossy_trial(rng: &mut Rng) -> GlossyTrial {
    let mut u = |lo: f64, hi: f64| lo + (hi - lo) * rng.uniform();
    let light = [u(-4.0, 4.0), u(2.0, 6.0), u(-4.0, 1.0)];
    let (ks, s, intensity) = (u(0.1, 0.6), u(5.0, 120.0), u(20.0, 60.0));
    let scene = glossy_scene(light, ks, s, intensity);
    let target: Vec<f32> = clipped_render(&scene);
    let (f, layout) = glossy_fitness(&scene, &target);
    GlossyTrial {
        light,
        ks,
        s,
        intensity,
        target,
        f,
        layout,
    }
}

#[test]
fn projected_kernel_with_a_specular_term_matches_the_plain_solve_and_recovers_the_truth() {
    let mut rng = Rng::new(17);
    for trial in 0..6 {
        let t = glossy_trial(&mut rng);
        for _ in 0..6 {
            let x = random_candidate(&mut rng, &t.layout);
            assert_matches_reference(&t.f, &x, (2e-3, 0.0), &format!("trial {trial}"));
        }
        // At the truth the loss vanishes and the products are the scene's: Q = intensity x specular,
        // P = exposure x intensity x colour x albedo.
        let truth = [t.light[0], t.light[1], t.light[2], t.s];
        let at_truth = loss_at_truth(
            &t.f,
            &truth,
            2e-5 * (96 * 72) as f64,
            &format!("trial {trial}"),
        );
        let solved = t.f.solved(&truth);
        assert!(
            (solved.specular[0] - t.intensity * t.ks).abs() < 2e-3 * t.intensity * t.ks,
            "trial {trial}: Q {} vs {}",
            solved.specular[0],
            t.intensity * t.ks
        );
        let colour = [1.0, 0.9, 0.8];
        for c in 0..3 {
            let want = 1.2 * t.intensity * colour[c] * [0.7, 0.4, 0.2][c];
            assert!(
                (solved.products[0][c] - want).abs() < 2e-3 * want,
                "trial {trial}: P {:?} vs {want}",
                solved.products[0]
            );
        }
        assert_eq!(
            solved.specular[1], 0.0,
            "a matte object gets no specular term"
        );
        // A wrong shininess fits worse: the lobe's shape is informative.
        let wrong = [
            t.light[0],
            t.light[1],
            t.light[2],
            if t.s > 40.0 { t.s / 4.0 } else { t.s * 4.0 },
        ];
        assert!(t.f.channel_losses(&wrong).iter().sum::<f64>() > 10.0 * at_truth.max(1e-3));
    }
}

#[test]
fn specular_solve_matches_a_dense_least_squares_solve() {
    use rtloop::fitness::{solve_object, SolveSums};
    let mut rng = Rng::new(23);
    for _ in 0..50 {
        let n = 40;
        let w = [
            rng.uniform() as f32 + 0.2,
            rng.uniform() as f32 + 0.2,
            rng.uniform() as f32 + 0.2,
        ];
        let (a, b): (Vec<f64>, Vec<f64>) = (0..n)
            .map(|_| (rng.uniform(), rng.uniform().powi(3)))
            .unzip();
        let y: Vec<[f64; 3]> = (0..n)
            .map(|_| [rng.uniform(), rng.uniform(), rng.uniform()])
            .collect();
        let mut s = SolveSums::default();
        // Dense normal equations for (P_r, P_g, P_b, Q): columns a·e_c and b·w (stacked channels).
        let mut m = [[0.0f64; 5]; 4];
        for i in 0..n {
            for c in 0..3 {
                s.saa[c] += a[i] * a[i];
                s.sab[c] += a[i] * b[i];
                s.sbb[c] += b[i] * b[i];
                s.sya[c] += y[i][c] * a[i];
                s.syb[c] += y[i][c] * b[i];
                let mut row = [0.0f64; 4];
                row[c] = a[i];
                row[3] = w[c] as f64 * b[i];
                for r in 0..4 {
                    for k in 0..4 {
                        m[r][k] += row[r] * row[k];
                    }
                    m[r][4] += row[r] * y[i][c];
                }
            }
        }
        // Gaussian elimination with partial pivoting.
        for col in 0..4 {
            let piv = (col..4)
                .max_by(|&i, &j| m[i][col].abs().total_cmp(&m[j][col].abs()))
                .unwrap();
            m.swap(col, piv);
            for r in 0..4 {
                if r != col {
                    let f = m[r][col] / m[col][col];
                    for k in col..5 {
                        m[r][k] -= f * m[col][k];
                    }
                }
            }
        }
        let dense: Vec<f64> = (0..4).map(|r| m[r][4] / m[r][r]).collect();
        let wide = [(-1e9, 1e9); 3];
        let (p, q) = solve_object(&s, w, &wide, (-1e9, 1e9), |_| unreachable!());
        for c in 0..3 {
            assert!(
                (p[c] - dense[c]).abs() < 1e-9 * (1.0 + dense[c].abs()),
                "{p:?} {dense:?}"
            );
        }
        assert!(
            (q - dense[3]).abs() < 1e-9 * (1.0 + dense[3].abs()),
            "{q} {dense:?}"
        );
        // Bounds hold whatever the data say.
        let (p, q) = solve_object(&s, w, &[(0.0, 0.1); 3], (0.0, 0.05), |_| unreachable!());
        assert!(p.iter().all(|v| (0.0..=0.1).contains(v)) && (0.0..=0.05).contains(&q));
    }
}
