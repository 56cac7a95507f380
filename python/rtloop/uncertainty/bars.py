"""The error bars a fit reports (``u["bars"]``): the block sandwich's sigma (``u["robust"]``; none where it
cannot be formed, with its reason), widened by what the model lacks, and every parameter the data do not
determine reported as not determined, with the reason, rather than as a sigma larger than the question.

- **What the model lacks**: the goodness verdict's structured residual (:mod:`rtloop.fit.structure`: each
  object's smooth residual beyond what fine residual leaves, over its noise floor), summed over the objects,
  is ``model_lacks``; every sigma is multiplied by ``widened_by`` = max(1, model_lacks / WIDEN_PER): in
  proportion to it. A photo the model explains (within the floor, or whose excess is texture and noise)
  keeps the sandwich's bars.
- **Not determined**: a light coordinate whose sigma exceeds LIGHT_DETERMINED of the light's distance from
  the subject or LIGHT_SIGMA_MAX_M (the direction then is what the photo fixes: ``light_distance``), or every light coordinate
  where that distance is not determined; any other parameter (a product, the intensity, an albedo, an
  environment) whose sigma exceeds a uniform distribution's over its bounds (range / sqrt(12): the photo
  says no more than the bounds), or, for a product, its own value (a colour known to no better than 100 %).
  Each gets ``sigma`` None and ``why``. Where the fit took a tone curve, every colour product is not
  determined (:func:`tone_curve_products`): the curve and the products share one scale.
- **The light's direction and distance** (``light_distance``): the sandwich's, widened alike, the distance
  again not determined where its widened sigma exceeds :data:`~.light.DISTANCE_DETERMINED` of it; this is
  what a photo of a far light fixes when its coordinates are not determined.
"""

from __future__ import annotations

import math
from typing import Any

from .light import DISTANCE_DETERMINED

__all__ = ["LIGHT_DETERMINED", "LIGHT_SIGMA_MAX_M", "WIDEN_PER", "error_bars", "model_lacks", "tone_curve_products"]

#: The bars are widened by model_lacks / WIDEN_PER (at least 1): by the structured residual's own ratio to
#: the noise floor. Measured with the synthetic coverage fixtures (studies/coverage.py: 87 of 90 judged
#: photos within 3 sigma with 1; 3 of 17 camera-class photos beyond with 3) and real photographs
#: (studies/real_photos.py --bars, the DiLiGenT ball: 99 % of 96 lights within 3 sigma with 1 and the
#: bias-reduced sandwich, the sandwich alone 95 %).
WIDEN_PER = 1.0

#: A light coordinate is determined when its sigma is at most this fraction of the light's distance from
#: the subject (one eighth: about 7 degrees of direction) ...
LIGHT_DETERMINED = 0.125
#: ... and at most this many metres (scenes are in metres): a light placed to no better than half a metre
#: is not placed, whatever its distance.
LIGHT_SIGMA_MAX_M = 0.5

_LIGHT = ("light.position.x", "light.position.y", "light.position.z")

#: Why a colour product has no bar where the fit took a tone curve: the curve and the products share a scale.
TONE_CURVE_PRODUCTS = ("a tone curve was fitted: it and the colours share one scale, so the photo fixes the colours' "
                       "ratios, not their common level")


def model_lacks(goodness: dict[str, Any] | None) -> float:
    """The structured residual over the noise floor, all objects together (0 where the goodness of fit
    found the residual within its floor or computed no split)."""
    per = (goodness or {}).get("per_object") or {}
    excess = floor = 0.0
    for name, v in per.items():
        s = v.get("structure")
        if name == "background" or not s or s.get("floor") is None:
            continue
        excess += float(s["excess"])
        floor += float(s["floor"])
    return excess / floor if floor > 0 else 0.0


def error_bars(u: dict[str, Any], d: dict[str, Any], bounds: dict[str, tuple[float, float]],
               values: dict[str, float], goodness: dict[str, Any] | None) -> dict[str, Any]:
    """The reported bars from an uncertainty estimate ``u`` (its robust sigma and product sigma), the fitted scene dict ``d``, each parameter's ``bounds`` and fitted ``values`` (by name;
    products by ``products.<object>.<c>``), and the fit's ``goodness``. Returns ``sigma`` (name: float or
    None), ``not_determined`` (name: why), ``widened_by``, ``model_lacks`` and ``source``."""
    base = u.get("robust") or {}
    source = "robust"
    sig = {**(base.get("sigma") or {}), **(base.get("product_sigma") or {})}
    lacks = model_lacks(goodness)
    widen = max(1.0, lacks / WIDEN_PER)
    out: dict[str, float | None] = {}
    why: dict[str, str] = {}
    distance = base.get("light_distance") or u.get("light_distance")
    for name, s in sig.items():
        if s is None:
            out[name] = None
            why[name] = base.get("why_none") or ("no used pixel fixes it, or the image fixes only a combination with "
                                                 "others (see warnings)")
            continue
        s = float(s) * widen
        out[name] = s
        if name in _LIGHT and distance:
            r = float(distance.get("distance_m") or 0.0)
            if not distance.get("distance_determined", True):
                why[name] = ("the light's distance is not determined: " + distance.get("why", "")
                             ).rstrip(": ") + "; its direction is (light_distance)"
            elif r > 0 and s > LIGHT_DETERMINED * r:
                why[name] = (f"its sigma ({s:.3g} m) exceeds {LIGHT_DETERMINED:g} of the light's distance from the "
                             f"subject ({r:.3g} m): the photo does not place the light along this axis")
            elif s > LIGHT_SIGMA_MAX_M:
                why[name] = (f"its sigma ({s:.3g} m) exceeds {LIGHT_SIGMA_MAX_M:g} m: the photo does not place the "
                             "light along this axis")
        elif name in bounds:
            lo, hi = bounds[name]
            spread = (hi - lo) / math.sqrt(12.0) if math.isfinite(hi - lo) else math.inf
            if s > spread:
                why[name] = (f"its sigma ({s:.3g}) exceeds a uniform one over its bounds [{lo:.3g}, {hi:.3g}] "
                             f"({spread:.3g}): the photo says no more than the bounds")
        if name not in why and name.startswith("products.") and name in values and s > abs(values[name]):
            why[name] = (f"its sigma ({s:.3g}) exceeds its value ({values[name]:.3g}): the photo does not fix this "
                         "colour (an object too dark, too small or unlit)")
        if name in why:
            out[name] = None
    bars = {"sigma": out, "not_determined": why, "widened_by": widen, "model_lacks": lacks, "source": source}
    if distance:
        bars["light_distance"] = widened_distance(distance, widen)
    return {**bars,
            "rule": (f"the {source} sigma times max(1, model_lacks / {WIDEN_PER:g}); a light coordinate over "
                     f"{LIGHT_DETERMINED:g} of the light's distance or {LIGHT_SIGMA_MAX_M:g} m, or another parameter "
                     "over a uniform sigma on its bounds (a product over its value), is not determined")}


def widened_distance(distance: dict[str, Any], widen: float) -> dict[str, Any]:
    """``light_distance`` (:func:`.light.light_distance`) with its sigmas times ``widen``, and the distance not
    determined where its widened sigma exceeds DISTANCE_DETERMINED of it."""
    out = dict(distance)
    if out.get("direction_sigma_deg") is None or out.get("distance_sigma_m") is None:
        return out
    out["direction_sigma_deg"] = float(out["direction_sigma_deg"]) * widen
    out["distance_sigma_m"] = float(out["distance_sigma_m"]) * widen
    r = float(out["distance_m"])
    if out.get("distance_determined") and not out["distance_sigma_m"] <= DISTANCE_DETERMINED * r:
        out["distance_determined"] = False
        out["why"] = (f"the distance's sigma ({out['distance_sigma_m']:.3g} m, widened {widen:.2g}x for what the "
                      f"model lacks) exceeds {DISTANCE_DETERMINED:.0%} of the distance ({r:.3g} m): the shading fixes "
                      "the light's direction, not how far it is")
    return out


def tone_curve_products(bars: dict[str, Any] | None) -> None:
    """Mark every colour product of ``bars`` (a fit's ``uncertainty["bars"]``) not determined, with the reason:
    the fit took a tone curve (fit/camera.py), which shares one scale with the colours."""
    if not bars:
        return
    for name in [n for n in bars.get("sigma", {}) if n.startswith("products.")]:
        bars["sigma"][name] = None
        bars.setdefault("not_determined", {})[name] = TONE_CURVE_PRODUCTS
