//! The held bounce and the solve margin.

use super::*;

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
        let mut f = matte_projected(&scene, layout.clone(), &target, true);
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
                let alone = alone_on(&f, x, threads);
                assert_eq!(serial[0].to_bits(), alone.to_bits(), "threads={threads}");
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
        let f = Fitness::new(
            &scene,
            layout.clone(),
            &target,
            FitnessSpec {
                loss: LossKind::L1Projected,
                clip: false,
                projection: Some(proj.clone()),
                solve_margin: margin,
                ..Default::default()
            },
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
