"""Ambient or environment: a scene that declares ``ambient`` light (unoccluded, the same everywhere) may mean
the room's light, which the objects occlude (darker under a ball and between objects). Where the fit with
the declared ambient leaves more than the noise, the same radiance as an occluded environment
(``render::environment``: the ambient's value, or its bounds where it is free) is compared at the light found,
and where it lowers the closed-form loss by MIN_GAIN or more the light is refitted with it; the model
records which it used and the evidence (``fit_report.model.constant``)."""

from __future__ import annotations

import json
from typing import Any

import numpy as np

from ..scene import Scene, scene_to_dict
from .selection import MIN_GAIN, closed_form_loss

__all__ = ["as_environment", "compare_constant"]


def as_environment(scene: Scene) -> Scene:
    """``scene`` with its ambient light as an occluded environment of the same radiance (a free ambient's
    bounds become the environment's), the ambient 0."""
    d = scene_to_dict(scene)
    fit = dict(d.get("fit", {}))
    if "ambient" in fit:
        fit["environment"] = fit.pop("ambient")
    d = {**d, "environment": list(d["ambient"]), "ambient": [0.0, 0.0, 0.0], "fit": fit}
    return Scene(json.dumps(d, allow_nan=False))


def declares_ambient(scene: Scene) -> bool:
    """Whether the scene declares ambient light (a value or free) and no environment."""
    d = scene_to_dict(scene)
    return ("ambient" in scene.fit_paths or any(v != 0 for v in d.get("ambient", [0, 0, 0]))) and not (
        "environment" in scene.fit_paths or any(v != 0 for v in d.get("environment", [0, 0, 0])))


def compare_constant(work: Scene, where: list[str], x: list[float], target: np.ndarray,
                     pixels: np.ndarray | None, **kw: Any) -> dict[str, Any]:
    """The closed-form loss at the light ``x`` (of ``where``) with the declared ambient and with the same
    radiance occluded (:func:`as_environment`), on ``pixels``; ``kw``: :func:`.selection.closed_form_loss`'s
    clip, norm, space, threads and saturated. ``use_environment`` where the environment lowers it by MIN_GAIN
    or more (the same number of unknowns: no information criterion needed); ``refit_blocked`` (why) where the
    ambient is free: its fitted values keep their names, so it is only compared."""
    amb = closed_form_loss(work.with_params(x, where), where, [x], target, pixels, environment=True, **kw)[0]
    env_scene = as_environment(work)
    env = closed_form_loss(env_scene.with_params(x, where), where, [x], target, pixels, environment=True, **kw)[0]
    gain = (amb - env) / amb if amb > 0 else 0.0
    out = {"declared": "ambient", "loss_ambient": float(amb), "loss_environment": float(env), "gain": float(gain),
           "use_environment": bool(gain >= MIN_GAIN),
           "rule": (f"the declared ambient's radiance as an occluded environment, compared at the light found: "
                    f"used when it lowers the loss by at least {MIN_GAIN:.0%} (the photo darker under and between "
                    "the objects than an unoccluded ambient allows)")}
    if "ambient" in work.fit_paths and out["use_environment"]:
        out["refit_blocked"] = ("the ambient is a fitted parameter (its values are reported by that name): not "
                                "refitted as an environment; give it a value, or free `environment` instead, to "
                                "fit the occluded room light")
    return out
