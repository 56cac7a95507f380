//! `cargo bench`: one 128x96 render; one DE population (60 candidates) of the stage-1 fitness and of the
//! default method's projected fitness, on 1 thread and on all threads, with the loss in linear space and
//! (`srgb`) in sRGB space; ten polish candidates of the projected fitness with the sphere glossy (its
//! Blinn-Phong lobe solved in closed form); the bounce's full fixed point and ten candidates with it held
//! (the scene with interreflection); and a whole stage-1 DE run
//! (the paper's 60 x 200) with and without early exit. Scene: the paper's sphere on a floor
//! (`examples/yellow-ball/scene.json`); objective: its own render, saturated at 1.
//!
//! Throughput is printed in elements/s where an element is one candidate-pixel (CPPS).

#[path = "../tests/common/targets.rs"]
mod targets;

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use rayon::prelude::*;
use rtloop::{
    render, search, search::Objective, DeConfig, Fitness, FitnessSpec, LossKind, ParamLayout,
    Projection, Scene, Space,
};
use targets::{clipped_render, random_candidate};

fn scene() -> Scene {
    let path = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/examples/yellow-ball/scene.json"
    );
    let text = std::fs::read_to_string(path).expect("examples/yellow-ball/scene.json");
    Scene::from_json(&text).expect("valid example scene")
}

fn population(layout: &ParamLayout, n: usize) -> Vec<Vec<f64>> {
    let mut rng = search::Rng::new(1);
    (0..n).map(|_| random_candidate(&mut rng, layout)).collect()
}

/// The fitness of `layout` against `target`: loss `loss`, closed-form products bounded by `projection`.
fn fitness_of(
    scene: &Scene,
    layout: &ParamLayout,
    target: &[f32],
    loss: LossKind,
    projection: Option<Projection>,
) -> Fitness {
    let spec = FitnessSpec {
        loss,
        projection,
        ..Default::default()
    };
    Fitness::new(scene, layout.clone(), target, spec).unwrap()
}

/// A pool of one thread and one of every core, each with its thread count.
fn pools() -> Vec<(usize, rayon::ThreadPool)> {
    [1, rayon::current_num_threads()]
        .into_iter()
        .map(|threads| {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap();
            (threads, pool)
        })
        .collect()
}

/// Ten candidates of `fitness` at `x` in a row inside `pool` (of `threads`), as the polish runs them.
fn ten_alone(
    g: &mut criterion::BenchmarkGroup<'_, criterion::measurement::WallTime>,
    pool: &rayon::ThreadPool,
    threads: usize,
    fitness: &Fitness,
    x: &[f64],
) {
    g.bench_function(
        format!("10 candidates alone projected threads={threads}"),
        |b| {
            b.iter(|| {
                pool.install(|| {
                    let mut o = [0.0];
                    for _ in 0..10 {
                        fitness.evaluate_alone(x, &mut o);
                    }
                    o
                })
            })
        },
    );
}

fn bench(c: &mut Criterion) {
    let scene = scene();
    let pixels = (scene.width * scene.height) as u64;
    let mut g = c.benchmark_group("render");
    g.throughput(Throughput::Elements(pixels));
    g.bench_function("128x96 spp1", |b| {
        b.iter(|| render(&scene, None, None, 1).unwrap())
    });
    g.finish();

    let target = clipped_render(&scene);
    let stage1 = vec!["light.position".to_string(), "light.intensity".to_string()];
    let position = vec!["light.position".to_string()];
    let bounds = vec![[(0.0, 400.0); 3]; scene.objects.len()];
    // Each loss in linear light, then in sRGB.
    let losses = [
        ("stage1 l1", &stage1, LossKind::L1, None),
        (
            "projected",
            &position,
            LossKind::L1Projected,
            Some(Projection::matte(bounds)),
        ),
    ];
    let at = &scene;
    let cases: Vec<_> = [(Space::Linear, ""), (Space::Srgb, " srgb")]
        .into_iter()
        .flat_map(|(space, suffix)| {
            losses.iter().map(move |(name, paths, kind, pb)| {
                let layout = ParamLayout::new(at, paths).unwrap();
                (format!("{name}{suffix}"), layout, *kind, pb.clone(), space)
            })
        })
        .collect();
    let mut g = c.benchmark_group("population");
    g.throughput(Throughput::Elements(60 * pixels));
    for (name, layout, kind, pb, space) in &cases {
        let mut fitness = fitness_of(&scene, layout, &target, *kind, pb.clone());
        fitness.set_space(*space);
        let pop = population(layout, 60);
        let mut out = vec![0.0; 60];
        for (threads, pool) in pools() {
            g.bench_function(format!("60 candidates {name} threads={threads}"), |b| {
                b.iter(|| {
                    pool.install(|| {
                        out.par_iter_mut().zip(pop.par_iter()).for_each(|(o, x)| {
                            fitness.evaluate(x, std::slice::from_mut(o));
                        })
                    })
                })
            });
        }
    }
    g.finish();

    // What one fit pays once, whatever its budget: building the projected fitness (primary rays, the
    // per-object pixel groups) and the loss-minimising products at the end; and one candidate alone, as the
    // polish evaluates them.
    let mut g = c.benchmark_group("fixed");
    let layout = ParamLayout::new(&scene, &position).unwrap();
    let matte = Projection::matte(vec![[(0.0, 400.0); 3]; scene.objects.len()]);
    let projected = || {
        fitness_of(
            &scene,
            &layout,
            &target,
            LossKind::L1Projected,
            Some(matte.clone()),
        )
    };
    g.bench_function("projected fitness new", |b| b.iter(projected));
    let fitness = projected();
    let truth = scene.light.position.to_vec();
    g.bench_function("refined products", |b| b.iter(|| fitness.refined(&truth)));
    for (threads, pool) in pools() {
        g.bench_function(format!("one candidate projected threads={threads}"), |b| {
            b.iter(|| {
                pool.install(|| {
                    let mut o = [0.0];
                    fitness.evaluate(&truth, &mut o);
                    o
                })
            })
        });
        ten_alone(&mut g, &pool, threads, &fitness, &truth);
    }
    g.finish();

    // With the footprint and the outlines (`FitnessSpec::footprint`, `FitnessSpec::outlines`, as a fit whose
    // outline gate fires): shadow edges, terminators and outline pixels over each pixel's area; one
    // candidate as the polish evaluates it, and the set-up.
    let mut g = c.benchmark_group("footprint");
    let with_footprint = || {
        Fitness::new(
            &scene,
            layout.clone(),
            &target,
            FitnessSpec {
                loss: LossKind::L1Projected,
                projection: Some(matte.clone()),
                footprint: true,
                outlines: true,
                ..Default::default()
            },
        )
        .unwrap()
    };
    g.bench_function("projected fitness new footprint", |b| {
        b.iter(with_footprint)
    });
    let fitness = with_footprint();
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .unwrap();
    g.bench_function("one candidate projected footprint threads=1", |b| {
        b.iter(|| {
            pool.install(|| {
                let mut o = [0.0];
                fitness.evaluate(&truth, &mut o);
                o
            })
        })
    });
    g.finish();

    // The same sphere glossy (specular 0.3, shininess 40) against its own render: the closed form then
    // solves the lobe's strength too, and every candidate shades the lobe on the sphere's pixels.
    let mut g = c.benchmark_group("glossy");
    let mut glossy = scene.clone();
    let ball = glossy
        .objects
        .iter()
        .position(|o| matches!(o.shape, rtloop::scene::Shape::Sphere { .. }))
        .expect("the example has a sphere");
    glossy.objects[ball].material.specular = 0.3;
    glossy.objects[ball].material.shininess = 40.0;
    let glossy_target = clipped_render(&glossy);
    let mut lobe = Projection::matte(vec![[(0.0, 400.0); 3]; glossy.objects.len()]);
    lobe.specular[ball] = (0.0, 400.0);
    let fitness = fitness_of(
        &glossy,
        &layout,
        &glossy_target,
        LossKind::L1Projected,
        Some(lobe),
    );
    let truth = glossy.light.position.to_vec();
    for (threads, pool) in pools() {
        ten_alone(&mut g, &pool, threads, &fitness, &truth);
    }
    g.finish();

    // The same scene with one diffuse bounce (the floor lighting the sphere's underside): the bounce's full
    // fixed point, which a fit solves where each held pass starts and at its result, alone and with the
    // loss-minimising products; and ten polish candidates with the bounce held there.
    let mut g = c.benchmark_group("bounce");
    let mut bounced = scene.clone();
    bounced.interreflection = true;
    let bounced_target = clipped_render(&bounced);
    let matte = Projection::matte(vec![[(0.0, 400.0); 3]; bounced.objects.len()]);
    let mut fitness = fitness_of(
        &bounced,
        &layout,
        &bounced_target,
        LossKind::L1Projected,
        Some(matte),
    );
    let truth = bounced.light.position.to_vec();
    let near: Vec<f64> = truth.iter().map(|v| v + 0.01).collect();
    for (threads, pool) in pools() {
        g.bench_function(format!("full fixed point threads={threads}"), |b| {
            b.iter(|| pool.install(|| fitness.freeze_bounce(Some(&near))))
        });
        pool.install(|| fitness.freeze_bounce(Some(&truth)));
        g.bench_function(format!("refined products threads={threads}"), |b| {
            b.iter(|| pool.install(|| fitness.refined(&near)))
        });
        ten_alone(&mut g, &pool, threads, &fitness, &near);
    }
    g.finish();

    let mut g = c.benchmark_group("de");
    g.sample_size(10);
    let layout = ParamLayout::new(&scene, &stage1).unwrap();
    for early in [false, true] {
        let mut fitness = fitness_of(&scene, &layout, &target, LossKind::L1, None);
        fitness.early_exit = early;
        let cfg = DeConfig {
            population: 60,
            generations: 200,
            f: 0.6,
            cr: 0.8,
            seed: 1,
        };
        g.bench_function(format!("paper stage1 60x200 early_exit={early}"), |b| {
            b.iter(|| search::rand1bin::minimize(&fitness, &layout.bounds, &cfg, |_| true).unwrap())
        });
    }
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
