//! Selection among candidates: the Pareto replacement rule, rankings and the best index, and the
//! population spread the stopping rules and the polish read.

/// `a` replaces `b`: single objective `a <= b`; several: no worse in every one and better in at least one.
pub fn replaces(a: &[f64], b: &[f64]) -> bool {
    if a.len() == 1 {
        return a[0] <= b[0];
    }
    a.iter().zip(b).all(|(x, y)| x <= y) && a.iter().zip(b).any(|(x, y)| x < y)
}

/// Scalar used to rank individuals of several objectives for "best": the sum of the objectives.
fn score(o: &[f64]) -> f64 {
    o.iter().sum()
}

/// The index with the smallest objective sum (the first of equals).
pub(crate) fn best_by_sum(fit: &[Vec<f64>]) -> usize {
    (0..fit.len())
        .min_by(|&a, &b| score(&fit[a]).total_cmp(&score(&fit[b])))
        .expect("population is never empty")
}

/// Indices of `fit` from best to worst (ties by index, so the order is deterministic).
pub(crate) fn ranking(fit: &[Vec<f64>]) -> Vec<usize> {
    let mut order: Vec<usize> = (0..fit.len()).collect();
    order.sort_by(|&a, &b| fit[a][0].total_cmp(&fit[b][0]).then(a.cmp(&b)));
    order
}

/// The index with the smallest (first) objective (the first of equals).
pub(crate) fn best_index(fit: &[Vec<f64>]) -> usize {
    (0..fit.len())
        .min_by(|&a, &b| fit[a][0].total_cmp(&fit[b][0]))
        .expect("population is never empty")
}

/// Largest per-dimension spread of `pop`, as a fraction of each free dimension's range (0 if none is free).
pub fn normalized_spread(pop: &[Vec<f64>], bounds: &[(f64, f64)]) -> f64 {
    normalized_spreads(pop, bounds)
        .into_iter()
        .fold(0.0, f64::max)
}

/// Per-dimension spread `(max − min) / (hi − lo)` of `pop` (0 for fixed dimensions).
pub fn normalized_spreads(pop: &[Vec<f64>], bounds: &[(f64, f64)]) -> Vec<f64> {
    bounds
        .iter()
        .enumerate()
        .map(|(j, &(lo, hi))| {
            if lo == hi || pop.is_empty() {
                return 0.0;
            }
            let (a, b) = pop
                .iter()
                .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), x| {
                    (a.min(x[j]), b.max(x[j]))
                });
            (b - a) / (hi - lo)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pareto_replacement_rule() {
        assert!(replaces(&[1.0, 2.0, 3.0], &[1.0, 2.0, 4.0]));
        assert!(!replaces(&[1.0, 2.0, 3.0], &[1.0, 2.0, 3.0]));
        assert!(!replaces(&[0.0, 3.0, 3.0], &[1.0, 2.0, 3.0]));
        assert!(replaces(&[1.0], &[1.0]));
    }
}
