#!/usr/bin/env python3
"""Render the held-out test photos of tests/fixtures/heldout with rtloop's own renderer.

``rim``: the direct-light truth of tests/fixtures/photos/direct-side (an orange ball on a floor, one point
light, no environment) rendered by rtloop (16 samples per pixel), with a bright band painted on the ball
along part of its silhouette: the ball's pixels within RIM_WIDTH pixels of a pixel that is not the ball,
whose direction from the ball's image centroid is within RIM_HALF_ANGLE degrees of RIM_ANGLE (counted
anticlockwise from the image's +x axis), raised by RIM_ADD in linear units. No light the scene format
holds makes such a band: it stands for the few pixels along a real ball's outline that the direct model
misses. The truth is the direct light (``scene.json``).

``room``: the same truth with a constant environment (ENVIRONMENT, occluded by the ball and the floor) and
no band: an environment the model has.

Each folder gets ``scene.json`` (the truth), ``scene_input.json`` (direct-side's: what a user writes),
``objective.png`` (8-bit sRGB of the clamped render) and ``meta.json`` (these settings).

Usage (from the repository root, with the extension built)::

    python tools/make_rim_photos.py tests/fixtures/heldout
"""

from __future__ import annotations

import argparse
import json
import shutil
from pathlib import Path

import numpy as np

import rtloop

REPO = Path(__file__).resolve().parents[1]
SOURCE = REPO / "tests" / "fixtures" / "photos" / "direct-side"
SPP = 16
RIM_WIDTH = 3.0
RIM_ANGLE = 200.0
RIM_HALF_ANGLE = 50.0
RIM_ADD = 0.4
ENVIRONMENT = [0.06, 0.07, 0.09]


def rim_band(ids: np.ndarray, obj: int = 0) -> np.ndarray:
    """The band of object ``obj``'s pixels (``ids``: object index per pixel) within RIM_WIDTH pixels
    (Euclidean) of another object's pixel, in the sector RIM_ANGLE +- RIM_HALF_ANGLE about its centroid."""
    mine = ids == obj
    h, w = mine.shape
    near = np.zeros_like(mine)
    r = int(np.ceil(RIM_WIDTH))
    padded = np.pad(~mine, r, constant_values=True)
    for dy in range(-r, r + 1):
        for dx in range(-r, r + 1):
            if dx * dx + dy * dy <= RIM_WIDTH * RIM_WIDTH:
                near |= padded[r + dy:r + dy + h, r + dx:r + dx + w]
    yy, xx = np.mgrid[0:h, 0:w]
    angle = np.degrees(np.arctan2(-(yy - yy[mine].mean()), xx - xx[mine].mean()))
    off = (angle - RIM_ANGLE + 180.0) % 360.0 - 180.0
    return mine & near & (np.abs(off) <= RIM_HALF_ANGLE)


def write_case(out: Path, truth: dict, image: np.ndarray, meta: dict) -> None:
    out.mkdir(parents=True, exist_ok=True)
    (out / "scene.json").write_text(json.dumps(truth, indent=2) + "\n")
    shutil.copyfile(SOURCE / "scene_input.json", out / "scene_input.json")
    rtloop.save_image(out / "objective.png", np.clip(image, 0.0, 1.0).astype(np.float32))
    (out / "meta.json").write_text(json.dumps(meta, indent=2) + "\n")


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("out", type=Path, help="folder for the case folders")
    args = p.parse_args(argv)
    truth = json.loads((SOURCE / "scene.json").read_text())
    scene = rtloop.load_scene(SOURCE / "scene.json")
    image = np.array(rtloop.render(scene, spp=SPP), np.float32)
    band = rim_band(np.asarray(rtloop.object_ids(scene)))
    image[band] += RIM_ADD
    common = {"renderer": f"rtloop {rtloop.__version__} render(spp={SPP})", "source": "photos/direct-side"}
    write_case(args.out / "rim", truth, image, {
        **common, "rim": {"width_px": RIM_WIDTH, "angle_deg": RIM_ANGLE, "half_angle_deg": RIM_HALF_ANGLE,
                          "add_linear": RIM_ADD, "pixels": int(band.sum())},
        "what": "direct light plus a bright band along part of the ball's outline that no modelled light makes"})
    room = {**truth, "environment": ENVIRONMENT}
    image = np.array(rtloop.render(rtloop.Scene(json.dumps(room)), spp=SPP), np.float32)
    write_case(args.out / "room", room, image, {
        **common, "environment": ENVIRONMENT, "what": "direct light and a constant occluded environment"})
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
