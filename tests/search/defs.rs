//! The standard test functions, each written out from its definition (all with minimum 0), independently of
//! the copies in `tests/common/test_functions.rs` that the Python test hooks share: `lshade.rs` checks those
//! against these.

use std::f64::consts::{E, PI};

use rtloop::search::GenerationReport;

/// Sphere: sum x_i^2, minimum 0 at the origin.
pub fn sphere(x: &[f64]) -> f64 {
    x.iter().map(|v| v * v).sum()
}

/// Rosenbrock: sum 100 (x_{i+1} - x_i^2)^2 + (1 - x_i)^2, minimum 0 at (1, ..., 1).
pub fn rosenbrock(x: &[f64]) -> f64 {
    (0..x.len().saturating_sub(1))
        .map(|i| 100.0 * (x[i + 1] - x[i] * x[i]).powi(2) + (1.0 - x[i]).powi(2))
        .sum()
}

/// Rastrigin: sum x_i^2 - 10 cos(2 pi x_i) + 10, minimum 0 at the origin; every other integer lattice point
/// is a local minimum with value >= ~1, so a search of a few dozen evaluations from random points ends in one.
pub fn rastrigin(x: &[f64]) -> f64 {
    x.iter()
        .map(|v| v * v - 10.0 * (2.0 * PI * v).cos() + 10.0)
        .sum()
}

/// Ackley (a = 20, b = 0.2, c = 2 pi), minimum 0 at the origin.
pub fn ackley(x: &[f64]) -> f64 {
    let n = x.len() as f64;
    let a = (x.iter().map(|v| v * v).sum::<f64>() / n).sqrt();
    let b = x.iter().map(|v| (2.0 * PI * v).cos()).sum::<f64>() / n;
    20.0 + E - 20.0 * (-0.2 * a).exp() - b.exp()
}

/// Griewank, minimum 0 at the origin.
pub fn griewank(x: &[f64]) -> f64 {
    let mut s = 0.0;
    let mut p = 1.0;
    for (i, v) in x.iter().enumerate() {
        s += v * v;
        p *= (v / ((i + 1) as f64).sqrt()).cos();
    }
    s / 4000.0 - p + 1.0
}

/// Euclidean distance.
pub fn distance(a: &[f64], b: &[f64]) -> f64 {
    a.iter()
        .zip(b)
        .map(|(x, y)| (x - y) * (x - y))
        .sum::<f64>()
        .sqrt()
}

/// Rastrigin with some more work per evaluation (terms of 1e-12), so that several threads really share a
/// generation in the determinism tests.
pub fn busy_rastrigin(x: &[f64]) -> f64 {
    let mut acc = rastrigin(x);
    for k in 1..50 {
        acc += 1e-12 * (k as f64 * x[0]).sin();
    }
    acc
}

/// The bit patterns of `v`, to compare results bit for bit.
pub fn bits(v: &[f64]) -> Vec<u64> {
    v.iter().map(|x| x.to_bits()).collect()
}

/// A generation callback that asserts the best value never gets worse from one generation to the next and
/// is the minimum of the population's values; it never stops the search.
pub fn assert_best_monotone() -> impl FnMut(&GenerationReport) -> bool {
    let mut last = f64::INFINITY;
    move |r: &GenerationReport| {
        let v = r.best_objectives[0];
        assert!(
            v <= last,
            "generation {}: best got worse ({last} -> {v})",
            r.generation
        );
        // The best really is the minimum of the population.
        let min = r
            .objectives
            .iter()
            .map(|o| o[0])
            .fold(f64::INFINITY, f64::min);
        assert_eq!(v, min);
        last = v;
        true
    }
}

/// A box whose corner (3, 3, 3, -2) is the constrained optimum of [`beyond_the_box`].
pub const BOX: [(f64, f64); 4] = [(-5.0, 3.0), (-5.0, 3.0), (-5.0, 3.0), (-2.0, 4.0)];

/// The constrained optimum of [`beyond_the_box`] in [`BOX`].
pub const CORNER: [f64; 4] = [3.0, 3.0, 3.0, -2.0];

/// sum (x_i - t_i)^2 with t = (10, 10, 10, -10): its minimum lies outside [`BOX`], whose corner
/// [`CORNER`] has the least value within it, 3 * 7^2 + 8^2 = 211.
pub fn beyond_the_box(x: &[f64]) -> f64 {
    x.iter()
        .zip(&[10.0, 10.0, 10.0, -10.0])
        .map(|(v, t)| (v - t).powi(2))
        .sum::<f64>()
}

/// Asserts that a search of [`beyond_the_box`] in [`BOX`] ended on [`CORNER`] (within 1e-6) with value `v`
/// no less than the corner's and within `tol` of it.
pub fn assert_on_the_corner(best: &[f64], v: f64, tol: f64) {
    let expected = beyond_the_box(&CORNER);
    assert_eq!(expected, 211.0);
    assert!(
        distance(best, &CORNER) < 1e-6,
        "best {best:?} should sit on the corner {CORNER:?}"
    );
    assert!(
        v >= expected,
        "nothing inside the box beats the corner: {v}"
    );
    assert!(v - expected < tol, "objective {v}, expected {expected}");
}

/// `f()` run inside a fresh pool of `threads` threads (checked to be that many).
pub fn on_threads<R: Send>(threads: usize, f: impl FnOnce() -> R + Send) -> R {
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .unwrap();
    pool.install(|| {
        assert_eq!(rayon::current_num_threads(), threads);
        f()
    })
}
