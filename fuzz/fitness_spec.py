"""fuzz/fuzz.py's ``fitness_spec`` surface: the native fitness spec (``_native.FitnessSpec``) and the calls
that take it (``_native.evaluate``, ``_native.held_out``, ``_native.optimize``).

A spec of a fit scene's fitness with valid values, or with one field replaced by an odd value (a wrong
type, dtype or shape, NaN, a bound whose low exceeds its high, an unknown name), then each native call on the
scene with a population, folds and a short search that fit it: the spec refuses in one line that starts with
the field's name, or the calls return finite values (or refuse in one line)."""

from __future__ import annotations

import copy
import random
from typing import Any, Callable

import numpy as np

import rtloop
from rtloop import _native
from rtloop.fit.products import product_bounds
from rtloop.fit.protocol import searched_paths

#: Odd values per field beside the campaign's own (``odd``): wrong dtypes, shapes and names.
ODD_FIELDS: dict[str, list[Any]] = {
    "paths": ["light.position", ["nowhere"], [1, 2], [["light.position"]]],
    "pixels": [np.zeros(3, np.int64), np.zeros((2, 2), np.uint32), np.array([1e9]), np.zeros(0, np.uint32),
               np.array([10**6], np.uint32), [0, 1]],
    "loss": ["L1", "l1_projected ", "l2"],
    "clip": [1, "yes", np.float32(1)],
    "product_bounds": [np.zeros((1, 5, 2)), np.zeros((1, 4, 2), np.float32), np.zeros((4, 2)),
                       np.full((1, 4, 2), np.nan), np.array([[[1.0, 0.0]] * 4]), np.zeros((7, 4, 2))],
    "norm": ["L1", "huber:-1", "huber:nan", "huber:", "l3"],
    "space": ["sRGB", "gamma"],
    "footprint": [2, "on"],
    "frozen_bounce": [-1, 2**70, 1.5, "2"],
    "saturated": [0.0, -1.0, float("nan"), float("inf"), "0.9"],
    "solve_margin": [-1, 2**70, 0.5],
}


def _valid(rng: random.Random, scene: rtloop.Scene, constant: bool) -> dict[str, Any]:
    """A spec's arguments as a fit passes them (``constant``: the scene's ambient or environment light
    needs the closed form's environment column)."""
    loss = rng.choice(["l1", "l1_rgb", "l1_projected", "l1_projected"])
    paths = rng.sample(scene.fit_paths, rng.randint(1, len(scene.fit_paths)))
    if loss == "l1_projected":
        paths = searched_paths(scene.fit_paths)
        if _native.projection_blocker(scene, paths) is not None:
            loss = "l1"
    n = scene.width * scene.height
    kw: dict[str, Any] = {
        "paths": paths,
        "loss": loss, "clip": rng.random() < 0.8, "norm": rng.choice(["l1", "l2", "huber", "huber:0.05"]),
        "space": rng.choice(["linear", "srgb"]), "footprint": rng.random() < 0.2,
        "frozen_bounce": rng.randint(0, 3), "solve_margin": rng.randint(0, 3),
    }
    if loss == "l1_projected":
        kw["product_bounds"] = product_bounds(scene, constant or rng.random() < 0.5)
    if rng.random() < 0.5:
        kw["pixels"] = np.sort(np.random.default_rng(rng.randrange(2**32)).choice(n, rng.randint(1, n), False)
                               ).astype(np.uint32)
    if rng.random() < 0.3:
        kw["saturated"] = rng.uniform(0.5, 1.0)
    return kw


def fitness_spec(rng: random.Random, c: Any, scenes: list[dict], odd: Callable[[random.Random], Any],
                 finite: Callable[[Any], bool]) -> None:
    """One input of the surface (``scenes``: fuzz.py's FIT_SCENES; ``finite``: its check of an output)."""
    d = copy.deepcopy(rng.choice(scenes))
    if rng.random() < 0.5:  # the intensity held, as a fit holds it where it only rescales the albedos
        d["fit"].pop("light.intensity", None)
    scene = rtloop.load_scene(d)
    kw = _valid(rng, scene, any(d.get("ambient") or [0]) or "environment" in d)
    field = None
    if rng.random() < 0.6:
        field = rng.choice(list(ODD_FIELDS))
        kw[field] = rng.choice(ODD_FIELDS[field]) if rng.random() < 0.6 else odd(rng)
    paths = kw.pop("paths")
    try:
        spec = _native.FitnessSpec(paths, **kw)
    except rtloop.RtloopError as e:
        if "\n" in str(e) or (field is not None and not str(e).startswith(f"{field}: ")):
            c.bump("traceback_not_one_line")
        raise
    values = _calls(rng, scene, spec, paths, kw)
    if not all(finite(v) for v in values):
        c.bump("nan_or_inf")


def _calls(rng: random.Random, scene: rtloop.Scene, spec: Any, paths: list[str], kw: dict[str, Any]) -> list:
    """``spec``'s evaluations at points in the bounds of ``paths``, its held-out losses (the closed form) and
    at times a short search: their outputs."""
    target = np.asarray(rtloop.render(scene), np.float32)
    bounds = np.array(scene.bounds(paths), np.float64).reshape(-1, 2)
    gen = np.random.default_rng(rng.randrange(2**32))
    population = bounds[:, 0] + (bounds[:, 1] - bounds[:, 0]) * gen.random((3, len(bounds)))
    values = [_native.evaluate(scene, target, population, spec, threads=1)]
    if kw["loss"] == "l1_projected":
        pixels = kw.get("pixels")
        count = scene.width * scene.height if pixels is None else len(pixels)
        folds = gen.integers(0, 5, count).astype(np.uint8)
        values.append(_native.held_out(scene, target, population[0], folds, spec, threads=1))
    if rng.random() < 0.3:
        out = _native.optimize(scene, target, spec, population=4, generations=1, seed=rng.randrange(100),
                               method="de" if kw["loss"] == "l1_rgb" else rng.choice(["de", "lshade"]),
                               polish=rng.choice([0, 5]), threads=1)
        values += [out.x, out.objectives]
    return values
