#!/usr/bin/env python3
"""Render the ambient-or-environment test photos with an independent renderer (Mitsuba 3, ``scalar_rgb``).

Each case is a point light and a bright constant room light (Mitsuba's ``constant`` emitter, occluded by the
objects: darker under the balls and between them) over balls on a floor, path traced with direct light only
(max depth 2). The scene a user writes declares that room light as ``ambient`` of the same radiance
(unoccluded): the fit must find that the photo shows it occluded. It reuses ``make_photos.py``'s
conventions and code; for each case it writes ``OUT/NAME/``: ``scene.json`` (the truth, its room light as
``environment``), ``scene_input.json`` (the geometry, a neutral light, ``ambient`` the room light's radiance,
the fit section of make_photos), ``objective.png`` (128x96 8-bit sRGB) and ``meta.json``.

Usage: ``nice -n 10 python3 tools/make_ambient_photos.py [--out DIR] [--only NAME ...]``.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
import make_photos as mp  # noqa: E402

DEFAULT_OUT = mp.REPO / "tests" / "fixtures" / "ambient"

CASES = [
    mp.Case(
        "room-one-ball",
        "orange ball, light high front right, a bright grey room light (a quarter of the lit floor's radiance)",
        "the scene declares the room light as unoccluded ambient; the photo shows it occluded under the ball",
        mp.CAM_A, [1.4, 3.3, -1.2], 30.0, [1.0, 1.0, 1.0],
        [mp._sphere("ball", [0.0, 0.75, 0.0], 0.75, mp._diffuse([0.75, 0.45, 0.25])), mp._floor([0.5, 0.5, 0.5])],
        integrator="path", max_depth=2, environment=[0.2, 0.2, 0.2], seed=41, spp=512,
    ),
    mp.Case(
        "room-two-balls",
        "a green and a white ball close together, light low from the left, a bright bluish room light",
        "occluded room light between the balls and under them, declared as unoccluded ambient",
        mp.CAM_B, [-3.2, 2.0, -0.8], 40.0, [1.0, 0.95, 0.9],
        [mp._sphere("green", [-0.45, 0.5, 0.1], 0.5, mp._diffuse([0.3, 0.65, 0.35])),
         mp._sphere("white", [0.6, 0.45, -0.2], 0.45, mp._diffuse([0.8, 0.8, 0.8])), mp._floor([0.45, 0.45, 0.45])],
        integrator="path", max_depth=2, environment=[0.12, 0.14, 0.2], seed=42, spp=512,
    ),
]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="make_ambient_photos.py", description=__doc__.split("\n\n")[0])
    parser.add_argument("--only", metavar="NAME", action="append", help="render only this case (repeatable)")
    parser.add_argument("--out", type=Path, default=DEFAULT_OUT, help=f"output folder ({DEFAULT_OUT})")
    args = parser.parse_args(argv)
    by_name = {c.name: c for c in CASES}
    for name in args.only or list(by_name):
        case = by_name[name]
        s = mp.make_case(case, args.out)
        folder = args.out / case.name
        given = json.loads((folder / "scene_input.json").read_text())
        given["ambient"] = list(case.environment)
        mp.write_json(folder / "scene_input.json", given)
        print(f"{name}: {s['seconds']:.1f} s, clipped {100 * s['clipped']:.2f} %", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
