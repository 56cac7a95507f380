//! The refined products (`fitness::refine`): the loss they minimise, the clip level, the exact L1 line minimum.

use super::*;

/// The paper's scene: a ball whose red saturates over much of its lit side, on a floor; the light's
/// position searched.
fn saturated_ball() -> Scene {
    Scene::from_json(
        r#"{"image": {"width": 128, "height": 96},
            "camera": {"position": [0, 1.6, -6], "look_at": [0, 0.8, 0], "vfov_deg": 35},
            "light": {"position": [2.5, 4.5, -1.0], "intensity": 70},
            "objects": [
              {"name": "ball", "shape": "sphere", "center": [0, 1, 0], "radius": 1,
               "material": {"albedo": [0.8, 0.7, 0.1]}},
              {"name": "floor", "shape": "plane", "point": [0, 0, 0], "normal": [0, 1, 0],
               "material": {"albedo": [0.6, 0.6, 0.6]}}],
            "fit": {"light.position": {"min": [-8, 0.5, -8], "max": [8, 8, 8]}}}"#,
    )
    .unwrap()
}

/// `clean` clipped at 1 with approximately normal noise (a sum of uniforms), sigma 0.05, on the saturated
/// photo (as compression or processing noise would be), so half the saturated pixels read below 1;
/// clamped to [0, 1].
fn noisy_saturated(clean: &[f32], rng: &mut Rng) -> Vec<f32> {
    clean
        .iter()
        .map(|&v| {
            let z: f64 = (0..12).map(|_| rng.uniform()).sum::<f64>() - 6.0;
            (v.min(1.0) + 0.05 * z as f32).clamp(0.0, 1.0)
        })
        .collect()
}

/// `runs` realisations of [`noisy_saturated`] of [`saturated_ball`]'s photo (seed 31), each as the closed-form
/// fitness of the light's position, and that position's true value.
fn saturated_fits(runs: usize) -> (Vec<Fitness>, Vec<f64>) {
    let scene = saturated_ball();
    let clean = render(&scene, None, None, 1).unwrap().rgb;
    let layout = ParamLayout::new(&scene, &["light.position".to_string()]).unwrap();
    let mut rng = Rng::new(31);
    let fits = (0..runs)
        .map(|_| {
            let target = noisy_saturated(&clean, &mut rng);
            let proj = Projection::matte(vec![[(0.0, 400.0); 3]; 2]);
            projected(&scene, layout.clone(), &target, proj, true)
        })
        .collect();
    (fits, scene.light.position.to_vec())
}

#[test]
fn refined_products_minimise_the_loss_and_undo_the_saturation_bias() {
    // The paper's scene: the ball's red saturates over much of its lit side. Noise pulls half of those
    // pixels below 1, where least squares fits them as unsaturated, and pushes some unsaturated pixels up
    // to 1, where it drops them: red comes out low. The refined products count saturated pixels
    // one-sidedly and keep the clip exact (a pixel the model saturates costs a constant). Bias: the mean
    // error over realisations.
    let want = [[56.0, 49.0, 7.0], [42.0, 42.0, 42.0]];
    let runs = 8;
    let (fits, x) = saturated_fits(runs);
    let (mut ls_bias, mut ref_bias) = ([[0.0f64; 3]; 2], [[0.0f64; 3]; 2]);
    for f in &fits {
        let ls = f.solved(&x);
        let ls_loss: f64 = f.channel_losses(&x).iter().sum();
        let (refined, loss) = f.refined(&x).unwrap();
        let loss: f64 = loss.iter().sum();
        assert!(loss <= ls_loss, "refined {loss} vs least squares {ls_loss}");
        for k in 0..2 {
            for c in 0..3 {
                ls_bias[k][c] += (ls.products[k][c] / want[k][c] - 1.0) / runs as f64;
                ref_bias[k][c] += (refined.products[k][c] / want[k][c] - 1.0) / runs as f64;
            }
        }
    }
    eprintln!("bias: least squares {ls_bias:?}, refined {ref_bias:?}");
    assert!(
        ls_bias[0][0] < -0.03,
        "the test needs a saturation bias to undo: {ls_bias:?}"
    );
    assert!(
        ref_bias.iter().flatten().all(|b| b.abs() < 0.01),
        "{ref_bias:?}"
    );
}

#[test]
fn a_clip_level_below_the_noise_takes_the_least_squares_bias_off_the_search() {
    // The scene and noise of the test above (sigma 0.05 on the saturated photo). The search ranks lights
    // by the least-squares products, so their bias moves the light; with the clip level at 1 - 3 sigma
    // (`set_saturated`, what `goodness.clip_level` gives such a photo) the pixels the noise scattered
    // below 1 are left out of the solve as possibly clipped.
    let want = 56.0; // the ball's red: exposure x intensity x albedo / pi x pi (unit light column)
    let runs = 8;
    let (fits, x) = saturated_fits(runs);
    let (mut at_default, mut at_level) = (0.0f64, 0.0f64);
    for mut f in fits {
        at_default += (f.solved(&x).products[0][0] / want - 1.0) / runs as f64;
        f.set_saturated(1.0 - 3.0 * 0.05);
        at_level += (f.solved(&x).products[0][0] / want - 1.0) / runs as f64;
        // a level above SATURATED is capped there
        f.set_saturated(2.0);
        assert_eq!(f.saturated(), SATURATED);
    }
    eprintln!("ball red bias: at 0.999 {at_default:.4}, at 1 - 3 sigma {at_level:.4}");
    assert!(at_default < -0.03, "the test needs a bias: {at_default}");
    assert!(at_level.abs() < 0.01, "{at_level}");
}

#[test]
fn refined_products_are_exact_on_a_clean_glossy_image() {
    let light = [1.5, 4.0, -2.5];
    let scene = glossy_scene(light, 0.3, 30.0, 160.0);
    let target: Vec<f32> = clipped_render(&scene);
    let (f, _) = glossy_fitness(&scene, &target);
    let (refined, loss) = f.refined(&[light[0], light[1], light[2], 30.0]).unwrap();
    for c in 0..3 {
        let want = 1.2 * 160.0 * [1.0, 0.9, 0.8][c] * [0.7, 0.4, 0.2][c];
        assert!(
            (refined.products[0][c] / want - 1.0).abs() < 1e-3,
            "{:?}",
            refined.products
        );
    }
    assert!(
        (refined.specular[0] / (160.0 * 0.3) - 1.0).abs() < 1e-3,
        "{:?}",
        refined.specular
    );
    assert!(
        loss.iter().sum::<f64>() < 2e-5 * (96 * 72) as f64,
        "{loss:?}"
    );
}

#[test]
fn l1_line_min_finds_the_global_minimum_of_the_clipped_loss() {
    use rtloop::fitness::l1_line_min;
    let mut rng = Rng::new(41);
    for trial in 0..200 {
        let n = 1 + trial % 60;
        let terms: Vec<(f64, f64, f64, bool)> = (0..n)
            .map(|_| {
                let k = 0.01 + rng.uniform();
                let o = if rng.uniform() < 0.3 {
                    0.3 * rng.uniform()
                } else {
                    0.0
                };
                let saturated = rng.uniform() < 0.25;
                let y = if saturated { 1.0 } else { rng.uniform() };
                (k, o, y, saturated)
            })
            .collect();
        let top = 1.0;
        let loss = |x: f64| -> f64 {
            terms
                .iter()
                .map(|&(k, o, y, sat)| {
                    let m = (k * x + o).min(top);
                    if sat {
                        top - m
                    } else {
                        (m - y).abs()
                    }
                })
                .sum()
        };
        let (lo, hi) = (0.0, 3.0 + 10.0 * rng.uniform());
        let x = l1_line_min(terms.iter().copied(), (lo, hi), top);
        assert!((lo..=hi).contains(&x));
        // The exact loss is piecewise linear: its minimum over [lo, hi] is at a breakpoint or an end.
        let mut candidates = vec![lo, hi];
        for &(k, o, y, _) in &terms {
            candidates.extend([(y - o) / k, (top - o) / k]);
        }
        let best = candidates
            .into_iter()
            .filter(|c| (lo..=hi).contains(c))
            .map(loss)
            .fold(f64::INFINITY, f64::min);
        assert!(
            loss(x) <= best + 1e-6 * (1.0 + best),
            "trial {trial}: {} at {x} vs {best}",
            loss(x)
        );
    }
}
