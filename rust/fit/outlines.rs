//! The outline gate: a default fit (the footprint in its polish, outlines at pixel centres) takes the
//! silhouette integration ([`FitnessSpec::outlines`]) only where its photo shows that it needs it. At the
//! fit's light its loss is compared with the same loss with the outline pixels averaged over their
//! sub-pixel rays (`Fitness::outline_gain`: two passes over the outline pixels' samples, no new set-up);
//! where that explains the photo better by [`OUTLINE_GAIN`] of the fit's loss (or by
//! [`OUTLINE_SHARE_GAIN`] where an object is lit mostly on its outline, [`OUTLINE_SHARE`]), the light is
//! polished again from there with the outlines integrated, and the result kept where its loss is below
//! the fit's. The two models have the same free parameters (the integration adds none), so their
//! in-sample losses compare as they are.

use crate::error::Result;
use crate::fitness::{Fitness, FitnessSpec};
use crate::params::ParamLayout;
use crate::scene::Scene;
use crate::stage::{polish_stage, OutlineEvidence, StageResult};

/// The gate fires where integrating the outline pixels lowers a default fit's loss, at its own light, by
/// this share of it: the outlines' error is then about half of what the fit leaves (on the 27 study photos
/// 1-41 % where the outlines barely move the light, 46-51 % on the outline-heavy ones; see
/// benches/results/silhouette.md).
pub const OUTLINE_GAIN: f64 = 0.45;
/// Or where some object has this share of its lit pixels on its outline (a ball lit from behind, lit on
/// its rim alone) and the fall is [`OUTLINE_SHARE_GAIN`] at least: its light is then measured on its
/// outline.
pub const OUTLINE_SHARE: f64 = 0.5;
pub const OUTLINE_SHARE_GAIN: f64 = 0.15;
/// The polish with the outlines integrated starts from the fit's light with this initial simplex (a
/// fraction of each range): the integration moves a light by millimetres to centimetres, inside its basin.
pub const OUTLINE_STEP: f64 = 0.02;

/// The outline gate on `result`, a default fit with `finer` (its footprint fitness, built with
/// [`FitnessSpec::outline_gate`]) of `layout` of `scene` to `target` (`spec`, its light searched within
/// `bounds`): the evidence, and `result` replaced by the polish with the outlines integrated
/// (`evaluations` at most, stopping at `x_tol`) where the gate fires and that polish lowers the loss.
pub(crate) fn outline_gate(
    finer: &Fitness,
    (scene, layout, target, spec): (&Scene, ParamLayout, &[f32], FitnessSpec),
    bounds: &[(f64, f64)],
    (evaluations, x_tol): (usize, f64),
    result: &mut StageResult,
) -> Result<Option<OutlineEvidence>> {
    let Some(gain) = finer.outline_gain(&result.x) else {
        return Ok(None);
    };
    let (centre, integrated) = (gain.loss, gain.loss - gain.centres + gain.integrated);
    let fall = centre - integrated;
    let mut evidence = OutlineEvidence {
        centre,
        integrated,
        pixels: gain.pixels,
        share: gain.share,
        fired: fall >= OUTLINE_GAIN * centre
            || (gain.share >= OUTLINE_SHARE && fall >= OUTLINE_SHARE_GAIN * centre),
        polished: None,
        kept: false,
    };
    if !evidence.fired {
        return Ok(Some(evidence));
    }
    let spec = FitnessSpec {
        outlines: true,
        outline_gate: false,
        footprint: true,
        ..spec
    };
    let outlined = Fitness::new(scene, layout, target, spec)?;
    let mut stage = polish_stage(
        &outlined,
        None,
        bounds,
        &result.x,
        OUTLINE_STEP,
        evaluations,
        x_tol,
    )?;
    stage.refine(&outlined, None);
    let polished: f64 = stage.objectives.iter().sum();
    let before: f64 = result.objectives.iter().sum();
    evidence.polished = Some(polished);
    evidence.kept = polished < before;
    result.evaluations += stage.evaluations;
    if evidence.kept {
        result.x = stage.x;
        result.objectives = stage.objectives;
        result.products = stage.products;
        result.lit_pixels = stage.lit_pixels;
    }
    Ok(Some(evidence))
}
