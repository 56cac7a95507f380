"""The lights fit's staged search: one light at a time, then all together.

The first light is searched alone (the others left out of the scene); each further light is then searched
with the lights found so far held at their values (these searches see every other chosen pixel); last,
L-SHADE started from that point with a small population, and its Nelder–Mead polish, move all the lights
together over all the chosen pixels. With a rectangle light's size searched, ``Stages.restarts`` more
rounds follow: each side scanned over its range, the rest held (:func:`_scan`), then a Nelder–Mead polish
from that point with a fresh simplex. The size moves the rectangle's grid of shadow rays across the
objects' edges, the loss is a staircase at the 0.2 % level, a simplex collapses on a step, and the search
can settle on a larger, further-off rectangle that the scan moves it off. Every candidate's products are the closed form of
``rust/fitness/lights.rs``. docs/methods.md, "Several lights".
"""

from __future__ import annotations

import copy
from dataclasses import dataclass
from typing import Any

import numpy as np

from .. import _native
from ..scene import load_scene


#: The number of values each searched key of a light takes (the others are 3-vectors).
WIDTHS = {"radius": 1, "size": 2}


def path_width(path: str) -> int:
    """How many values the searched light path (or its last key) ``path`` takes."""
    return WIDTHS.get(path.rsplit(".", 1)[-1], 3)


@dataclass(frozen=True)
class Stages:
    """The staged search's budget: each light's own search and the joint one (population, generations,
    polish evaluations)."""

    light: tuple[int, int, int] = (16, 20, 50)
    joint: tuple[int, int, int] = (8, 10, 500)
    #: Each light's own search sees every ``thin``-th chosen pixel; the joint one sees them all.
    thin: int = 2
    #: While a further light is searched, the lights found so far move within this share of their ranges.
    hold: float = 0.05
    #: With a rectangle's size searched: Nelder–Mead polishes restarted from the best point (population,
    #: generations and polish evaluations of each; how many).
    restart: tuple[int, int, int] = (4, 1, 300)
    restarts: int = 3
    #: Before each restart, each side is also scanned over this many values of its range.
    scan: int = 24


def _blocks(d: dict[str, Any], paths: list[str]) -> list[tuple[int, int, int]]:
    """Per searched path: its light's index and its slice of x."""
    from .lights import _locate
    out, k = [], 0
    for p in paths:
        light, _ = _locate(p, d["lights"])
        n = path_width(p)
        out.append((d["lights"].index(light), k, k + n))
        k += n
    return out


def _bounds(d: dict[str, Any], paths: list[str]) -> list[tuple[float, float]]:
    out: list[tuple[float, float]] = []
    for p in paths:
        b = d["fit"][p]
        n = path_width(p)
        lo = np.broadcast_to(np.asarray(b["min"], float), n)
        hi = np.broadcast_to(np.asarray(b["max"], float), n)
        out += [(float(a), float(c)) for a, c in zip(lo, hi)]
    return out


def _own_box(d: dict[str, Any], paths: list[str], box: list[tuple[float, float]]) -> list[tuple[float, float]]:
    """The search box of each light's own search: a rectangle's size held at the scene's value (clamped
    to its range; freed in the joint search), the rest as ``box``."""
    from .lights import _locate
    out, k = list(box), 0
    for p in paths:
        n = path_width(p)
        if p.endswith(".size"):
            light, _ = _locate(p, d["lights"])
            for j, v in enumerate(light["size"]):
                v = min(max(float(v), box[k + j][0]), box[k + j][1])
                out[k + j] = (v, v)
        k += n
    return out


def _first(d: dict[str, Any], paths: list[str], count: int) -> tuple[dict[str, Any], list[str]]:
    """The scene with its first ``count`` lights only, and their searched paths."""
    out = copy.deepcopy(d)
    gone = {light["name"] for light in out["lights"][count:]}
    out["lights"] = out["lights"][:count]
    out["fit"] = {p: v for p, v in out["fit"].items()
                  if not (p.startswith("lights.") and p.split(".")[1] in gone)}
    return out, [p for p in paths if not (p.startswith("lights.") and p.split(".")[1] in gone)]


def staged(d: dict[str, Any], paths: list[str], target: np.ndarray, pixels: np.ndarray, seed: int,
           threads: int | None, stages: Stages = Stages()) -> tuple[list[float], float, Any, int]:
    """Search the lights of ``d`` over ``paths`` as the module says; returns what ``_native.fit_lights``
    returns for the whole scene."""
    blocks = _blocks(d, paths)
    box = _bounds(d, paths)
    x: list[float] = []
    evaluations = 0
    few = np.ascontiguousarray(pixels[::stages.thin])
    for i in range(len(d["lights"])):
        n = sum(b - a for light, a, b in blocks if light <= i)
        if n == len(x):  # nothing of this light is searched
            continue
        sub, sub_paths = _first(d, paths, i + 1)
        pop, gens, polish = stages.light
        held = [(max(lo, v - stages.hold * (hi - lo)), min(hi, v + stages.hold * (hi - lo)))
                for v, (lo, hi) in zip(x, box)]
        own = _own_box(d, paths, box)[len(x):n]
        start = x + [(lo + hi) / 2 for lo, hi in own] if x else None
        found = _native.fit_lights(load_scene(sub), target, sub_paths, few, seed + i, pop, gens, threads,
                                   bounds=held + own, start=start, polish=polish)
        x = list(found[0])
        evaluations += int(found[3])
    pop, gens, polish = stages.joint
    found = _native.fit_lights(load_scene(d), target, paths, pixels, seed + len(d["lights"]), pop, gens, threads,
                               start=x, polish=polish)
    evaluations += int(found[3])
    sides = [i for (_, a, b), p in zip(blocks, paths) if p.endswith(".size") for i in range(a, b)]
    if sides:
        pop, gens, polish = stages.restart
        for k in range(stages.restarts):
            x, n = _scan(d, paths, target, pixels, list(found[0]), sides, box, stages.scan)
            found = _native.fit_lights(load_scene(d), target, paths, pixels, seed + len(d["lights"]) + 1 + k, pop,
                                       gens, threads, start=x, polish=polish)
            evaluations += n + int(found[3])
    return list(found[0]), float(found[1]), found[2], evaluations


def _scan(d: dict[str, Any], paths: list[str], target: np.ndarray, pixels: np.ndarray, x: list[float],
          sides: list[int], box: list[tuple[float, float]], points: int) -> tuple[list[float], int]:
    """Each rectangle's width and height in turn set to the best of ``points`` values spread evenly in
    its logarithm over its search range (and its own value), the rest held; returns x and the
    evaluations spent."""
    scene = load_scene(d)
    x = list(x)
    for i in sides:
        lo, hi = box[i]
        best = (float(_native.lights_solve(scene, target, paths, pixels, x)[0]), x[i])
        for v in np.geomspace(lo, hi, points):
            x[i] = float(v)
            best = min(best, (float(_native.lights_solve(scene, target, paths, pixels, x)[0]), x[i]))
        x[i] = best[1]
    return x, len(sides) * (points + 1)
