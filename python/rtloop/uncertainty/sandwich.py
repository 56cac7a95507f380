"""The block sandwich covariance: error bars that hold when neighbouring residuals are correlated (blur,
JPEG, demosaicing, a model that misses a smooth term), from the score contributions summed over image blocks."""

from __future__ import annotations

import time
from dataclasses import replace
from typing import Any

import numpy as np

from .. import _native

#: Smallest side of the square image blocks (pixels) whose score contributions are summed; the side is
#: the larger of this and a sixth of the image's short side (model error is correlated on an object's scale).
BLOCK_PX = 8


def block_side(width: int, height: int) -> int:
    """The block side for an image: max(BLOCK_PX, min(width, height) // 6)."""
    return max(BLOCK_PX, min(width, height) // 6)


def block_sandwich(Jt: np.ndarray, r0: np.ndarray, idx: np.ndarray, width: int, fit: Any, s2: float,
                   names: list[str], block: int) -> tuple[dict[str, Any], Any]:
    """A (Σ_b g_b g_bᵀ) A with A = (JᵀJ)⁺ and g_b = Σ_{i in block b} J_i r_i, with the small-sample factor
    B / (B - p) over the B blocks that hold used pixels. Each sigma is the larger of this and the
    Gauss-Newton one (the sandwich is the noisier estimate; with white residuals both agree).

    Returns the JSON-able block and a copy of ``fit`` carrying the robust covariance (None where it cannot
    be formed: too few blocks for the parameters)."""
    t0 = time.perf_counter()
    out: dict[str, Any] = {"method": "sandwich-blocks", "block_px": int(block), "blocks": 0,
                           "sigma": {n: None for n in names}, "inflation": {n: None for n in names},
                           "light_position_m": None}
    if fit.cov is None:
        out["seconds"] = time.perf_counter() - t0
        return out, None
    p = fit.idx_p.size
    y, x = np.divmod(idx, width)
    nbx = -(-width // block)
    bid = (y // block) * nbx + x // block
    present = np.bincount(bid) > 0
    bid = (np.cumsum(present) - 1)[bid]  # the blocks that hold used pixels, numbered in order (no sort)
    nb = int(present.sum())
    out["blocks"] = int(nb)
    if nb <= p:
        out["seconds"] = time.perf_counter() - t0
        return out, None
    # the per-residual score contributions summed per block, in the core (as np.bincount would)
    g = _native.block_scores(Jt, fit.idx_p.tolist(), r0, bid.astype(np.int64, copy=False), nb)
    meat = (g @ g.T) * (nb / (nb - p))
    # A photo the model explains exactly (zero residual): no spread at all, the Gauss-Newton zero.
    a = fit.cov / s2 if s2 > 0 else np.zeros_like(fit.cov)
    cov = a @ meat @ a
    cov = 0.5 * (cov + cov.T)
    var = np.maximum(np.diag(cov), np.diag(fit.cov))  # never below Gauss-Newton
    scale = np.sqrt(var / np.maximum(np.diag(cov), 1e-300))
    cov = cov * np.outer(scale, scale)
    sd = np.sqrt(np.diag(cov))
    gn = np.sqrt(np.diag(fit.cov))
    for a_, k in enumerate(fit.idx_p):
        if fit.determined[k]:
            out["sigma"][names[k]] = float(sd[a_])
            out["inflation"][names[k]] = float(sd[a_] / gn[a_]) if gn[a_] > 0 else None
    light = [f"light.position.{c}" for c in "xyz"]
    if all(n in names and fit.determined[names.index(n)] for n in light):
        at = [int(np.flatnonzero(fit.idx_p == names.index(n))[0]) for n in light]
        out["light_position_m"] = float(np.sqrt(max(np.linalg.eigvalsh(cov[np.ix_(at, at)])[-1], 0.0)))
    out["seconds"] = time.perf_counter() - t0
    return out, replace(fit, cov=cov)
