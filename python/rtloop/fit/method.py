"""The fit's method run on the photo (:func:`run_method`): the closed form with the image terms the photo
selects (:mod:`.terms`) and, for ``norm="auto"``, in L2 where its residual is dense (:mod:`.norm`); or the
paper's two stages."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from .. import _native
from ..scene import Scene
from .norm import dense_residual, linear_file, norm_verdict, not_linear_verdict, representable_pixels
from .observation import Observation
from .options import FitOptions
from .outlines import outlines_taken, record_outlines
from .plan import Plan, new_stages
from .selection import environment_given, interreflection_given
from .stages import Stages
from .terms import select_terms

__all__ = ["Fitted", "run_method"]


@dataclass
class Fitted:
    """A method's fit: the fitted ``scene`` (the gauges still held), its ``stages``, the ``photo`` as its
    last fit used it (the L2 refit uses the pixels that show one object only) and the ``model`` record."""

    scene: Scene
    stages: Stages
    photo: Observation
    model: dict[str, Any]


def run_method(options: FitOptions, photo: Observation, plan: Plan) -> Fitted:
    """The plan's method run on ``photo``: the closed form with its terms and norm, or the two stages; the
    outline pixels' record (:func:`.outlines.record_outlines`) in its model and settings."""
    fitted = _run_method(options, photo, plan)
    record_outlines(fitted.stages, plan.silhouettes, fitted.model, plan.settings)
    return fitted


def _run_method(options: FitOptions, photo: Observation, plan: Plan) -> Fitted:
    stages = new_stages(options, photo, plan.work, plan.budget, plan.ident, norm=options.first_norm,
                        space=options.first_space, footprint=plan.footprint, silhouettes=plan.silhouettes)
    model = plan.new_model()
    if plan.budget.method != "projected":
        if environment_given(plan.scene):
            model["terms"].append("environment")
        if interreflection_given(plan.work):
            model["terms"].append("interreflection")
        return Fitted(stages.two_stage(plan.seeds), stages, photo, model)
    first = Fitted(select_terms(options, photo, plan, stages, model), stages, photo, model)
    if options.norm == "auto" and options.first_space == "linear" and model.get("space", {}).get("used") != "srgb":
        return _norm_refit(options, plan, first)
    return first


def _norm_refit(options: FitOptions, plan: Plan, first: Fitted) -> Fitted:
    """``norm="auto"``: the L1 fit ``first`` refitted in L2, with its terms selected again, on the pixels that
    show one object only, where the photo is a linear camera file and the L1 fit's residual is dense
    (:mod:`.norm`); ``model["norm"]`` records the choice."""
    photo, current = first.photo, first.scene
    if photo.codes is None and not photo.jpeg and linear_file(photo.target):
        render = _native.render(current, current.width, current.height, 1, plan.footprint != "off",
                                outlines=outlines_taken(first.stages, plan.silhouettes))
        chosen = norm_verdict(dense_residual(render, photo.target, photo.use, None, photo.sigma, [0.0, 0.0, 0.0],
                                             clip=options.clip))
    else:
        chosen = not_linear_verdict()
    if chosen["used"] != "l2":
        first.model["norm"] = chosen
        return first
    dense_photo = photo.within(representable_pixels(plan.scene, photo.use, photo.ids))
    dense = new_stages(options, dense_photo, plan.work, plan.budget, plan.ident, norm="l2",
                       space=options.first_space, footprint=plan.footprint, silhouettes=plan.silhouettes)
    model = plan.new_model()
    current = select_terms(options, dense_photo, plan, dense, model, encoding=first.model.get("encoding", {}))
    dense.stages[:0] = first.stages.stages
    dense.evaluations += first.stages.evaluations
    chosen.update(first_fit_terms=first.model["terms"],
                  outline_pixels_left_out=photo.pixels - dense_photo.pixels)
    model["norm"] = chosen
    return Fitted(current, dense, dense_photo, model)
