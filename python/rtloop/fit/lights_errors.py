"""Error bars of the lights fit: each light's position (or direction, radius, a rectangle's size) and
intensity.

The geometry's covariance is the sum of two terms. The Laplace approximation at the optimum: the loss
(the sum of squared residuals, the products solved in closed form at every point, so the curvature is the
profile's) has the Hessian H there; with s^2 = loss / (residuals - parameters) it is 2 s^2 H^-1 (the
pixels taken as independent). H comes from central differences of the closed form
(``_native.lights_solve``); a flat or concave direction gets the whole search box. And a delete-a-tile
jackknife (:func:`jackknife`), which sees the residuals that are alike over a region (where the model
misses a little everywhere, the independent-pixel term alone is 10-20x too small). The intensities' error
bars are the spread of the closed form's intensities over ``DRAWS`` seeded draws of the geometry from that
covariance (clamped to the box).

A rectangle light's width and height: their steps are ``SIZE_STEP`` of the side, not of the range (the
loss is a staircase below that, its grid's shadow rays crossing the objects' edges one cell at a time). A
side whose error bar exceeds ``DETERMINED`` of it is not determined by the photo: it gets no error bar, and
the others' error bars are computed with it held (a flat direction would otherwise leak the whole box
into every light through the jackknife's Newton steps).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from .. import _native
from ..scene import load_scene
from .lights_search import path_width

#: The geometry draws behind the intensities' error bars.
DRAWS = 32
#: The central differences' step, a fraction of each parameter's search range.
STEP = 1e-3
#: The jackknife's tiles across and down the image.
TILES = (4, 3)
#: The central differences' step for a rectangle light's centre, width and height, a fraction of its side.
RECT_STEP = 0.05
#: A rectangle's side is determined when its 1-sigma error bar is at most this fraction of it.
DETERMINED = 0.25


def _bounds(d: dict[str, Any], paths: list[str]) -> tuple[np.ndarray, np.ndarray]:
    lo, hi = [], []
    for p in paths:
        b = d["fit"][p]
        n = path_width(p)
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


def _steps(d: dict[str, Any], paths: list[str], x: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """The central differences' steps: ``STEP`` of each search range; for a rectangle light's centre and
    size, ``RECT_STEP`` of its (smaller) side at ``x``: its grid of shadow rays crosses the objects' edges
    one cell at a time, so its loss is a staircase below that scale."""
    h = STEP * np.maximum(hi - lo, 1e-9)
    k = 0
    for p in paths:
        n = path_width(p)
        light = _light_of(d, p)
        if "size" in light:
            size = x[k:k + n] if p.endswith(".size") else _searched_size(d, paths, x, light)
            h[k:k + n] = RECT_STEP * np.maximum(size if n == 2 else min(size), 1e-6)
        k += n
    return h


def _light_of(d: dict[str, Any], path: str) -> dict[str, Any]:
    parts = path.split(".")
    return d["lights"][0] if len(parts) == 2 else next(light for light in d["lights"] if light["name"] == parts[1])


def _searched_size(d: dict[str, Any], paths: list[str], x: np.ndarray, light: dict[str, Any]) -> np.ndarray:
    """A rectangle light's size at ``x``: its searched values, else the scene's."""
    k = 0
    for p in paths:
        if p.endswith(".size") and _light_of(d, p) is light:
            return x[k:k + 2]
        k += path_width(p)
    return np.asarray(light["size"], float)


def _size_indices(paths: list[str]) -> list[int]:
    """The indices in x of the rectangles' widths and heights."""
    out, k = [], 0
    for p in paths:
        n = path_width(p)
        if p.endswith(".size"):
            out += list(range(k, k + n))
        k += n
    return out


def curvature(d: dict[str, Any], paths: list[str], x: list[float], target: np.ndarray,
              pixels: np.ndarray) -> tuple[np.ndarray, float]:
    """The loss's Hessian at ``x`` (central differences of the closed form) and s^2, the loss over the
    residuals' degrees of freedom."""
    scene = load_scene(d)
    lo, hi = _bounds(d, paths)
    x0 = np.clip(np.asarray(x, float), lo, hi)

    def f(v: np.ndarray) -> float:
        return float(_native.lights_solve(scene, target, paths, pixels, list(v))[0])

    H = _hessian(f, x0, _steps(d, paths, x0, lo, hi))
    loss = f(x0)
    lights = len(d["lights"])
    objects = len(d["objects"])
    dof = max(3 * int(pixels.size) - x0.size - 3 * objects * (lights + 1), 1)
    return H, loss / dof


def covariance(H: np.ndarray, s2: float, span: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The independent-pixel covariance 2 s^2 H^-1, the Hessian with its flat or concave directions
    lifted, as the module says (``span``: the search ranges), and those directions (columns; none when
    the Hessian is positive definite)."""
    w, v = np.linalg.eigh(0.5 * (H + H.T))
    # A flat or concave direction: as uncertain as the whole box (its variance the box's squared span).
    floor = 2 * s2 / float(span.max()) ** 2
    floor = floor if floor > 0 else 1e-300
    flat = v[:, w < floor]
    w = np.maximum(w, floor)
    return (v / w) @ v.T * 2 * s2, (v * w) @ v.T, flat


def _gradient(f: Callable[[np.ndarray], float], x: np.ndarray, h: np.ndarray) -> np.ndarray:
    e = np.diag(h)
    return np.array([(f(x + e[i]) - f(x - e[i])) / (2 * h[i]) for i in range(x.size)])


def tile_gradients(d: dict[str, Any], paths: list[str], x: list[float], target: np.ndarray,
                   pixels: np.ndarray) -> list[tuple[np.ndarray, tuple[int, int]]]:
    """For the delete-a-tile jackknife (:func:`jackknife`): the image cut into ``TILES`` (columns x rows)
    tiles; per tile b, the gradient of the loss over the other tiles' pixels (their products re-solved)
    and those pixels' count and all pixels' count."""
    scene = load_scene(d)
    lo, hi = _bounds(d, paths)
    x0 = np.clip(np.asarray(x, float), lo, hi)
    h = _steps(d, paths, x0, lo, hi)
    width, height = scene.width, scene.height
    col = (pixels % width) * TILES[0] // width
    row = (pixels // width) * TILES[1] // height
    tile = row * TILES[0] + col
    out = []
    for b in range(TILES[0] * TILES[1]):
        keep = pixels[tile != b]
        if keep.size in (0, pixels.size):
            continue

        def f(v: np.ndarray, keep: np.ndarray = keep) -> float:
            return float(_native.lights_solve(scene, target, paths, keep, list(v))[0])

        out.append((_gradient(f, x0, h), (keep.size, pixels.size)))
    return out


def jackknife(gradients: list[tuple[np.ndarray, tuple[int, int]]], hessian: np.ndarray,
              flat: np.ndarray | None = None) -> np.ndarray:
    """The delete-a-tile jackknife covariance of the geometry: without tile b the optimum moves by one
    Newton step, -H_b^-1 g_b, with g_b its gradient (:func:`tile_gradients`) and H_b the Hessian scaled to
    the other tiles' share. Residuals that are alike over a region (a shadow the model places a little off,
    a light's fall-off it misses) move the tiles' estimates together: this sees what the independent-pixel
    curvature cannot. Along the ``flat`` directions (columns; the Laplace term already gives them the whole
    box) a Newton step means nothing: the moves are taken without them."""
    if flat is not None and flat.size:
        keep = np.eye(hessian.shape[0]) - flat @ flat.T
        gradients = [(keep @ g, share) for g, share in gradients]
    moves = [-np.linalg.lstsq(hessian * kept / total, g, rcond=1e-12)[0] for g, (kept, total) in gradients]
    if len(moves) < 2:
        return np.zeros(hessian.shape)
    m = np.asarray(moves)
    dev = m - m.mean(axis=0)
    return dev.T @ dev * (len(moves) - 1) / len(moves)


def geometry_covariance(H: np.ndarray, s2: float, span: np.ndarray,
                        gradients: list[tuple[np.ndarray, tuple[int, int]]], free: np.ndarray) -> np.ndarray:
    """The sum of the two covariances over the ``free`` values (flags), the others held at the optimum
    (zero rows and columns)."""
    idx = np.flatnonzero(free)
    cov, lifted, flat = covariance(H[np.ix_(idx, idx)], s2, span[idx])
    cov = cov + jackknife([(g[idx], share) for g, share in gradients], lifted, flat)
    out = np.zeros(H.shape)
    out[np.ix_(idx, idx)] = cov
    return out


def loose_sizes(paths: list[str], x: np.ndarray, sd: np.ndarray) -> list[int]:
    """The rectangles' sides the photo does not fix: a 1-sigma error bar over ``DETERMINED`` of the side."""
    return [k for k in _size_indices(paths) if not sd[k] <= DETERMINED * x[k]]


def light_errors(d: dict[str, Any], paths: list[str], x: list[float], target: np.ndarray, pixels: np.ndarray,
                 seed: int, split: Callable[[list[float], Any], list[dict[str, Any]]]) -> list[dict[str, Any]]:
    """Per light (in the order of ``d["lights"]``): ``position_error`` (metres, per axis) or
    ``direction_error`` / ``radius_error`` / ``size_error`` where searched, and ``intensity_error``.
    A rectangle's side the photo does not fix (:func:`loose_sizes`) has None for its error and is held
    at its value for the others' error bars; ``size_note`` says which and why. ``split(x, products)``
    gives the light report at another geometry (the fit's own write-back)."""
    lo, hi = _bounds(d, paths)
    span = np.maximum(hi - lo, 1e-9)
    x0 = np.asarray(x, float)
    H, s2 = curvature(d, paths, x, target, pixels)
    gradients = tile_gradients(d, paths, x, target, pixels)
    free = np.ones(x0.size, bool)
    cov = geometry_covariance(H, s2, span, gradients, free)
    loose = loose_sizes(paths, x0, np.sqrt(np.clip(np.diag(cov), 0.0, None)))
    if loose:
        free[loose] = False
        cov = geometry_covariance(H, s2, span, gradients, free)
    sd = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    out = _bars(d, paths, sd, free)
    rng = np.random.default_rng(seed)
    scene = load_scene(d)
    draws = []
    try:
        chol = np.linalg.cholesky(cov + 1e-30 * np.eye(len(x)))
    except np.linalg.LinAlgError:
        chol = np.diag(sd)
    for _ in range(DRAWS):
        xk = np.clip(x0 + chol @ rng.standard_normal(len(x)), lo, hi)
        _, products = _native.lights_solve(scene, target, paths, pixels, list(xk))
        draws.append([light["intensity"] for light in split(list(xk), products)])
    spread = np.std(np.asarray(draws, float), axis=0)
    for i, e in enumerate(out):
        e["intensity_error"] = float(spread[i])
    return out


def _bars(d: dict[str, Any], paths: list[str], sd: np.ndarray, free: np.ndarray) -> list[dict[str, Any]]:
    """Per light, its searched values' error bars (``free`` False: not determined, None and a note)."""
    out: list[dict[str, Any]] = [{} for _ in d["lights"]]
    names = [light["name"] for light in d["lights"]]
    k = 0
    for p in paths:
        parts = p.split(".")
        i, key = (0, parts[1]) if len(parts) == 2 else (names.index(parts[1]), parts[2])
        n = path_width(key)
        bars = [float(v) if f else None for v, f in zip(sd[k:k + n], free[k:k + n])]
        out[i][f"{key}_error"] = bars[0] if n == 1 else bars
        if key == "size" and None in bars:
            sides = [side for side, b in zip(("width", "height"), bars) if b is None]
            it = "it" if len(sides) == 1 else "them"
            out[i]["size_note"] = (f"{' and '.join(sides)} not determined: the photo does not fix {it} (a "
                                   f"1-sigma error bar would exceed {DETERMINED:.0%} of the side); held at the "
                                   "fitted value for the other error bars")
        k += n
    return out
