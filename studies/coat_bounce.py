"""The coat in the bounce (docs/methods.md, "A coat in the bounce"): the default fit with and without the coat
tried where the fit models the bounce (``rtloop.fit.selection.COAT_WITH_BOUNCE``), on the Mitsuba photos
whose fit adds the bounce or a highlight and on rtloop's own renders of the lamp photos' truths.

Per case of ``tests/fixtures/photos`` (default: the lamp, bounce, env-bounce and gloss photos):

- ``light error``: the default ``rtloop.fit`` of ``objective.png``, seeds 0-2, with the switch off (today's
  default: Blinn-Phong over Lambert with the bounce) and on (the coat, where its evidence selects it);
- ``loss at the truth``: the same fit with the light held at the truth (a box of +-0.1 mm), off and on;
- ``lobe``: the lobe the on fit chose (``-`` where no highlight term was added);
- ``fit (ms)``: the median of the three seeds' wall-clock times, off and on.

Then, for the lamp photos, rtloop's render of the truth (the ball coated as Mitsuba's roughplastic, one
bounce; ``studies/room_light_causes.py``), clean and with the photo's noise and JPEG, fitted off and on.

Usage (from the repository root)::

    python studies/coat_bounce.py > studies/results/coat_bounce.md
    python studies/coat_bounce.py --cases lamp-side
    python studies/coat_bounce.py --cases lamp-side lamp-desk lamp-front --bounce-passes 0

``--bounce-passes 0`` searches the light on the full bounce instead of the held one (``rtloop.fit.terms``'s
``BOUNCE_PASSES``; the default fit holds it in 3 passes).
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

import importlib

import rtloop
from rtloop.fit import selection

sys.path.insert(0, str(Path(__file__).resolve().parent))
import room_light_causes as causes  # noqa: E402

FIXTURES = causes.FIXTURES
CASES = ("lamp-side", "lamp-desk", "lamp-front", "bounce-red-ball", "bounce-two-balls", "env-bounce-low",
         "env-bounce-overhead", "gloss-a010", "gloss-a025", "gloss-back")


def _fit(scene: Any, photo: np.ndarray, on: bool, seed: int = 0) -> tuple[Any, float]:
    selection.COAT_WITH_BOUNCE = on
    t = time.perf_counter()
    r = rtloop.fit(scene, photo, seed=seed, uncertainty=False)
    return r, 1000.0 * (time.perf_counter() - t)


def study(case: str) -> str:
    """The case's row (see the module)."""
    folder = FIXTURES / case
    truth = json.loads((folder / "scene.json").read_text())
    user = json.loads((folder / "scene_input.json").read_text())
    scene = rtloop.load_scene(user)
    photo = rtloop.load_image(folder / "objective.png", scene)
    held = json.loads(json.dumps(user))
    t = np.asarray(truth["light"]["position"], float)
    held["fit"]["light.position"] = {"min": list(t - 1e-4), "max": list(t + 1e-4)}
    cells, lobe = [], "-"
    for on in (False, True):
        fits = [_fit(scene, photo, on, s) for s in (0, 1, 2)]
        at = _fit(rtloop.load_scene(held), photo, on)[0]
        errs = ", ".join(f"{causes._error_mm(r, truth):.1f}" for r, _ in fits)
        ms = statistics.median(m for _, m in fits)
        cells.append((errs, f"{at.fitness:.2f}", f"{ms:.0f}"))
        if on:
            lobe = fits[0][0].model["evidence"].get("specular", {}).get("lobe", "-")
    (e0, l0, m0), (e1, l1, m1) = cells
    return f"| {case} | {e0} | {e1} | {l0} / {l1} | {lobe} | {m0} / {m1} |"


def own_renders(case: str) -> list[str]:
    """rtloop's coated render of the case's truth, clean and as the photo's post-processing leaves it."""
    folder = FIXTURES / case
    truth = json.loads((folder / "scene.json").read_text())
    meta = json.loads((folder / "meta.json").read_text())
    scene = rtloop.load_scene(json.loads((folder / "scene_input.json").read_text()))
    rows = []
    for label, post in (("clean", None), ("noise, JPEG", meta["post"])):
        image = causes._as_photo(causes._truth_render(truth, meta, sphere=False, coated=True), post)
        errs = [f"{causes._error_mm(_fit(scene, image, on)[0], truth):.1f}" for on in (False, True)]
        rows.append(f"| {case} | {label} | {errs[0]} | {errs[1]} |")
    return rows


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--cases", nargs="+", default=list(CASES), metavar="NAME")
    parser.add_argument("--bounce-passes", type=int, default=None, metavar="N")
    args = parser.parse_args(argv)
    title = "# The coat in the bounce (`python studies/coat_bounce.py`)"
    if args.bounce_passes is not None:
        importlib.import_module("rtloop.fit.terms").BOUNCE_PASSES = args.bounce_passes
        n = args.bounce_passes
        title = f"## The light searched with {n} held-bounce passes (`--bounce-passes {n}`)"
    print(title + "\n")
    print("| case | light error (mm), off: seeds 0-2 | on: seeds 0-2 | loss at the truth, off / on "
          "| lobe (on) | fit (ms), off / on |\n| --- | --- | --- | --- | --- | --- |")
    for case in args.cases:
        print(study(case), flush=True)
    lamps = [c for c in args.cases if c.startswith("lamp-")]
    if lamps:
        print("\nrtloop's render of the truth, the ball coated as the photo's (light error, mm):\n")
        print("| case | image | off | on |\n| --- | --- | ---: | ---: |")
        for case in lamps:
            for row in own_renders(case):
                print(row, flush=True)
    selection.COAT_WITH_BOUNCE = False
    return 0


if __name__ == "__main__":
    sys.exit(main())
