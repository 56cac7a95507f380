//! `cargo bench --bench mesh`: BVH build and single-thread traversal on a 20480-triangle icosphere
//! (camera rays: nearest hit; shadow rays: any hit). Throughput in elements/s: one element is one ray.

use std::collections::HashMap;

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use glam::{DVec3, Vec3A};
use rtloop::geometry::mesh::Mesh;

/// The unit icosphere subdivided `levels` times (20·4^levels triangles).
fn icosphere(levels: u32) -> Vec<[DVec3; 3]> {
    let t = (1.0 + 5f64.sqrt()) / 2.0;
    let mut v: Vec<DVec3> = [
        (-1.0, t, 0.0),
        (1.0, t, 0.0),
        (-1.0, -t, 0.0),
        (1.0, -t, 0.0),
        (0.0, -1.0, t),
        (0.0, 1.0, t),
        (0.0, -1.0, -t),
        (0.0, 1.0, -t),
        (t, 0.0, -1.0),
        (t, 0.0, 1.0),
        (-t, 0.0, -1.0),
        (-t, 0.0, 1.0),
    ]
    .iter()
    .map(|&(x, y, z)| DVec3::new(x, y, z).normalize())
    .collect();
    let mut f: Vec<[usize; 3]> = vec![
        [0, 11, 5],
        [0, 5, 1],
        [0, 1, 7],
        [0, 7, 10],
        [0, 10, 11],
        [1, 5, 9],
        [5, 11, 4],
        [11, 10, 2],
        [10, 7, 6],
        [7, 1, 8],
        [3, 9, 4],
        [3, 4, 2],
        [3, 2, 6],
        [3, 6, 8],
        [3, 8, 9],
        [4, 9, 5],
        [2, 4, 11],
        [6, 2, 10],
        [8, 6, 7],
        [9, 8, 1],
    ];
    for _ in 0..levels {
        let mut mid = HashMap::new();
        let mut m = |a: usize, b: usize, v: &mut Vec<DVec3>| {
            *mid.entry((a.min(b), a.max(b))).or_insert_with(|| {
                v.push((v[a] + v[b]).normalize());
                v.len() - 1
            })
        };
        let mut next = Vec::with_capacity(4 * f.len());
        for [a, b, c] in f {
            let (ab, bc, ca) = (m(a, b, &mut v), m(b, c, &mut v), m(c, a, &mut v));
            next.extend([[a, ab, ca], [b, bc, ab], [c, ca, bc], [ab, bc, ca]]);
        }
        f = next;
    }
    f.iter().map(|&[a, b, c]| [v[a], v[b], v[c]]).collect()
}

/// A 256 x 256 grid of unit rays from `origin` through the square of half-size 1.2 around the sphere.
fn rays(origin: Vec3A) -> Vec<Vec3A> {
    let n = 256;
    (0..n * n)
        .map(|k| {
            let (i, j) = ((k % n) as f32, (k / n) as f32);
            let target = Vec3A::new(
                2.4 * (i + 0.5) / n as f32 - 1.2,
                2.4 * (j + 0.5) / n as f32 - 1.2,
                0.0,
            );
            (target - origin).normalize()
        })
        .collect()
}

fn bench(c: &mut Criterion) {
    let tris = icosphere(5);
    let mut g = c.benchmark_group("mesh");
    g.throughput(Throughput::Elements(tris.len() as u64));
    g.bench_function("bvh_build_20480_triangles", |b| {
        b.iter(|| Mesh::new(&tris, None).expect("non-degenerate"))
    });
    let mesh = Mesh::new(&tris, None).expect("non-degenerate");
    let origin = Vec3A::new(0.0, 0.0, -5.0);
    let dirs = rays(origin);
    let hits = dirs
        .iter()
        .filter(|&&d| mesh.intersect(origin, d, 0.0, f32::INFINITY).is_some())
        .count();
    eprintln!("{hits} of {} rays hit the sphere", dirs.len());
    g.throughput(Throughput::Elements(dirs.len() as u64));
    g.bench_function("camera_rays_1_thread", |b| {
        b.iter(|| {
            dirs.iter()
                .filter_map(|&d| mesh.intersect(origin, d, 0.0, f32::INFINITY))
                .map(|h| h.t)
                .sum::<f32>()
        })
    });
    g.bench_function("shadow_rays_1_thread", |b| {
        b.iter(|| {
            dirs.iter()
                .filter(|&&d| mesh.hits_segment(origin, d, 0.0, 10.0))
                .count()
        })
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
