//! One search stage of a fit: run a search [`Method`] on a [`Fitness`], then what the fit needs at the
//! best point (for the projected loss: the products that minimise the loss itself there, and that loss).

use crate::error::Result;
use crate::fitness::{Fitness, LossKind, Solved};
use crate::search::{self, GenerationReport, Method, Objective, PolishReport, StopReason};

/// Per object `[P_r, P_g, P_b, Q]`: the colour products and `Q` = intensity × specular (0 when matte),
/// then `[E_r, E_g, E_b]`, the environment products, when the projection has an environment term.
pub type ProductRow = Vec<f64>;

/// The products of `s`, one row per object.
pub fn product_rows(s: &Solved) -> Vec<ProductRow> {
    (0..s.products.len())
        .map(|k| {
            let (p, q) = (s.products[k], s.specular[k]);
            let mut row = vec![p[0], p[1], p[2], q];
            if let Some(e) = s.environment.get(k) {
                row.extend_from_slice(e);
            }
            row
        })
        .collect()
}

/// What the per-generation callback of [`run_stage`] sees.
pub struct StageReport<'a> {
    /// 0 for the initial population, then 1, 2, ...
    pub generation: usize,
    pub best: &'a [f64],
    pub best_objectives: &'a [f64],
    pub evaluations: usize,
    /// The closed-form products of `best` (one more evaluation): only when asked for, for the projected loss.
    pub products: Option<Vec<ProductRow>>,
}

/// What a stage found.
#[derive(Clone, Debug)]
pub struct StageResult {
    pub x: Vec<f64>,
    /// The loss at `x`: for the projected loss its sum at the refined products, else the search's objectives.
    pub objectives: Vec<f64>,
    /// Projected loss only: the loss at the least-squares products the search ranked candidates by.
    pub search_objectives: Option<Vec<f64>>,
    /// All evaluations, a polish's included.
    pub evaluations: usize,
    pub generations: usize,
    pub stop: StopReason,
    pub polish: Option<PolishReport>,
    pub active_pixels: usize,
    /// Projected loss only: the products minimising the loss at `x` and each object's lit pixels.
    pub products: Option<Vec<ProductRow>>,
    pub lit_pixels: Option<Vec<usize>>,
    /// Projected loss with interreflection: the gauge u = 1 / intensity the bounce was solved with.
    pub gauge: Option<f64>,
    /// A default fit's outline gate (`fit::outlines`): its evidence, where it ran.
    pub outlines: Option<OutlineEvidence>,
}

/// What the outline gate saw at a default fit's light, and what it did.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct OutlineEvidence {
    /// The fit's search loss at its light (outlines at pixel centres, the least-squares products).
    pub centre: f64,
    /// The same with the outline pixels averaged over their sub-pixel rays (`Fitness::outline_gain`).
    pub integrated: f64,
    /// The pixels on an outline.
    pub pixels: usize,
    /// The largest share, over the objects, of an object's lit pixels that are on an outline.
    pub share: f64,
    /// Whether the gate fired (`fit::outlines`): the light was polished again with the outlines integrated.
    pub fired: bool,
    /// The loss after that polish at its refined products (`None` where the gate did not fire).
    pub polished: Option<f64>,
    /// Whether the polished result replaced the fit's (`polished` below the fit's refined loss).
    pub kept: bool,
}

/// Search `fitness` within `bounds` with `method`. `callback` runs after the initial population and
/// after every generation (returning `false` stops); with `with_products` its report carries the
/// closed-form products of the best, for the projected loss. With `polish`, the method's final polish,
/// the refined products and the reported loss are `polish`'s (the same loss with a finer image model,
/// the pixel footprint): the search finds the basin, the polish the last digits. Without `refine` the
/// result carries the search's own loss and no products, unless the callback stopped the search (a search
/// whose point alone is wanted: for the bounce, the refined products' fixed point is solved again where
/// the next pass holds it). `start`: a point the initial population holds (`search::run_polishing`).
#[allow(clippy::too_many_arguments)]
pub fn run_stage<C>(
    fitness: &Fitness,
    polish: Option<&Fitness>,
    bounds: &[(f64, f64)],
    method: &Method,
    start: Option<&[f64]>,
    with_products: bool,
    refine: bool,
    mut callback: C,
) -> Result<StageResult>
where
    C: FnMut(&StageReport) -> bool,
{
    let active_pixels = fitness.active_pixels();
    let products_wanted = with_products && fitness.kind() == LossKind::L1Projected;
    let found = search::run_polishing(
        method,
        fitness,
        polish,
        bounds,
        start,
        |rep: &GenerationReport| {
            let products = products_wanted.then(|| product_rows(&fitness.solved(rep.best)));
            callback(&StageReport {
                generation: rep.generation,
                best: rep.best,
                best_objectives: rep.best_objectives,
                evaluations: rep.evaluations,
                products,
            })
        },
    )?;
    let stopped = found.stop == StopReason::Callback;
    let mut out = StageResult {
        x: found.best,
        objectives: found.best_objectives,
        search_objectives: None,
        evaluations: found.evaluations,
        generations: found.generations,
        stop: found.stop,
        polish: found.polish,
        active_pixels,
        products: None,
        lit_pixels: None,
        gauge: None,
        outlines: None,
    };
    // The search ranks lights by least-squares products; the result carries the products that minimise
    // the loss itself (saturated pixels one-sided), and that loss.
    // (a search the callback stopped is the result: refined whatever was asked)
    if refine || stopped {
        out.refine(fitness, polish);
    }
    Ok(out)
}

/// A stage that only polishes: Nelder–Mead on `polish` (else `fitness`) from `x0` within `bounds`, its
/// initial simplex `step` (a fraction of each range) along every free dimension, `evaluations` at most,
/// stopping once the simplex spans less than `x_tol` of every range. Its point and loss only: the
/// loss-minimising products at it come with [`StageResult::refine`], once no further pass follows. For a
/// search resumed near a known light, where a population would only find the basin again.
pub fn polish_stage(
    fitness: &Fitness,
    polish: Option<&Fitness>,
    bounds: &[(f64, f64)],
    x0: &[f64],
    step: f64,
    evaluations: usize,
    x_tol: f64,
) -> Result<StageResult> {
    let obj = polish.unwrap_or(fitness);
    let mut f0 = [0.0];
    obj.evaluate_alone(x0, &mut f0);
    let f0 = if f0[0].is_nan() { f64::INFINITY } else { f0[0] };
    let steps = vec![step; bounds.len()];
    let nm = search::nelder_mead::nelder_mead(obj, bounds, x0, f0, &steps, evaluations, x_tol)?;
    let (x, f) = if nm.f < f0 {
        (nm.x, nm.f)
    } else {
        (x0.to_vec(), f0)
    };
    Ok(StageResult {
        x,
        objectives: vec![f],
        search_objectives: None,
        evaluations: nm.evaluations + 1,
        generations: 0,
        stop: StopReason::MaxGenerations,
        polish: Some(PolishReport {
            evaluations: nm.evaluations,
            f_before: f0,
            f_after: f,
            improvement: if f < f0 { f0 - f } else { 0.0 },
            converged: nm.converged,
        }),
        active_pixels: fitness.active_pixels(),
        products: None,
        lit_pixels: None,
        gauge: None,
        outlines: None,
    })
}

impl StageResult {
    /// The refined products at `x` as the result (the products that minimise the loss itself there, and
    /// that loss): for a stage run without them, once no further pass follows it.
    /// Its products, lit pixels and gauge, their loss as `objectives`, the search's own loss kept as
    /// `search_objectives` (nothing where the loss has no closed-form products).
    pub fn refine(&mut self, fitness: &Fitness, polish: Option<&Fitness>) {
        if let Some((solved, loss)) = polish.unwrap_or(fitness).refined(&self.x) {
            self.products = Some(product_rows(&solved));
            self.lit_pixels = Some(solved.lit);
            self.gauge = solved.gauge;
            self.search_objectives = Some(std::mem::replace(
                &mut self.objectives,
                vec![loss.iter().sum::<f64>()],
            ));
        }
    }
}
