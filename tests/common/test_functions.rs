//! Standard test functions for the optimisers (all with minimum 0). Shared by the cargo tests
//! (tests/search/) and the `test-hooks` Python extension (rust/python/test_hooks.rs); not part of the
//! library.
#![allow(dead_code)]
use std::f64::consts::PI;

/// Σ x².  Minimum 0 at the origin.
pub fn sphere(x: &[f64]) -> f64 {
    x.iter().map(|v| v * v).sum()
}

/// Σ 100 (x_{i+1} − x_i²)² + (1 − x_i)².  Minimum 0 at (1, …, 1).
pub fn rosenbrock(x: &[f64]) -> f64 {
    x.windows(2)
        .map(|w| 100.0 * (w[1] - w[0] * w[0]).powi(2) + (1.0 - w[0]).powi(2))
        .sum()
}

/// 10 n + Σ x² − 10 cos(2π x).  Minimum 0 at the origin.
pub fn rastrigin(x: &[f64]) -> f64 {
    10.0 * x.len() as f64
        + x.iter()
            .map(|v| v * v - 10.0 * (2.0 * PI * v).cos())
            .sum::<f64>()
}

/// −20 exp(−0.2 √(Σx²/n)) − exp(Σ cos(2π x)/n) + 20 + e.  Minimum 0 at the origin.
pub fn ackley(x: &[f64]) -> f64 {
    let n = x.len().max(1) as f64;
    let s2 = x.iter().map(|v| v * v).sum::<f64>() / n;
    let sc = x.iter().map(|v| (2.0 * PI * v).cos()).sum::<f64>() / n;
    -20.0 * (-0.2 * s2.sqrt()).exp() - sc.exp() + 20.0 + std::f64::consts::E
}

/// 1 + Σ x²/4000 − Π cos(x_i / √i).  Minimum 0 at the origin.
pub fn griewank(x: &[f64]) -> f64 {
    let s = x.iter().map(|v| v * v).sum::<f64>() / 4000.0;
    let p: f64 = x
        .iter()
        .enumerate()
        .map(|(i, v)| (v / ((i + 1) as f64).sqrt()).cos())
        .product();
    1.0 + s - p
}

/// The function called `name` (`sphere`, `rosenbrock`, `rastrigin`, `ackley`, `griewank`).
pub fn by_name(name: &str) -> Option<fn(&[f64]) -> f64> {
    Some(match name {
        "sphere" => sphere,
        "rosenbrock" => rosenbrock,
        "rastrigin" => rastrigin,
        "ackley" => ackley,
        "griewank" => griewank,
        _ => return None,
    })
}

/// Where each function has its minimum (value 0) in `dim` dimensions.
pub fn minimizer(name: &str, dim: usize) -> Option<Vec<f64>> {
    by_name(name)?;
    Some(vec![if name == "rosenbrock" { 1.0 } else { 0.0 }; dim])
}

pub const NAMES: [&str; 5] = ["sphere", "rosenbrock", "rastrigin", "ackley", "griewank"];
