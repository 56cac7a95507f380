//! `cargo bench --bench passes`: one whole bounce fit through the core's pass driver
//! (`rtloop::fit::run_passes`; the scene and budget of tests/common/bounce_fit.rs), on all threads.

#[path = "../tests/common/bounce_fit.rs"]
mod bounce_fit;

use bounce_fit::{bounce_fit, bounce_scene, clipped};
use criterion::{criterion_group, criterion_main, Criterion};

fn bench(c: &mut Criterion) {
    let scene = bounce_scene();
    let target = clipped(&scene);
    let mut g = c.benchmark_group("passes");
    g.sample_size(10);
    g.bench_function("bounce fit 3 passes", |b| {
        b.iter(|| bounce_fit(&scene, &target, |_| true))
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
