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

# Immerkaer's Laplacian-difference kernel [[1, -2, 1], [-2, 4, -2], [1, -2, 1]]: zero on constant and
# linear ramps, 6 sigma (the root of its squared weights) for white noise.


def noise_sigma(image: np.ndarray) -> np.ndarray:
    """Per channel, the photo's pixel noise (linear units) from flat regions: the median absolute response
    of Immerkaer's kernel (which cancels smooth shading) over 0.6745 x 6, so edges, a minority of pixels,
    do not count (J. Immerkaer, "Fast noise variance estimation", CVIU 1996, made robust with the median)."""
    x = np.asarray(image, np.float32)
    h, w = x.shape[:2]
    if h < 3 or w < 3:
        return np.zeros(3)
    # The kernel is the outer product of [1, -2, 1] with itself: two second differences.
    dx = x[:, :-2] - 2 * x[:, 1:-1] + x[:, 2:]
    acc = dx[:-2] - 2 * dx[1:-1] + dx[2:]
    return np.median(np.abs(acc).reshape(-1, 3), axis=0).astype(np.float64) / (0.6745 * 6.0)


def goodness(scene: Any, target: np.ndarray, use: np.ndarray | None, clip: bool = True,
             render: np.ndarray | None = None) -> dict[str, Any]:
    """The residual of ``scene``'s render against ``target`` (L1 over the used, unsaturated pixels) over
    its floor: per pixel and channel the larger of the 8-bit quantisation's mean error (a quarter code
    step) and the measured noise's (sigma x sqrt(2/pi)). With a verdict, and where the model falls short of
    the floor, per object its share of the excess (``per_object``, empty otherwise). ``render``: the
    scene's render (spp 1) when the caller has it."""
    if render is None:
        render = _native.render(scene, scene.width, scene.height, 1)
    model = np.minimum(render, np.float32(1.0)) if clip else render
    # float32 throughout: the floor is a quarter code step, far above float32's resolution.
    t = np.asarray(target, np.float32).reshape(-1, 3)
    m = np.asarray(model, np.float32).reshape(-1, 3)
    keep = (t[:, 0] < SATURATED) & (t[:, 1] < SATURATED) & (t[:, 2] < SATURATED)
    if use is not None:
        keep &= np.isin(np.arange(t.shape[0]), np.asarray(use))
    tk = t[keep]
    e = encode(tk, np.float32)
    half = np.float32(0.5 / 255)
    quant = np.float32(0.25) * (decode(np.minimum(e + half, np.float32(1))) - decode(np.maximum(e - half, np.float32(0))))
    sigma = noise_sigma(target)
    floor = np.maximum(quant, (sigma * math.sqrt(2.0 / math.pi)).astype(np.float32)[None, :])
    resid = np.abs(m[keep] - tk)
    total, fl = float(resid.sum(dtype=np.float64)), float(floor.sum(dtype=np.float64))
    ratio = total / fl if fl > 0 else float("inf")
    per: dict[str, Any] = {}
    if ratio >= EXPLAINED_RATIO and math.isfinite(ratio):  # where the excess lies: only worth a look then
        ids = np.asarray(_native.object_ids(scene)).reshape(-1)[keep]
        for k, name in [*enumerate(scene.object_names), (-1, "background")]:
            sel = ids == k
            if sel.any():
                r, f = float(resid[sel].sum(dtype=np.float64)), float(floor[sel].sum(dtype=np.float64))
                per[name] = {"pixels": int(sel.sum()), "ratio": r / f if f > 0 else float("inf"),
                             "share_of_excess": max(r - f, 0.0)}
        excess = sum(v["share_of_excess"] for v in per.values())
        for v in per.values():
            v["share_of_excess"] = v["share_of_excess"] / excess if excess > 0 else 0.0
    out: dict[str, Any] = {"ratio": ratio, "loss": total, "floor": fl, "noise_sigma": [float(s) for s in sigma],
                           "pixels": int(keep.sum()), "per_object": per, "explained_below": EXPLAINED_RATIO}
    if not keep.any() or not math.isfinite(ratio):
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
