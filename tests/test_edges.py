"""Photos whose light shows on the objects' outlines (Mitsuba 3, direct, 1024 samples per pixel, with truth in
tests/fixtures/photos/edge-*): a ball lit from behind (a rim narrower than a pixel), a crescent lit from behind
on one side, a ball over a nearly black floor, a light straight overhead. The default fit, against the truth
the fit did not see: the light within 1 cm, the target for photos the direct model explains."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

import rtloop

PHOTOS = Path(__file__).resolve().parent / "fixtures" / "photos"
EDGES = sorted(p.name for p in PHOTOS.iterdir() if p.name.startswith("edge-") and (p / "scene.json").exists())
#: Where the fit misses the target, and why.
GAPS = {
    "edge-dark-floor": "a ball over a floor of albedo 0.03, whose 8-bit sRGB codes are a few steps: the outline "
                       "gate takes the outline pixels averaged (24 -> 16 mm), and rtloop's own 256-spp render "
                       "of the truth fitted so is 5 mm off, 16 mm once rounded to 8 bits as the photo is",
}


def test_the_edge_photos_are_there():
    assert len(EDGES) == 4, EDGES


@pytest.mark.parametrize("name", [pytest.param(n, marks=pytest.mark.xfail(strict=True, reason=GAPS[n]))
                                  if n in GAPS else n for n in EDGES])
def test_light_within_1cm(name):
    folder = PHOTOS / name
    scene = rtloop.load_scene(folder / "scene_input.json")
    result = rtloop.fit(scene, rtloop.load_image(folder / "objective.png", scene), seed=0, uncertainty=False)
    truth = json.loads((folder / "scene.json").read_text())["light"]["position"]
    fitted = [result.x[f"light.position.{a}"] for a in "xyz"]
    error = float(np.linalg.norm(np.subtract(fitted, truth)))
    assert error < 0.01, f"{name}: light {1000 * error:.1f} mm off"
