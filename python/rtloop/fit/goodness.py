"""Goodness of fit: the fitted render's residual against the photo's own noise floor (8-bit quantisation
and the noise measured in the photo), as one ratio and a verdict that says where the excess lies."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from .. import _native
from .._pixels import SATURATED
from .._srgb import decode, encode

__all__ = ["EXPLAINED_RATIO", "goodness", "noise_sigma"]

#: A residual within this many times the noise floor is explained to the noise level (the same factor as
#: the term selection's screen, :data:`rtloop.fit.selection.EXPLAINED`).
EXPLAINED_RATIO = 3.0

# Immerkaer's Laplacian-difference kernel: zero on constant and linear ramps, 6 sigma for white noise.
_KERNEL = np.array([[1.0, -2.0, 1.0], [-2.0, 4.0, -2.0], [1.0, -2.0, 1.0]])


def noise_sigma(image: np.ndarray) -> np.ndarray:
    """Per channel, the photo's pixel noise (linear units) from flat regions: the median absolute response
    of Immerkaer's kernel (which cancels smooth shading) over 0.6745 x 6, so edges, a minority of pixels,
    do not count (J. Immerkaer, "Fast noise variance estimation", CVIU 1996, made robust with the median)."""
    x = np.asarray(image, np.float64)
    h, w = x.shape[:2]
    if h < 3 or w < 3:
        return np.zeros(3)
    acc = np.zeros((h - 2, w - 2, 3))
    for dy in range(3):
        for dx in range(3):
            acc += _KERNEL[dy, dx] * x[dy : dy + h - 2, dx : dx + w - 2]
    return np.median(np.abs(acc).reshape(-1, 3), axis=0) / (0.6745 * 6.0)


def goodness(scene: Any, target: np.ndarray, use: np.ndarray | None, clip: bool = True) -> dict[str, Any]:
    """The residual of ``scene``'s render against ``target`` (L1 over the used, unsaturated pixels) over
    its floor: per pixel and channel the larger of the 8-bit quantisation's mean error (a quarter code
    step) and the measured noise's (sigma x sqrt(2/pi)). With a verdict, and per object its share."""
    render = _native.render(scene, scene.width, scene.height, 1)
    model = np.minimum(render, 1.0) if clip else render
    t = np.asarray(target, np.float64).reshape(-1, 3)
    m = np.asarray(model, np.float64).reshape(-1, 3)
    ids = np.asarray(_native.object_ids(scene)).reshape(-1)
    pixels = np.arange(t.shape[0]) if use is None else np.asarray(use, np.int64)
    keep = pixels[(t[pixels] < SATURATED).all(axis=1)]
    e = encode(np.clip(t[keep], 0.0, 1.0))
    half = 0.5 / 255
    quant = 0.25 * (decode(np.minimum(e + half, 1.0)) - decode(np.maximum(e - half, 0.0)))
    sigma = noise_sigma(target)
    floor = np.maximum(quant, sigma[None, :] * math.sqrt(2.0 / math.pi))
    resid = np.abs(m[keep] - t[keep])
    total, fl = float(resid.sum()), float(floor.sum())
    ratio = total / fl if fl > 0 else float("inf")
    names = list(scene.object_names)
    per: dict[str, Any] = {}
    for k, name in [*enumerate(names), (-1, "background")]:
        sel = ids[keep] == k
        if sel.any():
            r, f = float(resid[sel].sum()), float(floor[sel].sum())
            per[name] = {"pixels": int(sel.sum()), "ratio": r / f if f > 0 else float("inf"),
                         "share_of_excess": max(r - f, 0.0)}
    excess = sum(v["share_of_excess"] for v in per.values())
    for v in per.values():
        v["share_of_excess"] = v["share_of_excess"] / excess if excess > 0 else 0.0
    out: dict[str, Any] = {"ratio": ratio, "loss": total, "floor": fl, "noise_sigma": [float(s) for s in sigma],
                           "pixels": int(keep.size), "per_object": per, "explained_below": EXPLAINED_RATIO}
    if not per or not math.isfinite(ratio):
        out["ratio"] = None
        out["verdict"] = "no unsaturated pixel to judge the fit by: every used pixel is at or above 1"
    elif ratio < EXPLAINED_RATIO:
        out["verdict"] = "the model explains this photo to the noise level"
    else:
        worst = max(per, key=lambda n: per[n]["share_of_excess"])
        out["verdict"] = (f"the residual is {ratio:.2g}x the noise floor, {per[worst]['share_of_excess']:.0%} of "
                          f"the excess on {worst}: the model does not explain this photo (the error bars do not "
                          "cover what it lacks; look at the difference image, and at a mask for what the scene "
                          "leaves out)")
    return out
