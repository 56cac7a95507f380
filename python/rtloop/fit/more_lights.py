"""The default fit's number of lights: one light, and more only where the photo asks for them.

``fit(scene, image)`` without ``lights`` fits one light (the ordinary fit). Where that fit does not explain
the photo (its goodness ratio at or above EXPLAINED_RATIO, with a smooth residual on some object: a
cheap test, the verdict the fit computes anyway: :func:`gate`), the lights fit tries a further light on half
the pixels and keeps it only where the other half say so (:func:`.lights.held_out_counts`, ``"auto"``'s
rule, up to AUTO_LIMIT lights). A kept light makes the result a :class:`.lights.LightsFit`; otherwise the
one-light result is returned unchanged, with the test and its evidence in ``result.model["lights"]``.
docs/methods.md, "Several lights".
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np

from ..errors import RtloopError
from ..scene import Scene, load_scene, scene_to_dict
from .goodness import EXPLAINED_RATIO
from .inputs import objective
from .lights import AUTO_GAIN, AUTO_LIMIT, LightsFit, attach_errors, held_out_counts
from .result import FitResult

__all__ = ["MIN_SHARE", "gate", "more_lights"]

#: A further light the default fit adds must carry this share of the objects' diffuse light at least (its
#: products over all the lights' products): a light that lights no matte surface (its diffuse products 0,
#: a lobe's only) stands in for a mismatch of the highlight, not for a lamp.
MIN_SHARE = 0.02


def gate(result: FitResult) -> dict[str, Any]:
    """The test on the one-light fit: ``fires`` where its residual is at least EXPLAINED_RATIO times the
    photo's noise floor and some object's excess is smooth (``structured``: the objects whose residual
    :mod:`.goodness` does not call texture or noise)."""
    g = result.goodness or {}
    ratio = g.get("ratio")
    structured = sorted(name for name, what in (g.get("explained") or {}).items() if what != "texture/noise")
    fires = ratio is not None and ratio >= EXPLAINED_RATIO and bool(structured)
    return {"ratio": ratio, "explained_below": EXPLAINED_RATIO, "structured": structured, "fires": bool(fires)}


def _refused_arguments(args: dict[str, Any], defaults: dict[str, Any], taken: tuple[str, ...]) -> str | None:
    """Why the lights fit cannot take this call (an argument it does not take given), or None."""
    for name in taken:
        value, default = args[name], defaults[name]
        if value is not None if default is None else not (type(value) is type(default) and value == default):
            return f"{name} given, which the lights fit does not take"
    if args["uncertainty"] == "bootstrap":
        return "uncertainty 'bootstrap' asked, which the lights fit does not take"
    return None


def _trial_scene(scene: Scene, result: FitResult) -> Scene:
    """The scene the further lights are tried in: as given, but with the lobes the one-light fit found (their
    specular and shininess held: the lights fit solves a lobe's product, not its shininess)."""
    d = scene_to_dict(scene)
    fitted = {o["name"]: o["material"] for o in result.scene.to_dict()["objects"]}
    for o in d["objects"]:
        m = fitted.get(o["name"], {})
        if float(m.get("specular", 0.0)) > 0:
            o["material"].update(specular=float(m["specular"]), shininess=float(m["shininess"]))
    d["fit"] = {p: v for p, v in d["fit"].items() if not p.endswith((".specular", ".shininess"))}
    return load_scene(d)


def more_lights(result: FitResult, scene: Scene, image: np.ndarray, mask: Any, args: dict[str, Any],
                defaults: dict[str, Any], taken: tuple[str, ...], t0: float) -> FitResult | LightsFit:
    """The default fit's answer: ``result`` (the one-light fit) unchanged where :func:`gate` does not fire;
    else a further light tried, and the lights fit returned where held-out pixels keep one (``args``:
    fit()'s arguments, ``defaults`` its defaults, ``taken``: those the lights fit must see at their
    defaults; ``t0``: when the fit began)."""
    test = gate(result)
    if not test["fires"]:
        return result
    why = _refused_arguments(args, defaults, taken)
    found: LightsFit | None = None
    if why is None:
        try:
            trial = _trial_scene(scene, result)
            target, use = objective(scene, image, mask, [])
            found, pixels = held_out_counts(trial, target, seed=args["seed"], limit=AUTO_LIMIT, mask=use,
                                            min_share=MIN_SHARE, threads=args["threads"])
        except RtloopError as e:  # a scene the lights fit does not take (a coat, a directional light, ...)
            why = str(e)
    if found is None or len(found.lights) == 1:
        record = {**test, "tried": why is None, "limit": AUTO_LIMIT, "gain": AUTO_GAIN, "kept": 1}
        record.update({"evidence": found.evidence} if found is not None else {"why": why})
        if found is not None:
            record["why"] = (f"a further light did not lower the held-out error by {AUTO_GAIN:.0%} while "
                             f"carrying {MIN_SHARE:.0%} of the light: the one-light fit is kept")
            record["min_share"] = MIN_SHARE
        result.model["lights"] = record
        result.seconds = time.perf_counter() - t0
        return result
    attach_errors(trial, found, target, pixels, args["seed"])
    found.gate = {**test, "tried": True, "limit": AUTO_LIMIT, "gain": AUTO_GAIN, "min_share": MIN_SHARE,
                  "kept": len(found.lights)}
    found.seconds = time.perf_counter() - t0
    return found
