//! `cargo bench`: one 128x96 render, and one DE population (60 candidates) of the stage-1 fitness,
//! on the paper's sphere-on-floor scene (the example shipped in `examples/yellow-ball`).

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use rayon::prelude::*;
use rtloop::{de::Objective, render, Fitness, LossKind, ParamLayout, Scene};

fn scene() -> Scene {
    let text = std::fs::read_to_string(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/examples/yellow-ball/scene.json"
    ))
    .expect("examples/yellow-ball/scene.json");
    Scene::from_json(&text).expect("valid example scene")
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

    // Stage-1 fitness: light position + intensity against the whole image.
    let target = render(&scene, None, None, 1).unwrap().rgb;
    let paths = vec!["light.position".to_string(), "light.intensity".to_string()];
    let layout = ParamLayout::new(&scene, &paths).unwrap();
    let fitness = Fitness::new(
        &scene,
        layout.clone(),
        &target,
        None,
        LossKind::L1,
        true,
        None,
    )
    .unwrap();
    let mut rng = rtloop::de::Rng::new(1);
    let population: Vec<Vec<f64>> = (0..60)
        .map(|_| {
            layout
                .bounds
                .iter()
                .map(|&(lo, hi)| lo + (hi - lo) * rng.uniform())
                .collect()
        })
        .collect();
    let mut out = vec![0.0; 60];
    let mut g = c.benchmark_group("population");
    g.throughput(Throughput::Elements(60 * pixels)); // candidate-pixels
    for threads in [1, rayon::current_num_threads()] {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        g.bench_function(format!("60 candidates stage1 threads={threads}"), |b| {
            b.iter(|| {
                pool.install(|| {
                    out.par_iter_mut()
                        .zip(population.par_iter())
                        .for_each(|(o, x)| {
                            fitness.evaluate(x, std::slice::from_mut(o));
                        })
                })
            })
        });
    }
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
