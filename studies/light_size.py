#!/usr/bin/env python3
"""A rectangle light's fitted size on the Mitsuba photos of tests/fixtures/lights: per photo and seed, the
size found against the truth, each side's error bar and the error over it, the lamp's and the rectangle's
centre's distance from the truth, the evaluations and the time. ``lamp-softbox`` frees its softbox's size
in its own scene_input.json; on ``lamp-window`` the window's size is freed here (a 0.6 x 0.6 m guess,
bounds 0.1-3 m) as on the softbox.

    PYTHONPATH=python python studies/light_size.py --seeds 0 1 2 3 --out studies/results/light_size.md
"""

from __future__ import annotations

import argparse
import copy
import json
import sys
import time
from pathlib import Path

import numpy as np

import rtloop

REPO = Path(__file__).resolve().parents[1]
LIGHTS = REPO / "tests" / "fixtures" / "lights"
CASES = [("lamp-softbox", "softbox"), ("lamp-window", "window")]


def inputs(name: str, rect: str) -> tuple[dict, np.ndarray, dict]:
    folder = LIGHTS / name
    truth = json.loads((folder / "scene.json").read_text())
    d = json.loads((folder / "scene_input.json").read_text())
    if f"lights.{rect}.size" not in d["fit"]:
        d = copy.deepcopy(d)
        next(light for light in d["lights"] if light["name"] == rect)["size"] = [0.6, 0.6]
        d["fit"][f"lights.{rect}.size"] = {"min": 0.1, "max": 3.0}
    return truth, rtloop.load_image(folder / "objective.png", rtloop.load_scene(truth)), d


def row(name: str, rect: str, seed: int) -> list[str]:
    truth, image, d = inputs(name, rect)
    t0 = time.perf_counter()
    res = rtloop.fit(d, image, seed=seed)
    seconds = time.perf_counter() - t0
    want = next(light for light in truth["lights"] if light["name"] == rect)
    got = next(light for light in res.lights if light["name"] == rect)
    lamp = np.linalg.norm(np.subtract(res.lights[0]["position"], truth["lights"][0]["position"])) * 100
    centre = np.linalg.norm(np.subtract(got["position"], want["position"])) * 100
    size = " x ".join(f"{v:.3f}" for v in got["size"])
    off = [(s - w) / w * 100 for s, w in zip(got["size"], want["size"])]
    bars = ["not determined" if b is None else f"{b:.3f}" for b in got["size_error"]]
    ratio = ["-" if b is None else f"{abs(s - w) / b:.1f}" for s, w, b in zip(got["size"], want["size"],
                                                                                got["size_error"])]
    return [name, str(seed), size, " x ".join(str(v) for v in want["size"]), " / ".join(f"{v:+.1f}" for v in off),
            " / ".join(bars), " / ".join(ratio), f"{lamp:.1f}", f"{centre:.1f}", str(res.evaluations),
            f"{seconds:.1f}"]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2, 3])
    ap.add_argument("--out", type=Path)
    a = ap.parse_args(argv)
    head = ["photo", "seed", "size (m)", "truth (m)", "off (%)", "error bars (m)", "error / bar",
            "lamp (cm)", "centre (cm)", "evaluations", "time (s)"]
    lines = [f"`PYTHONPATH=python python studies/light_size.py --seeds {' '.join(map(str, a.seeds))}"
             + (f" --out {a.out}`" if a.out else "`"), "",
             "| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for name, rect in CASES:
        for seed in a.seeds:
            lines.append("| " + " | ".join(row(name, rect, seed)) + " |")
            print(lines[-1], file=sys.stderr, flush=True)
    text = "\n".join(lines) + "\n"
    if a.out:
        a.out.write_text(text)
    print(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
