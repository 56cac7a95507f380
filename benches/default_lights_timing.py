#!/usr/bin/env python3
"""The default fit's cost now that it chooses how many lights: CPU seconds per ``rtloop.fit`` with its
defaults (``threads=1``, seed 0) in this tree and in another (``--against``, a checkout whose ``python/``
holds rtloop), runs interleaved (each tree in turn, in a fresh process: one untimed fit, then three of each
kind alternating), the least of ``--runs`` x 3; beside it this tree's ``lights=1`` (the test skipped), timed
in the same processes. Photos: direct-side (one light, explained: no further light tried),
key-fill-25 (a key and a fill: two lights kept) and, with ``--diligent DIR`` (a folder made by
prepare_diligent.py), DiLiGenT's ball under light 1 (explained) and 47 (not explained: a further light tried
and refused), read as studies/real_photos.py reads them. Replaces its own section of
benches/results/lights.md.

Usage: ``PYTHONPATH=python python3 benches/default_lights_timing.py --against ../main [--diligent DIR]
[--runs N]``.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import time
import warnings
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
PHOTOS = {"direct-side": REPO / "tests" / "fixtures" / "photos" / "direct-side",
          "key-fill-25": REPO / "tests" / "fixtures" / "lights" / "key-fill-25"}
HEADING = "# `PYTHONPATH=python python3 benches/default_lights_timing.py"


def child(folder: Path) -> None:
    """One untimed fit, then three of the default and three with ``lights=1``, alternating: prints the least
    CPU seconds of each, the default's number of lights and whether further lights were tried."""
    import rtloop

    warnings.simplefilter("ignore")
    scene = rtloop.load_scene(folder / "scene_input.json")
    kw = {}
    if (folder / "mask.png").is_file():  # a DiLiGenT light: linear 16-bit, masked
        image = rtloop.load_image(folder / "objective.png", scene, response="linear")
        kw["mask"] = rtloop.load_mask(folder / "mask.png", scene)
    else:
        image = rtloop.load_image(folder / "objective.png", scene)
    rtloop.fit(scene, image, seed=0, threads=1, **kw)
    best = {None: float("inf"), 1: float("inf")}
    for order in ((None, 1), (1, None), (None, 1)):  # each first in turn: neither gains from the order
        for lights in order:
            t = time.process_time()
            result = rtloop.fit(scene, image, seed=0, threads=1, lights=lights, **kw)
            best[lights] = min(best[lights], time.process_time() - t)
            if lights is None:
                default = result
    seconds, one, result = best[None], best[1], default
    lights = len(result.lights) if hasattr(result, "lights") else 1
    tried = bool(getattr(result, "gate", None) or (getattr(result, "model", {}) or {}).get("lights"))
    print(json.dumps({"seconds": seconds, "one": one, "lights": lights, "tried": tried}))


def timed(tree: Path, folder: Path) -> dict:
    env = {**os.environ, "PYTHONPATH": str(tree / "python")}
    out = subprocess.run([sys.executable, __file__, "--child", str(folder)], env=env, check=True,
                         capture_output=True, text=True).stdout
    return json.loads(out.strip().splitlines()[-1])


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--against", type=Path, help="the other checkout (its python/ holds rtloop)")
    ap.add_argument("--diligent", type=Path, help="a folder made by prepare_diligent.py")
    ap.add_argument("--runs", type=int, default=5)
    ap.add_argument("--out", type=Path, default=REPO / "benches" / "results" / "lights.md")
    ap.add_argument("--child", type=Path, help=argparse.SUPPRESS)
    a = ap.parse_args(argv)
    if a.child is not None:
        child(a.child)
        return 0
    if a.against is None:
        ap.error("--against DIR is required")
    photos = dict(PHOTOS)
    if a.diligent is not None:
        photos.update({"DiLiGenT L001": a.diligent / "L001", "DiLiGenT L047": a.diligent / "L047"})
    rows = []
    for name, folder in photos.items():
        best: dict = {"this": None, "other": None, "one": float("inf")}
        for _ in range(a.runs):
            for key, tree in (("other", a.against.resolve()), ("this", REPO)):
                r = timed(tree, folder)
                if best[key] is None or r["seconds"] < best[key]["seconds"]:
                    best[key] = r
                if key == "this":
                    best["one"] = min(best["one"], r["one"])
        best["this"]["one"] = best["one"]
        rows.append((name, best["other"], best["this"]))
        print(name, best, file=sys.stderr)
    command = f"{HEADING[3:]} --against {a.against}" + (f" --diligent {a.diligent}" if a.diligent else "") + \
        (f" --runs {a.runs}" if a.runs != 5 else "")
    lines = [f"# `{command}`", "",
             "The default fit (`rtloop.fit` with its defaults, its uncertainty included; `threads=1`, seed 0): "
             f"CPU seconds, least of {a.runs} runs interleaved with the other tree, each a fresh process (one "
             f"untimed fit, then three of each kind alternating); {platform.machine()}, 2 cores shared with other jobs, Python "
             f"{platform.python_version()}. \"Other\" is the tree before the default chose how many lights (one "
             "light always).", "",
             "| photo | other tree | this tree | this / other | this tree, `lights=1` | this / `lights=1` | "
             "lights (this tree) | further light tried |",
             "|---|---|---|---|---|---|---|---|"]
    for name, other, this in rows:
        tried = "yes" if this["tried"] else "no"
        lines.append(f"| {name} | {other['seconds']:.3f} | {this['seconds']:.3f} | "
                     f"{this['seconds'] / other['seconds']:.2f} | {this['one']:.3f} | "
                     f"{this['seconds'] / this['one']:.2f} | {this['lights']} | {tried} |")
    calm = [(name, this["seconds"] / other["seconds"], this["seconds"] / this["one"])
            for name, other, this in rows if not this["tried"]]
    lines += ["", "`lights=1`: the same processes' fits with the test skipped. The test "
              "that decides whether further lights are tried reads the goodness of fit the one-light fit computes "
              "anyway: where the one light explains the photo (" +
              ", ".join(f"{name} {r:.2f}x the other tree, {q:.2f}x `lights=1`" for name, r, q in calm) +
              ") the default costs what it did, within the runs' spread. Where the test fires, the lights fit's "
              "search is added: on key + fill, "
              "one, two and three lights fitted on half the pixels and the kept lights' error bars; on "
              "DiLiGenT L047, one and two lights, refused (the one-light answer returned unchanged)."]
    text = a.out.read_text() if a.out.is_file() else ""
    keep = text.split(HEADING)[0].rstrip("\n")
    a.out.write_text((keep + "\n\n" if keep else "") + "\n".join(lines) + "\n")
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
