"""Error bars of the lights fit: each light's position (or direction, or radius) and intensity.

The geometry's covariance is the sum of two terms. The Laplace approximation at the optimum: the loss
(the sum of squared residuals, the products solved in closed form at every point, so the curvature is the
profile's) has the Hessian H there; with s^2 = loss / (residuals - parameters) it is 2 s^2 H^-1 (the
pixels taken as independent). H comes from central differences of the closed form
(``_native.lights_solve``); a flat or concave direction gets the whole search box. And a delete-a-tile
jackknife (:func:`jackknife`), which sees the residuals that are alike over a region (where the model
misses a little everywhere, the independent-pixel term alone is 10-20x too small). The intensities' error
bars are the spread of the closed form's intensities over ``DRAWS`` seeded draws of the geometry from that
covariance (clamped to the box).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from .. import _native
from ..scene import load_scene

#: The geometry draws behind the intensities' error bars.
DRAWS = 32
#: The central differences' step, a fraction of each parameter's search range.
STEP = 1e-3
#: The jackknife's tiles across and down the image.
TILES = (4, 3)


def _bounds(d: dict[str, Any], paths: list[str]) -> tuple[np.ndarray, np.ndarray]:
    lo, hi = [], []
    for p in paths:
        b = d["fit"][p]
        n = 1 if p.endswith(".radius") else 3
        lo += list(np.broadcast_to(np.asarray(b["min"], float), n))
        hi += list(np.broadcast_to(np.asarray(b["max"], float), n))
    return np.asarray(lo), np.asarray(hi)


def _hessian(f: Callable[[np.ndarray], float], x: np.ndarray, h: np.ndarray) -> np.ndarray:
    n = x.size
    f0 = f(x)
    e = np.diag(h)
    H = np.zeros((n, n))
    for i in range(n):
        H[i, i] = (f(x + e[i]) - 2 * f0 + f(x - e[i])) / h[i] ** 2
        for j in range(i + 1, n):
            H[i, j] = H[j, i] = (f(x + e[i] + e[j]) - f(x + e[i] - e[j]) - f(x - e[i] + e[j])
                                 + f(x - e[i] - e[j])) / (4 * h[i] * h[j])
    return H


def covariance(d: dict[str, Any], paths: list[str], x: list[float], target: np.ndarray,
               pixels: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The searched geometry's independent-pixel covariance (the order of ``x``) and the loss's Hessian
    (its flat or concave directions lifted), as the module says."""
    scene = load_scene(d)
    lo, hi = _bounds(d, paths)
    span = np.maximum(hi - lo, 1e-9)
    x0 = np.clip(np.asarray(x, float), lo, hi)

    def f(v: np.ndarray) -> float:
        return float(_native.lights_solve(scene, target, paths, pixels, list(v))[0])

    H = _hessian(f, x0, STEP * span)
    loss = f(x0)
    lights = len(d["lights"])
    objects = len(d["objects"])
    dof = max(3 * int(pixels.size) - x0.size - 3 * objects * (lights + 1), 1)
    s2 = loss / dof
    w, v = np.linalg.eigh(0.5 * (H + H.T))
    # A flat or concave direction: as uncertain as the whole box (its variance the box's squared span).
    floor = 2 * s2 / float(span.max()) ** 2
    w = np.maximum(w, floor if floor > 0 else 1e-300)
    return (v / w) @ v.T * 2 * s2, (v * w) @ v.T


def _gradient(f: Callable[[np.ndarray], float], x: np.ndarray, h: np.ndarray) -> np.ndarray:
    e = np.diag(h)
    return np.array([(f(x + e[i]) - f(x - e[i])) / (2 * h[i]) for i in range(x.size)])


def jackknife(d: dict[str, Any], paths: list[str], x: list[float], target: np.ndarray, pixels: np.ndarray,
              hessian: np.ndarray) -> np.ndarray:
    """The delete-a-tile jackknife covariance of the geometry: the image cut into ``TILES`` (columns x rows)
    tiles; without tile b the optimum moves by one Newton step, -H_b^-1 g_b, with g_b the gradient of the
    loss over the other tiles' pixels (their products re-solved) and H_b the Hessian scaled to their
    share. Residuals that are alike over a region (a shadow the model places a little off, a light's fall-off
    it misses) move the tiles' estimates together: this sees what the independent-pixel curvature cannot."""
    scene = load_scene(d)
    lo, hi = _bounds(d, paths)
    h = STEP * np.maximum(hi - lo, 1e-9)
    x0 = np.clip(np.asarray(x, float), lo, hi)
    width, height = scene.width, scene.height
    col = (pixels % width) * TILES[0] // width
    row = (pixels // width) * TILES[1] // height
    tile = row * TILES[0] + col
    moves = []
    for b in range(TILES[0] * TILES[1]):
        keep = pixels[tile != b]
        if keep.size in (0, pixels.size):
            continue

        def f(v: np.ndarray, keep: np.ndarray = keep) -> float:
            return float(_native.lights_solve(scene, target, paths, keep, list(v))[0])

        g = _gradient(f, x0, h)
        hb = hessian * keep.size / pixels.size
        moves.append(-np.linalg.lstsq(hb, g, rcond=1e-12)[0])
    if len(moves) < 2:
        return np.zeros((x0.size, x0.size))
    m = np.asarray(moves)
    dev = m - m.mean(axis=0)
    return dev.T @ dev * (len(moves) - 1) / len(moves)


def light_errors(d: dict[str, Any], paths: list[str], x: list[float], target: np.ndarray, pixels: np.ndarray,
                 seed: int, split: Callable[[list[float], Any], list[dict[str, Any]]]) -> list[dict[str, Any]]:
    """Per light (in the order of ``d["lights"]``): ``position_error`` (metres, per axis) or
    ``direction_error`` / ``radius_error`` where searched, and ``intensity_error``. ``split(x, products)``
    gives the light report at another geometry (the fit's own write-back)."""
    cov, hessian = covariance(d, paths, x, target, pixels)
    cov = cov + jackknife(d, paths, x, target, pixels, hessian)
    sd = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    out: list[dict[str, Any]] = [{} for _ in d["lights"]]
    names = [light["name"] for light in d["lights"]]
    k = 0
    for p in paths:
        parts = p.split(".")
        i, key = (0, parts[1]) if len(parts) == 2 else (names.index(parts[1]), parts[2])
        n = 1 if key == "radius" else 3
        out[i][f"{key}_error"] = float(sd[k]) if n == 1 else [float(v) for v in sd[k:k + n]]
        k += n
    lo, hi = _bounds(d, paths)
    rng = np.random.default_rng(seed)
    scene = load_scene(d)
    draws = []
    try:
        chol = np.linalg.cholesky(cov + 1e-30 * np.eye(len(x)))
    except np.linalg.LinAlgError:
        chol = np.diag(sd)
    for _ in range(DRAWS):
        xk = np.clip(np.asarray(x, float) + chol @ rng.standard_normal(len(x)), lo, hi)
        _, products = _native.lights_solve(scene, target, paths, pixels, list(xk))
        draws.append([light["intensity"] for light in split(list(xk), products)])
    spread = np.std(np.asarray(draws, float), axis=0)
    for i, e in enumerate(out):
        e["intensity_error"] = float(spread[i])
    return out
