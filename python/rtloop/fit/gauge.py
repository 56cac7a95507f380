"""Light colour and exposure where the photo cannot tell them from the albedos: held for the closed form
(the products P = exposure x intensity x colour x albedo absorb them), exposure first measured from the
background's pixels when the photo shows a lit background."""

from __future__ import annotations

import json
from typing import Any

import numpy as np

from .. import _native
from .._pixels import SATURATED
from ..scene import Scene, scene_to_dict

__all__ = ["hold_gauges", "release_gauges"]


def hold_gauges(scene: Scene, paths: list[str], target: np.ndarray, use: np.ndarray | None, *,
                bounce: bool = False) -> tuple[Scene, dict[str, str]]:
    """``scene`` without the fit entries of ``light.color`` and ``exposure`` where they only rescale the
    albedos, and why each is held ({} and ``scene`` itself when none is, or when the closed form would not
    apply even then). Every object's albedo must be free; a lobe (its highlight has the light's colour)
    or interreflection (given, or ``bounce``: forced on; it sees the albedo itself) keeps ``light.color``
    free."""
    d = scene_to_dict(scene)
    if not any(p in paths for p in ("light.color", "exposure")):
        return scene, {}
    if not all(f"objects.{o['name']}.albedo" in paths for o in d["objects"]):
        return scene, {}
    holds: dict[str, str] = {}
    lobes = [o["name"] for o in d["objects"]
             if o["material"].get("specular", 0) != 0 or f"objects.{o['name']}.specular" in paths]
    if "light.color" in paths and not lobes and not (bounce or d.get("interreflection")):
        holds["light.color"] = ("the albedos absorb it (each product is exposure x intensity x colour x albedo): "
                                "held at the scene's value (inside its bounds)")
    if "exposure" in paths:
        measured = _exposure_from_background(scene, d, target, use)
        if measured is None:
            holds["exposure"] = ("no lit background shows it apart from the albedos: held at the scene's value "
                                 "(inside its bounds), which the products absorb")
        elif measured == "saturated":
            pass
        else:
            lo, hi = scene.bounds(["exposure"])[0]
            d["exposure"] = float(min(max(measured, lo), hi))
            holds["exposure"] = (f"measured from the background's pixels ({d['exposure']:.6g}: photo / background "
                                 "radiance, their weighted median) and held")
    if not holds:
        return scene, {}
    # held inside their bounds (a scene may start outside them)
    if "light.color" in holds:
        d["light"]["color"] = [float(min(max(v, lo), hi))
                               for v, (lo, hi) in zip(d["light"]["color"], scene.bounds(["light.color"]))]
    if "exposure" in holds:
        lo, hi = scene.bounds(["exposure"])[0]
        d["exposure"] = float(min(max(d["exposure"], lo), hi))
    d["fit"] = {k: v for k, v in d["fit"].items() if k not in holds}
    reduced = Scene(json.dumps(d, allow_nan=False))
    if _native.projection_blocker(reduced, reduced.fit_paths) is not None:
        return scene, {}
    return reduced, holds


def release_gauges(fitted: Scene, original: Scene, holds: dict[str, str]) -> Scene:
    """``fitted`` with the held entries back in its fit section (their values as held)."""
    if not holds:
        return fitted
    d = scene_to_dict(fitted)
    d["fit"] = {**d["fit"], **{p: v for p, v in scene_to_dict(original)["fit"].items() if p in holds}}
    return Scene(json.dumps(d, allow_nan=False))


def _exposure_from_background(scene: Scene, d: dict[str, Any], target: np.ndarray, use: np.ndarray | None
                              ) -> float | str | None:
    """The exposure that makes exposure x background match the photo's background pixels (L1: the median of
    photo / background weighted by the background), None when no lit background is visible, "saturated"
    when every such pixel is clipped."""
    bg = np.asarray(d["background"], float)
    if not (bg > 0).any():
        return None
    seen = (_native.object_ids(scene) < 0).ravel()
    if use is not None:
        keep = np.zeros_like(seen)
        keep[use] = True
        seen &= keep
    if not seen.any():
        return None
    y = target.reshape(-1, 3)[seen].astype(np.float64)
    ratios, weights = [], []
    for c in range(3):
        if bg[c] > 0:
            ok = y[:, c] < SATURATED
            ratios.append(y[ok, c] / bg[c])
            weights.append(np.full(int(ok.sum()), bg[c]))
    r, w = np.concatenate(ratios), np.concatenate(weights)
    if r.size == 0:
        return "saturated"
    order = np.argsort(r)
    cum = np.cumsum(w[order])
    return float(r[order][np.searchsorted(cum, 0.5 * cum[-1])])
