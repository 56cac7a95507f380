"""fuzz/fuzz.py's ``lights`` surface: the lights fit with a rectangle light's size free (and at times a
glossy object, its lobe one more column per light).

The base scene's window (its centre and size free) fitted to a photo of the base with the window resized
(or of a mutated scene), or the base with its size entry's bounds, or the window's own size, replaced by
odd values: it fits (every size within its bounds, finite, each side's error bar finite or None with a
note) or refuses in one line."""

from __future__ import annotations

import copy
import math
import random
from typing import Any, Callable

import numpy as np

import rtloop


def lights_size(rng: random.Random, c: Any, base: dict, mutate: Callable[[random.Random, dict], dict],
                odd: Callable[[random.Random], Any], check: Callable[[Any, dict, Any], None]) -> None:
    """One input of the surface (``base``: fuzz.py's LIGHTS_BASE; ``check``: its check_fit)."""
    truth = copy.deepcopy(base)
    window = next(light for light in truth["lights"] if light["name"] == "window")
    window["size"] = [rng.uniform(0.3, 3.0), rng.uniform(0.3, 3.0)]
    photo = np.minimum(rtloop.render(truth), 1.0)
    scene = copy.deepcopy(base)
    which = rng.random()
    if which < 0.3:
        entry = scene["fit"]["lights.window.size"]
        entry[rng.choice(["min", "max"])] = odd(rng) if rng.random() < 0.7 else [odd(rng), odd(rng)]
    elif which < 0.4:
        next(light for light in scene["lights"] if light["name"] == "window")["size"] = odd(rng)
    elif which < 0.5:
        scene = mutate(rng, scene)
    if which >= 0.5 and rng.random() < 0.6:  # a glossy object: its lobe is one more column per light
        material = scene["objects"][0].setdefault("material", {})
        material["specular"] = rng.uniform(0.0, 2.0) if rng.random() < 0.8 else odd(rng)
        material["shininess"] = rng.uniform(0.0, 200.0) if rng.random() < 0.8 else odd(rng)
    res = rtloop.fit(scene, photo, seed=rng.randrange(100), population=4, generations=1)
    check(res, scene, c)
    entry = scene["fit"].get("lights.window.size")
    for light in res.lights:
        if light["name"] != "window" or not isinstance(entry, dict) or "size_error" not in light:
            continue
        lo, hi = (np.broadcast_to(np.asarray(entry[k], float), 2) for k in ("min", "max"))
        if not all(math.isfinite(v) and a - 1e-12 <= v <= b + 1e-12 for v, a, b in zip(light["size"], lo, hi)):
            c.bump("out_of_bounds")
        for bar in light["size_error"]:
            if bar is not None and not (math.isfinite(bar) and bar >= 0):
                c.bump("nan_or_inf")
        if None in light["size_error"] and "size_note" not in light:
            c.bump("wrong_ok")
    for o in rtloop.scene_to_dict(res.scene)["objects"]:
        if not (math.isfinite(o["material"]["specular"]) and o["material"]["specular"] >= 0):
            c.bump("nan_or_inf")
