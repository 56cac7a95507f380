"""Where the lamp photos' light error comes from: the default fit on the Mitsuba photo against the same fit
on rtloop's own renders of the photo's truth, each with one of the photo's features added.

Per case of ``tests/fixtures/photos`` (default: the three lamp photos):

- ``photo, seeds 0-2``: the default ``rtloop.fit`` of ``objective.png`` with three seeds (a spread of
  millimetres: the search converges, the error is the loss's);
- ``loss at the truth``: the fit with the light held at the truth (a box of +-0.1 mm) against the fitted
  light's loss, both in the fit's own loss;
- rtloop's render of ``scene.json`` (16 spp, one bounce), the default fit of it, with: nothing more
  (``matte, clean``); the lamp a sphere of the photo's radius (``sphere lamp``); the ball coated as
  Mitsuba's roughplastic (its diffuse reflectance under a GGX coat of the photo's alpha, IOR 1.49:
  ``coated``); Gaussian noise and JPEG as the photo's ``post`` says (``+ noise, JPEG``).

Usage (from the repository root)::

    python studies/room_light_causes.py > studies/results/room_light_causes.md
    python studies/room_light_causes.py --cases lamp-side
"""

from __future__ import annotations

import argparse
import io
import json
import sys
from pathlib import Path
from typing import Any

import numpy as np
from PIL import Image

import rtloop
from rtloop._srgb import decode, encode

REPO = Path(__file__).resolve().parents[1]
FIXTURES = REPO / "tests" / "fixtures" / "photos"
CASES = ("lamp-side", "lamp-desk", "lamp-front")


def _error_mm(result: Any, truth: dict[str, Any]) -> float:
    fitted = np.asarray(result.scene.to_dict()["light"]["position"], float)
    return 1000.0 * float(np.linalg.norm(fitted - np.asarray(truth["light"]["position"], float)))


def _truth_render(truth: dict[str, Any], meta: dict[str, Any], *, sphere: bool, coated: bool) -> np.ndarray:
    """rtloop's render of the truth with one bounce, the lamp a sphere and the ball coated where asked."""
    t = {k: v for k, v in truth.items() if k != "fit"}
    t["interreflection"] = True
    t["objects"] = json.loads(json.dumps(t["objects"]))
    lamp = meta["extra_truth"]["lamp"]
    if sphere:
        light = t.pop("light")
        t["lights"] = [{"type": "sphere", "name": "lamp", "position": light["position"], "radius": lamp["radius_m"],
                        "intensity": light["intensity"], "color": light["color"]}]
    for name, glossy in meta["extra_truth"].get("glossy_objects", {}).items() if coated else ():
        bsdf = glossy["bsdf"]
        for o in t["objects"]:
            if o["name"] == name:
                o["material"] = {"albedo": bsdf["diffuse_reflectance"], "specular": 1.0,
                                 "coat": {"roughness": bsdf["alpha"], "ior": 1.49}}
    return np.asarray(rtloop.render(t, spp=16), np.float64)


def _as_photo(linear: np.ndarray, post: dict[str, Any] | None) -> np.ndarray:
    """``linear`` as an 8-bit sRGB file holds it: with the photo's noise and JPEG where ``post`` is given."""
    if post is not None:
        linear = linear + np.random.default_rng(post["noise_seed"]).normal(0.0, post["noise_sigma_linear"],
                                                                           linear.shape)
    codes = np.round(255.0 * encode(np.clip(linear, 0.0, 1.0))).astype(np.uint8)
    if post is not None and post.get("jpeg_quality"):
        buf = io.BytesIO()
        Image.fromarray(codes).save(buf, "JPEG", quality=post["jpeg_quality"])
        codes = np.asarray(Image.open(io.BytesIO(buf.getvalue())).convert("RGB"))
    return decode(codes / 255.0).astype(np.float32)


def study(case: str) -> list[str]:
    """The case's rows: (what was fitted, light error in mm, terms added)."""
    folder = FIXTURES / case
    truth = json.loads((folder / "scene.json").read_text())
    meta = json.loads((folder / "meta.json").read_text())
    user = json.loads((folder / "scene_input.json").read_text())
    scene = rtloop.load_scene(user)
    photo = rtloop.load_image(folder / "objective.png", scene)
    rows = []
    fits = [rtloop.fit(scene, photo, seed=s, uncertainty=False) for s in (0, 1, 2)]
    errs = ", ".join(f"{_error_mm(r, truth):.1f}" for r in fits)
    rows.append(f"| {case} | the photo, seeds 0-2 | {errs} | {'+'.join(fits[0].model['terms'][1:])} |")
    held = json.loads(json.dumps(user))
    t = np.asarray(truth["light"]["position"], float)
    held["fit"]["light.position"] = {"min": list(t - 1e-4), "max": list(t + 1e-4)}
    at_truth = rtloop.fit(rtloop.load_scene(held), photo, seed=0, uncertainty=False)
    rows.append(f"| {case} | loss at the fitted light / at the truth | {fits[0].fitness:.2f} / "
                f"{at_truth.fitness:.2f} | {'+'.join(at_truth.model['terms'][1:])} |")
    for label, sphere, coated, post in (("rtloop's render of the truth: matte, clean", False, False, None),
                                        ("... sphere lamp, clean", True, False, None),
                                        ("... coated, clean", False, True, None),
                                        ("... matte + noise, JPEG", False, False, meta["post"]),
                                        ("... coated + noise, JPEG", False, True, meta["post"])):
        image = _as_photo(_truth_render(truth, meta, sphere=sphere, coated=coated), post)
        r = rtloop.fit(scene, image, seed=0, uncertainty=False)
        rows.append(f"| {case} | {label} | {_error_mm(r, truth):.1f} | {'+'.join(r.model['terms'][1:])} |")
    return rows


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--cases", nargs="+", default=list(CASES), metavar="NAME")
    args = parser.parse_args(argv)
    print("# Where the lamp photos' light error comes from (`python studies/room_light_causes.py`)\n")
    print("| case | fitted | light error (mm) | terms added |\n| --- | --- | ---: | --- |")
    for case in args.cases:
        for row in study(case):
            print(row, flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
