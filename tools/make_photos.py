#!/usr/bin/env python3
"""Render rtloop's test photos "as cameras take them" with an independent renderer (Mitsuba 3).

Every case is a small scene (one or two balls on an infinite floor, one lamp) rendered by Mitsuba 3
(``mitsuba==3.9.1``, variant ``scalar_rgb``: no LLVM needed; ``pip install '.[photos]'``) with effects
that rtloop's own renderer does not model yet: a pixel footprint (box filter, many samples per pixel),
a constant environment light that the objects occlude, interreflection, a GGX clear coat
(``roughplastic``), a spherical lamp of finite size, sensor noise and JPEG.  For each case the script
writes a folder ``OUT/NAME/`` with

``scene.json``
    the truth in rtloop's scene format (what a perfect fit recovers; a constant environment as the
    top-level key ``"environment": [r, g, b]``, radiance in the units of ``ambient``);
``scene_input.json``
    what a user writes today: the same camera and geometry, a neutral guess for the light and the
    colours, and the ``fit`` section freeing ``light.position``, ``light.intensity`` and every albedo;
``objective.png``
    the photo: 128x96, 8-bit sRGB, the sRGB OETF of clamp(x, 0, 1) (``lamp-*``: the decoded JPEG);
``objective.jpg``
    ``lamp-*`` only: the JPEG itself (quality 85);
``meta.json``
    how it was made (Mitsuba settings, integrator and depth, samples, seed, post-processing), what makes
    the case hard, the truth rtloop's format cannot hold yet (environment, lamp radius and radiance,
    roughplastic parameters and how the effective albedo was measured), exposure statistics and the
    measured Monte Carlo noise.

Conventions (checked against rtloop: ``--compare-with`` renders a reference scene's truth through the same
code path and prints the mean absolute difference from its ``objective.png`` in 8-bit codes): point
light ``intensity`` in W/sr = Mitsuba ``point`` ``intensity`` (times the light's colour); ``vfov_deg``
is the vertical field of view (``fov_axis: "y"``); the camera is Mitsuba's ``look_at`` of the scene's
position, look_at and up; an infinite plane is a two-sided 2000 m x 2000 m rectangle; a pixel is the
average radiance over its area (box reconstruction filter, stratified samples) times exposure 1.

Renders run on every core Mitsuba finds; run it under ``nice -n 10`` on a shared machine.
Needs Mitsuba, NumPy, Pillow and rtloop (the repository's ``python/`` with its extension built, or an
installed rtloop): the object ids and the sRGB encoding are rtloop's own.  The code is in
``tools/photos/``: cases.py (the cases), mitsuba.py (scenes, render), pixels.py (sRGB, PNG), truth.py
(truth and input scenes, object ids, measurements), make.py (one case's folder); this file is the
command line.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
from PIL import Image

sys.path.insert(0, str(Path(__file__).resolve().parent))
# The names the other make_*_photos.py tools use as ``make_photos.X``.
from photos import REPO  # noqa: E402
from photos.cases import (CAM_A, CAM_B, CAM_C, CASES, FIT_ALBEDO, FIT_INTENSITY,  # noqa: E402,F401
                          FIT_LIGHT_POSITION, HEIGHT, INPUT_ALBEDO, INPUT_LIGHT, WIDTH, Case, _diffuse,
                          _floor, _plastic, _sphere)
from photos.make import make_case, write_json  # noqa: E402,F401
from photos.mitsuba import (MITSUBA_VERSION, VARIANT, _mi, _rgb,  # noqa: E402,F401
                            lamp_radiance, mitsuba_dict, render)
from photos.pixels import encode8, png_bytes  # noqa: E402,F401
from photos.truth import input_scene, truth_scene  # noqa: E402,F401

DEFAULT_OUT = REPO / "tests" / "fixtures" / "photos"


def case_from_rtloop_scene(scene: dict[str, Any], *, spp: int, seed: int) -> Case:
    """A direct-light case of an rtloop scene (point light, diffuse objects, no ambient/specular)."""
    objects = []
    for obj in scene["objects"]:
        o = {k: v for k, v in obj.items() if k != "material"}
        o["bsdf"] = _diffuse(obj.get("material", {}).get("albedo", [0.5, 0.5, 0.5]))
        objects.append(o)
    light = scene["light"]
    return Case("compare", "", "", scene["camera"], light["position"], float(light["intensity"]),
                light.get("color", [1.0, 1.0, 1.0]), objects, spp=spp, seed=seed)


def compare_with(folder: Path, spp: int) -> float:
    """Render ``folder/scene.json`` through this script's code path; mean |codes - objective.png|."""
    scene = json.loads((folder / "scene.json").read_text())
    if (scene["image"]["width"], scene["image"]["height"]) != (WIDTH, HEIGHT):
        raise SystemExit(f"--compare-with: only {WIDTH}x{HEIGHT} scenes")
    case = case_from_rtloop_scene(scene, spp=spp, seed=1)
    mine = encode8(render(mitsuba_dict(case, spp=spp, seed=1))).astype(np.int32)
    ref = np.asarray(Image.open(folder / "objective.png").convert("RGB"), np.int32)
    diff = np.abs(mine - ref)
    mad = float(diff.mean())
    print(f"{folder}: mean |codes - objective.png| = {mad:.3f}, max {int(diff.max())}, "
          f"pixels differing by > 2 codes: {float(np.mean(diff.max(axis=2) > 2)) * 100:.2f} %")
    return mad


def main(argv: list[str] | None = None) -> int:
    """Command line: render every case (or one) into OUT."""
    parser = argparse.ArgumentParser(
        prog="make_photos.py",
        description=__doc__.split("\n\n")[0] + "\n\nCases: " + ", ".join(c.name for c in CASES) + ".",
        epilog="Examples: nice -n 10 python tools/make_photos.py  (all cases into tests/fixtures/photos)\n"
               "          python tools/make_photos.py --only gloss-a010 --out /tmp/photos\n"
               "          python tools/make_photos.py --compare-with ../shared/scenes/yellow-ball\n"
               "Each case folder gets scene.json (truth), scene_input.json (fit section a user writes), "
               "objective.png (8-bit sRGB), meta.json (how it was made); lamp-* also objective.jpg.",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("--only", metavar="NAME", action="append",
                        help="render only this case (repeatable); default: all")
    parser.add_argument("--out", type=Path, default=DEFAULT_OUT,
                        help="output folder, one sub-folder per case (default: tests/fixtures/photos)")
    parser.add_argument("--list", action="store_true", help="list the cases and exit")
    parser.add_argument("--compare-with", type=Path, metavar="DIR",
                        help="convention check: render DIR/scene.json (rtloop format, point light, diffuse) "
                             "with the direct integrator through this script's code path and print the mean "
                             "absolute difference from DIR/objective.png in 8-bit codes; renders no case")
    parser.add_argument("--compare-spp", type=int, default=1024, help="samples for --compare-with (1024)")
    args = parser.parse_args(argv)

    if args.list:
        for c in CASES:
            print(f"{c.name:22s} {c.description}")
        return 0
    if args.compare_with:
        compare_with(args.compare_with, args.compare_spp)
        return 0
    by_name = {c.name: c for c in CASES}
    names = args.only or list(by_name)
    unknown = [n for n in names if n not in by_name]
    if unknown:
        parser.error(f"unknown case {', '.join(unknown)} (cases: {', '.join(by_name)})")
    args.out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    for name in names:
        s = make_case(by_name[name], args.out)
        print(f"{s['name']:22s} {s['seconds']:6.1f} s  MC noise {s['noise']:.3f} "
              f"(rms {s['noise_rms']:.3f}) codes  clipped "
              f"{100 * s['clipped']:.2f} %  ball p90 {s['ball_p90']:.3f}"
              + (f"  env/floor {s['env_ratio']:.3f}" if s["env_ratio"] is not None else ""), flush=True)
    print(f"{len(names)} case(s) in {time.perf_counter() - t0:.1f} s -> {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())