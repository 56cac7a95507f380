"""A refit near the light a first fit found, with a smaller search (:func:`refit_stages`): with the terms a
photo selected (:mod:`.terms`), or a JPEG's in the sRGB space (:func:`jpeg_refit`)."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from .. import _native
from ..scene import Scene
from .bounds import narrowed, restore_bounds
from .identifiability import identifiability
from .jpeg import codes_alike
from .observation import Observation
from .options import FitOptions
from .plan import new_stages
from .protocol import PROTOCOLS, budget, choose_method, searched_paths
from .result import StageResult
from .stages import Stages

__all__ = ["REFIT_BUDGET", "REFIT_FRACTION", "jpeg_refit", "refit_stages", "stays_linear"]

#: The refit with the terms a photo selected searches near the light found without them (its box shrunk to
#: +-REFIT_FRACTION of each range around it: the terms move the light by centimetres, the box by metres)
#: with a smaller search (population, generations, polish).
REFIT_FRACTION = 0.15
REFIT_BUDGET = (8, 6, 120)


def refit_stages(options: FitOptions, photo: Observation, stages: Stages, box: Scene, space: str) -> Stages | None:
    """The stages of one refit of ``box`` (a box around the light ``stages`` found) in ``space`` with the
    smaller search (REFIT_BUDGET, scaled to the searched parameters as the protocol's own budget is: a
    freed shininess adds one); None where that budget takes the closed form no more."""
    k = max(1.0, len(box.param_names(searched_paths(box.fit_paths))) / PROTOCOLS["rtloop"]["per_dimensions"])
    o = options
    b2 = budget(o.protocol, space, round(REFIT_BUDGET[0] * k) if o.population is None else o.population,
                round(REFIT_BUDGET[1] * k) if o.generations is None else o.generations, o.f, o.cr)
    choose_method(b2, box, box.fit_paths, population=b2.population, generations=b2.generations,
                  optimizer=o.optimizer, polish=round(REFIT_BUDGET[2] * k * k) if o.polish is None else o.polish)
    if b2.method != "projected":
        return None
    return new_stages(options, photo, box, b2, identifiability(box, box.fit_paths), norm=stages.norm, space=space,
                      footprint=stages.footprint, report_names=stages.all_names,
                      silhouettes=stages.silhouettes)


def stays_linear(model: dict[str, Any], codes: float) -> None:
    """Record in ``model`` that a JPEG (its blocks' error ``codes``) stays in the linear space."""
    model["space"] = {"used": "linear", "jpeg_error_codes": codes,
                      "why": "a JPEG, but the model needs more than direct light: the linear loss, as the sRGB "
                             "one would weigh up the dark pixels where the model's approximations err"}


def jpeg_refit(current: Scene, work: Scene, stages: Stages, first: StageResult, model: dict[str, Any], seed: int,
               *, codes: float | None, env: bool, refit: Callable[[Scene, str], Stages | None],
               photo: Observation) -> Scene:
    """For ``space="auto"``: a JPEG (``codes``: :func:`.jpeg.jpeg_codes`, None for another photo) that the
    base model explains (no term selected or given) refitted in the sRGB space, near the light found (as the
    terms' refit). JPEG quantises the DCT of the sRGB-encoded values, so its errors are alike in code values
    and in linear radiance grow with the brightness: the sRGB loss weighs each pixel by what the file knows
    about it. On the JPEG-40 variants of the 11 direct Mitsuba photos the median light error falls 24.5 ->
    11.7 mm (docs/accuracy.md, "Noisy and JPEG photos"). Where the model lacks something the photo shows (a
    desk lamp's soft shadow, a coat), the sRGB loss weighs up the dark pixels where that shows most
    (lamp-desk: 10 -> 30 mm), so a photo with extra terms stays linear. So does a JPEG whose errors are not
    alike in code values (:func:`.jpeg.codes_alike`: a noisy sensor's, its dark pixels' read noise and its
    clipping at 0 many codes, which the sRGB loss would follow: the Bayer fixtures 55 and 25 mm in sRGB,
    13 and 12 mm linear). ``model["space"]`` records the choice."""
    if codes is None:
        return current
    if len(model["terms"]) > 1 or env:
        stays_linear(model, codes)
        return current
    render = _native.render(current, current.width, current.height, 1, stages.footprint != "off")
    alike = codes_alike(render, photo.target, photo.use, photo.saturated)
    if alike["alike"] is False:
        model["space"] = {"used": "linear", "jpeg_error_codes": codes, "codes": alike,
                          "why": (f"a JPEG, but its errors are not alike in code values: the first fit's residual "
                                  f"spreads {alike['dark_spread_codes']:.2g} codes in the dark pixels against "
                                  f"{alike['bright_spread_codes']:.2g} in the bright ones, which the sRGB loss would "
                                  "weigh up: the linear loss")}
        return current
    box = narrowed(work.with_params(list(first.x), first.paths), first.paths, REFIT_FRACTION)
    more = refit(box, "srgb")
    if more is None:
        return current
    candidate = more.projected(seed, name="light+colour (srgb)", from_scene=True)
    stages.stages += more.stages
    stages.evaluations += more.evaluations
    model["space"] = {"used": "srgb", "jpeg_error_codes": codes, "codes": alike,
                      "why": (f"a JPEG (its blocks err by {codes:.2g} codes RMS) that direct light explains: "
                              "refitted in the sRGB space, where its errors are alike")}
    return restore_bounds(candidate, work)
