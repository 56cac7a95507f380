//! The fused kernel against the plain per-pixel path: random scenes, thread counts, the bounce fitness, lights inside occluders, the early exit, every norm, directional lights.

use super::*;

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
                // Shadow-boundary pixels may flip between the two shadow tests; each flip moves a sum of
                // ~thousands of terms by at most one pixel value.
                assert_matches_reference(&f, &x, (2e-3, 0.0), &format!("trial {trial} {kind:?}"));
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
        assert_matches_reference(&f, &x, (1e-5, 0.0), "candidate");
    }
}

#[test]
fn projected_kernel_matches_the_plain_solve() {
    let mut rng = Rng::new(5);
    for trial in 0..12 {
        let scene = random_scene(&mut rng, 1 + trial % 3, false, false);
        let target: Vec<f32> = clipped_render(&scene);
        let layout = ParamLayout::new(&scene, &["light.position".to_string()]).unwrap();
        let f = matte_projected(&scene, layout.clone(), &target, true);
        for _ in 0..6 {
            let x = random_candidate(&mut rng, &layout);
            assert_matches_reference(&f, &x, (2e-3, 0.0), &format!("trial {trial}"));
        }
        // At the true light the projected loss vanishes (up to float rounding).
        let truth: Vec<f64> = scene.light.position.to_vec();
        eprintln!(
            "trial {trial}: at truth ref {:?} products {:?} light {:?} objs {:?}",
            f.reference_channel_losses(&truth),
            f.products(&truth),
            scene.light.position,
            scene
                .objects
                .iter()
                .map(|o| o.shape.clone())
                .collect::<Vec<_>>()
        );
        let pixels = (scene.width * scene.height) as f64;
        loss_at_truth(&f, &truth, 1e-5 * pixels, &format!("trial {trial}"));
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
            let f = matte_projected(scene, layout.clone(), &target, true);
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
                    let alone = alone_on(&f, x, threads);
                    assert_eq!(
                        serial[0].to_bits(),
                        alone.to_bits(),
                        "{space:?} threads={threads} x={x:?}: {} vs {alone}",
                        serial[0],
                    );
                }
            }
        }
    }
}

/// A random scene of one or two spheres (`k` odd: two) with interreflection, its clipped render and the
/// light's position as the searched parameters.
pub(crate) fn bounce_case(rng: &mut Rng, k: usize) -> (Scene, Vec<f32>, ParamLayout) {
    let mut scene = random_scene(rng, 1 + k % 2, false, false);
    scene.interreflection = true;
    let target = clipped_render(&scene);
    let layout = ParamLayout::new(&scene, &["light.position".to_string()]).unwrap();
    (scene, target, layout)
}

/// The closed-form (matte) fitness of a [`bounce_case`], with or without the pixel footprint.
pub(crate) fn bounce_fitness(
    scene: &Scene,
    layout: &ParamLayout,
    target: &[f32],
    footprint: bool,
) -> Fitness {
    let bounds = vec![[(0.0, 200.0); 3]; scene.objects.len()];
    Fitness::new(
        scene,
        layout.clone(),
        target,
        FitnessSpec {
            loss: LossKind::L1Projected,
            projection: Some(Projection::matte(bounds)),
            footprint,
            ..Default::default()
        },
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
        let target = noisy(&clean, &mut rng, 0.05);
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
pub(crate) fn random_sun_scene(rng: &mut Rng, spheres: usize, specular: bool) -> Scene {
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
            assert_matches_reference(&f, &x, (2e-3, 0.0), &format!("trial {trial}"));
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
