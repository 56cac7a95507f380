//! The sRGB loss space: the kernel's table encoding against the exact one, the closed form and the encoded line minimum.

use super::*;

/// The loss-space tests' allowance for the kernel's table encoding against the plain path's exact one:
/// at most 2e-5 per encoded value, so 4e-5 per difference, times the penalty's slope (1 for L1 and
/// Huber, 2|d| for L2), per term.
pub(crate) fn table_allowance(norm: rtloop::Norm, terms: usize, largest: f64) -> f64 {
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
                        let slack = table_allowance(norm, target.len() / 3, 30.0);
                        let what = format!("trial {trial} clip {clip} {norm:?} {kind:?}");
                        assert_matches_reference(&f, &x, (2e-3, slack), &what);
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
        let target = noisy(&render(&scene, None, None, 1).unwrap().rgb, &mut rng, 0.03);
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
                let mut f = matte_projected(&scene, layout.clone(), &target, clip);
                f.set_norm(norm);
                f.set_space(Space::Srgb);
                for _ in 0..3 {
                    let x = random_candidate(&mut rng, &layout);
                    let slack = table_allowance(norm, target.len() / 3, 30.0);
                    let what = format!("trial {trial} clip {clip} {norm:?}");
                    assert_matches_reference(&f, &x, (2e-3, slack), &what);
                }
                // The objective goes through the kernel's own encoding: the model that renders it
                // exactly costs (almost) nothing, in any norm.
                let pixels = (scene.width * scene.height) as f64;
                loss_at_truth(
                    &f,
                    &truth,
                    1e-5 * pixels,
                    &format!("trial {trial} clip {clip} {norm:?}"),
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
        let mut t = glossy_trial(&mut rng);
        t.f.set_space(Space::Srgb);
        for _ in 0..4 {
            let x = random_candidate(&mut rng, &t.layout);
            let slack = table_allowance(rtloop::Norm::L1, t.target.len() / 3, 1.0);
            assert_matches_reference(&t.f, &x, (2e-3, slack), &format!("trial {trial}"));
        }
        let truth = [t.light[0], t.light[1], t.light[2], t.s];
        loss_at_truth(
            &t.f,
            &truth,
            2e-5 * (96 * 72) as f64,
            &format!("trial {trial}"),
        );
        let (refined, _) = t.f.refined(&truth).unwrap();
        assert!(
            (refined.specular[0] / (t.intensity * t.ks) - 1.0).abs() < 1e-3,
            "trial {trial}: Q {:?} vs {}",
            refined.specular,
            t.intensity * t.ks
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
pub(crate) fn grid_min(f: impl Fn(f64) -> f64, (lo, hi): (f64, f64), n: usize) -> (f64, f64) {
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
        // A fitness of `paths` over the interior pixels, in the sRGB space of `norm`.
        let on_interior = |paths: &[&str], loss, projection| {
            let paths: Vec<String> = paths.iter().map(|p| p.to_string()).collect();
            let layout = ParamLayout::new(&scene, &paths).unwrap();
            let pixels = Some(interior.clone());
            let spec = FitnessSpec {
                pixels,
                loss,
                projection,
                ..Default::default()
            };
            let mut f = Fitness::new(&scene, layout, &target, spec).unwrap();
            f.set_norm(norm);
            f.set_space(Space::Srgb);
            f
        };
        let matte = Projection::matte(vec![[(0.0, 400.0); 3]; 2]);
        let proj = on_interior(&["light.position"], LossKind::L1Projected, Some(matte));
        let ls_loss: f64 = proj.channel_losses(&light).iter().sum();
        let (refined, loss) = proj.refined(&light).unwrap();
        let loss: f64 = loss.iter().sum();
        // The same loss as a plain fitness of the products (the albedos here).
        let albedos = ["objects.ball.albedo", "objects.floor.albedo"];
        let plain = on_interior(&albedos, LossKind::L1, None);
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
