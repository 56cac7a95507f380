//! The fused fitness kernel (SoA, blocked, shadow terms precomputed) against the plain per-pixel path
//! through the renderer's `shade`, on random scenes with shadows, several spheres, specular terms,
//! ambient light and saturated objective pixels.

mod common;

use common::Oracle;
use rtloop::fitness::SATURATED;
use rtloop::search::{Objective, Rng};
use rtloop::{render, Fitness, LossKind, Norm, ParamLayout, Projection, Scene};

fn random_scene(rng: &mut Rng, spheres: usize, specular: bool, ambient: bool) -> Scene {
    let mut u = |lo: f64, hi: f64| lo + (hi - lo) * rng.uniform();
    let mut objects = Vec::new();
    for k in 0..spheres {
        let r = u(0.3, 1.0);
        let (ks, s) = if specular {
            (u(0.0, 0.5), u(1.0, 60.0))
        } else {
            (0.0, 0.0)
        };
        objects.push(format!(
            r#"{{"name": "s{k}", "shape": "sphere", "center": [{}, {r}, {}], "radius": {r},
               "material": {{"albedo": [{}, {}, {}], "specular": {ks}, "shininess": {s}}}}}"#,
            u(-2.0, 2.0),
            u(-1.5, 1.5),
            u(0.05, 1.0),
            u(0.05, 1.0),
            u(0.05, 1.0)
        ));
    }
    objects.push(format!(
        r#"{{"name": "floor", "shape": "plane", "point": [0, 0, 0], "normal": [{}, 1, {}],
           "material": {{"albedo": [{}, {}, {}]}}}}"#,
        u(-0.05, 0.05),
        u(-0.05, 0.05),
        u(0.1, 0.9),
        u(0.1, 0.9),
        u(0.1, 0.9)
    ));
    let amb = if ambient { u(0.0, 0.2) } else { 0.0 };
    let mut fit = vec![
        r#""light.position": {"min": [-6, 0.5, -6], "max": [6, 8, 6]}"#.to_string(),
        r#""light.intensity": {"min": 1, "max": 200}"#.to_string(),
    ];
    for k in 0..spheres {
        fit.push(format!(r#""objects.s{k}.albedo": {{"min": 0, "max": 1}}"#));
    }
    fit.push(r#""objects.floor.albedo": {"min": 0, "max": 1}"#.to_string());
    let text = format!(
        r#"{{"image": {{"width": 96, "height": 72}},
            "camera": {{"position": [{}, {}, -7], "look_at": [0, 0.7, 0], "vfov_deg": 40}},
            "light": {{"position": [{}, {}, {}], "intensity": {}}},
            "ambient": [{amb}, {amb}, {amb}], "exposure": {},
            "objects": [{}], "fit": {{{}}}}}"#,
        u(-1.0, 1.0),
        u(1.0, 3.0),
        u(-4.0, 4.0),
        u(1.0, 6.0),
        u(-4.0, 4.0),
        u(20.0, 120.0),
        u(0.7, 1.5),
        objects.join(","),
        fit.join(",")
    );
    Scene::from_json(&text).unwrap()
}

/// A fitness of all of `layout` over the whole image, no closed-form products.
fn fitness(
    scene: &Scene,
    layout: &ParamLayout,
    target: &[f32],
    kind: LossKind,
    clip: bool,
) -> Fitness {
    Fitness::new(scene, layout.clone(), target, None, kind, clip, None).unwrap()
}

/// The scene's render as the fitness models pixels (the footprint), clipped at 1 as a photo saturates.
fn clipped_render(scene: &Scene) -> Vec<f32> {
    render(scene, None, None, 1)
        .unwrap()
        .rgb
        .iter()
        .map(|v| v.min(1.0))
        .collect()
}

/// The closed-form (projected) fitness of `layout` over the whole image.
fn projected(
    scene: &Scene,
    layout: ParamLayout,
    target: &[f32],
    proj: Projection,
    clip: bool,
) -> Fitness {
    Fitness::new(
        scene,
        layout,
        target,
        None,
        LossKind::L1Projected,
        clip,
        Some(proj),
    )
    .unwrap()
}

fn random_candidate(rng: &mut Rng, layout: &ParamLayout) -> Vec<f64> {
    layout
        .bounds
        .iter()
        .map(|&(lo, hi)| lo + (hi - lo) * rng.uniform())
        .collect()
}

/// Relative difference with a floor: the losses are sums over ~7000 pixels x 3 channels of f32 terms.
fn close(a: f64, b: f64, rel: f64) -> bool {
    (a - b).abs() <= rel * a.abs().max(b.abs()).max(1.0)
}

#[test]
fn kernel_matches_the_plain_path_on_random_scenes() {
    let mut rng = Rng::new(42);
    let mut cases = 0;
    for trial in 0..24 {
        let spheres = 1 + trial % 4;
        let specular = trial % 3 == 1;
        let ambient = trial % 4 == 2;
        let scene = random_scene(&mut rng, spheres, specular, ambient);
        // The objective: the scene itself, saturating at 1, so some pixels are clipped.
        let target: Vec<f32> = clipped_render(&scene);
        let layout = ParamLayout::all(&scene);
        for kind in [LossKind::L1, LossKind::L1PerChannel] {
            let f = fitness(&scene, &layout, &target, kind, true);
            for _ in 0..6 {
                let x = random_candidate(&mut rng, &layout);
                let fast = f.channel_losses(&x);
                let slow = f.reference_channel_losses(&x);
                for c in 0..3 {
                    // Shadow-boundary pixels may flip between the two shadow tests; each flip moves a sum
                    // of ~thousands of terms by at most one pixel value.
                    assert!(
                        close(fast[c], slow[c], 2e-3),
                        "trial {trial} {kind:?} channel {c}: {fast:?} vs {slow:?}"
                    );
                }
                let mut out = vec![0.0; f.n_objectives()];
                f.evaluate(&x, &mut out);
                assert!(out.iter().all(|v| v.is_finite()));
                cases += 1;
            }
        }
    }
    assert_eq!(cases, 24 * 2 * 6);
}

#[test]
fn kernel_agrees_exactly_where_no_shadow_boundary_exists() {
    // One sphere alone: no occluders at all, so both paths shade the same pixels with the same formula.
    let scene = Scene::from_json(
        r#"{"image": {"width": 64, "height": 48},
            "camera": {"position": [0, 0, -5], "look_at": [0, 0, 0], "vfov_deg": 40},
            "light": {"position": [1, 2, -3], "intensity": 30},
            "objects": [{"name": "b", "shape": "sphere", "center": [0, 0, 0], "radius": 1,
                         "material": {"albedo": [0.7, 0.5, 0.2], "specular": 0.3, "shininess": 20}}],
            "fit": {"light.position": {"min": -5, "max": 5}, "light.intensity": {"min": 1, "max": 100}}}"#,
    )
    .unwrap();
    let target = vec![0.3f32; 64 * 48 * 3];
    let layout = ParamLayout::all(&scene);
    let f = fitness(&scene, &layout, &target, LossKind::L1, true);
    let mut rng = Rng::new(3);
    for _ in 0..20 {
        let x = random_candidate(&mut rng, &layout);
        let (a, b) = (f.channel_losses(&x), f.reference_channel_losses(&x));
        for c in 0..3 {
            assert!(close(a[c], b[c], 1e-5), "{a:?} vs {b:?}");
        }
    }
}

#[test]
fn projected_kernel_matches_the_plain_solve() {
    let mut rng = Rng::new(5);
    for trial in 0..12 {
        let scene = random_scene(&mut rng, 1 + trial % 3, false, false);
        let target: Vec<f32> = clipped_render(&scene);
        let layout = ParamLayout::new(&scene, &["light.position".to_string()]).unwrap();
        let bounds = vec![[(0.0, 200.0); 3]; scene.objects.len()];
        let f = projected(
            &scene,
            layout.clone(),
            &target,
            Projection::matte(bounds),
            true,
        );
        for _ in 0..6 {
            let x = random_candidate(&mut rng, &layout);
            let (a, b) = (f.channel_losses(&x), f.reference_channel_losses(&x));
            for c in 0..3 {
                assert!(close(a[c], b[c], 2e-3), "trial {trial}: {a:?} vs {b:?}");
            }
        }
        // At the true light the projected loss vanishes (up to float rounding).
        let truth: Vec<f64> = scene.light.position.to_vec();
        let at_truth: f64 = f.channel_losses(&truth).iter().sum();
        eprintln!(
            "trial {trial}: at truth {at_truth} ref {:?} products {:?} light {:?} objs {:?}",
            f.reference_channel_losses(&truth),
            f.products(&truth),
            scene.light.position,
            scene
                .objects
                .iter()
                .map(|o| o.shape.clone())
                .collect::<Vec<_>>()
        );
        assert!(
            at_truth < 1e-5 * (scene.width * scene.height) as f64,
            "{at_truth}"
        );
    }
}

/// A polish evaluates one candidate at a time and spreads its pixels over the pool: the value must be
/// the population path's, bit for bit, on any number of threads (matte and glossy, linear and sRGB,
/// candidates near and far from the truth, the truth itself).
#[test]
fn one_candidate_alone_gives_the_serial_value_bit_for_bit_on_any_thread_count() {
    let mut rng = Rng::new(17);
    let glossy = glossy_scene([1.5, 3.0, -2.0], 0.3, 40.0, 30.0);
    let mut cases: Vec<(Scene, bool)> = vec![(glossy, true)];
    for k in 0..3 {
        cases.push((random_scene(&mut rng, 1 + k, false, false), false));
    }
    for (scene, shiny) in &cases {
        let target: Vec<f32> = clipped_render(scene);
        let (mut f, layout) = if *shiny {
            glossy_fitness(scene, &target)
        } else {
            let layout = ParamLayout::new(scene, &["light.position".to_string()]).unwrap();
            let bounds = vec![[(0.0, 200.0); 3]; scene.objects.len()];
            let f = projected(
                scene,
                layout.clone(),
                &target,
                Projection::matte(bounds),
                true,
            );
            (f, layout)
        };
        let mut xs: Vec<Vec<f64>> = (0..5)
            .map(|_| random_candidate(&mut rng, &layout))
            .collect();
        let mut truth = scene.light.position.to_vec();
        if *shiny {
            truth.push(scene.objects[0].material.shininess);
        }
        xs.push(truth);
        for space in [rtloop::Space::Linear, rtloop::Space::Srgb] {
            f.set_space(space);
            for x in &xs {
                let mut serial = [0.0];
                f.evaluate(x, &mut serial);
                assert!(serial[0].is_finite());
                for threads in [1, 2, 3, 5] {
                    let pool = rayon::ThreadPoolBuilder::new()
                        .num_threads(threads)
                        .build()
                        .unwrap();
                    let mut alone = [0.0];
                    pool.install(|| f.evaluate_alone(x, &mut alone));
                    assert_eq!(
                        serial[0].to_bits(),
                        alone[0].to_bits(),
                        "{space:?} threads={threads} x={x:?}: {} vs {}",
                        serial[0],
                        alone[0]
                    );
                }
            }
        }
    }
}

/// A random scene of one or two spheres (`k` odd: two) with interreflection, its clipped render and the
/// light's position as the searched parameters.
fn bounce_case(rng: &mut Rng, k: usize) -> (Scene, Vec<f32>, ParamLayout) {
    let mut scene = random_scene(rng, 1 + k % 2, false, false);
    scene.interreflection = true;
    let target = clipped_render(&scene);
    let layout = ParamLayout::new(&scene, &["light.position".to_string()]).unwrap();
    (scene, target, layout)
}

/// The closed-form (matte) fitness of a [`bounce_case`], with or without the pixel footprint.
fn bounce_fitness(scene: &Scene, layout: &ParamLayout, target: &[f32], footprint: bool) -> Fitness {
    let bounds = vec![[(0.0, 200.0); 3]; scene.objects.len()];
    Fitness::with_solve_margin(
        scene,
        layout.clone(),
        target,
        None,
        LossKind::L1Projected,
        true,
        Some(Projection::matte(bounds)),
        footprint,
        0,
    )
    .unwrap()
}

/// With interreflection the fitness's geometry and the bounce's gathers are built over the pool, and
/// the held bounce and the refined products are solved over it: the values must be a one-thread
/// build's, bit for bit, on any number of threads (the full bounce, the held one, the refined
/// products and loss; with and without the pixel footprint), and one candidate alone over the pool
/// gives the population's serial value.
#[test]
fn a_bounce_fitness_built_and_held_on_any_thread_count_gives_the_same_bits() {
    let mut rng = Rng::new(23);
    for k in 0..3 {
        let (scene, target, layout) = bounce_case(&mut rng, k);
        let xs: Vec<Vec<f64>> = (0..3)
            .map(|_| random_candidate(&mut rng, &layout))
            .chain([scene.light.position.to_vec()])
            .collect();
        for footprint in [false, true] {
            let values = |threads: usize| {
                let pool = rayon::ThreadPoolBuilder::new()
                    .num_threads(threads)
                    .build()
                    .unwrap();
                pool.install(|| {
                    let mut f = bounce_fitness(&scene, &layout, &target, footprint);
                    // the population's serial value, which one candidate alone over the pool must give
                    let value = |f: &Fitness, x: &[f64], held: bool| {
                        let (mut o, mut alone) = ([0.0], [0.0]);
                        f.evaluate(x, &mut o);
                        f.evaluate_alone(x, &mut alone);
                        assert_eq!(o[0].to_bits(), alone[0].to_bits(), "held {held}, {x:?}");
                        o[0].to_bits()
                    };
                    let mut bits = Vec::new();
                    for x in &xs {
                        bits.push(value(&f, x, false));
                        let (solved, loss) = f.refined(x).unwrap();
                        bits.extend(loss.iter().map(|v| v.to_bits()));
                        bits.extend(solved.products.iter().flatten().map(|v| v.to_bits()));
                        bits.push(solved.gauge.unwrap().to_bits());
                    }
                    assert!(f.freeze_bounce(Some(&xs[0])));
                    for x in &xs {
                        bits.push(value(&f, x, true));
                    }
                    bits
                })
            };
            let one = values(1);
            for threads in [2, 3, 5] {
                assert_eq!(
                    values(threads),
                    one,
                    "scene {k}, footprint {footprint}, {threads} threads"
                );
            }
        }
    }
}

#[test]
fn light_inside_an_occluder_or_on_a_surface_gives_finite_losses() {
    let mut rng = Rng::new(9);
    let scene = random_scene(&mut rng, 2, true, false);
    let target = vec![0.5f32; (scene.width * scene.height * 3) as usize];
    let layout = ParamLayout::all(&scene);
    let f = fitness(&scene, &layout, &target, LossKind::L1, false);
    let mut x = layout.read(&scene);
    let rtloop::scene::Shape::Sphere { center, .. } = scene.objects[0].shape else {
        unreachable!()
    };
    for pos in [center, [0.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 1e-7, 0.0]] {
        x[..3].copy_from_slice(&pos);
        let (a, b) = (f.channel_losses(&x), f.reference_channel_losses(&x));
        assert!(
            a.iter().chain(&b).all(|v| v.is_finite()),
            "{pos:?}: {a:?} {b:?}"
        );
    }
}

#[test]
fn early_exit_changes_cost_not_results() {
    // DE only asks whether a trial beats its target; stopping the sum early must not change any choice.
    let mut rng = Rng::new(11);
    let scene = random_scene(&mut rng, 2, false, false);
    let target: Vec<f32> = clipped_render(&scene);
    let paths = vec!["light.position".to_string(), "light.intensity".to_string()];
    let layout = ParamLayout::new(&scene, &paths).unwrap();
    let cfg = rtloop::DeConfig {
        population: 16,
        generations: 25,
        seed: 4,
        ..Default::default()
    };
    let run = |early: bool| {
        let mut f = fitness(&scene, &layout, &target, LossKind::L1, true);
        f.early_exit = early;
        let mut history = Vec::new();
        let r = rtloop::search::rand1bin::minimize(&f, &layout.bounds, &cfg, |g| {
            history.push((
                g.best.to_vec(),
                g.best_objectives.to_vec(),
                g.objectives.to_vec(),
            ));
            true
        })
        .unwrap();
        (r.best, r.best_objectives, history)
    };
    let (exact, early) = (run(false), run(true));
    assert_eq!(exact.0, early.0);
    assert_eq!(exact.1, early.1);
    assert_eq!(
        exact.2, early.2,
        "every generation's population objectives are identical"
    );
    // And a bounded evaluation above the bound really is cut short but still above it.
    let f = fitness(&scene, &layout, &target, LossKind::L1, true);
    let x = vec![0.0, 7.5, 0.0, 150.0];
    let mut full = [0.0];
    f.evaluate(&x, &mut full);
    let mut cut = [0.0];
    f.evaluate_bounded(&x, &mut cut, full[0] * 0.1);
    assert!(
        cut[0] > full[0] * 0.1 && cut[0] < full[0],
        "{} vs {}",
        cut[0],
        full[0]
    );
}

#[test]
fn every_norm_matches_the_plain_path_and_its_definition() {
    use rtloop::Norm;
    let mut rng = Rng::new(21);
    for trial in 0..6 {
        let scene = random_scene(&mut rng, 1 + trial % 3, trial % 2 == 1, false);
        let clean = render(&scene, None, None, 1).unwrap().rgb;
        // A noisy objective, so differences span both sides of the Huber threshold.
        let target: Vec<f32> = clean
            .iter()
            .map(|v| (v + 0.05 * (rng.uniform() as f32 - 0.5)).clamp(0.0, 1.0))
            .collect();
        let layout = ParamLayout::all(&scene);
        for norm in [Norm::L1, Norm::L2, Norm::Huber(0.01)] {
            let mut f = fitness(&scene, &layout, &target, LossKind::L1, true);
            f.set_norm(norm);
            let x = random_candidate(&mut rng, &layout);
            let (fast, slow) = (f.channel_losses(&x), f.reference_channel_losses(&x));
            // And from the definition: render the candidate, penalise every pixel.
            let mut s = scene.clone();
            layout.apply(&mut s, &x);
            let img = render(&s, None, None, 1).unwrap().rgb;
            let mut direct = [0.0f64; 3];
            for (i, (m, t)) in img.iter().zip(&target).enumerate() {
                direct[i % 3] += norm.penalty(m.min(1.0) - t) as f64;
            }
            for c in 0..3 {
                assert!(
                    close(fast[c], slow[c], 2e-3),
                    "{norm:?} trial {trial}: {fast:?} vs {slow:?}"
                );
                assert!(
                    close(fast[c], direct[c], 2e-3),
                    "{norm:?} trial {trial}: {fast:?} vs {direct:?}"
                );
            }
        }
    }
    assert_eq!(Norm::parse("huber:0.05"), Ok(Norm::Huber(0.05)));
    assert!(Norm::parse("huber:-1").is_err() && Norm::parse("l3").is_err());
    // Huber is continuous at its threshold and linear beyond it.
    let h = Norm::Huber(0.1);
    assert!(
        (h.penalty(0.1) - 0.05).abs() < 1e-7
            && (h.penalty(1.1) - h.penalty(1.0) - 0.1).abs() < 1e-6
    );
}

/// A random scene lit by a directional light (a sun): the same geometry generator, the light swapped.
fn random_sun_scene(rng: &mut Rng, spheres: usize, specular: bool) -> Scene {
    let point = random_scene(rng, spheres, specular, false);
    let mut v = point.to_value();
    let dir = [
        rng.uniform() * 2.0 - 1.0,
        0.3 + rng.uniform(),
        rng.uniform() * 2.0 - 1.0,
    ];
    v["light"] = serde_json::json!({"type": "directional", "direction": dir, "intensity": 3.0});
    let fit = v["fit"].as_object_mut().unwrap();
    fit.remove("light.position");
    fit.insert(
        "light.direction".into(),
        serde_json::json!({"min": [-1, 0.05, -1], "max": [1, 1, 1]}),
    );
    Scene::from_json(&v.to_string()).unwrap()
}

#[test]
fn directional_light_kernel_matches_the_plain_path() {
    let mut rng = Rng::new(33);
    for trial in 0..8 {
        let scene = random_sun_scene(&mut rng, 1 + trial % 4, trial % 2 == 1);
        let target: Vec<f32> = clipped_render(&scene);
        let layout = ParamLayout::all(&scene);
        assert_eq!(layout.names[0], "light.direction.x");
        let f = fitness(&scene, &layout, &target, LossKind::L1, true);
        for _ in 0..5 {
            let x = random_candidate(&mut rng, &layout);
            let (fast, slow) = (f.channel_losses(&x), f.reference_channel_losses(&x));
            for c in 0..3 {
                assert!(
                    close(fast[c], slow[c], 2e-3),
                    "trial {trial}: {fast:?} vs {slow:?}"
                );
            }
        }
        // At the true parameters the loss vanishes; the direction's length does not matter.
        let mut x = layout.read(&scene);
        let exact: f64 = f.channel_losses(&x).iter().sum();
        x[..3].iter_mut().for_each(|v| *v *= 2.5);
        let scaled: f64 = f.channel_losses(&x).iter().sum();
        assert!(
            exact < 1e-5 * target.len() as f64 && (scaled - exact).abs() < 1e-3,
            "{exact} {scaled}"
        );
    }
}

/// A glossy sphere beside a matte one on a floor: the projected loss with the specular product solved in
/// closed form and the shininess searched.
fn glossy_scene(light: [f64; 3], ks: f64, shininess: f64, intensity: f64) -> Scene {
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

fn glossy_fitness(scene: &Scene, target: &[f32]) -> (Fitness, ParamLayout) {
    let paths = ["light.position", "objects.glossy.shininess"].map(String::from);
    let layout = ParamLayout::new(scene, &paths).unwrap();
    let mut proj = Projection::matte(vec![[(0.0, 500.0); 3]; 3]);
    proj.specular[0] = (0.0, 500.0);
    let f = projected(scene, layout.clone(), target, proj, true);
    (f, layout)
}

#[test]
fn projected_kernel_with_a_specular_term_matches_the_plain_solve_and_recovers_the_truth() {
    let mut rng = Rng::new(17);
    for trial in 0..6 {
        let mut u = |lo: f64, hi: f64| lo + (hi - lo) * rng.uniform();
        let light = [u(-4.0, 4.0), u(2.0, 6.0), u(-4.0, 1.0)];
        let (ks, s, intensity) = (u(0.1, 0.6), u(5.0, 120.0), u(20.0, 60.0));
        let scene = glossy_scene(light, ks, s, intensity);
        let target: Vec<f32> = clipped_render(&scene);
        let (f, layout) = glossy_fitness(&scene, &target);
        for _ in 0..6 {
            let x = random_candidate(&mut rng, &layout);
            let (a, b) = (f.channel_losses(&x), f.reference_channel_losses(&x));
            for c in 0..3 {
                assert!(close(a[c], b[c], 2e-3), "trial {trial}: {a:?} vs {b:?}");
            }
        }
        // At the truth the loss vanishes and the products are the scene's: Q = intensity x specular,
        // P = exposure x intensity x colour x albedo.
        let truth = [light[0], light[1], light[2], s];
        let at_truth: f64 = f.channel_losses(&truth).iter().sum();
        assert!(
            at_truth < 2e-5 * (96 * 72) as f64,
            "trial {trial}: {at_truth}"
        );
        let solved = f.solved(&truth);
        assert!(
            (solved.specular[0] - intensity * ks).abs() < 2e-3 * intensity * ks,
            "trial {trial}: Q {} vs {}",
            solved.specular[0],
            intensity * ks
        );
        let colour = [1.0, 0.9, 0.8];
        for c in 0..3 {
            let want = 1.2 * intensity * colour[c] * [0.7, 0.4, 0.2][c];
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
            light[0],
            light[1],
            light[2],
            if s > 40.0 { s / 4.0 } else { s * 4.0 },
        ];
        assert!(f.channel_losses(&wrong).iter().sum::<f64>() > 10.0 * at_truth.max(1e-3));
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

#[test]
fn refined_products_minimise_the_loss_and_undo_the_saturation_bias() {
    // The paper's scene: the ball's red saturates over much of its lit side. Noise pulls half of those
    // pixels below 1, where least squares fits them as unsaturated, and pushes some unsaturated pixels up
    // to 1, where it drops them: red comes out low. The refined products count saturated pixels
    // one-sidedly and keep the clip exact (a pixel the model saturates costs a constant). Bias: the mean
    // error over realisations.
    let scene = Scene::from_json(
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
    .unwrap();
    let clean = render(&scene, None, None, 1).unwrap().rgb;
    let layout = ParamLayout::new(&scene, &["light.position".to_string()]).unwrap();
    let x = scene.light.position.to_vec();
    let want = [[56.0, 49.0, 7.0], [42.0, 42.0, 42.0]];
    let mut rng = Rng::new(31);
    let runs = 8;
    let (mut ls_bias, mut ref_bias) = ([[0.0f64; 3]; 2], [[0.0f64; 3]; 2]);
    for _ in 0..runs {
        let target: Vec<f32> = clean
            .iter()
            .map(|&v| {
                // Approximately normal (a sum of uniforms), sigma 0.05, on the saturated photo (as
                // compression or processing noise would be), so half the saturated pixels read below 1.
                let z: f64 = (0..12).map(|_| rng.uniform()).sum::<f64>() - 6.0;
                (v.min(1.0) + 0.05 * z as f32).clamp(0.0, 1.0)
            })
            .collect();
        let proj = Projection::matte(vec![[(0.0, 400.0); 3]; 2]);
        let f = projected(&scene, layout.clone(), &target, proj, true);
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
    let scene = Scene::from_json(
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
    .unwrap();
    let clean = render(&scene, None, None, 1).unwrap().rgb;
    let layout = ParamLayout::new(&scene, &["light.position".to_string()]).unwrap();
    let x = scene.light.position.to_vec();
    let want = 56.0; // the ball's red: exposure x intensity x albedo / pi x pi (unit light column)
    let mut rng = Rng::new(31);
    let runs = 8;
    let (mut at_default, mut at_level) = (0.0f64, 0.0f64);
    for _ in 0..runs {
        let target: Vec<f32> = clean
            .iter()
            .map(|&v| {
                let z: f64 = (0..12).map(|_| rng.uniform()).sum::<f64>() - 6.0;
                (v.min(1.0) + 0.05 * z as f32).clamp(0.0, 1.0)
            })
            .collect();
        let proj = Projection::matte(vec![[(0.0, 400.0); 3]; 2]);
        let mut f = projected(&scene, layout.clone(), &target, proj, true);
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

/// The loss-space tests' allowance for the kernel's table encoding against the plain path's exact one:
/// at most 2e-5 per encoded value, so 4e-5 per difference, times the penalty's slope (1 for L1 and
/// Huber, 2|d| for L2), per term.
fn table_allowance(norm: rtloop::Norm, terms: usize, largest: f64) -> f64 {
    let slope = match norm {
        rtloop::Norm::L2 => 2.0 * largest.max(1.0),
        _ => 1.0,
    };
    4e-5 * slope * terms as f64
}

#[test]
fn srgb_losses_match_the_plain_path_for_every_norm_clip_and_loss() {
    use rtloop::{Norm, Space};
    let mut rng = Rng::new(71);
    let mut cases = 0;
    for trial in 0..8 {
        let specular = trial % 3 == 1;
        let ambient = trial % 4 == 2;
        let scene = random_scene(&mut rng, 1 + trial % 3, specular, ambient);
        let clean = render(&scene, None, None, 1).unwrap().rgb;
        let layout = ParamLayout::all(&scene);
        for clip in [true, false] {
            // Noisy, dark and bright pixels; without a clip the objective may exceed 1 as well.
            let target: Vec<f32> = clean
                .iter()
                .map(|v| {
                    let v = (v + 0.04 * (rng.uniform() as f32 - 0.5)).max(0.0);
                    if clip {
                        v.min(1.0)
                    } else {
                        v
                    }
                })
                .collect();
            for norm in [Norm::L1, Norm::L2, Norm::Huber(0.01)] {
                for kind in [LossKind::L1, LossKind::L1PerChannel] {
                    let mut f = fitness(&scene, &layout, &target, kind, clip);
                    f.set_norm(norm);
                    f.set_space(Space::Srgb);
                    assert_eq!(f.space(), Space::Srgb);
                    for _ in 0..3 {
                        let x = random_candidate(&mut rng, &layout);
                        let (fast, slow) = (f.channel_losses(&x), f.reference_channel_losses(&x));
                        let slack = table_allowance(norm, target.len() / 3, 30.0);
                        for c in 0..3 {
                            assert!(
                                (fast[c] - slow[c]).abs()
                                    <= 2e-3 * fast[c].abs().max(slow[c].abs()).max(1.0) + slack,
                                "trial {trial} clip {clip} {norm:?} {kind:?} channel {c}: {fast:?} vs {slow:?}"
                            );
                        }
                        cases += 1;
                    }
                }
            }
        }
    }
    assert_eq!(cases, 8 * 2 * 3 * 2 * 3);
}

#[test]
fn srgb_loss_is_the_loss_of_the_encoded_images() {
    // From the definition: render the candidate, encode it (clipped) and the objective exactly, penalise.
    use rtloop::render::film::srgb_encode_exact;
    use rtloop::{Norm, Space};
    let mut rng = Rng::new(72);
    for trial in 0..4 {
        let scene = random_scene(&mut rng, 1 + trial % 3, trial % 2 == 1, false);
        let target: Vec<f32> = render(&scene, None, None, 1)
            .unwrap()
            .rgb
            .iter()
            .map(|v| (v + 0.03 * (rng.uniform() as f32 - 0.5)).clamp(0.0, 1.0))
            .collect();
        let layout = ParamLayout::all(&scene);
        for norm in [Norm::L1, Norm::L2, Norm::Huber(0.02)] {
            let mut f = fitness(&scene, &layout, &target, LossKind::L1, true);
            f.set_norm(norm);
            f.set_space(Space::Srgb);
            let x = random_candidate(&mut rng, &layout);
            let mut s = scene.clone();
            layout.apply(&mut s, &x);
            let img = render(&s, None, None, 1).unwrap().rgb;
            let mut direct = [0.0f64; 3];
            for (i, (m, t)) in img.iter().zip(&target).enumerate() {
                let d = srgb_encode_exact(m.min(1.0) as f64) - srgb_encode_exact(*t as f64);
                direct[i % 3] += norm.penalty(d as f32) as f64;
            }
            let fast = f.channel_losses(&x);
            let slack = table_allowance(norm, target.len() / 3, 1.0);
            for c in 0..3 {
                assert!(
                    (fast[c] - direct[c]).abs() <= 2e-3 * fast[c].max(direct[c]).max(1.0) + slack,
                    "{norm:?} trial {trial}: {fast:?} vs {direct:?}"
                );
            }
        }
    }
}

#[test]
fn projected_srgb_loss_matches_the_plain_solve_and_vanishes_at_the_truth() {
    use rtloop::{Norm, Space};
    let mut rng = Rng::new(73);
    for trial in 0..6 {
        let scene = random_scene(&mut rng, 1 + trial % 3, false, false);
        let clean: Vec<f32> = render(&scene, None, None, 1).unwrap().rgb;
        let layout = ParamLayout::new(&scene, &["light.position".to_string()]).unwrap();
        let truth: Vec<f64> = scene.light.position.to_vec();
        for clip in [true, false] {
            let target: Vec<f32> = clean
                .iter()
                .map(|&v| if clip { v.min(1.0) } else { v })
                .collect();
            for norm in [Norm::L1, Norm::L2, Norm::Huber(0.01)] {
                let bounds = vec![[(0.0, 200.0); 3]; scene.objects.len()];
                let mut f = projected(
                    &scene,
                    layout.clone(),
                    &target,
                    Projection::matte(bounds),
                    clip,
                );
                f.set_norm(norm);
                f.set_space(Space::Srgb);
                for _ in 0..3 {
                    let x = random_candidate(&mut rng, &layout);
                    let (a, b) = (f.channel_losses(&x), f.reference_channel_losses(&x));
                    let slack = table_allowance(norm, target.len() / 3, 30.0);
                    for c in 0..3 {
                        assert!(
                            (a[c] - b[c]).abs() <= 2e-3 * a[c].max(b[c]).max(1.0) + slack,
                            "trial {trial} clip {clip} {norm:?}: {a:?} vs {b:?}"
                        );
                    }
                }
                // The objective goes through the kernel's own encoding: the model that renders it
                // exactly costs (almost) nothing, in any norm.
                let at_truth: f64 = f.channel_losses(&truth).iter().sum();
                assert!(
                    at_truth < 1e-5 * (scene.width * scene.height) as f64,
                    "trial {trial} clip {clip} {norm:?}: {at_truth}"
                );
            }
        }
    }
}

#[test]
fn projected_srgb_loss_with_a_specular_term_matches_the_plain_solve() {
    use rtloop::Space;
    let mut rng = Rng::new(74);
    for trial in 0..4 {
        let mut u = |lo: f64, hi: f64| lo + (hi - lo) * rng.uniform();
        let light = [u(-4.0, 4.0), u(2.0, 6.0), u(-4.0, 1.0)];
        let (ks, s, intensity) = (u(0.1, 0.6), u(5.0, 120.0), u(20.0, 60.0));
        let scene = glossy_scene(light, ks, s, intensity);
        let target: Vec<f32> = clipped_render(&scene);
        let (mut f, layout) = glossy_fitness(&scene, &target);
        f.set_space(Space::Srgb);
        for _ in 0..4 {
            let x = random_candidate(&mut rng, &layout);
            let (a, b) = (f.channel_losses(&x), f.reference_channel_losses(&x));
            let slack = table_allowance(rtloop::Norm::L1, target.len() / 3, 1.0);
            for c in 0..3 {
                assert!(
                    (a[c] - b[c]).abs() <= 2e-3 * a[c].max(b[c]).max(1.0) + slack,
                    "trial {trial}: {a:?} vs {b:?}"
                );
            }
        }
        let truth = [light[0], light[1], light[2], s];
        let at_truth: f64 = f.channel_losses(&truth).iter().sum();
        assert!(
            at_truth < 2e-5 * (96 * 72) as f64,
            "trial {trial}: {at_truth}"
        );
        let (refined, _) = f.refined(&truth).unwrap();
        assert!(
            (refined.specular[0] / (intensity * ks) - 1.0).abs() < 1e-3,
            "trial {trial}: Q {:?} vs {}",
            refined.specular,
            intensity * ks
        );
    }
}

#[test]
fn linear_space_is_untouched_by_a_round_trip_through_srgb() {
    use rtloop::Space;
    let mut rng = Rng::new(75);
    let scene = random_scene(&mut rng, 2, true, true);
    let target: Vec<f32> = render(&scene, None, None, 1)
        .unwrap()
        .rgb
        .iter()
        .map(|v| (v * 0.9).min(1.0))
        .collect();
    let layout = ParamLayout::all(&scene);
    let plain = fitness(&scene, &layout, &target, LossKind::L1, true);
    let mut back = fitness(&scene, &layout, &target, LossKind::L1, true);
    assert_eq!(back.space(), Space::Linear, "linear is the default");
    back.set_space(Space::Srgb);
    let x = random_candidate(&mut rng, &layout);
    assert_ne!(back.channel_losses(&x), plain.channel_losses(&x));
    back.set_space(Space::Linear);
    for _ in 0..5 {
        let x = random_candidate(&mut rng, &layout);
        assert_eq!(back.channel_losses(&x), plain.channel_losses(&x));
    }
    assert_eq!(Space::parse("srgb"), Ok(Space::Srgb));
    let err = Space::parse("sRGB").unwrap_err();
    assert!(
        err.contains("space") && err.contains("\"linear\", \"srgb\""),
        "{err}"
    );
}

/// F(x) = Σ_j ℓ_j(x) on a grid of `n` + 1 points over [lo, hi]: (argmin, min).
fn grid_min(f: impl Fn(f64) -> f64, (lo, hi): (f64, f64), n: usize) -> (f64, f64) {
    (0..=n)
        .map(|i| lo + (hi - lo) * i as f64 / n as f64)
        .map(|x| (x, f(x)))
        .fold((lo, f64::INFINITY), |b, p| if p.1 < b.1 { p } else { b })
}

#[test]
fn encoded_line_min_finds_the_global_minimum() {
    use rtloop::fitness::SrgbLut;
    use rtloop::fitness::{encoded_line_min, EncodedTerm};
    use rtloop::Norm;
    let lut = SrgbLut::get();
    let term = |k: f64, o: f64, y: f64| EncodedTerm {
        k,
        o,
        y: y.min(1.0),
        ye: lut.encode(y.min(1.0) as f32),
        saturated: y >= 0.999,
    };
    // The loss as Kernel::refine defines it: penalty(enc(min(k x + o, 1)) - enc(y)), one-sided when
    // saturated.
    let sum = |terms: &[EncodedTerm], norm: Norm, x: f64| -> f64 {
        terms
            .iter()
            .map(|t| {
                let m = lut.encode((t.k * x + t.o).min(1.0) as f32);
                let d = if t.saturated {
                    (m - lut.encode(1.0)).min(0.0)
                } else {
                    m - t.ye
                };
                norm.penalty(d) as f64
            })
            .sum()
    };
    // A sum whose minimum is not at a breakpoint: a pixel with an offset (a specular lobe) and three
    // times the gain rising above its breakpoint 1/60, beside one falling towards its breakpoint 0.9
    // (beyond the bounds); their encoded slopes, 3 enc'(3x + 0.3) and enc'(x), cross near x = 0.084.
    let two = [term(3.0, 0.3, 0.35), term(1.0, 0.0, 0.9)];
    let f2 = |x: f64| sum(&two, Norm::L1, x);
    let bounds = (0.0, 0.23);
    let x = encoded_line_min(&two, Norm::L1, 1.0, bounds, 0.2);
    let (gx, gf) = grid_min(f2, bounds, 200_000);
    let breakpoints = [0.0, 1.0 / 60.0, 0.23]
        .map(f2)
        .into_iter()
        .fold(f64::INFINITY, f64::min);
    assert!(
        gf < breakpoints - 0.02,
        "the case needs an interior minimum: {gf} vs {breakpoints}"
    );
    assert!(
        f2(x) <= gf + 1e-7 && (x - gx).abs() < 1e-3,
        "{x} {} vs grid {gx} {gf}",
        f2(x)
    );
    // Random sums: dark and bright pixels, offsets (a specular lobe), saturated pixels; every norm.
    let mut rng = Rng::new(76);
    for trial in 0..90 {
        let norm = [Norm::L1, Norm::L2, Norm::Huber(0.02)][trial % 3];
        let n = [1, 2, 3, 7, 40, 400][trial % 6];
        let truth = 0.2 + rng.uniform();
        let terms: Vec<EncodedTerm> = (0..n)
            .map(|_| {
                let k = 10f64.powf(-3.0 + 3.0 * rng.uniform());
                let o = if rng.uniform() < 0.3 {
                    0.05 * rng.uniform()
                } else {
                    0.0
                };
                term(k, o, (k * truth + o) * (0.7 + 0.6 * rng.uniform()))
            })
            .collect();
        let bounds = (0.0, 3.0);
        let start = rng.uniform() * 3.0;
        let x = encoded_line_min(&terms, norm, 1.0, bounds, start);
        let f = |x: f64| sum(&terms, norm, x);
        let (gx, gf) = grid_min(f, bounds, if n > 10 { 30_000 } else { 300_000 });
        // The sums are of f32 terms: a grid point may find a rounding dip of about 1e-6 of F.
        assert!(
            f(x) <= gf * (1.0 + 1e-5) + 1e-9,
            "trial {trial} {norm:?}: {x} -> {} vs grid {gx} -> {gf}",
            f(x)
        );
        assert!(f(x) <= f(start) && (0.0..=3.0).contains(&x));
    }
}

#[test]
fn refined_srgb_products_minimise_the_srgb_loss() {
    // Ball and floor, a noisy and partly saturated photo: the refined products of the sRGB-space loss
    // are no worse than any on a fine grid around them (each object and channel; a matte scene's
    // unknowns are separable), and better than least squares. The pixels exclude silhouettes, so that
    // the refine's terms are exactly the loss's.
    use rtloop::{Norm, Space};
    let scene = Scene::from_json(
        r#"{"image": {"width": 96, "height": 72},
            "camera": {"position": [0, 1.6, -6], "look_at": [0, 0.8, 0], "vfov_deg": 35},
            "light": {"position": [2.5, 4.5, -1.0], "intensity": 1, "color": [1, 1, 1]},
            "objects": [
              {"name": "ball", "shape": "sphere", "center": [0, 1, 0], "radius": 1,
               "material": {"albedo": [56, 30, 2]}},
              {"name": "floor", "shape": "plane", "point": [0, 0, 0], "normal": [0, 1, 0],
               "material": {"albedo": [20, 20, 5]}}],
            "fit": {"light.position": {"min": [-8, 0.5, -8], "max": [8, 8, 8]},
                    "objects.ball.albedo": {"min": 0, "max": 400},
                    "objects.floor.albedo": {"min": 0, "max": 400}}}"#,
    )
    .unwrap();
    // Intensity 1 and white light: the albedos are the products P = intensity x colour x albedo.
    let ids = rtloop::render::object_ids(&scene, None, None);
    let (w, h) = (96usize, 72usize);
    let interior: Vec<u32> = (0..w * h)
        .filter(|&i| {
            let (x, y) = (i % w, i / w);
            let o = ids[i];
            (x == 0 || ids[i - 1] == o)
                && (x + 1 == w || ids[i + 1] == o)
                && (y == 0 || ids[i - w] == o)
                && (y + 1 == h || ids[i + w] == o)
        })
        .map(|i| i as u32)
        .collect();
    let clean = render(&scene, None, None, 1).unwrap().rgb;
    let mut rng = Rng::new(77);
    let light = scene.light.position.to_vec();
    let want = [[56.0, 30.0, 2.0], [20.0, 20.0, 5.0]];
    for norm in [Norm::L1, Norm::L2, Norm::Huber(0.02)] {
        let target: Vec<f32> = clean
            .iter()
            .map(|&v| {
                let z: f64 = (0..12).map(|_| rng.uniform()).sum::<f64>() - 6.0;
                (v.min(1.0) * (1.0 + 0.1 * z as f32)).clamp(0.0, 1.0)
            })
            .collect();
        let position = ParamLayout::new(&scene, &["light.position".to_string()]).unwrap();
        let mut proj = Fitness::new(
            &scene,
            position,
            &target,
            Some(&interior),
            LossKind::L1Projected,
            true,
            Some(Projection::matte(vec![[(0.0, 400.0); 3]; 2])),
        )
        .unwrap();
        proj.set_norm(norm);
        proj.set_space(Space::Srgb);
        let ls_loss: f64 = proj.channel_losses(&light).iter().sum();
        let (refined, loss) = proj.refined(&light).unwrap();
        let loss: f64 = loss.iter().sum();
        // The same loss as a plain fitness of the products (the albedos here).
        let albedos = ParamLayout::new(
            &scene,
            &[
                "objects.ball.albedo".to_string(),
                "objects.floor.albedo".to_string(),
            ],
        )
        .unwrap();
        let mut plain = Fitness::new(
            &scene,
            albedos,
            &target,
            Some(&interior),
            LossKind::L1,
            true,
            None,
        )
        .unwrap();
        plain.set_norm(norm);
        plain.set_space(Space::Srgb);
        let x: Vec<f64> = refined.products.iter().flatten().copied().collect();
        let at = |x: &[f64]| plain.channel_losses(x).iter().sum::<f64>();
        assert!(
            (at(&x) - loss).abs() < 1e-5 * loss,
            "{norm:?}: {} vs {loss}",
            at(&x)
        );
        assert!(
            loss <= ls_loss,
            "{norm:?}: refined {loss} vs least squares {ls_loss}"
        );
        for j in 0..6 {
            let (gx, gf) = grid_min(
                |v| {
                    let mut y = x.clone();
                    y[j] = v;
                    at(&y)
                },
                (0.9 * x[j], 1.1 * x[j]),
                2000,
            );
            assert!(
                loss <= gf + 1e-6 * loss,
                "{norm:?} product {j}: refined {} -> {loss}, grid {gx} -> {gf}",
                x[j]
            );
        }
        // And the products are right: within the noise.
        for k in 0..2 {
            for c in 0..3 {
                let rel = refined.products[k][c] / want[k][c] - 1.0;
                assert!(rel.abs() < 0.05, "{norm:?}: {:?}", refined.products);
            }
        }
    }
}

/// The projected fitness refuses a scene the closed form does not model, for the reason
/// `projection_blocker` gives (the one decision, which Python's fit asks too).
#[test]
fn projected_fitness_refuses_what_projection_blocker_refuses() {
    let mut rng = Rng::new(11);
    let paths = ["light.position".to_string()];
    for ambient in [false, true] {
        let scene = random_scene(&mut rng, 1, false, ambient);
        let layout = ParamLayout::new(&scene, &paths).unwrap();
        let target = clipped_render(&scene);
        let bounds = vec![[(0.0, 400.0); 3]; scene.objects.len()];
        let why = rtloop::fitness::projection_blocker(&scene, &paths);
        let made = Fitness::new(
            &scene,
            layout,
            &target,
            None,
            LossKind::L1Projected,
            true,
            Some(Projection::matte(bounds)),
        );
        // Ambient light is the closed form's constant column: the blocker allows it, and a projection
        // without that column is refused, naming it.
        assert_eq!(why, None);
        match made {
            Ok(_) => assert!(!ambient),
            Err(e) => assert!(ambient && e.to_string().contains("needs its column"), "{e}"),
        }
    }
}

/// With ambient light the constant column's factor is 1 (no occlusion): at the true light of a clean
/// render the solved products are the truth's, P = exposure x I x albedo and E = exposure x ambient x
/// albedo per object and channel (to float precision), over random scenes.
#[test]
fn ambient_is_the_closed_forms_constant_column() {
    let mut rng = Rng::new(12);
    let paths = ["light.position".to_string()];
    let mut checked = 0;
    for _ in 0..4 {
        let scene = random_scene(&mut rng, 2, false, true);
        assert!(scene.ambient[0] > 0.0);
        let layout = ParamLayout::new(&scene, &paths).unwrap();
        let target: Vec<f32> = render(&scene, None, None, 1).unwrap().rgb; // unclipped: every pixel informs
        let n = scene.objects.len();
        let mut proj = Projection::matte(vec![[(0.0, 1e4); 3]; n]);
        proj.environment = vec![[(0.0, 1e4); 3]; n];
        let f = Fitness::new(
            &scene,
            layout,
            &target,
            None,
            LossKind::L1Projected,
            false,
            Some(proj),
        )
        .unwrap();
        let solved = f.solved(&scene.light.position);
        let ids = rtloop::render::object_ids(&scene, None, None);
        for (k, o) in scene.objects.iter().enumerate() {
            if ids.iter().filter(|&&i| i == k as i32).count() < 50 {
                continue; // (nearly) out of view: too few pixels to solve two columns
            }
            checked += 1;
            for c in 0..3 {
                let p = scene.exposure * scene.light.intensity * o.material.albedo[c];
                let e = scene.exposure * scene.ambient[c] * o.material.albedo[c];
                let (gp, ge) = (solved.products[k][c], solved.environment[k][c]);
                assert!((gp - p).abs() <= 1e-4 * p, "{}: P {gp} vs {p}", o.name);
                assert!((ge - e).abs() <= 1e-4 * p, "{}: E {ge} vs {e}", o.name);
            }
        }
    }
    assert!(checked >= 6, "only {checked} objects in view");
}

/// The scalar paths (`rtloop::fitness::scalar_paths`, as `RTLOOP_SIMD=scalar` forces everywhere) against
/// the AVX2 ones this CPU picks: direct and closed-form losses, linear and sRGB, every norm. They differ
/// only in the intrinsics loops (fused multiply-adds in the dot products and the normal equations), so
/// the sums over ~7000 pixels agree to 1e-5 relative;
/// the shadow tests and everything else compile to the same arithmetic (Rust never contracts to FMA).
#[test]
fn scalar_and_avx2_paths_agree() {
    use rtloop::fitness::{scalar_paths, simd_path};
    use rtloop::{Norm, Space};
    let cpu_avx2 = std::env::var("RTLOOP_SIMD").map_or(true, |v| v != "scalar")
        && cfg!(target_arch = "x86_64")
        && is_avx2_fma();
    assert_eq!(simd_path(), if cpu_avx2 { "avx2" } else { "scalar" });
    assert_eq!(scalar_paths(simd_path), "scalar");
    assert_eq!(simd_path(), if cpu_avx2 { "avx2" } else { "scalar" });
    let mut rng = Rng::new(16);
    let (mut cases, mut identical) = (0, 0);
    for trial in 0..6 {
        // The matte closed form refuses a specular term and ambient light: those trials are direct only.
        let (specular, ambient) = (trial % 2 == 1, trial == 2);
        let scene = random_scene(&mut rng, 1 + trial % 3, specular, ambient);
        let target = clipped_render(&scene);
        let layout = ParamLayout::all(&scene);
        let direct = fitness(&scene, &layout, &target, LossKind::L1PerChannel, true);
        let light = ParamLayout::new(&scene, &["light.position".to_string()]).unwrap();
        let mut fits = vec![(direct, &layout)];
        if !specular && !ambient {
            let bounds = vec![[(0.0, 200.0); 3]; scene.objects.len()];
            let solved = projected(
                &scene,
                light.clone(),
                &target,
                Projection::matte(bounds),
                true,
            );
            fits.push((solved, &light));
        }
        for (mut f, layout) in fits {
            for space in [Space::Linear, Space::Srgb] {
                for norm in [Norm::L1, Norm::L2, Norm::Huber(0.01)] {
                    f.set_space(space);
                    f.set_norm(norm);
                    for _ in 0..2 {
                        let x = random_candidate(&mut rng, layout);
                        let fast = f.channel_losses(&x);
                        let slow = scalar_paths(|| f.channel_losses(&x));
                        for c in 0..3 {
                            assert!(
                                close(fast[c], slow[c], 1e-5),
                                "trial {trial} {space:?} {norm:?}: {fast:?} vs {slow:?}"
                            );
                        }
                        identical += usize::from(fast == slow);
                        cases += 1;
                    }
                }
            }
        }
    }
    assert_eq!(cases, (6 + 2) * 2 * 3 * 2);
    eprintln!(
        "scalar vs {}: {identical} of {cases} bit for bit",
        simd_path()
    );
}

fn is_avx2_fma() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        std::arch::is_x86_feature_detected!("avx2") && std::arch::is_x86_feature_detected!("fma")
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}

/// A ball resting on the floor with a second, smaller ball in its shadow, under `light` (a point light's
/// position, or a directional light's direction with `sun`).
/// `Fitness::with_pixel_footprint` or `Fitness::new`, as `footprint` says.
#[allow(clippy::too_many_arguments)]
fn with_or_without_footprint(
    footprint: bool,
    scene: &Scene,
    layout: &ParamLayout,
    target: &[f32],
    pixels: Option<&[u32]>,
    kind: LossKind,
    clip: bool,
    proj: Option<Projection>,
) -> Fitness {
    let ctor = if footprint {
        Fitness::with_pixel_footprint
    } else {
        Fitness::new
    };
    ctor(scene, layout.clone(), target, pixels, kind, clip, proj).unwrap()
}

fn edge_scene(light: [f64; 3], sun: bool) -> Scene {
    let light = if sun {
        format!(
            r#""type": "directional", "direction": [{}, {}, {}], "intensity": 3"#,
            light[0], light[1], light[2]
        )
    } else {
        format!(
            r#""position": [{}, {}, {}], "intensity": 40"#,
            light[0], light[1], light[2]
        )
    };
    Scene::from_json(&format!(
        r#"{{"image": {{"width": 96, "height": 72}},
            "camera": {{"position": [0.3, 2.2, -5.5], "look_at": [0, 0.4, 0], "vfov_deg": 38}},
            "light": {{{light}}},
            "objects": [
              {{"name": "big", "shape": "sphere", "center": [0, 0.6, 0], "radius": 0.6,
                "material": {{"albedo": [0.8, 0.5, 0.3]}}}},
              {{"name": "small", "shape": "sphere", "center": [-1.0, 0.3, 0.4], "radius": 0.3,
                "material": {{"albedo": [0.3, 0.6, 0.8]}}}},
              {{"name": "floor", "shape": "plane", "point": [0, 0, 0], "normal": [0, 1, 0],
                "material": {{"albedo": [0.6, 0.6, 0.6]}}}}],
            "fit": {{"{}": {{"min": -9, "max": 9}}}}}}"#,
        if sun {
            "light.direction"
        } else {
            "light.position"
        }
    ))
    .unwrap()
}

#[test]
fn pixel_footprint_matches_a_supersampled_render_at_shadow_edges_and_terminators() {
    // The reference integrates every pixel by brute force (a 32 x 32 grid of camera rays, the renderer's
    // own shading per ray); the footprint kernel integrates only where an edge crosses a pixel, in
    // closed form. Compared on the pixels where the two differ from the pixel-centre render by more than
    // 1 %, away from silhouettes (which the footprint does not integrate).
    for (light, sun) in [
        ([2.5, 2.2, 0.8], false),
        ([1.8, 4.0, -1.5], false),
        ([0.7, 0.5, 0.2], true),
    ] {
        let scene = edge_scene(light, sun);
        let (w, h) = (scene.width as usize, scene.height as usize);
        let fine = render(&scene, None, None, 1024).unwrap().rgb;
        let centre = render(&scene, None, None, 1).unwrap().rgb;
        let ids = rtloop::render::object_ids(&scene, None, None);
        let near_silhouette = |i: usize| {
            let (x, y) = ((i % w) as i64, (i / w) as i64);
            (-1..=1).any(|dy| {
                (-1..=1).any(|dx| {
                    let (u, v) = (x + dx, y + dy);
                    u >= 0
                        && v >= 0
                        && (u as usize) < w
                        && (v as usize) < h
                        && ids[v as usize * w + u as usize] != ids[i]
                })
            })
        };
        let edges: Vec<u32> = (0..w * h)
            .filter(|&i| {
                let d = (0..3)
                    .map(|c| (fine[3 * i + c] - centre[3 * i + c]).abs())
                    .fold(0.0f32, f32::max);
                ids[i] >= 0
                    && !near_silhouette(i)
                    && d > 0.01 * fine[3 * i..3 * i + 3].iter().sum::<f32>() / 3.0 + 1e-4
            })
            .map(|i| i as u32)
            .collect();
        assert!(
            edges.len() > 40,
            "{light:?}: only {} edge pixels",
            edges.len()
        );
        let path = if sun {
            "light.direction"
        } else {
            "light.position"
        };
        let layout = ParamLayout::new(&scene, &[path.to_string()]).unwrap();
        let x = if sun {
            light.to_vec()
        } else {
            scene.light.position.to_vec()
        };
        let err = |f: Fitness| f.channel_losses(&x).iter().sum::<f64>() / (3 * edges.len()) as f64;
        let make = |footprint: bool| {
            with_or_without_footprint(
                footprint,
                &scene,
                &layout,
                &fine,
                Some(&edges),
                LossKind::L1,
                false,
                None,
            )
        };
        let (with, without) = (err(make(true)), err(make(false)));
        let mean: f64 = edges
            .iter()
            .map(|&i| fine[3 * i as usize..3 * i as usize + 3].iter().sum::<f32>() as f64 / 3.0)
            .sum::<f64>()
            / edges.len() as f64;
        eprintln!(
            "{light:?}: footprint {with:.5}, pixel centres {without:.5}, mean edge pixel {mean:.4}"
        );
        assert!(
            with < 0.1 * without,
            "{light:?}: footprint error {with:.5}, pixel centres {without:.5}, mean edge pixel {mean:.4}"
        );
    }
}

#[test]
fn footprint_render_is_what_the_footprint_fitness_models() {
    // The renderer (`shade_pixel`, pixel by pixel) and the kernel (blocked, with its cheap edge bound)
    // call the same footprint formulas: at the true scene the loss against the footprint render vanishes.
    for (light, sun) in [([2.5, 2.2, 0.8], false), ([0.7, 0.5, 0.2], true)] {
        let scene = edge_scene(light, sun);
        let target = rtloop::render::render_with(&scene, None, None, 1, true)
            .unwrap()
            .rgb;
        let path = if sun {
            "light.direction"
        } else {
            "light.position"
        };
        let layout = ParamLayout::new(&scene, &[path.to_string()]).unwrap();
        let x = if sun {
            light.to_vec()
        } else {
            scene.light.position.to_vec()
        };
        let f =
            Fitness::with_pixel_footprint(&scene, layout, &target, None, LossKind::L1, false, None)
                .unwrap();
        let loss: f64 = f.channel_losses(&x).iter().sum();
        let total: f64 = target.iter().map(|&v| v as f64).sum();
        assert!(loss < 1e-5 * total, "{light:?}: {loss} against {total}");
        // ... and differs from the centre render there.
        let centre = render(&scene, None, None, 1).unwrap().rgb;
        let moved: f64 = centre
            .iter()
            .zip(&target)
            .map(|(a, b)| (a - b).abs() as f64)
            .sum();
        assert!(moved > 100.0 * loss.max(1e-9), "{light:?}: {moved}");
    }
}

#[test]
fn a_footprint_fitness_at_pixel_centres_is_the_plain_fitness_bit_for_bit() {
    // The default fit searches with `at_pixel_centres()` of the fitness its polish takes (one set-up for
    // both models): it must be the fitness `new` builds, on every loss the fit uses, point and
    // directional light, with the closed-form products. The footprint fitness itself differs (the test
    // can fail both ways).
    let mut rng = Rng::new(17);
    for sun in [false, true] {
        let scene = edge_scene(
            if sun {
                [0.7, 0.5, 0.2]
            } else {
                [2.5, 2.2, 0.8]
            },
            sun,
        );
        let path = if sun {
            "light.direction"
        } else {
            "light.position"
        };
        let layout = ParamLayout::new(&scene, &[path.to_string()]).unwrap();
        let target = clipped_render(&edge_scene(
            if sun {
                [0.6, 0.55, 0.25]
            } else {
                [2.2, 2.5, 0.6]
            },
            sun,
        ));
        let proj = Projection::matte(vec![[(0.0, 50.0); 3]; scene.objects.len()]);
        for (kind, proj) in [(LossKind::L1, None), (LossKind::L1Projected, Some(proj))] {
            let make = |footprint: bool| {
                with_or_without_footprint(
                    footprint,
                    &scene,
                    &layout,
                    &target,
                    None,
                    kind,
                    true,
                    proj.clone(),
                )
            };
            let (plain, fine) = (make(false), make(true));
            let centres = fine.at_pixel_centres();
            let mut differs = false;
            for _ in 0..20 {
                let x = random_candidate(&mut rng, &layout);
                let (mut a, mut b, mut c) = ([0.0], [0.0], [0.0]);
                plain.evaluate(&x, &mut a);
                centres.evaluate(&x, &mut b);
                fine.evaluate(&x, &mut c);
                assert_eq!(a[0].to_bits(), b[0].to_bits(), "{kind:?} sun {sun}: {x:?}");
                differs |= a[0] != c[0];
            }
            assert!(differs, "{kind:?} sun {sun}: the footprint changed no loss");
        }
    }
}

/// With interreflection the search ranks lights with the bounce held (`Fitness::freeze_bounce`): a polish's
/// lone candidate spreads its pixels over the pool, and must give the population path's value bit for bit
/// on any number of threads; a bound below the value may stop the serial sum (above the bound), a bound
/// above it may not change it.
#[test]
fn held_bounce_alone_gives_the_serial_value_on_any_thread_count() {
    let mut rng = Rng::new(23);
    for spheres in [1, 2] {
        let mut scene = random_scene(&mut rng, spheres, false, false);
        scene.interreflection = true;
        let target = clipped_render(&scene);
        let layout = ParamLayout::new(&scene, &["light.position".to_string()]).unwrap();
        let bounds = vec![[(0.0, 200.0); 3]; scene.objects.len()];
        let mut f = projected(
            &scene,
            layout.clone(),
            &target,
            Projection::matte(bounds),
            true,
        );
        assert!(f.freeze_bounce(None), "a bounce to hold");
        let mut xs: Vec<Vec<f64>> = (0..4)
            .map(|_| random_candidate(&mut rng, &layout))
            .collect();
        xs.push(scene.light.position.to_vec());
        for x in &xs {
            let mut serial = [0.0];
            f.evaluate(x, &mut serial);
            assert!(serial[0].is_finite() && serial[0] >= 0.0);
            for threads in [1, 2, 3] {
                let pool = rayon::ThreadPoolBuilder::new()
                    .num_threads(threads)
                    .build()
                    .unwrap();
                let mut alone = [0.0];
                pool.install(|| f.evaluate_alone(x, &mut alone));
                assert_eq!(serial[0].to_bits(), alone[0].to_bits(), "threads={threads}");
            }
            let mut above = [0.0];
            f.evaluate_bounded(x, &mut above, serial[0] * 1.5 + 1.0);
            assert_eq!(above[0].to_bits(), serial[0].to_bits());
            let mut below = [0.0];
            f.evaluate_bounded(x, &mut below, serial[0] * 0.5);
            assert!(below[0] > serial[0] * 0.5 && below[0] <= serial[0] * (1.0 + 1e-12));
        }
    }
}

/// `interior_by`: margin 0 is the 4-neighbour test (`interior`); margin m keeps exactly the pixels whose
/// (2m + 1)^2 neighbourhood (inside the image) shows their own object. A fitness built with a margin
/// solves the same products from a clean render at the truth (fewer pixels, none of them mixed).
#[test]
fn solve_margin_keeps_the_pixels_whose_neighbourhood_shows_their_object() {
    use rtloop::fitness::{interior, interior_by};
    let mut rng = Rng::new(12);
    let scene = random_scene(&mut rng, 2, false, false);
    let g = rtloop::render::GBuffer::new(
        &rtloop::render::Geometry::new(&scene),
        scene.width,
        scene.height,
    );
    let ids = rtloop::render::object_ids(&scene, None, None);
    let (w, h) = (scene.width as i64, scene.height as i64);
    let mut dropped = 0;
    for i in 0..(w * h) as usize {
        assert_eq!(interior_by(&g, i, 0), interior(&g, i), "pixel {i}");
        let (x, y) = (i as i64 % w, i as i64 / w);
        for m in [1i64, 2] {
            let want = (-m..=m).all(|dy| {
                (-m..=m).all(|dx| {
                    let (xx, yy) = (x + dx, y + dy);
                    xx < 0 || yy < 0 || xx >= w || yy >= h || ids[(yy * w + xx) as usize] == ids[i]
                })
            });
            assert_eq!(
                interior_by(&g, i, m as usize),
                want,
                "pixel {i}, margin {m}"
            );
            dropped += usize::from(m == 2 && interior(&g, i) && !want);
        }
    }
    assert!(dropped > 0, "the case needs silhouettes");
    let bounds = serde_json::json!({"min": [-6, 0.5, -6], "max": [6, 8, 6]});
    let scene = scene
        .without_fit()
        .with_bounds(&[("light.position".to_string(), bounds)])
        .unwrap();
    let layout = ParamLayout::new(&scene, &["light.position".to_string()]).unwrap();
    let target = render(&scene, None, None, 1).unwrap().rgb;
    let n = scene.objects.len();
    let proj = Projection::matte(vec![[(0.0, 1e4); 3]; n]);
    let truth = scene.light.position;
    let lit: Vec<bool> = (0..n)
        .map(|k| {
            (0..(w * h) as usize).any(|i| {
                ids[i] == k as i32
                    && interior_by(&g, i, 2)
                    && target[3 * i..][..3].iter().any(|v| *v > 0.0)
            })
        })
        .collect();
    assert!(
        lit.iter().filter(|&&l| l).count() >= 2,
        "the case needs two lit objects"
    );
    // margin 40: no pixel of the 96 x 72 image passes: every object falls back to its 4-neighbour interior
    for margin in [0, 2, 40] {
        let f = Fitness::with_solve_margin(
            &scene,
            layout.clone(),
            &target,
            None,
            LossKind::L1Projected,
            false,
            Some(proj.clone()),
            false,
            margin,
        )
        .unwrap();
        let solved = f.solved(&truth);
        for (k, o) in scene.objects.iter().enumerate().filter(|(k, _)| lit[*k]) {
            for c in 0..3 {
                let p = scene.exposure
                    * scene.light.intensity
                    * scene.light.color[c]
                    * o.material.albedo[c];
                let got = solved.products[k][c];
                assert!(
                    (got - p).abs() <= 1e-4 * p,
                    "margin {margin}, object {k}, channel {c}: {got} vs {p}"
                );
            }
        }
    }
}

/// `refined` where the bounce was last held (`freeze_bounce` at that candidate, which keeps its full fixed
/// point for it) gives the bits a fresh fitness computes there, and so does `refined` elsewhere and after a
/// setting that changes the loss (which drops the kept solve).
#[test]
fn refined_where_the_bounce_is_held_is_the_fresh_solve() {
    let mut rng = Rng::new(29);
    for k in 0..3 {
        let (scene, target, layout) = bounce_case(&mut rng, k);
        let (x, y) = (
            random_candidate(&mut rng, &layout),
            random_candidate(&mut rng, &layout),
        );
        for footprint in [false, true] {
            let build = || bounce_fitness(&scene, &layout, &target, footprint);
            let bits = |f: &Fitness, x: &[f64]| {
                let (solved, loss) = f.refined(x).unwrap();
                let mut b: Vec<u64> = loss.iter().map(|v| v.to_bits()).collect();
                b.extend(solved.products.iter().flatten().map(|v| v.to_bits()));
                b.push(solved.gauge.unwrap().to_bits());
                b.extend(solved.lit.iter().map(|&v| v as u64));
                b
            };
            let fresh = build();
            let mut held = build();
            assert!(held.freeze_bounce(Some(&x)));
            assert_eq!(
                bits(&held, &x),
                bits(&fresh, &x),
                "scene {k}, footprint {footprint}, at the hold"
            );
            assert_eq!(
                bits(&held, &y),
                bits(&fresh, &y),
                "scene {k}, footprint {footprint}, elsewhere"
            );
            let (mut fresh, mut held) = (fresh, held);
            fresh.set_norm(Norm::L2);
            held.set_norm(Norm::L2);
            assert_eq!(
                bits(&held, &x),
                bits(&fresh, &x),
                "scene {k}, footprint {footprint}, L2 after the hold"
            );
        }
    }
}
