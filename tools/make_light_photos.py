#!/usr/bin/env python3
"""Render rtloop's several-light test photos with an independent renderer (Mitsuba 3, ``scalar_rgb``).

Each case is a small scene (balls on an infinite floor) under two or three lights: a key light and a fill
of a given fraction of its power, three lamps, a lamp and a sphere light, one sphere light of 0.1-0.5 m
(soft shadows), or a lamp beside a window (a 1.5 x 1 m rectangle light about 4 m away, radiance
intensity x colour / area, one-sided) or beside a 1.2 x 0.8 m softbox about 2 m away (its size free in the fit
section: its soft shadows show it), the window under a dim constant room light. It reuses ``make_photos.py``'s conventions and code (camera, floor, materials, sRGB
encoding, a sphere light's radiance I / (pi r^2)). For each case it writes ``OUT/NAME/``:

``scene.json``        the truth in rtloop's scene format (a ``lights`` list);
``scene_input.json``  what a user writes: the geometry, one neutral light, the fit section freeing the
                      first light's position (and, for a sphere light, its radius) and every albedo, and a
                      rectangle light's centre (and for the softbox its size);
``objective.png``     the photo, 128x96 8-bit sRGB;
``meta.json``         how it was made.

Usage: ``nice -n 10 python3 tools/make_light_photos.py [--out DIR] [--only NAME ...] [--spp N]``.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import make_photos as mp  # noqa: E402

DEFAULT_OUT = mp.REPO / "tests" / "fixtures" / "lights"
SPP = 256

TWO_BALLS = [
    mp._sphere("red", [-0.6, 0.5, 0.1], 0.5, mp._diffuse([0.75, 0.3, 0.25])),
    mp._sphere("blue", [0.75, 0.4, -0.3], 0.4, mp._diffuse([0.25, 0.4, 0.7])),
    mp._floor([0.55, 0.55, 0.5]),
]
KEY = {"name": "key", "position": [2.0, 3.4, -1.8], "intensity": 40.0, "color": [1.0, 0.95, 0.9]}


def fill(fraction: float) -> dict[str, Any]:
    """A fill light on the other side, about 3.6 m from the balls, at ``fraction`` of the key's intensity."""
    return {"name": "fill", "position": [-2.6, 2.4, -1.2], "intensity": KEY["intensity"] * fraction,
            "color": [0.9, 0.95, 1.0]}


CASES: list[dict[str, Any]] = [
    {"name": f"key-fill-{int(100 * f)}", "description": f"two balls, a key light and a fill at {f:.0%} of its power",
     "lights": [KEY, fill(f)], "objects": TWO_BALLS, "seed": 31 + k}
    for k, f in enumerate([0.1, 0.25, 0.5])
] + [
    {"name": "three-lights", "description": "two balls under a key, a fill and a back light",
     "lights": [KEY, fill(0.3), {"name": "back", "position": [0.4, 3.8, 2.6], "intensity": 20.0,
                                  "color": [1.0, 1.0, 1.0]}],
     "objects": TWO_BALLS, "seed": 40},
] + [
    {"name": f"soft-{int(100 * r)}", "description": f"two balls under one sphere light of radius {r} m",
     "lights": [{**KEY, "type": "sphere", "radius": r}], "objects": TWO_BALLS, "seed": 50 + k}
    for k, r in enumerate([0.1, 0.3, 0.5])
]


WINDOW_CENTRE = np.array([-3.4, 2.2, 1.4])
WINDOW_NORMAL = (np.array([0.0, 0.6, 0.0]) - WINDOW_CENTRE) / np.linalg.norm(np.array([0.0, 0.6, 0.0]) - WINDOW_CENTRE)
WINDOW = {"name": "window", "type": "rectangle", "position": WINDOW_CENTRE.tolist(), "size": [1.5, 1.0],
          "normal": WINDOW_NORMAL.tolist(), "up": [0.0, 1.0, 0.0], "intensity": 30.0, "color": [0.85, 0.92, 1.0]}
CASES.append({"name": "lamp-window", "description": "two balls under a lamp and a 1.5 x 1 m window about 4 m "
              "away, a dim constant room light", "lights": [KEY, WINDOW], "objects": TWO_BALLS, "seed": 60,
              "environment": [0.01, 0.01, 0.01]})

SOFTBOX_CENTRE = np.array([-2.1, 1.5, -1.0])
SOFTBOX_NORMAL = (np.array([0.0, 0.4, 0.0]) - SOFTBOX_CENTRE) / np.linalg.norm(np.array([0.0, 0.4, 0.0]) - SOFTBOX_CENTRE)
SOFTBOX = {"name": "softbox", "type": "rectangle", "position": SOFTBOX_CENTRE.tolist(), "size": [1.2, 0.8],
           "normal": SOFTBOX_NORMAL.tolist(), "up": [0.0, 1.0, 0.0], "intensity": 10.0, "color": [1.0, 0.96, 0.9]}
CASES.append({"name": "lamp-softbox", "description": "two balls under a lamp and a 1.2 x 0.8 m softbox about "
              "2 m away whose soft shadows show its size",
              "lights": [KEY, SOFTBOX], "objects": TWO_BALLS, "seed": 61, "fit_size": True})


def rectangle_frame(light: dict[str, Any]) -> np.ndarray:
    """The 4x4 matrix taking Mitsuba's rectangle ([-1, 1]^2 in z = 0, normal +z) to the window: x along
    its width (up x normal), y along its height (up made orthogonal to the normal), z along its normal."""
    n = np.asarray(light["normal"], float)
    n /= np.linalg.norm(n)
    up = np.asarray(light.get("up", [0.0, 1.0, 0.0]), float)
    up = up - up.dot(n) * n
    up /= np.linalg.norm(up)
    u = np.cross(up, n)
    m = np.eye(4)
    m[:3, 0] = u * light["size"][0] / 2
    m[:3, 1] = up * light["size"][1] / 2
    m[:3, 2] = n
    m[:3, 3] = light["position"]
    return m


def mitsuba_scene(case: dict[str, Any], spp: int) -> dict[str, Any]:
    first = case["lights"][0]
    c = mp.Case(case["name"], case["description"], "", mp.CAM_A, first["position"], first["intensity"],
                first["color"], case["objects"], integrator="direct", spp=spp, seed=case["seed"],
                lamp_radius=float(first.get("radius", 0.0)))
    d = mp.mitsuba_dict(c, spp=spp, seed=case["seed"])
    for k, light in enumerate(case["lights"][1:]):
        rgb = light["intensity"] * np.asarray(light["color"], float)
        if light.get("type") == "rectangle":
            radiance = rgb / (light["size"][0] * light["size"][1])
            d[f"window{k + 1}"] = {"type": "rectangle",
                                   "to_world": mp._mi().ScalarTransform4f(rectangle_frame(light).tolist()),
                                   "bsdf": {"type": "diffuse", "reflectance": mp._rgb([0, 0, 0])},
                                   "emitter": {"type": "area", "radiance": mp._rgb(radiance)}}
        elif light.get("type") == "sphere":
            d[f"lamp{k + 1}"] = {"type": "sphere", "center": light["position"], "radius": light["radius"],
                                 "bsdf": {"type": "diffuse", "reflectance": mp._rgb([0, 0, 0])},
                                 "emitter": {"type": "area",
                                             "radiance": mp._rgb(mp.lamp_radiance(rgb, light["radius"]))}}
        else:
            d[f"light{k + 1}"] = {"type": "point", "position": light["position"], "intensity": mp._rgb(rgb)}
    if case.get("environment"):
        d["environment"] = {"type": "constant", "radiance": mp._rgb(case["environment"])}
    return d


def objects_json(case: dict[str, Any], albedo: list[float] | None = None) -> list[dict[str, Any]]:
    out = []
    for o in case["objects"]:
        g = {k: v for k, v in o.items() if k != "bsdf"}
        g["material"] = {"albedo": albedo or o["bsdf"]["albedo"]}
        out.append(g)
    return out


def make(case: dict[str, Any], out: Path, spp: int) -> None:
    folder = out / case["name"]
    folder.mkdir(parents=True, exist_ok=True)
    linear = mp.render(mitsuba_scene(case, spp))
    (folder / "objective.png").write_bytes(mp.png_bytes(mp.encode8(linear)))
    camera = dict(mp.CAM_A)
    truth = {"name": case["name"], "description": case["description"],
             "image": {"width": mp.WIDTH, "height": mp.HEIGHT}, "camera": camera,
             "lights": [{k: v for k, v in light.items()} for light in case["lights"]],
             "ambient": [0.0, 0.0, 0.0], "exposure": 1.0, "objects": objects_json(case)}
    if case.get("environment"):
        truth["environment"] = case["environment"]
    first = case["lights"][0]
    guess = {"name": "key", "position": mp.INPUT_LIGHT["position"], "intensity": first["intensity"],
             "color": first["color"]}
    fit = {"light.position": mp.FIT_LIGHT_POSITION,
           **{f"objects.{o['name']}.albedo": mp.FIT_ALBEDO for o in case["objects"]}}
    if first.get("type") == "sphere":
        guess.update(type="sphere", radius=0.2)
        fit["lights.key.radius"] = {"min": 0.02, "max": 0.8}
    scene_input = {k: v for k, v in truth.items() if k not in ("lights", "objects", "environment")}
    lights = [guess]
    for light in case["lights"][1:]:
        if light.get("type") == "rectangle":
            # The window's size and the wall it is in are known; its centre is a guess, fitted.
            lights.append({**light, "position": [-3.0, 2.5, 0.0], "intensity": first["intensity"],
                           "color": [1.0, 1.0, 1.0]})
            fit[f"lights.{light['name']}.position"] = {"min": [-6.0, 0.5, -4.0], "max": [-1.0, 5.0, 4.0]}
            if case.get("fit_size"):
                # ... and, where the photo shows it, its size: a guess, fitted.
                lights[-1]["size"] = [0.6, 0.6]
                fit[f"lights.{light['name']}.size"] = {"min": 0.1, "max": 3.0}
    scene_input.update(lights=lights, objects=objects_json(case, mp.INPUT_ALBEDO), fit=fit)
    mp.write_json(folder / "scene.json", truth)
    mp.write_json(folder / "scene_input.json", scene_input)
    mp.write_json(folder / "meta.json", {"renderer": f"mitsuba {mp.MITSUBA_VERSION} {mp.VARIANT}",
                                         "integrator": "direct", "spp": spp, "seed": case["seed"],
                                         "sphere lights": "radiance = intensity x color / (pi r^2)",
                                         "post": "sRGB OETF of clamp(x, 0, 1), 8 bit, no noise"})
    print(case["name"], "written", file=sys.stderr)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=DEFAULT_OUT)
    ap.add_argument("--only", nargs="*")
    ap.add_argument("--spp", type=int, default=SPP)
    a = ap.parse_args(argv)
    for case in CASES:
        if not a.only or case["name"] in a.only:
            make(case, a.out, a.spp)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
