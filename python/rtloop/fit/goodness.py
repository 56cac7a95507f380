"""Goodness of fit: the fitted render's residual against the photo's own noise floor (8-bit quantisation
and the noise measured in the photo), as one ratio and a verdict that says where the excess lies."""

from __future__ import annotations

import functools
import math
from collections.abc import Callable
from typing import Any

import numpy as np

from .. import _native
from .._pixels import SATURATED
from .._srgb import decode, encode, per_code
from .structure import CAUSES, residual_structure
from .._stats import median

__all__ = ["CLIPPED_SIGMAS", "EXPLAINED_RATIO", "clip_level", "encoded", "goodness", "jpeg_blocking", "noise_sigma"]

#: A residual within this many times the noise floor is explained to the noise level (the same factor as
#: the term selection's screen, :data:`rtloop.fit.selection.EXPLAINED`).
EXPLAINED_RATIO = 3.0

# Immerkaer's Laplacian-difference kernel [[1, -2, 1], [-2, 4, -2], [1, -2, 1]]: zero on constant and
# linear ramps, 6 sigma (the root of its squared weights) for white noise.


def noise_sigma(image: np.ndarray) -> np.ndarray:
    """Per channel, the photo's pixel noise (linear units) from flat regions: the median absolute response
    of Immerkaer's kernel (which cancels smooth shading) over 0.6745 x 6, so edges, a minority of pixels,
    do not count (J. Immerkaer, "Fast noise variance estimation", CVIU 1996, made robust with the median)."""
    x = np.ascontiguousarray(image, np.float32)
    h, w = x.shape[:2]
    if h < 3 or w < 3:
        return np.zeros(3)
    # The kernel is the outer product of [1, -2, 1] with itself: two second differences (the core's loop).
    return _native.noise_medians(x).astype(np.float64) / (0.6745 * 6.0)


#: JPEG's 8x8 grid: the block side in pixels.
JPEG_BLOCK = 8
#: A second difference beyond this many codes is an edge, not blocking: its square is clipped here.
JPEG_EDGE_CODES = 6.0
#: Blocking is detected when the grid lines' mean squared jump exceeds the median of phases 1-5 by this many
#: of their standard deviations (channel mean).
JPEG_DETECT_SD = 4.0
#: The JPEG's RMS error per pixel over the blocking amplitude (the per-block offset that the grid lines'
#: jumps show): the DCT's quantisation also errs inside the blocks. Measured on direct-side's JPEGs at
#: qualities 75, 50 and 30 (tests/fixtures/photos): 1.4-2.1 (green lowest, as luma weighs it most).
JPEG_ERROR_OVER_BLOCKING = 2.0


def encoded(image: np.ndarray, codes: np.ndarray | None = None) -> np.ndarray:
    """The photo's sRGB encoding in [0, 1] (clipped), float32 as ``image`` in float32: what
    :func:`jpeg_blocking` and :func:`goodness` take from it, computed once where a caller needs both.
    ``codes``: the image's 8-bit codes (:func:`rtloop._srgb.codes8`) where it has them (looked up, the
    same numbers)."""
    if codes is not None:
        return per_code(_encode32, codes)
    return _encode32(np.asarray(image, np.float32))


def _encode32(x: np.ndarray) -> np.ndarray:
    return encode(x, np.float32)


def _quarter_step(e: np.ndarray) -> np.ndarray:
    """A quarter of the 8-bit code step (the mean absolute error of rounding to a code) in linear units at
    the float32 sRGB encodings ``e``."""
    half = np.float32(0.5 / 255)
    return np.float32(0.25) * (decode(np.minimum(e + half, np.float32(1))) - decode(np.maximum(e - half, np.float32(0))))


def _quarter_step_at(x: np.ndarray) -> np.ndarray:
    """:func:`_quarter_step` at the float32 linear values ``x``."""
    return _quarter_step(_encode32(x))


def jpeg_blocking(image: np.ndarray, encoding: np.ndarray | None = None) -> dict[str, Any]:
    """JPEG blocking in a photo, measured on its 8-bit sRGB codes: along rows and columns the second
    difference across each pixel pair, d_j - (d_{j-1} + d_{j+1}) / 2 (d the first difference: a smooth
    gradient cancels), squared and clipped at an edge's (JPEG_EDGE_CODES), averaged per phase of the 8-pixel
    grid. A JPEG's blocks err by an offset each, so the pairs across its grid lines (phase 7) jump more than
    the pairs of phases 1-5 (whose neighbours are inside a block too), which are the photo's own (the grid is
    arbitrary for any other photo). Where that
    excess is significant (JPEG_DETECT_SD), the blocks' offset amplitude is sqrt(excess / 2) codes per
    channel, and the JPEG's RMS error ``error_codes`` JPEG_ERROR_OVER_BLOCKING times it; else 0.
    ``encoding``: the image's :func:`encoded` when the caller has it."""
    x = np.asarray(image, np.float32)
    h, w = x.shape[:2]
    out: dict[str, Any] = {"detected": False, "error_codes": [0.0, 0.0, 0.0], "jump_grid": None,
                           "jump_inside": None, "significance_sd": None}
    if h < 3 * JPEG_BLOCK or w < 3 * JPEG_BLOCK:
        return out
    codes = (encoded(x) if encoding is None else encoding) * np.float32(255.0)
    # Per phase k, along the rows then the columns, the mean of min(jump^2, edge^2) halved (the core's loop)
    phases = _native.jpeg_phases(np.ascontiguousarray(codes, np.float32), JPEG_BLOCK, np.float32(JPEG_EDGE_CODES ** 2))
    # phases 0 and 6 have a grid line's pair as a neighbour (in d_{j-1} or d_{j+1}): not the photo's own
    grid, others = phases[JPEG_BLOCK - 1], phases[1 : JPEG_BLOCK - 2]
    inside = median(others, axis=0)
    spread = float(others.std(axis=0).mean())
    excess = grid - inside
    sd = float(excess.mean() / spread) if spread > 0 else (float("inf") if excess.mean() > 0 else 0.0)
    out.update(jump_grid=[float(v) for v in grid], jump_inside=[float(v) for v in inside], significance_sd=sd)
    if sd >= JPEG_DETECT_SD:
        out["detected"] = True
        out["error_codes"] = [float(JPEG_ERROR_OVER_BLOCKING * np.sqrt(max(v, 0.0) / 2)) for v in excess]
    return out


#: A pixel within this many of the photo's per-pixel errors (noise and JPEG) below 1 may be a clipped one
#: that the error scattered down: the fit treats it as saturated (:func:`clip_level`).
CLIPPED_SIGMAS = 3.0


#: The clip level never falls below this: on a photo whose noise is a sizeable fraction of its range (three
#: errors would put the level below 0, where the core refuses it) a pixel above half the range may be clipped.
CLIP_LEVEL_FLOOR = 0.5


@functools.cache
def _top_code_step() -> float:
    """The 8-bit sRGB code step at 1 (254 to 255) in linear units."""
    return float(decode(np.float64(1.0)) - decode(np.float64(254 / 255)))


def clip_level(sigma: Any, blocking: dict[str, Any]) -> float:
    """The objective value from which a pixel may be clipped, given the photo's noise ``sigma`` (per
    channel, linear, :func:`noise_sigma`) and its JPEG ``blocking`` (:func:`jpeg_blocking`): 1 less
    CLIPPED_SIGMAS times the largest channel's error at 1 (the noise and the JPEG's RMS error in codes
    times the top code step, in quadrature), at most SATURATED. A clipped pixel (a sensor's full well, an
    8-bit file's 255) that noise is added to, or that a JPEG's blocks ring around, lies up to a few errors
    below 1; read as a measurement, it pulls the closed-form products down (its model is far above 1),
    and on a low, grazing light that moved the fitted light by half a metre."""
    jpeg = np.asarray(blocking.get("error_codes", [0.0, 0.0, 0.0]), np.float64) * _top_code_step()
    err = np.sqrt(np.asarray(sigma, np.float64) ** 2 + jpeg ** 2)
    return float(min(SATURATED, max(CLIP_LEVEL_FLOOR, 1.0 - CLIPPED_SIGMAS * float(err.max()))))


def goodness(scene: Any, target: np.ndarray, use: np.ndarray | None, clip: bool = True,
             render: np.ndarray | None = None, sigma: np.ndarray | None = None,
             blocking: dict[str, Any] | None = None, encoding: np.ndarray | None = None,
             codes: np.ndarray | None = None, split: bool = True,
             ids: Callable[[], np.ndarray] | None = None) -> dict[str, Any]:
    """The residual of ``scene``'s render against ``target`` (L1 over the used, unsaturated pixels) over
    its floor: per pixel and channel the larger of the 8-bit quantisation's mean error (a quarter code
    step) and the mean error of the measured noise (sigma x sqrt(2/pi)) and of a JPEG's blocks
    (:func:`jpeg_blocking`, its RMS error in codes times the code step there x sqrt(2/pi)), added in quadrature. With a verdict, and where the model falls short of
    the floor, per object its share of the excess (``per_object``, empty otherwise). ``render``: the
    scene's render (spp 1) when the caller has it; ``sigma`` and ``blocking``: ``target``'s
    :func:`noise_sigma`, :func:`jpeg_blocking` and :func:`encoded` when the caller has them, ``codes`` its
    8-bit codes (:func:`rtloop._srgb.codes8`) where it has them (the same numbers, looked up). ``split``:
    measure the structure of a residual between the floor and EXPLAINED_RATIO too (what the error bars
    widen for); above it, it is always measured, with its causes. ``ids``: where the caller traces the
    object index per pixel once (:attr:`.observation.Observation.ids`), a function giving it, called only
    where the residual is split by object."""
    if render is None:
        render = _native.render(scene, scene.width, scene.height, 1)
    model = np.minimum(render, np.float32(1.0)) if clip else render
    # float32 throughout: the floor is a quarter code step, far above float32's resolution.
    t = np.asarray(target, np.float32).reshape(-1, 3)
    m = np.asarray(model, np.float32).reshape(-1, 3)
    keep = (t[:, 0] < SATURATED) & (t[:, 1] < SATURATED) & (t[:, 2] < SATURATED)
    if use is not None:
        keep &= np.isin(np.arange(t.shape[0]), np.asarray(use))
    # Every pixel kept (no mask, none saturated): the arrays themselves, else their kept rows.
    everywhere = bool(keep.all())
    if codes is not None:
        c = np.asarray(codes).reshape(-1, 3)
        quant = per_code(_quarter_step_at, c if everywhere else np.compress(keep, c, axis=0))
    elif encoding is not None:
        e = np.asarray(encoding, np.float32).reshape(-1, 3)
        quant = _quarter_step(e if everywhere else np.compress(keep, e, axis=0))
    else:
        quant = _quarter_step_at(t if everywhere else np.compress(keep, t, axis=0))
    sigma = noise_sigma(target) if sigma is None else np.asarray(sigma, np.float64)
    blocking = jpeg_blocking(target) if blocking is None else blocking
    # The JPEG's error per pixel in linear units: its RMS in codes times the code step there (4 quarter steps).
    jpeg_codes = np.asarray(blocking["error_codes"], np.float32)[None, :]
    noise = (sigma * math.sqrt(2.0 / math.pi)).astype(np.float32)[None, :]
    if jpeg_codes.any():
        jpeg = np.float32(4.0) * quant * jpeg_codes
        floor = np.maximum(quant, np.sqrt(noise * noise + np.float32(2.0 / math.pi) * jpeg * jpeg))
    else:  # no JPEG: its term is 0, and noise^2 + 0 is noise^2 itself, per channel
        floor = np.maximum(quant, np.sqrt(noise * noise))
    resid = m - t
    np.abs(resid, out=resid)
    resid = resid if everywhere else np.compress(keep, resid, axis=0)
    total, fl = float(resid.sum(dtype=np.float64)), float(floor.sum(dtype=np.float64))
    ratio = total / fl if fl > 0 else float("inf")
    per: dict[str, Any] = {}
    if (ratio >= EXPLAINED_RATIO or split and ratio > 1.0) and math.isfinite(ratio):
        # where the excess lies, and how much of it is structure the error bars must widen for
        # (uncertainty.bars.model_lacks): wherever there is any, so the widening grows with it from 0
        per = _per_object(scene, target, m, keep, resid, floor, causes=ratio >= EXPLAINED_RATIO, ids=ids)
    out: dict[str, Any] = {"ratio": ratio, "loss": total, "floor": fl, "noise_sigma": [float(s) for s in sigma],
                           "jpeg_blocking": blocking,
                           "pixels": int(keep.sum()), "per_object": per, "explained_below": EXPLAINED_RATIO}
    if per and ratio >= EXPLAINED_RATIO:  # a diagnosis only where the photo is not explained
        out["explained"], out["diagnosis"] = _diagnosis(per)
    if not keep.any() or not math.isfinite(ratio):
        out["ratio"] = None
        out["verdict"] = "no unsaturated pixel to judge the fit by: every used pixel is at or above 1"
    elif ratio < EXPLAINED_RATIO:
        out["verdict"] = "the model explains this photo to the noise level"
    elif fine_only(out):
        out["fine_only"] = True
        out["verdict"] = (f"the model explains this photo: the residual is {ratio:.2g}x the noise floor, the excess "
                          f"fine and zero-mean on {', '.join(out['explained'])} (texture or noise: no smooth part "
                          "the light or the colours could absorb)")
    else:
        worst = max(per, key=lambda n: per[n]["share_of_excess"])
        out["verdict"] = (f"the residual is {ratio:.2g}x the noise floor, {per[worst]['share_of_excess']:.0%} of "
                          f"the excess on {worst}: the model does not explain this photo (the error bars do not "
                          "cover what it lacks; look at the difference image, and at a mask for what the scene "
                          "leaves out)")
    return out


def fine_only(good: dict[str, Any]) -> bool:
    """Whether a goodness over the noise floor is all texture or noise: every object whose residual exceeds
    its floor has a fine, zero-mean residual (``good["explained"]``, :func:`_diagnosis`)."""
    explained = good.get("explained") or {}
    return bool(explained) and all(v == "texture/noise" for v in explained.values())


def _per_object(scene: Any, target: np.ndarray, m: np.ndarray, keep: np.ndarray, resid: np.ndarray,
                floor: np.ndarray, causes: bool = True, ids: Callable[[], np.ndarray] | None = None) -> dict[str, Any]:
    """Per object (and the background) with a kept pixel: its pixels, its residual's ratio to its floor,
    its share of the excess over the floor, and the structure of its residual (:func:`residual_structure`;
    its causes only with ``causes``; ``ids`` gives the object index per pixel, None: traced here).
    ``m``: the model's values (pixels, 3); ``resid`` and ``floor``: over the kept pixels."""
    per: dict[str, Any] = {}
    full_ids = np.asarray(_native.object_ids(scene) if ids is None else ids()).reshape(-1)
    ids = full_ids[keep]
    for k, name in [*enumerate(scene.object_names), (-1, "background")]:
        sel = ids == k
        if sel.any():
            r, f = float(resid[sel].sum(dtype=np.float64)), float(floor[sel].sum(dtype=np.float64))
            per[name] = {"pixels": int(sel.sum()), "ratio": r / f if f > 0 else float("inf"),
                         "share_of_excess": max(r - f, 0.0)}
    excess = sum(v["share_of_excess"] for v in per.values())
    for v in per.values():
        v["share_of_excess"] = v["share_of_excess"] / excess if excess > 0 else 0.0
    parts = residual_structure(scene, np.asarray(target, np.float32).reshape(scene.height, scene.width, 3),
                               m.reshape(scene.height, scene.width, 3), keep, floor,
                               full_ids, list(scene.object_names), causes)
    for name, part in parts.items():
        per[name]["structure"] = part
    return per


def _diagnosis(per: dict[str, Any]) -> tuple[dict[str, str], str]:
    """Per object whose residual exceeds its floor, what it is (``explained``: "texture/noise" where the
    excess is fine and zero-mean, else the cause named by :func:`.structure.residual_structure`, or
    "unexplained structure"), and one line saying so."""
    explained: dict[str, str] = {}
    lines = []
    for name, v in per.items():
        part = v.get("structure")
        if part is None or (v["ratio"] is not None and v["ratio"] < EXPLAINED_RATIO):
            continue
        if not part["structured"]:
            explained[name] = "texture/noise"
            lines.append(f"{name}: explained: texture/noise (fine, zero-mean residual; its smooth part is "
                         f"{part['structured_ratio']:.2g}x the noise floor)")
        elif part.get("cause"):
            explained[name] = part["cause"]
            lines.append(f"{name}: not explained: {CAUSES[part['cause']]} (smooth residual "
                         f"{part['structured_ratio']:.2g}x the noise floor, {part['causes'][part['cause']]:.0%} of it)")
        else:
            explained[name] = "unexplained structure"
            why = part.get("why", "smooth residual")
            lines.append(f"{name}: not explained: {why} ({part['structured_ratio']:.2g}x the noise floor)"
                         if part["structured_ratio"] is not None else f"{name}: not explained: {why}")
    return explained, "; ".join(lines)
