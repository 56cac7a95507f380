"""Loss space: linear against sRGB (``rtloop.fit(..., space=...)``), errors against ground truth.

Cases:

- the reference scenes in ``../shared/scenes`` (Mitsuba 3 renders, 8-bit sRGB PNG: ``objective.png``
  loaded with ``rtloop.load_image``), scored with ``score()`` from ``../shared/tools/score_result.py``;
- two synthetic photos of the paper's ball-on-floor scene rendered by rtloop and damaged as a file would
  damage them (as in ``tests/test_hard_cases.py``): ``jpeg-q50`` (128x96, JPEG quality 50) and
  ``dim-png`` (64x48, intensity 1.5: the brightest pixel about 0.03, a handful of 8-bit levels).

Every case is fitted with the default protocol in both spaces for ``--seeds`` seeds; light error (m) and
the worst relative error of intensity x albedo over the objects are reported per run and as medians.

Usage (from the repository root)::

    python studies/loss_space.py                     # 5 seeds, all cases
    python studies/loss_space.py --seeds 2 --out /tmp/ls

Writes ``loss_space.csv`` and ``loss_space.md`` to ``--out`` (default ``studies/results/``) and prints the
markdown.
"""

from __future__ import annotations

import argparse
import copy
import csv
import importlib.util
import io
import platform
import statistics
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np
from PIL import Image

import rtloop
from rtloop._srgb import encode8

REPO = Path(__file__).resolve().parents[1]
SCENES = REPO.parent / "shared" / "scenes"
SCORE_TOOL = REPO.parent / "shared" / "tools" / "score_result.py"
SPACES = ("linear", "srgb")
sys.path.insert(0, str(REPO / "tests"))
from scenes import BALL_ON_FLOOR, centred_start  # noqa: E402

BALL = {**copy.deepcopy(BALL_ON_FLOOR), "image": {"width": 128, "height": 96}}


def load_score():
    spec = importlib.util.spec_from_file_location("rtloop_bench_score_result", SCORE_TOOL)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module.score


def through_file(linear: np.ndarray, fmt: str, **save: Any) -> bytes:
    """8-bit sRGB file bytes of a linear image."""
    buf = io.BytesIO()
    Image.fromarray(encode8(linear)).save(buf, fmt, **save)
    return buf.getvalue()


def synthetic_cases(tmp: Path) -> list[tuple[str, dict, Path, dict]]:
    """(name, start scene, photo path, truth) of the damaged self-rendered photos."""
    jpeg = copy.deepcopy(BALL)
    dim = copy.deepcopy(BALL)
    dim["image"] = {"width": 64, "height": 48}
    dim["light"]["intensity"] = 1.5
    out = []
    for name, truth, fmt, suffix, save in (("jpeg-q50", jpeg, "JPEG", ".jpg", {"quality": 50}),
                                            ("dim-png", dim, "PNG", ".png", {})):
        path = tmp / f"{name}{suffix}"
        path.write_bytes(through_file(np.minimum(rtloop.render(truth), 1.0), fmt, **save))
        out.append((name, centred_start(truth), path, truth))
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seeds", type=int, default=5, help="seeds per case and space (0, 1, ...)")
    ap.add_argument("--out", type=Path, default=REPO / "studies" / "results", help="where to write CSV and markdown")
    ap.add_argument("--threads", type=int, default=None, help="threads for rtloop.fit (default: all)")
    args = ap.parse_args(argv)
    score = load_score() if SCORE_TOOL.is_file() else None
    rows: list[dict[str, Any]] = []
    with tempfile.TemporaryDirectory() as tmp:
        cases: list[tuple[str, Any, Path, dict]] = []
        if SCENES.is_dir() and score is not None:
            for d in sorted(p for p in SCENES.iterdir() if (p / "scene.json").is_file()):
                truth = rtloop.scene_to_dict(rtloop.load_scene(d / "scene.json"))
                cases.append((d.name, d / "scene_input.json", d / "objective.png", truth))
        else:
            print(f"{SCENES} or {SCORE_TOOL} not found: synthetic cases only", file=sys.stderr)
        cases += synthetic_cases(Path(tmp))
        for name, start, photo_path, truth in cases:
            scene = rtloop.load_scene(start)
            photo = rtloop.load_image(photo_path, scene)
            for space in SPACES:
                for seed in range(args.seeds):
                    t0 = time.perf_counter()
                    result = rtloop.fit(scene, photo, seed=seed, space=space, threads=args.threads)
                    seconds = time.perf_counter() - t0
                    fitted = rtloop.scene_to_dict(result.scene)
                    if score is not None:
                        s = score(fitted, truth)
                        light, product = s["light_err_m"], max(s["product_rel_err"].values())
                    else:  # the same measures
                        light = float(np.linalg.norm(np.subtract(fitted["light"]["position"],
                                                                 truth["light"]["position"])))
                        product = max(
                            float(np.max(np.abs(np.multiply(f["material"]["albedo"], fitted["light"]["intensity"])
                                                - np.multiply(o["material"]["albedo"], truth["light"]["intensity"])))
                                  / np.max(np.multiply(o["material"]["albedo"], truth["light"]["intensity"])))
                            for o, f in zip(truth["objects"], fitted["objects"]))
                    rows.append({"case": name, "space": space, "seed": seed, "seconds": seconds,
                                 "light_err_m": light, "product_err_max": product})
                    print(f"{name:20s} {space:6s} seed {seed}: light {light * 1000:8.2f} mm, "
                          f"product {product * 100:6.3f} %, {seconds:.2f} s", file=sys.stderr)
    md = io.StringIO()
    md.write("| case | space | light error, median (min-max) | product error, median (min-max) | seconds |\n")
    md.write("|---|---|---|---|---|\n")
    for name in dict.fromkeys(r["case"] for r in rows):
        for space in SPACES:
            rs = [r for r in rows if r["case"] == name and r["space"] == space]
            light = [r["light_err_m"] * 1000 for r in rs]
            prod = [r["product_err_max"] * 100 for r in rs]
            md.write(f"| {name} | {space} | {statistics.median(light):.2f} mm ({min(light):.2f}-{max(light):.2f}) | "
                     f"{statistics.median(prod):.3f} % ({min(prod):.3f}-{max(prod):.3f}) | "
                     f"{statistics.median(r['seconds'] for r in rs):.2f} |\n")
    md.write(f"\n{args.seeds} seeds per row, default protocol; {platform.processor() or platform.machine()}, "
             f"{platform.python_version()}.\n")
    args.out.mkdir(parents=True, exist_ok=True)
    with open(args.out / "loss_space.csv", "w", newline="", encoding="utf-8") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    (args.out / "loss_space.md").write_text(md.getvalue(), encoding="utf-8")
    print(md.getvalue())
    return 0


if __name__ == "__main__":
    sys.exit(main())
