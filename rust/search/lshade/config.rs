//! L-SHADE's configuration: the variant (L-SHADE or jSO), the initialisation, the budget, the
//! adaptation's constants and the stopping rules, with their checks.

use crate::error::{Error, Result};

/// Which adaptive DE.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Variant {
    /// L-SHADE as published (Tanabe & Fukunaga 2014).
    LShade,
    /// L-SHADE with the jSO refinements (Brest et al. 2017). Use [`LshadeConfig::jso`] for its defaults.
    Jso,
}

/// How the initial population is drawn.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Init {
    /// Latin hypercube: each dimension's range is cut into `N` equal strata and every stratum holds exactly
    /// one individual (a random point inside it), strata paired at random across dimensions.
    LatinHypercube,
    /// Independent uniform draws.
    Uniform,
}

/// Settings of [`minimize`]. `Default` is L-SHADE with the paper's parameters; [`LshadeConfig::jso`] gives
/// jSO's. `D` below is the number of free dimensions (those with `min < max`, at least 1).
#[derive(Clone, Debug)]
pub struct LshadeConfig {
    pub variant: Variant,
    /// Evaluation budget of the evolution (the polish has its own). The population reduction is scheduled
    /// over this budget, and the last generation evaluates only as many trials as are left, so the count
    /// never exceeds it. Default 12 000 (the paper protocol's 60 × 200 per stage).
    pub max_evaluations: usize,
    /// Optional cap on the number of generations (`None`: no cap).
    pub max_generations: Option<usize>,
    /// Initial population `N_init`; `None`: `round(18 D)` for L-SHADE, `round(25 ln(max(D, 2)) √D)` for
    /// jSO, at least `min_population`.
    pub population_init: Option<usize>,
    /// Final population `N_min` of the linear reduction (at least 4). Default 4.
    pub min_population: usize,
    /// Size `H` of the success-history memory. L-SHADE 6, jSO 5.
    pub memory_size: usize,
    /// Initial `M_F`. L-SHADE 0.5, jSO 0.3.
    pub memory_f: f64,
    /// Initial `M_CR`. L-SHADE 0.5, jSO 0.8.
    pub memory_cr: f64,
    /// Fraction `p` of the population from which `x_pbest` is drawn (at least 2 individuals). L-SHADE
    /// 0.11; for jSO the starting value 0.25, decreasing linearly to half of it.
    pub p_best: f64,
    /// Archive size as a multiple of the population size. L-SHADE 2.6, jSO 1.0.
    pub archive_rate: f64,
    pub init: Init,
    /// Stop when, in every free dimension, `(max − min) / (hi − lo)` over the population is below `x_tol`
    /// (0 disables). Default 1e-9.
    pub x_tol: f64,
    /// Stop after this many consecutive generations without an improvement of the best value by more than
    /// `stall_tol` (0 disables, the default).
    pub stall_generations: usize,
    /// Smallest decrease of the best value that counts as an improvement for `stall_generations`
    /// (absolute). Default 0: any strict decrease.
    pub stall_tol: f64,
    /// Evaluation budget of a final Nelder–Mead polish of the best individual (0, the default: no polish).
    /// Skipped when the callback stopped the search.
    pub polish_evaluations: usize,
    /// The polish stops when every simplex vertex is within this normalised distance (per dimension, as a
    /// fraction of the range) of the best one. Default 1e-13.
    pub polish_x_tol: f64,
    pub seed: u64,
}

impl Default for LshadeConfig {
    /// L-SHADE with the parameters of Tanabe & Fukunaga (2014).
    fn default() -> Self {
        LshadeConfig {
            variant: Variant::LShade,
            max_evaluations: 12_000,
            max_generations: None,
            population_init: None,
            min_population: 4,
            memory_size: 6,
            memory_f: 0.5,
            memory_cr: 0.5,
            p_best: 0.11,
            archive_rate: 2.6,
            init: Init::LatinHypercube,
            x_tol: 1e-9,
            stall_generations: 0,
            stall_tol: 0.0,
            polish_evaluations: 0,
            polish_x_tol: 1e-13,
            seed: 0,
        }
    }
}

impl LshadeConfig {
    /// L-SHADE's defaults (same as `Default`).
    pub fn lshade() -> Self {
        Self::default()
    }

    /// jSO's defaults (Brest, Maučec & Bošković 2017).
    pub fn jso() -> Self {
        LshadeConfig {
            variant: Variant::Jso,
            memory_size: 5,
            memory_f: 0.3,
            memory_cr: 0.8,
            p_best: 0.25,
            archive_rate: 1.0,
            ..Self::default()
        }
    }

    /// The initial population size used for `dim` free dimensions.
    pub fn initial_population(&self, dim: usize) -> usize {
        if let Some(n) = self.population_init {
            return n;
        }
        let d = dim.max(1) as f64;
        let n = match self.variant {
            Variant::LShade => (18.0 * d).round(),
            Variant::Jso => (25.0 * d.max(2.0).ln() * d.sqrt()).round(),
        };
        (n as usize).max(self.min_population)
    }

    pub(super) fn validate(&self, n_init: usize) -> Result<()> {
        let bad = |m: String| Err(Error::Invalid(m));
        if self.min_population < 4 {
            return bad(format!(
                "min_population must be at least 4 (got {})",
                self.min_population
            ));
        }
        if n_init < self.min_population {
            return bad(format!(
                "population_init ({n_init}) must be at least min_population ({})",
                self.min_population
            ));
        }
        if self.max_evaluations < n_init {
            return bad(format!(
                "max_evaluations ({}) must cover the initial population ({n_init})",
                self.max_evaluations
            ));
        }
        if self.memory_size == 0 {
            return bad("memory_size must be at least 1".into());
        }
        if !(self.memory_f > 0.0 && self.memory_f <= 1.0) {
            return bad(format!(
                "memory_f must be in (0, 1] (got {})",
                self.memory_f
            ));
        }
        if !(0.0..=1.0).contains(&self.memory_cr) {
            return bad(format!(
                "memory_cr must be in [0, 1] (got {})",
                self.memory_cr
            ));
        }
        if !(self.p_best > 0.0 && self.p_best <= 1.0) {
            return bad(format!("p_best must be in (0, 1] (got {})", self.p_best));
        }
        if !(self.archive_rate >= 0.0 && self.archive_rate.is_finite()) {
            return bad(format!(
                "archive_rate must be finite and >= 0 (got {})",
                self.archive_rate
            ));
        }
        for (name, v) in [
            ("x_tol", self.x_tol),
            ("stall_tol", self.stall_tol),
            ("polish_x_tol", self.polish_x_tol),
        ] {
            if v.is_nan() || v < 0.0 {
                return bad(format!("{name} must be >= 0 (got {v})"));
            }
        }
        Ok(())
    }
}
