//! L-SHADE from a given start (`rtloop::search::lshade::minimize_polishing_from`, what a refit near a light
//! already found uses): the initial population holds the start (clamped to the bounds) in place of its
//! first member and is otherwise the population drawn without it, so a search refining a point never
//! ends worse than that point, however small its budget. Expected values come from the test function's
//! definition (Rastrigin's global minimum 0 at the origin), not from earlier runs.

use crate::defs::rastrigin;
use rtloop::search::lshade::{minimize, minimize_polishing_from};
use rtloop::search::{run_polishing, DeConfig, GenerationReport, LshadeConfig, Method};

fn small(seed: u64) -> LshadeConfig {
    LshadeConfig {
        max_evaluations: 40,
        population_init: Some(8),
        seed,
        ..LshadeConfig::default()
    }
}

type NoPolish = fn(&[f64]) -> f64;

/// Rastrigin searched within `bounds` (from `start` where given): the result and the initial population.
fn searched(
    bounds: &[(f64, f64)],
    cfg: &LshadeConfig,
    start: Option<&[f64]>,
) -> (rtloop::search::LshadeResult, Vec<Vec<f64>>) {
    let mut first = Vec::new();
    let res = minimize_polishing_from(
        &rastrigin,
        None::<&NoPolish>,
        bounds,
        cfg,
        start,
        |r: &GenerationReport| {
            if r.generation == 0 {
                first = r.population.to_vec();
            }
            true
        },
    )
    .unwrap();
    (res, first)
}

#[test]
fn a_start_is_held_and_never_lost() {
    let bounds = [(-5.12, 5.12); 4];
    let origin = [0.0; 4];
    let mut worse_without = 0;
    for seed in 0..8 {
        let cfg = small(seed);
        let (plain, first) = searched(&bounds, &cfg, None);
        // Without a start, `minimize` is the same search.
        let same = minimize(&rastrigin, &bounds, &cfg, |_| true).unwrap();
        assert_eq!(same.best, plain.best);
        let (from, held) = searched(&bounds, &cfg, Some(&origin));
        // The start replaces the first member; the others are the draws made without it.
        assert_eq!(held[0], origin.to_vec());
        assert_eq!(held[1..], first[1..]);
        // Elitist selection: the start's value (the global minimum) is never given up.
        assert_eq!(from.best_objectives[0], 0.0, "seed {seed}: {:?}", from.best);
        assert_eq!(from.best, origin.to_vec());
        worse_without += usize::from(plain.best_objectives[0] > 1e-6);
    }
    // The budget is too small to find the minimum alone: the start is what holds it.
    assert!(
        worse_without >= 6,
        "{worse_without} of 8 searches without the start missed the minimum"
    );
}

#[test]
fn a_start_outside_the_box_is_clamped_and_a_bad_one_refused() {
    let bounds = [(-1.0, 1.0), (0.5, 0.5), (-2.0, 2.0)];
    let (_, first) = searched(&bounds, &small(3), Some(&[4.0, 0.0, -3.0]));
    let held = first[0].clone();
    assert_eq!(held, vec![1.0, 0.5, -2.0]);
    for bad in [vec![0.0, 0.5], vec![0.0, 0.5, f64::NAN]] {
        let err = minimize_polishing_from(
            &rastrigin,
            None::<&NoPolish>,
            &bounds,
            &small(3),
            Some(&bad),
            |_| true,
        );
        assert!(err.is_err(), "{bad:?}");
    }
    // The paper's DE/rand/1/bin draws its whole population: a start is refused, not ignored.
    let de = Method::RandOneBin(DeConfig {
        population: 8,
        generations: 2,
        f: 0.6,
        cr: 0.8,
        seed: 0,
    });
    let got = run_polishing(
        &de,
        &rastrigin,
        None::<&NoPolish>,
        &bounds,
        Some(&[0.0, 0.5, 0.0]),
        |_| true,
    );
    assert!(got.is_err());
}
