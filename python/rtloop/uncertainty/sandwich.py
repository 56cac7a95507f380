"""The block sandwich covariance: error bars that hold when neighbouring residuals are correlated (blur,
JPEG, demosaicing, a model that misses a smooth term), from the score contributions summed over image blocks.

For a fit that minimised least squares the scores are J_i r_i and the bread (JᵀJ)⁺. A fit that minimised
the L1 norm (the default) is a median regression: its scores are J_i sign(r_i) and its bread the inverse of
H = 2 Σ_i f_i(0) J_i J_iᵀ, f_i(0) the density of pixel i's residual at zero, from Powell's kernel
estimate Σ_{|r_i| <= h} J_i J_iᵀ / (2h) of Σ_i f_i(0) J_i J_iᵀ, with the Hall-Sheather bandwidth h (the cluster-robust quantile
regression covariance: J. L. Powell 1991; J. A. F. Machado, P. M. D. C. Parente and J. M. C. Santos Silva,
"Quantile regression with clustered data", J. Econometric Methods 2016; R. Koenker, "Quantile Regression",
2005, 3.4). It describes the estimator the fit used: under a model error the residuals of a region are large
and of one sign, so their density at zero is small and their signs are correlated over the region, both of
which the least-squares form, weighting each residual by its size, does not see.

Each block's score is bias-reduced for the block's own leverage (CR2, :func:`_bias_reduced`): a block that
holds much of what fixes a parameter (a highlight, for the light and the lobe) has absorbed in its own fit
the part of its model error the plain form would read, and with one such block the plain form's variance is
one block's score squared (docs/uncertainty.md, "A block's own leverage")."""

from __future__ import annotations

import math
import time
from dataclasses import replace
from statistics import NormalDist
from typing import Any

import numpy as np

from .. import _native

#: Smallest side of the square image blocks (pixels) whose score contributions are summed; the side is
#: the larger of this and a sixth of the image's short side (model error is correlated on an object's scale).
BLOCK_PX = 8
#: The covariance is the bias-reduced block sandwich (CR2, :func:`_bias_reduced`); False: the plain one with
#: the small-sample factor B / (B - p) (CR1), as before (studies compare the two).
BIAS_REDUCED = True
#: A block's leverage eigenvalue within this of 1 counts as 1: the block alone determines that direction.
LEVERAGE_ONE = 1e-9
#: The L1 bread's density-weighted Gram matrix (unit diagonal) counts as singular below this ratio of its
#: eigenvalues: the Gauss-Newton decomposition's RCOND (1e-4 on singular values), squared.
RCOND_L1 = 1e-8


def block_side(width: int, height: int) -> int:
    """The block side for an image: max(BLOCK_PX, min(width, height) // 6)."""
    return max(BLOCK_PX, min(width, height) // 6)


def hall_sheather(r: np.ndarray, alpha: float = 0.05) -> float:
    """The Hall-Sheather bandwidth for the density of residuals ``r`` at their median (as R's quantreg
    ``summary.rq``): in quantiles h_q = n^(-1/3) z_(1-alpha/2)^(2/3) (1.5 phi(0)^2)^(1/3), in residual units
    h = kappa (Phi^-1(0.5 + h_q) - Phi^-1(0.5 - h_q)), kappa = min(sd, IQR / 1.34). 0 when it cannot be formed."""
    n = r.size
    if n < 2:
        return 0.0
    nd = NormalDist()
    hq = n ** (-1.0 / 3.0) * nd.inv_cdf(1 - alpha / 2) ** (2.0 / 3.0) * (1.5 * nd.pdf(0.0) ** 2) ** (1.0 / 3.0)
    hq = min(hq, 0.49)
    lo, hi = (n - 1) // 4, (3 * (n - 1)) // 4  # the quartiles to one order statistic: a selection, no sort
    q_lo, q_hi = _native.order_statistics(np.ascontiguousarray(r, np.float64), [lo, hi])
    kappa = min(float(np.sqrt(np.einsum("i,i->", r, r) / n - (r.sum() / n) ** 2)), (q_hi - q_lo) / 1.34)
    return float(kappa * (nd.inv_cdf(0.5 + hq) - nd.inv_cdf(0.5 - hq))) if kappa > 0 and math.isfinite(kappa) else 0.0


def sandwich_norm(settings: dict[str, Any]) -> str:
    """The sandwich's form for a fit's ``settings``: "l1" for an L1 fit compared in linear space (the
    default), else "l2" (least squares; also for an sRGB comparison, whose L1 scores would carry the
    encoding's slope, and for other norms, which the least-squares form approximates)."""
    return "l1" if settings.get("norm") == "l1" and settings.get("space", "linear") == "linear" else "l2"


def block_sandwich(Jt: np.ndarray, r0: np.ndarray, idx: np.ndarray, width: int, fit: Any, s2: float,
                   names: list[str], block: int, norm: str = "l2", bias: np.ndarray | None = None,
                   nuisance: np.ndarray | None = None) -> tuple[dict[str, Any], Any]:
    """The block sandwich A (Σ_b g~_b g~_bᵀ) A over the B blocks that hold used pixels, each block's score g_b
    bias-reduced for the block's own leverage (CR2, :func:`_bias_reduced`; with BIAS_REDUCED False the plain
    g_b and the small-sample factor B / (B - p), CR1). ``norm`` "l2" (least squares): A = (JᵀJ)⁺,
    g_b = Σ_{i in block b} J_i r_i. ``norm`` "l1" (the fit's default; see the module): A = H⁺,
    H = Σ_{|r_i| <= h} J_i J_iᵀ / h (twice Powell's), g_b = Σ_{i in b} J_i sign(r_i), h the Hall-Sheather
    bandwidth of the used residuals; where H cannot be formed (no residual within h, or H singular where
    JᵀJ is not) the least-squares form. ``bias`` (over the determined parameters, ``fit.idx_p`` order): a
    systematic shift the residuals cannot show (the pixel footprint's), added as its outer product and
    reported as ``footprint_shift``. Each sigma is the larger of this and the Gauss-Newton one (the sandwich
    is the noisier estimate). ``nuisance``: an orthonormal basis (3 n, k) of nuisance parameters' columns
    (:mod:`.nuisance`): the sandwich is formed over the parameters and the nuisance together and its
    parameters' block kept, so that every sigma is marginal over them (``fit`` is then Gauss-Newton's with
    them profiled out, which is that joint covariance's block).

    Where the blocks of side ``block`` are no more than the parameters (many objects, each with its own
    colour), the side is halved, down to BLOCK_PX, until they are more than twice as many (``block_px`` is
    the side used, ``smaller_blocks`` says why). Where even then they are not more than the parameters the
    covariance cannot be formed: every sigma is None and ``why_none`` says why in one line.

    Residual rows left out are zero in ``Jt`` and ``r0`` (they count in no sum). Returns the JSON-able
    block and a copy of ``fit`` carrying the robust covariance (None where it cannot be formed)."""
    t0 = time.perf_counter()
    out: dict[str, Any] = {"method": "sandwich-blocks", "norm": "l2", "bandwidth": None, "block_px": int(block),
                           "blocks": 0, "sigma": {n: None for n in names}, "inflation": {n: None for n in names},
                           "light_position_m": None, "footprint_shift": {n: None for n in names}}
    if fit.cov is None:
        out["why_none"] = "Gauss-Newton's covariance could not be formed (see the warnings)"
        out["seconds"] = time.perf_counter() - t0
        return out, None
    q = fit.idx_p.size
    p = q + (0 if nuisance is None else nuisance.shape[1])  # the nuisance's count too
    bid, nb = _block_ids(idx, width, block)
    if nb <= p and block > BLOCK_PX:
        first = (block, nb)
        while block > BLOCK_PX and nb <= 2 * p:
            block = max(BLOCK_PX, block // 2)
            bid, nb = _block_ids(idx, width, block)
        out["smaller_blocks"] = (f"{block} px blocks, not {first[0]} px: the {first[1]} blocks of {first[0]} px "
                                 f"that hold used pixels are no more than the {p} parameters")
    out["block_px"], out["blocks"] = int(block), int(nb)
    if nb <= p:
        out["why_none"] = (f"too few image blocks for the parameters: the block sandwich needs more blocks holding "
                           f"used pixels than fitted parameters, and {nb} blocks of {block} px hold them for {p} "
                           "parameters (fit fewer parameters, e.g. fewer objects' colours, or a larger photo)")
        out["seconds"] = time.perf_counter() - t0
        return out, None
    bid = bid.astype(np.int64, copy=False)
    # The rows of the estimating equations: the determined parameters', then the nuisance's (joint).
    js, rows = Jt, fit.idx_p.tolist()
    if nuisance is not None:
        js = np.ascontiguousarray(np.vstack([Jt[fit.idx_p], nuisance.T]))
        rows = list(range(p))
    a = _l1_bread(js, r0, rows, out) if norm == "l1" else None
    weights = None
    # the per-residual score contributions summed per block, in the core (as np.bincount would)
    if a is not None:
        g = _native.block_scores(js, rows, np.sign(r0), bid, nb)
        weights = ((np.abs(r0) <= out["bandwidth"]) & (r0 != 0.0)) / out["bandwidth"]  # the kernel's
    else:
        g = _native.block_scores(js, rows, r0, bid, nb)
        # A photo the model explains exactly (zero residual): no spread at all, the Gauss-Newton zero.
        a = (fit.cov / s2 if nuisance is None else _gram_inverse(js)) if s2 > 0 else np.zeros((p, p))
    if BIAS_REDUCED:
        influence, out["block_leverage"] = _bias_reduced(js, rows, g, bid, nb, a, weights)
        out["form"] = "CR2"
        cov = influence @ influence.T
    else:
        out["form"] = "CR1"
        cov = a @ ((g @ g.T) * (nb / (nb - p))) @ a
    cov = cov[:q, :q]  # the parameters' block: marginal over the nuisance
    cov = 0.5 * (cov + cov.T)
    if bias is not None:  # a model error's systematic shift: the mean squared error's bias part
        cov = cov + np.outer(bias, bias)
    var = np.maximum(np.diag(cov), np.diag(fit.cov))  # never below Gauss-Newton
    scale = np.sqrt(var / np.maximum(np.diag(cov), 1e-300))
    cov = cov * np.outer(scale, scale)
    sd = np.sqrt(np.diag(cov))
    gn = np.sqrt(np.diag(fit.cov))
    for a_, k in enumerate(fit.idx_p):
        if fit.determined[k]:
            out["sigma"][names[k]] = float(sd[a_])
            out["inflation"][names[k]] = float(sd[a_] / gn[a_]) if gn[a_] > 0 else None
            if bias is not None:
                out["footprint_shift"][names[k]] = float(bias[a_])
    light = [f"light.position.{c}" for c in "xyz"]
    if all(n in names and fit.determined[names.index(n)] for n in light):
        at = [int(np.flatnonzero(fit.idx_p == names.index(n))[0]) for n in light]
        lw, lv = np.linalg.eigh(cov[np.ix_(at, at)])
        out["light_position_m"] = float(np.sqrt(max(lw[-1], 0.0)))
        # How many blocks the light's bar rests on: along its largest axis, each block's plain influence
        # (A g_b) squared, (Σ a_b²)² / Σ a_b⁴ (1: one block's score is all of it)
        a_b = lv[:, -1] @ (a @ g)[at]
        out["light_blocks"] = float(np.sum(a_b**2) ** 2 / np.sum(a_b**4)) if np.any(a_b) else None
    out["seconds"] = time.perf_counter() - t0
    return out, replace(fit, cov=cov)


def _gram_inverse(js: np.ndarray) -> np.ndarray:
    """(JᵀJ)⁺ of the rows ``js`` (all of them), on unit-diagonal scaling with Gauss-Newton's cut-off."""
    gram = np.einsum("ij,kj->ik", js, js)
    d = np.sqrt(np.diag(gram))
    d = np.where(d > 0, d, 1.0)
    w, v = np.linalg.eigh(gram / np.outer(d, d))
    good = w > RCOND_L1 * w[-1]
    return ((v[:, good] / w[good]) @ v[:, good].T) / np.outer(d, d)


def _bias_reduced(jt: np.ndarray, rows: list[int], g: np.ndarray, bid: np.ndarray, nb: int, a: np.ndarray,
                  weights: np.ndarray | None) -> tuple[np.ndarray, float]:
    """Each block's influence on the estimate, bias-reduced (CR2): F (I - K_b)^(-1/2) Fᵀ g_b, with A = F Fᵀ the
    bread, K_b = Fᵀ H_b F block b's leverage (H_b = Σ_{i in b} w_i J_i J_iᵀ, the bread's matrix over the block,
    ``weights`` w its residuals' (None: 1; the L1 bread's kernel weights 1{|r_i| <= h} / h), Σ_b K_b = I) and
    g_b its score. A block's own fit absorbs the part K_b of what its residuals push, which the plain form
    then reads as K_b less; (I - K_b)^(-1/2) restores it on average (exactly for independent residuals of
    equal variance: Bell and McCaffrey 2002). Directions a block alone determines (an eigenvalue of K_b of 1:
    its residual there is 0) count 0, the Moore-Penrose convention (Pustejovsky and Tipton 2018). Returns the
    influences (p, B) over ``rows`` of ``jt``, whose outer product is the covariance, and the largest
    eigenvalue of any K_b."""
    # Each block's residuals (three per pixel) in one sort, then H_b from its columns of the sorted copy
    res_bid = np.repeat(bid, 3)
    used = np.flatnonzero(res_bid >= 0) if weights is None else np.flatnonzero(weights)
    order = used[np.argsort(res_bid[used], kind="stable")]
    cuts = np.searchsorted(res_bid[order], np.arange(nb + 1))
    jo = jt[np.ix_(rows, order)]
    jw = jo if weights is None else jo * weights[order]
    hb = np.stack([jw[:, cuts[b]:cuts[b + 1]] @ jo[:, cuts[b]:cuts[b + 1]].T for b in range(nb)])  # (B, p, p)
    u = np.sqrt(np.clip(np.diag(a), 0.0, None))
    u = np.where(u > 0, u, 1.0)
    w, v = np.linalg.eigh(a / np.outer(u, u))  # unit-diagonal scaling: the parameters' units differ
    f = u[:, None] * ((v * np.sqrt(np.clip(w, 0.0, None))) @ v.T)  # F, A = F Fᵀ
    k = f.T @ hb @ f  # K_b = Fᵀ H_b F, all blocks at once
    lw, lv = np.linalg.eigh(0.5 * (k + k.transpose(0, 2, 1)))
    scale = np.where(lw < 1.0 - LEVERAGE_ONE, 1.0 / np.sqrt(np.clip(1.0 - lw, LEVERAGE_ONE, None)), 0.0)
    x = (lv.transpose(0, 2, 1) @ (f.T @ g).T[:, :, None])[:, :, 0] * scale  # (I - K_b)^(-1/2) Fᵀ g_b, K_b's axes
    out = f @ (lv @ x[:, :, None])[:, :, 0].T
    return out, float(lw[:, -1].max()) if nb else 0.0


def _block_ids(idx: np.ndarray, width: int, block: int) -> tuple[np.ndarray, int]:
    """Each used pixel's block, the blocks that hold used pixels numbered in order, and their count."""
    y, x = np.divmod(idx, width)
    nbx = -(-width // block)
    bid = (y // block) * nbx + x // block
    present = np.bincount(bid) > 0
    return (np.cumsum(present) - 1)[bid], int(present.sum())  # no sort


def _l1_bread(Jt: np.ndarray, r0: np.ndarray, rows: list[int], out: dict[str, Any]) -> np.ndarray | None:
    """H⁺ for the median regression, H = Σ_{|r_i| <= h} J_i J_iᵀ / h over the parameters ``rows`` of ``Jt``
    (Powell's kernel estimate of the density-weighted Gram matrix, h the Hall-Sheather bandwidth of the
    used residuals); None where it cannot be formed: then the least-squares bread serves. Notes the norm
    and the bandwidth in ``out``."""
    used = r0[r0 != 0.0]  # rows left out are exactly 0 (a used residual of exactly 0 counts in no sum either)
    h = hall_sheather(used)
    p = len(rows)
    if not h > 0:
        return None
    small = np.flatnonzero((np.abs(r0) <= h) & (r0 != 0.0))
    if small.size < p:
        return None
    js = Jt[:, small]  # the few columns first, then the determined rows: no copy of all of Jt
    if p < Jt.shape[0]:
        js = js[rows]
    hess = (js @ js.T) / h  # 2 x Powell's estimate of Σ f_i(0) J_i J_iᵀ: the scores are signs, not 1/2 - 1{r < 0}
    # H is a weighted JᵀJ: singular only in the directions JᵀJ is (which the determined set excludes)
    # unless no residual near zero falls where a parameter acts. Then the L1 objective is flat along it
    # to this resolution, and the least-squares form is the safer estimate.
    d = np.sqrt(np.diag(hess))
    if not (np.isfinite(d).all() and (d > 0).all()):
        return None
    try:  # on unit-diagonal scaling, as the Gauss-Newton decomposition: the parameters' units differ
        w, v = np.linalg.eigh(hess / np.outer(d, d))
    except np.linalg.LinAlgError:
        return None
    if not (np.isfinite(w).all() and w[0] > RCOND_L1 * w[-1]):
        return None
    out["norm"] = "l1"
    out["bandwidth"] = float(h)
    return ((v / w) @ v.T) / np.outer(d, d)
