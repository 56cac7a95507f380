//! Integration tests of the differential-evolution engine (`rtloop::search::rand1bin`): known optima, bounds, fixed
//! dimensions, determinism across thread counts, Pareto selection, early stopping and NaN handling.
//!
//! Expected values come from the test functions' definitions (their known minima), never from earlier
//! runs. Run with `cargo test --test search rand1bin`.

use crate::defs::{
    assert_best_monotone, assert_on_the_corner, beyond_the_box, bits, busy_rastrigin, distance,
    on_threads, rastrigin, rosenbrock, sphere, BOX,
};
use rtloop::search::rand1bin::minimize;
use rtloop::search::{replaces, DeConfig, DeResult, GenerationReport, Objective};

// ---------------------------------------------------------------------------------------------------
// Test functions and helpers
// ---------------------------------------------------------------------------------------------------

fn cfg(population: usize, generations: usize, seed: u64) -> DeConfig {
    DeConfig {
        population,
        generations,
        seed,
        ..DeConfig::default()
    }
}

fn run<O: Objective + ?Sized>(obj: &O, bounds: &[(f64, f64)], cfg: &DeConfig) -> DeResult {
    minimize(obj, bounds, cfg, |_: &GenerationReport| true).expect("valid configuration")
}

/// Run `f` on the box [-5, 3]^`dim` (not centred on the optimum) with seeds 1 and 2, and check each result
/// against the known optimum: `x_star` in every coordinate.
fn check_optimum(
    name: &str,
    f: fn(&[f64]) -> f64,
    (dim, x_star): (usize, f64),
    (population, generations): (usize, usize),
    (x_tol, f_tol): (f64, f64),
) {
    let bounds = vec![(-5.0, 3.0); dim];
    let x_star = vec![x_star; dim];
    let f_star = f(&x_star);
    for seed in [1, 2] {
        let res = run(&f, &bounds, &cfg(population, generations, seed));
        let d = distance(&res.best, &x_star);
        let v = res.best_objectives[0];
        assert_eq!(res.best_objectives.len(), 1);
        assert_eq!(
            v,
            f(&res.best),
            "{name}: reported objective is the best vector's value"
        );
        assert!(
            d < x_tol,
            "{name} (seed {seed}): distance to optimum {d:e} >= {x_tol:e}; best {:?}",
            res.best
        );
        assert!(
            (v - f_star).abs() < f_tol,
            "{name} (seed {seed}): objective {v:e}, expected {f_star:e} +- {f_tol:e}"
        );
    }
}

// ---------------------------------------------------------------------------------------------------
// Known optima
// ---------------------------------------------------------------------------------------------------

/// One test per row: `test: name, f, (dim, optimum coordinate), (population, generations), (x_tol, f_tol)`.
macro_rules! optimum_tests {
    ($($test:ident: $name:literal, $f:expr, $at:expr, $run:expr, $tol:expr;)+) => {
        $(
            #[test]
            fn $test() {
                check_optimum($name, $f, $at, $run, $tol);
            }
        )+
    };
}

optimum_tests! {
    sphere_dim5_finds_origin: "sphere-5", sphere, (5, 0.0), (40, 300), (1e-4, 1e-8);
    rosenbrock_dim2_finds_ones: "rosenbrock-2", rosenbrock, (2, 1.0), (40, 300), (1e-3, 1e-6);
    rosenbrock_dim4_finds_ones: "rosenbrock-4", rosenbrock, (4, 1.0), (60, 800), (1e-2, 1e-4);
    rastrigin_dim2_finds_global_minimum: "rastrigin-2", rastrigin, (2, 0.0), (40, 300), (1e-4, 1e-6);
    rastrigin_dim3_finds_global_minimum: "rastrigin-3", rastrigin, (3, 0.0), (60, 400), (1e-4, 1e-6);
}

// ---------------------------------------------------------------------------------------------------
// Bounds and fixed dimensions
// ---------------------------------------------------------------------------------------------------

/// Run `obj` and assert every individual of every generation lies within `bounds`; returns the result.
fn run_checking_bounds<O: Objective + ?Sized>(
    obj: &O,
    bounds: &[(f64, f64)],
    cfg: &DeConfig,
) -> DeResult {
    let mut reports = 0;
    let res = minimize(obj, bounds, cfg, |r: &GenerationReport| {
        reports += 1;
        assert_eq!(r.population.len(), cfg.population);
        assert_eq!(r.objectives.len(), cfg.population);
        for (i, x) in r.population.iter().enumerate() {
            assert_eq!(x.len(), bounds.len());
            for (j, (&v, &(lo, hi))) in x.iter().zip(bounds).enumerate() {
                assert!(
                    lo <= v && v <= hi,
                    "generation {}, individual {i}, dimension {j}: {v} outside [{lo}, {hi}]",
                    r.generation
                );
            }
        }
        for (j, (&v, &(lo, hi))) in r.best.iter().zip(bounds).enumerate() {
            assert!(
                lo <= v && v <= hi,
                "best, dimension {j}: {v} outside [{lo}, {hi}]"
            );
        }
        true
    })
    .unwrap();
    assert_eq!(
        reports,
        cfg.generations + 1,
        "callback runs for generation 0..=generations"
    );
    res
}

#[test]
fn every_individual_stays_within_bounds() {
    // Asymmetric, differently sized boxes per dimension, optimum inside.
    let bounds = [(-5.0, 3.0), (-0.5, 0.25), (-100.0, 1.0), (0.0, 1e-3)];
    let obj = |x: &[f64]| rastrigin(&x[..3]) + (x[3] - 5e-4).powi(2);
    for seed in [1, 2] {
        let res = run_checking_bounds(&obj, &bounds, &cfg(30, 200, seed));
        assert!(res.best_objectives[0] < 1e-6, "{:?}", res);
    }
}

#[test]
fn optimum_outside_the_box_ends_on_the_bound() {
    // Minimum of sum (x_i - 10)^2 is at 10 per dimension, outside [-5, 3]: the constrained optimum is the
    // corner at 3 with value 3 * 7^2 = 147. Dimension 3 wants -10 against a lower bound of -2.
    for seed in [1, 2] {
        let res = run_checking_bounds(&beyond_the_box, &BOX, &cfg(30, 300, seed));
        assert_on_the_corner(&res.best, res.best_objectives[0], 1e-4);
    }
}

#[test]
fn dimension_with_min_equal_max_stays_fixed() {
    // Dimension 1 is fixed at 2.5 although the objective would like it at 0.
    let bounds = [(-5.0, 3.0), (2.5, 2.5), (-5.0, 3.0), (-1.0, -1.0)];
    for seed in [1, 2] {
        let mut generations_seen = 0;
        let res = minimize(
            &sphere,
            &bounds,
            &cfg(30, 150, seed),
            |r: &GenerationReport| {
                generations_seen += 1;
                for x in r.population {
                    assert_eq!(x[1], 2.5, "generation {}", r.generation);
                    assert_eq!(x[3], -1.0, "generation {}", r.generation);
                }
                true
            },
        )
        .unwrap();
        assert_eq!(generations_seen, 151);
        assert_eq!(res.best[1], 2.5);
        assert_eq!(res.best[3], -1.0);
        // The free dimensions still reach their optimum 0; the objective is 2.5^2 + 1^2 = 7.25.
        assert!(
            res.best[0].abs() < 1e-4 && res.best[2].abs() < 1e-4,
            "{:?}",
            res.best
        );
        assert!(
            (res.best_objectives[0] - 7.25).abs() < 1e-8,
            "{:?}",
            res.best_objectives
        );
    }
}

// ---------------------------------------------------------------------------------------------------
// Determinism across thread counts
// ---------------------------------------------------------------------------------------------------

/// Best vector and objectives of every generation, as bits, plus the final result.
type History = (Vec<(Vec<u64>, Vec<u64>, usize)>, Vec<u64>, Vec<u64>);

fn history_on_threads(threads: usize, seed: u64) -> History {
    let obj = busy_rastrigin;
    let bounds = [(-5.0, 3.0); 6];
    on_threads(threads, || {
        let mut hist = Vec::new();
        let res = minimize(
            &obj,
            &bounds,
            &cfg(40, 120, seed),
            |r: &GenerationReport| {
                hist.push((bits(r.best), bits(r.best_objectives), r.evaluations));
                true
            },
        )
        .unwrap();
        (hist, bits(&res.best), bits(&res.best_objectives))
    })
}

#[test]
fn result_is_bit_identical_on_1_2_4_8_threads() {
    let reference = history_on_threads(1, 42);
    assert_eq!(reference.0.len(), 121);
    for n in [2, 4, 8] {
        let other = history_on_threads(n, 42);
        assert_eq!(other.1, reference.1, "best vector differs on {n} threads");
        assert_eq!(
            other.2, reference.2,
            "best objectives differ on {n} threads"
        );
        assert_eq!(other.0.len(), reference.0.len());
        for (g, (a, b)) in reference.0.iter().zip(&other.0).enumerate() {
            assert_eq!(a, b, "generation {g} differs on {n} threads");
        }
    }
    let different_seed = history_on_threads(4, 43);
    assert_ne!(
        different_seed.0, reference.0,
        "another seed should give another history"
    );
    assert_ne!(different_seed.0[0], reference.0[0], "even the initial best");
}

#[test]
fn same_seed_repeats_within_a_pool() {
    let a = history_on_threads(3, 7);
    let b = history_on_threads(3, 7);
    assert_eq!(a, b);
}

// ---------------------------------------------------------------------------------------------------
// Multi-objective (Pareto) selection
// ---------------------------------------------------------------------------------------------------

/// Three separable objectives with a common minimum at (1, 2, -1) (x3 is ignored by all of them).
struct Separable3;

impl Objective for Separable3 {
    fn n_objectives(&self) -> usize {
        3
    }
    fn evaluate(&self, x: &[f64], out: &mut [f64]) {
        out[0] = (x[0] - 1.0).powi(2);
        out[1] = (x[1] - 2.0).powi(2);
        out[2] = (x[2] + 1.0).powi(2) + 0.0 * x[3];
    }
}

#[test]
fn separable_three_objective_problem_is_solved() {
    let bounds = [(-5.0, 3.0); 4];
    let optimum = [1.0, 2.0, -1.0];
    for seed in [1, 2] {
        let res = run(&Separable3, &bounds, &cfg(40, 400, seed));
        assert_eq!(res.best_objectives.len(), 3);
        let d = distance(&res.best[..3], &optimum);
        assert!(d < 1e-3, "seed {seed}: best {:?}, distance {d:e}", res.best);
        let mut expected = [0.0; 3];
        Separable3.evaluate(&res.best, &mut expected);
        assert_eq!(res.best_objectives, expected.to_vec());
        for (k, v) in res.best_objectives.iter().enumerate() {
            assert!(*v < 1e-6, "seed {seed}: objective {k} = {v:e}");
        }
    }
}

/// Two conflicting objectives: distances to (0, 0) and to (1, 0). Their Pareto set is the segment
/// between the two points, so many trials are better in one objective and worse in the other.
struct Conflicting;

impl Objective for Conflicting {
    fn n_objectives(&self) -> usize {
        2
    }
    fn evaluate(&self, x: &[f64], out: &mut [f64]) {
        out[0] = x[0] * x[0] + x[1] * x[1];
        out[1] = (x[0] - 1.0).powi(2) + x[1] * x[1];
    }
}

type Snapshot = (Vec<Vec<f64>>, Vec<Vec<f64>>);

#[test]
fn pareto_selection_never_trades_one_objective_for_another() {
    let bounds = [(-4.0, 3.0), (-2.0, 5.0)];
    for seed in [1, 2, 3] {
        // Previous generation's population and objectives.
        let mut prev: Option<Snapshot> = None;
        let mut replacements = 0usize;
        let res = minimize(
            &Conflicting,
            &bounds,
            &cfg(30, 200, seed),
            |r: &GenerationReport| {
                if let Some((px, po)) = &prev {
                    for i in 0..r.population.len() {
                        let (old, new) = (&po[i], &r.objectives[i]);
                        for k in 0..2 {
                            assert!(
                            new[k] <= old[k],
                            "seed {seed}, generation {}, individual {i}: objective {k} got worse \
                             ({} -> {})",
                            r.generation,
                            old[k],
                            new[k]
                        );
                        }
                        if r.population[i] != px[i] {
                            replacements += 1;
                            assert!(
                                replaces(new, old),
                                "a replacement must dominate its target: {old:?} -> {new:?}"
                            );
                            // The objectives stored are those of the stored vector.
                            let mut o = [0.0; 2];
                            Conflicting.evaluate(&r.population[i], &mut o);
                            assert_eq!(&o[..], &new[..]);
                        } else {
                            assert_eq!(old, new);
                        }
                    }
                }
                prev = Some((r.population.to_vec(), r.objectives.to_vec()));
                true
            },
        )
        .unwrap();
        assert!(replacements > 0, "the test needs some accepted trials");
        assert_eq!(res.generations, 200);
        // Minimising the sum of the objectives would pull everyone to (0.5, 0). Pareto selection keeps
        // the population spread along the Pareto segment y = 0, 0 <= x <= 1 instead.
        let (px, _) = prev.unwrap();
        let (lo, hi) = px
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), x| {
                (lo.min(x[0]), hi.max(x[0]))
            });
        assert!(hi - lo > 0.5, "seed {seed}: x0 spans only [{lo}, {hi}]");
        assert!(
            px.iter()
                .all(|x| (-0.1..=1.1).contains(&x[0]) && x[1].abs() < 0.1),
            "seed {seed}: the population should have reached the Pareto segment: {px:?}"
        );
    }
}

#[test]
fn replaces_rule() {
    // Single objective: not worse wins (ties move the population along plateaus).
    assert!(replaces(&[1.0], &[2.0]));
    assert!(replaces(&[1.0], &[1.0]));
    assert!(!replaces(&[2.0], &[1.0]));
    // Several: no worse in every objective and strictly better in one.
    assert!(replaces(&[1.0, 1.0], &[1.0, 2.0]));
    assert!(replaces(&[0.5, 1.0, 0.0], &[1.0, 2.0, 0.0]));
    assert!(
        !replaces(&[1.0, 2.0], &[1.0, 2.0]),
        "equal does not replace"
    );
    assert!(
        !replaces(&[0.0, 2.1], &[1.0, 2.0]),
        "better in one, worse in another"
    );
    assert!(!replaces(&[2.0, 0.0], &[1.0, 2.0]));
    // A NaN-free infinite value (how the engine stores NaN) never wins against a finite one.
    assert!(!replaces(&[f64::INFINITY], &[1e300]));
    assert!(!replaces(&[f64::INFINITY, 0.0], &[1.0, 1.0]));
}

// ---------------------------------------------------------------------------------------------------
// Callback, early stop and counts
// ---------------------------------------------------------------------------------------------------

#[test]
fn callback_can_stop_early_and_counts_are_consistent() {
    let bounds = [(-5.0, 3.0); 3];
    let np = 24;
    for stop_at in [0usize, 1, 7] {
        let mut seen = Vec::new();
        let res = minimize(
            &sphere,
            &bounds,
            &cfg(np, 100, 5),
            |r: &GenerationReport| {
                seen.push(r.generation);
                assert_eq!(r.evaluations, np * (r.generation + 1));
                r.generation < stop_at
            },
        )
        .unwrap();
        assert!(res.stopped());
        assert_eq!(res.generations, stop_at);
        assert_eq!(seen, (0..=stop_at).collect::<Vec<_>>());
        assert_eq!(res.evaluations, np * (res.generations + 1));
    }
    // Running to the end: not stopped, every generation done.
    for gens in [0usize, 1, 30] {
        let mut calls = 0;
        let res = minimize(
            &sphere,
            &bounds,
            &cfg(np, gens, 5),
            |r: &GenerationReport| {
                assert_eq!(r.generation, calls);
                calls += 1;
                true
            },
        )
        .unwrap();
        assert!(!res.stopped());
        assert_eq!(res.generations, gens);
        assert_eq!(calls, gens + 1);
        assert_eq!(res.evaluations, np * (gens + 1));
    }
}

#[test]
fn evaluation_count_matches_calls_to_the_objective() {
    use std::sync::atomic::{AtomicUsize, Ordering};
    let calls = AtomicUsize::new(0);
    let obj = |x: &[f64]| {
        calls.fetch_add(1, Ordering::Relaxed);
        sphere(x)
    };
    let res = minimize(
        &obj,
        &[(-1.0, 2.0); 2],
        &cfg(16, 40, 3),
        |r: &GenerationReport| r.generation < 25,
    )
    .unwrap();
    assert_eq!(res.generations, 25);
    assert_eq!(res.evaluations, 16 * 26);
    assert_eq!(calls.load(Ordering::Relaxed), res.evaluations);
}

#[test]
fn best_is_monotone_over_generations() {
    let bounds = [(-5.0, 3.0); 4];
    minimize(
        &rastrigin,
        &bounds,
        &cfg(30, 100, 9),
        assert_best_monotone(),
    )
    .unwrap();
}

// ---------------------------------------------------------------------------------------------------
// NaN handling
// ---------------------------------------------------------------------------------------------------

#[test]
fn nan_objective_values_never_win() {
    // NaN for x0 < 0 (half of the box [-3, 3]); elsewhere a sphere centred on (1, 1, 1).
    let obj = |x: &[f64]| {
        if x[0] < 0.0 {
            f64::NAN
        } else {
            x.iter().map(|v| (v - 1.0).powi(2)).sum()
        }
    };
    let bounds = [(-3.0, 3.0); 3];
    for seed in [1, 2] {
        let mut saw_non_finite = false;
        let res = minimize(
            &obj,
            &bounds,
            &cfg(30, 300, seed),
            |r: &GenerationReport| {
                for (x, o) in r.population.iter().zip(r.objectives) {
                    assert!(
                        !o[0].is_nan(),
                        "NaN must not reach the population's objectives"
                    );
                    if x[0] < 0.0 {
                        assert_eq!(o[0], f64::INFINITY);
                        saw_non_finite = true;
                    }
                }
                assert!(r.best_objectives[0].is_finite() || r.generation == 0);
                true
            },
        )
        .unwrap();
        assert!(
            saw_non_finite,
            "the initial population should touch the NaN half"
        );
        assert!(res.best[0] >= 0.0);
        assert!(distance(&res.best, &[1.0; 3]) < 1e-4, "{:?}", res.best);
        assert!(res.best_objectives[0] < 1e-8);
    }
}

#[test]
fn nan_for_several_objectives_is_dominated() {
    // NaN in one objective for x0 > 0; the common minimum (-1, -1) is in the other half.
    struct HalfNan;
    impl Objective for HalfNan {
        fn n_objectives(&self) -> usize {
            2
        }
        fn evaluate(&self, x: &[f64], out: &mut [f64]) {
            out[0] = (x[0] + 1.0).powi(2);
            out[1] = if x[0] > 0.0 {
                f64::NAN
            } else {
                (x[1] + 1.0).powi(2)
            };
        }
    }
    let res = run(&HalfNan, &[(-3.0, 3.0); 2], &cfg(30, 300, 4));
    assert!(res.best_objectives.iter().all(|v| v.is_finite()));
    assert!(distance(&res.best, &[-1.0, -1.0]) < 1e-3, "{:?}", res.best);
}

#[test]
fn all_nan_objective_does_not_panic() {
    let obj = |_: &[f64]| f64::NAN;
    let bounds = [(-1.0, 1.0); 2];
    let res = run_checking_bounds(&obj, &bounds, &cfg(8, 20, 1));
    assert_eq!(res.best_objectives, vec![f64::INFINITY]);
    assert_eq!(res.evaluations, 8 * 21);
}
