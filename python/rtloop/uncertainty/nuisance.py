"""Nuisance parameters: what a fit estimated besides its scene's parameters and then held fixed (a camera's
tone curve, :mod:`rtloop.fit.camera`), profiled out of the error bars so that each parameter's sigma is
marginal over them.

The fit through a tone curve maps the photo through the fitted curve g and fits the scene to the corrected
photo y = g(v) (v the file's values). The corrected photo's residual r = f(θ) - g(v; w) then depends on the
curve's parameters w too, and the bars of θ computed with w held fixed leave out how far w is itself
uncertain. Treated as parameters of the same estimating equations, (θ, w) have a joint covariance whose θ
block is the marginal one. By the Schur complement (for least squares the Frisch-Waugh-Lovell theorem) that
block is what the θ-alone formulas give with the Jacobian's columns replaced by their residuals after a
weighted projection on the nuisance columns N:

    J~ = J - N (Nᵀ W N)⁺ Nᵀ W J

W the bread's weights: 1 for least squares (Gauss-Newton, the least-squares sandwich), the kernel weights
1{|r_i| <= h} for the median regression's bread (:mod:`.sandwich`, where H = Σ_{|r_i| <= h} J_i J_iᵀ / h).
Its scores become Σ J~_i ψ(r_i), its bread J~ᵀ W J~: exactly the θ block of the joint sandwich, whatever
the residual's relation to N. Nothing else changes, so a fit without nuisance parameters keeps its bars to
the bit (docs/uncertainty.md, "A fitted tone curve").
"""

from __future__ import annotations

import json
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from contextvars import ContextVar
from dataclasses import dataclass

import numpy as np

from .. import _native
from ..scene import Scene, scene_to_dict

__all__ = ["Nuisance", "basis", "current", "held_terms", "profile", "profiled_by"]

#: Nuisance columns whose singular value (after scaling the columns to unit norm) is below this fraction of
#: the largest are dropped: a curve segment no used pixel falls in moves nothing.
RCOND = 1e-8


@dataclass(frozen=True)
class Nuisance:
    """Parameters the fit estimated and then held: ``what`` they are (one line), ``names`` (one per
    column) and ``columns(idx)``: at the used pixels (flat indices ``idx``) the derivative of the photo
    the fit compared with along each of them, (3 n, k) in the residuals' order (pixel-major, r g b)."""

    what: str
    names: tuple[str, ...]
    columns: Callable[[np.ndarray], np.ndarray]


#: Whether the bars carry what the fit chose and holds (:func:`held_terms`); False: held as known, as before
#: (studies compare the two).
HELD_TERMS = True
#: The finite-difference step of a held coat roughness: this fraction of the range the fit chooses it in
#: (rtloop.fit.coat.ROUGHNESS_TRIALS: 0.03 to 0.9), as a parameter's step is of its bounds.
ROUGHNESS_STEP = 1e-3


_CURRENT: ContextVar[Nuisance | None] = ContextVar("rtloop_nuisance", default=None)


@contextmanager
def profiled_by(nuisance: Nuisance | None) -> Iterator[None]:
    """Within the block, the error bars of every fit (:func:`rtloop.fit.analysis`) profile out ``nuisance``:
    the fits of a photo corrected by it (``rtloop.fit.camera.fit_through_camera``)."""
    token = _CURRENT.set(nuisance)
    try:
        yield
    finally:
        _CURRENT.reset(token)


def current() -> Nuisance | None:
    """The nuisance parameters the fits now running profile out (None: none)."""
    return _CURRENT.get()


def basis(columns: np.ndarray, dropped: np.ndarray | None) -> np.ndarray:
    """An orthonormal basis (3 n, k') of the nuisance ``columns`` over the used residuals (rows in
    ``dropped``, flat bool, count as 0, as in the Jacobian), columns no used residual moves left out."""
    n = np.array(columns, dtype=np.float64, copy=True)
    if n.ndim != 2:
        raise ValueError(f"nuisance columns: expected a 2-d array, got shape {n.shape}")
    if dropped is not None:
        n[dropped] = 0.0
    norms = np.sqrt(np.einsum("ij,ij->j", n, n))
    n = n[:, norms > 0] / norms[norms > 0]
    if n.shape[1] == 0:
        return n
    u, s, _ = np.linalg.svd(n, full_matrices=False)
    q = u[:, s > RCOND * s[0]]
    if dropped is not None:
        q[dropped] = 0.0  # rounding's 1e-16s, so that the left-out rows count in no sum
    return q


def profile(Jt: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Jᵀ with the nuisance columns ``q`` (an orthonormal :func:`basis`) profiled out by least squares:
    J - q qᵀ J, whose Gauss-Newton covariance is the joint one's block of the parameters (Frisch-Waugh-Lovell).
    Returns a new array of Jt's shape."""
    if q.shape[1] == 0:
        return Jt.copy()
    return Jt - np.einsum("pi,ik->pk", Jt, q) @ q.T


def held_terms(result: object, space: object, wd: dict, idx: np.ndarray, clip: bool) -> Nuisance | None:
    """What the fit chose from the photo and then held, as nuisance parameters: the roughness of each coat
    it chose for a highlight (:mod:`rtloop.fit.coat`: searched at the light found, held while the light is
    refitted). Its column is the central difference of the work scene's render (``space.work``, as dict
    ``wd``) at the used pixels ``idx`` (clipped at 1 with ``clip``). None where the fit chose none: a coat
    the scene gives, or whose roughness its fit section frees (then a parameter of the bars), stays as it
    is. (The environment term's colour, also chosen and held, is left out: carried so it left the colours of
    the objects it lights most not determined and moved no light's bar by more than a third on the coverage
    photos, docs/uncertainty.md.)"""
    from ..fit.coat import ROUGHNESS_TRIALS

    if not HELD_TERMS:
        return None
    model = getattr(result, "model", None) or {}
    chosen = set(model.get("specular_objects") or [])
    paths = set(getattr(space, "paths", []))
    base = scene_to_dict(space.work)
    moves: list[tuple[str, Callable[[dict, float], float]]] = []  # (name, set the value moved by a step)
    lo, hi = ROUGHNESS_TRIALS[0], ROUGHNESS_TRIALS[-1]
    for o in base["objects"]:
        if o["name"] in chosen and o["material"].get("coat") and f"objects.{o['name']}.roughness" not in paths:
            moves.append((f"objects.{o['name']}.roughness", _roughness_move(o["name"], lo, hi)))
    if not moves:
        return None
    at = idx.astype(np.uint32)
    cols = []
    for _, move in moves:
        renders = []
        for sign in (1.0, -1.0):
            d = json.loads(json.dumps(base))
            value = move(d, sign)
            img = np.asarray(_native.render_pixels(Scene(json.dumps(d, allow_nan=False)), at), np.float64)
            renders.append((np.minimum(img, 1.0) if clip else img, value))
        (up, vu), (down, vd) = renders
        cols.append(((up - down) / (vu - vd)).ravel())
    col = np.stack(cols, axis=1)
    names = tuple(n for n, _ in moves)
    return Nuisance("what the fit chose and holds: " + ", ".join(names), names, lambda _idx: col)


def _roughness_move(name: str, lo: float, hi: float) -> Callable[[dict, float], float]:
    """Move object ``name``'s coat roughness one step (ROUGHNESS_STEP of [lo, hi]) up or down, within them."""
    def move(d: dict, sign: float) -> float:
        coat = next(o for o in d["objects"] if o["name"] == name)["material"]["coat"]
        coat["roughness"] = min(max(float(coat["roughness"]) + sign * ROUGHNESS_STEP * (hi - lo), lo), hi)
        return coat["roughness"]
    return move
