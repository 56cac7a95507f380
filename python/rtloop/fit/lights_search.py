"""The lights fit's staged search: one light at a time, then all together.

The first light is searched alone (the others left out of the scene); each further light is then searched
with the lights found so far held at their values (these searches see every other chosen pixel); last,
L-SHADE started from that point with a small population, and its Nelder–Mead polish, move all the lights
together over all the chosen pixels. Every candidate's products are the closed form
of ``rust/fitness/lights.rs``. docs/methods.md, "Several lights".
"""

from __future__ import annotations

import copy
from dataclasses import dataclass
from typing import Any

import numpy as np

from .. import _native
from ..scene import load_scene


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


def _blocks(d: dict[str, Any], paths: list[str]) -> list[tuple[int, int, int]]:
    """Per searched path: its light's index and its slice of x."""
    from .lights import _locate
    out, k = [], 0
    for p in paths:
        light, key = _locate(p, d["lights"])
        n = 1 if key == "radius" else 3
        out.append((d["lights"].index(light), k, k + n))
        k += n
    return out


def _bounds(d: dict[str, Any], paths: list[str]) -> list[tuple[float, float]]:
    out: list[tuple[float, float]] = []
    for p in paths:
        b = d["fit"][p]
        n = 1 if p.endswith(".radius") else 3
        lo = np.broadcast_to(np.asarray(b["min"], float), n)
        hi = np.broadcast_to(np.asarray(b["max"], float), n)
        out += [(float(a), float(c)) for a, c in zip(lo, hi)]
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
        start = x + [(lo + hi) / 2 for lo, hi in box[len(x):n]] if x else None
        found = _native.fit_lights(load_scene(sub), target, sub_paths, few, seed + i, pop, gens, threads,
                                   bounds=held + box[len(x):n], start=start, polish=polish)
        x = list(found[0])
        evaluations += int(found[3])
    pop, gens, polish = stages.joint
    found = _native.fit_lights(load_scene(d), target, paths, pixels, seed + len(d["lights"]), pop, gens, threads,
                               start=x, polish=polish)
    return list(found[0]), float(found[1]), found[2], evaluations + int(found[3])
