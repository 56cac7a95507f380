//! The pixel footprint against a supersampled render, and at pixel centres against the plain fitness.

use super::*;

/// A ball resting on the floor with a second, smaller ball in its shadow, under `light` (a point light's
/// position, or a directional light's direction with `sun`).
pub(crate) fn edge_scene(light: [f64; 3], sun: bool) -> Scene {
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
        light_path(sun)
    ))
    .unwrap()
}

/// The light's parameter an [`edge_scene`] searches: the direction of a sun, else the position.
fn light_path(sun: bool) -> &'static str {
    if sun {
        "light.direction"
    } else {
        "light.position"
    }
}

/// The layout searching the light of `scene` ([`edge_scene`] of `light` and `sun`) and the light's true
/// value there.
fn searched_light(scene: &Scene, light: [f64; 3], sun: bool) -> (ParamLayout, Vec<f64>) {
    let layout = ParamLayout::new(scene, &[light_path(sun).to_string()]).unwrap();
    let x = if sun {
        light.to_vec()
    } else {
        scene.light.position.to_vec()
    };
    (layout, x)
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
        let (layout, x) = searched_light(&scene, light, sun);
        let err = |f: Fitness| f.channel_losses(&x).iter().sum::<f64>() / (3 * edges.len()) as f64;
        let make = |footprint: bool| {
            let spec = FitnessSpec {
                pixels: Some(edges.clone()),
                clip: false,
                footprint,
                ..Default::default()
            };
            Fitness::new(&scene, layout.clone(), &fine, spec).unwrap()
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
    // The renderer (`Shading::shade`, pixel by pixel) and the kernel (blocked, with its cheap edge bound)
    // call the same footprint formulas: at the true scene the loss against the footprint render vanishes.
    for (light, sun) in [([2.5, 2.2, 0.8], false), ([0.7, 0.5, 0.2], true)] {
        let scene = edge_scene(light, sun);
        let target = rtloop::render::render_with(&scene, None, None, 1, true)
            .unwrap()
            .rgb;
        let (layout, x) = searched_light(&scene, light, sun);
        let f = Fitness::new(
            &scene,
            layout,
            &target,
            FitnessSpec {
                loss: LossKind::L1,
                clip: false,
                footprint: true,
                ..Default::default()
            },
        )
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
        let layout = ParamLayout::new(&scene, &[light_path(sun).to_string()]).unwrap();
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
                let spec = FitnessSpec {
                    loss: kind,
                    projection: proj.clone(),
                    footprint,
                    ..Default::default()
                };
                Fitness::new(&scene, layout.clone(), &target, spec).unwrap()
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

/// The pixels of `ids` (a `w`-wide image) with a 4-neighbour that shows another object or the background.
fn outline_pixels(ids: &[i32], w: usize) -> Vec<usize> {
    let h = ids.len() / w;
    (0..ids.len())
        .filter(|&i| {
            let (x, y) = (i % w, i / w);
            (x > 0 && ids[i - 1] != ids[i])
                || (x + 1 < w && ids[i + 1] != ids[i])
                || (y > 0 && ids[i - w] != ids[i])
                || (y + 1 < h && ids[i + w] != ids[i])
        })
        .collect()
}

#[test]
fn silhouette_pixels_match_a_supersampled_render() {
    // The reference integrates every pixel by brute force (a 32 x 32 grid of camera rays, the renderer's
    // own shading per ray). On the pixels that straddle an outline (ball against floor, ball against
    // ball, the floor's horizon against the background) the footprint render averages a 4 x 4 grid of
    // sub-pixel rays: it must be far nearer the reference than the pixel-centre render, lit from the
    // front, from behind (a rim on the outline) and by a sun.
    for (light, sun) in [
        ([2.5, 2.2, 0.8], false),
        ([0.4, 1.6, 2.4], false),
        ([0.7, 0.5, 0.2], true),
    ] {
        let scene = edge_scene(light, sun);
        let w = scene.width as usize;
        let fine = render(&scene, None, None, 1024).unwrap().rgb;
        let centre = render(&scene, None, None, 1).unwrap().rgb;
        let over = rtloop::render::render_model(&scene, (None, None), 1, true, true)
            .unwrap()
            .rgb;
        let outline = outline_pixels(&rtloop::render::object_ids(&scene, None, None), w);
        assert!(
            outline.len() > 150,
            "{light:?}: {} outline pixels",
            outline.len()
        );
        let err = |img: &[f32]| {
            let sum: f64 = outline
                .iter()
                .flat_map(|&i| (0..3).map(move |c| 3 * i + c))
                .map(|k| (img[k] - fine[k]).abs() as f64)
                .sum();
            sum / (3 * outline.len()) as f64
        };
        let (with, without) = (err(&over), err(&centre));
        eprintln!("{light:?}: outline error {with:.5} with the footprint, {without:.5} at centres");
        assert!(
            with < 0.3 * without,
            "{light:?}: outline error {with:.5} with the footprint, {without:.5} at centres"
        );
    }
}

#[test]
fn the_closed_form_with_silhouettes_models_the_footprint_render() {
    // The projected kernel solves the products on interior pixels and adds the outline pixels' sub-pixel
    // means at them: against the footprint render of the true scene (unclipped) the loss vanishes at the
    // true light, and the silhouettes are part of it (the pixel-centre model's loss is far above).
    let (light, sun) = ([2.5, 2.2, 0.8], false);
    let scene = edge_scene(light, sun);
    let target = rtloop::render::render_model(&scene, (None, None), 1, true, true)
        .unwrap()
        .rgb;
    let (layout, x) = searched_light(&scene, light, sun);
    let f = closed_form_footprint(&scene, layout, &target, (true, false));
    let loss: f64 = f.channel_losses(&x).iter().sum();
    let centres: f64 = f.at_pixel_centres().channel_losses(&x).iter().sum();
    let total: f64 = target.iter().map(|&v| v as f64).sum();
    assert!(loss < 1e-5 * total, "{loss} against {total}");
    assert!(centres > 100.0 * loss.max(1e-9), "{centres} against {loss}");
    let (_, refined) = f.refined(&x).unwrap();
    let refined: f64 = refined.iter().sum();
    assert!(refined < 1e-5 * total, "refined: {refined} against {total}");
}

#[test]
fn the_outline_gain_tells_an_integrated_photo_from_a_pixel_centre_one() {
    // The gate's evidence (`Fitness::outline_gain`, a fitness with the outlines at their centres and their
    // samples beside it) at the true light: against the render with the outlines averaged over their
    // samples, their averaged loss vanishes and their centre loss does not; against the footprint render
    // with the outlines at their centres, the other way round (up to the centre's own footprint, which
    // the gate's centre values leave out).
    let (light, sun) = ([2.5, 2.2, 0.8], false);
    let scene = edge_scene(light, sun);
    let (layout, x) = searched_light(&scene, light, sun);
    let gain = |outlines: bool| {
        let target = rtloop::render::render_model(&scene, (None, None), 1, true, outlines)
            .unwrap()
            .rgb;
        let f = closed_form_footprint(&scene, layout.clone(), &target, (false, true));
        let total: f64 = target.iter().map(|&v| v as f64).sum();
        (f.outline_gain(&x).unwrap(), total)
    };
    let (integrated, total) = gain(true);
    assert!(integrated.pixels > 150, "{integrated:?}");
    assert!(
        integrated.integrated < 1e-5 * total,
        "{integrated:?} against {total}"
    );
    assert!(
        integrated.centres > 100.0 * integrated.integrated.max(1e-9),
        "{integrated:?}"
    );
    assert!(
        integrated.centres <= integrated.loss * (1.0 + 1e-9),
        "{integrated:?}"
    );
    let (centred, _) = gain(false);
    assert!(centred.centres < 0.3 * centred.integrated, "{centred:?}");
}

/// The closed form's fitness (products within 0-50, unclipped) of `layout` of `scene` against `target`,
/// with the footprint, and (`FitnessSpec::outlines`, `FitnessSpec::outline_gate`) as given.
fn closed_form_footprint(
    scene: &Scene,
    layout: ParamLayout,
    target: &[f32],
    (outlines, outline_gate): (bool, bool),
) -> Fitness {
    let projection = Some(Projection::matte(vec![
        [(0.0, 50.0); 3];
        scene.objects.len()
    ]));
    let (loss, clip, footprint) = (LossKind::L1Projected, false, true);
    let spec = FitnessSpec {
        loss,
        projection,
        clip,
        footprint,
        outlines,
        outline_gate,
        ..Default::default()
    };
    Fitness::new(scene, layout, target, spec).unwrap()
}
