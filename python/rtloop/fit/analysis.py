"""A fit's result put together (:func:`fit_result`: the gauges released, a grey card's scale) and judged
(:func:`analyse`: the goodness of fit, the framing, the values at their bounds, the uncertainty)."""

from __future__ import annotations

import time
import warnings

import numpy as np

from .. import _native
from ..errors import RtloopError, RtloopWarning
from .bounds import at_bounds
from .framing import framing_check, mismatch_verdict
from .gauge import release_gauges
from .goodness import goodness
from .method import Fitted
from .observation import Observation
from .options import FitOptions
from .plan import Plan
from .products import products
from .reference import pin_to_reference
from .result import FitResult

__all__ = ["analyse", "fit_result"]


def fit_result(fitted: Fitted, options: FitOptions, photo: Observation, plan: Plan, t0: float
               ) -> tuple[FitResult, list[str]]:
    """The result of the method's fit ``fitted`` of ``photo`` (as observed), and the doubts to warn of."""
    current, model, ident = release_gauges(fitted.scene, plan.given, plan.held), fitted.model, plan.ident
    doubts = list(photo.doubts)
    if model.get("encoding", {}).get("suspect"):
        doubts.append(model["encoding"]["doubt"])
    if "interreflection" in model["terms"] and ident.get("degenerate"):
        ident = {**ident, "degenerate": False,
                 "note": "the bounce between the objects is as bright as their albedos themselves, so the photo "
                         "fixes the light's intensity and the albedos, not only their products (weakly where the "
                         "bounce is faint: see the uncertainty)"}
    pinned = None
    if photo.card is not None:
        current, pinned = pin_to_reference(current, photo.target, photo.card[0], photo.card[1])
        ident = {**ident, "degenerate": False, "note": pinned["note"]}
        if "warning" in pinned:
            doubts.append(pinned["warning"])
    settings = dict(plan.settings)
    if "norm" in model:
        settings["norm"] = model["norm"]["used"]
    if model.get("space", {}).get("used") == "srgb":
        settings["space"] = "srgb"
    values = current.get_params(plan.given.fit_paths)
    result = FitResult(scene=current, x={n: float(v) for n, v in zip(plan.given.param_names(), values)},
                       stages=fitted.stages.stages, evaluations=fitted.stages.evaluations,
                       seconds=time.perf_counter() - t0, protocol=options.protocol, seed=options.seed,
                       products=products(current), identifiability=ident, settings=settings, model=model,
                       reference=pinned)
    return result, doubts


def analyse(result: FitResult, options: FitOptions, photo: Observation, plan: Plan, doubts: list[str]) -> None:
    """``result``'s goodness of fit against ``photo`` (as the method's last fit used it) and its framing,
    the doubts (``doubts`` and the values at their bounds) warned of, and the uncertainty."""
    current = result.scene
    # The model the fit compared with the photo, for the goodness of fit and the uncertainty's residual, and
    # the pixel-centre render the uncertainty's finite differences start from (the same where the fit took no
    # footprint; else both in one pass, the light a footprint does not change shaded once).
    outlines = bool(result.settings.get("silhouettes", False))
    if plan.footprint == "off":
        as_compared = at_optimum = _native.render(current, current.width, current.height, 1, False)
    elif options.with_sigma:
        at_optimum, as_compared = _native.render_centre_and_footprint(current, outlines=outlines)
    else:
        as_compared = _native.render(current, current.width, current.height, 1, True, outlines=outlines)
        at_optimum = None
    result.goodness = goodness(current, photo.target, photo.use, clip=options.clip, render=as_compared,
                               sigma=photo.sigma, blocking=photo.blocking, encoding=photo.encoding,
                               codes=photo.codes, split=options.with_sigma, ids=lambda: photo.ids)
    result.goodness["framing"] = framing_check(current, photo.target, photo.use, result.goodness["ratio"],
                                               options.framing, as_compared)
    if result.goodness["framing"]["mismatch"]:
        result.goodness["verdict"] = mismatch_verdict(result.goodness["framing"])
    doubts += at_bounds(current, [p for p in plan.given.fit_paths if p not in plan.held])  # a held gauge was not fitted
    for d in doubts:
        warnings.warn(d, RtloopWarning, stacklevel=3)  # at the call of fit()
    result.warnings = doubts
    if options.with_sigma:
        _uncertainty(result, options, photo, at_optimum, as_compared)


def _uncertainty(result: FitResult, options: FitOptions, photo: Observation, at_optimum: np.ndarray | None,
                 as_compared: np.ndarray) -> None:
    """``result.uncertainty``: the Gauss-Newton and sandwich error bars, and with ``uncertainty="bootstrap"``
    the block bootstrap's; a failure recorded in its ``warnings``."""
    from ..uncertainty import estimate_uncertainty
    from ..uncertainty.nuisance import current

    try:  # a photo a camera term corrected (.camera): the term's parameters profiled out (``current()``)
        result.uncertainty = estimate_uncertainty(result, photo.target, clip=options.clip, mask=photo.mask,
                                                  render=at_optimum, compared=as_compared, nuisance=current())
    except RtloopError as e:
        result.uncertainty = {"method": "gauss-newton", "sigma": {}, "warnings": [str(e)]}
    if options.uncertainty == "bootstrap":
        from ..uncertainty.bootstrap import block_bootstrap

        try:
            shift = (result.uncertainty.get("robust") or {}).get("footprint_shift")
            result.uncertainty["bootstrap"] = block_bootstrap(result, photo.target, photo.use, seed=options.seed,
                                                              threads=options.threads, shift=shift,
                                                              callback=options.callback)
        except RtloopError as e:
            result.uncertainty["bootstrap"] = {"method": "block-bootstrap", "sigma": {}, "warnings": [str(e)]}
