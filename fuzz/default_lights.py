"""fuzz/fuzz.py's ``default_lights`` surface: the default fit's number of lights (rtloop/fit/more_lights.py).

A one-light scene (fuzz.py's BASE, or one of its fit scenes, or a mutated one) fitted with the defaults
(``lights`` not given, at times ``lights=1`` or an argument the lights fit does not take) to a photo of it
under a second light anywhere, of any power, at times with noise, clipped or with odd pixels: it fits or
refuses in one line. A one-light answer carries a JSON-able, finite record of what it tried; a lights fit
a gate that fired and evidence that keeps every light it added (else a wrong answer reported as ok)."""

from __future__ import annotations

import copy
import json
import math
import random
from typing import Any, Callable

import numpy as np

import rtloop
from rtloop.fit.lights import AUTO_GAIN


def _photo(rng: random.Random, scene: dict) -> np.ndarray:
    """The scene under its light and a second one anywhere (at times none), noisy, clipped or odd."""
    d = copy.deepcopy(scene)
    light = d.pop("light", None) or {"position": [0.0, 4.0, 0.0], "intensity": 50.0}
    second = {"name": "second", "position": [rng.uniform(-8, 8), rng.uniform(0.5, 8), rng.uniform(-8, 8)],
              "intensity": float(light.get("intensity", 50.0)) * rng.choice([0.0, 0.05, 0.3, 1.0, 3.0])}
    d["lights"] = [{"name": "key", **light}, second]
    d["fit"] = {}
    photo = np.asarray(rtloop.render(d), np.float32)
    if rng.random() < 0.3:
        photo = photo + np.random.default_rng(rng.randrange(2**32)).normal(0, rng.choice([0.005, 0.05]), photo.shape)
    if rng.random() < 0.3:
        photo = np.minimum(photo, 1.0)
    if rng.random() < 0.05:
        photo[rng.randrange(photo.shape[0]), rng.randrange(photo.shape[1])] = rng.choice([np.nan, np.inf, -1.0])
    return np.asarray(photo, np.float32)


def _check_one(res: Any, c: Any, finite: Callable[[Any], bool]) -> None:
    tested = res.model.get("lights")
    if tested is None:
        return
    c.bump("default_lights_tried" if tested.get("tried") else "default_lights_not_tried")
    try:
        json.dumps(tested, allow_nan=False)
    except ValueError:
        c.bump("nan_or_inf")
    if tested.get("kept") != 1 or not tested.get("why") or any(e["kept"] for e in tested.get("evidence", [])[1:]):
        c.bump("wrong_ok")


def _check_lights(res: Any, c: Any) -> None:
    c.bump("default_lights_kept")
    gate, ev = res.gate or {}, res.evidence
    kept = [e for e in ev if e["kept"]]
    if not gate.get("fires") or len(kept) != 1 or kept[0]["lights"] != len(res.lights) or len(res.lights) < 2:
        c.bump("wrong_ok")
        return
    for before, after in zip(ev, ev[1:]):
        if after["lights"] <= kept[0]["lights"] and not (
                after["held_out"] < (1 - AUTO_GAIN) * before["held_out"] and after.get("passes")):
            c.bump("wrong_ok")
    if not all(math.isfinite(e["held_out"]) for e in ev):
        c.bump("nan_or_inf")


def default_lights(rng: random.Random, c: Any, scenes: list[dict], mutate: Callable[[random.Random, dict], dict],
                   check: Callable[[Any, dict, Any], None], finite: Callable[[Any], bool]) -> None:
    """One input of the surface (``scenes``: fuzz.py's FIT_SCENES, BASE first; ``check``: its check_fit)."""
    scene = copy.deepcopy(rng.choice(scenes))
    photo = _photo(rng, scene)
    if rng.random() < 0.1:
        scene = mutate(rng, scene)
    kw: dict[str, Any] = {"seed": rng.randrange(100), "uncertainty": rng.random() < 0.3}
    if rng.random() < 0.2:
        kw.update(rng.choice([{"lights": 1}, {"norm": "l2"}, {"protocol": "paper", "generations": 2},
                              {"framing": "correct"}, {"uncertainty": "bootstrap"}, {"population": 8}]))
    res = rtloop.fit(scene, photo, **kw)
    check(res, scene, c)
    if isinstance(res, rtloop.FitResult):
        if kw.get("lights") == 1 and "lights" in res.model:
            c.bump("wrong_ok")
        _check_one(res, c, finite)
    else:
        _check_lights(res, c)
