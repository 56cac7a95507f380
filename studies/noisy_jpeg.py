"""Light error and fit time of the default fit on the clean direct Mitsuba photos and their noisy and JPEG
variants (studies/coverage.py's: 2 % Gaussian noise, linear, seed 0, clipped to [0, 1]; the PNG re-saved as
JPEG quality 40 with Pillow's defaults, 4:2:0 chroma).

Per case: the light error (mm), the worst colour product error (relative to the object's largest true
product), the loss space and clip level the fit chose, and the CPU time of the fit (process time, 2 threads,
the least of ``--repeat`` runs; uncertainty on, as the default fit). To compare two commits, run it once on
each, alternating (``--rounds``: each case is fitted that many times, rounds interleaved with the other
commit's by the caller), e.g.::

    for r in 1 2; do PYTHONPATH=old/python python studies/noisy_jpeg.py --json old$r.json
                     PYTHONPATH=new/python python studies/noisy_jpeg.py --json new$r.json; done
"""

from __future__ import annotations

import argparse
import json
import sys
import time
import warnings
from pathlib import Path

import numpy as np

import rtloop
from rtloop.fit.products import products_of

sys.path.insert(0, str(Path(__file__).resolve().parent))
from coverage import FIXTURES, photo_of


def run(name: str, variant: str | None, repeat: int) -> dict:
    folder = FIXTURES / name
    truth = json.loads((folder / "scene.json").read_text())
    scene = rtloop.load_scene(folder / "scene_input.json")
    photo = photo_of(folder, scene, variant)
    best = float("inf")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the noisy variants' negative-value doubt
        for _ in range(repeat):
            t = time.process_time()
            r = rtloop.fit(scene, photo)
            best = min(best, time.process_time() - t)
    fitted = np.array(r.scene.to_dict()["light"]["position"], float)
    err = 1e3 * float(np.linalg.norm(fitted - np.array(truth["light"]["position"], float)))
    tp = products_of(truth)
    worst = max(abs(r.products[o][i] - tp[o][i]) / max(tp[o]) for o in tp for i in range(3))
    return {"case": name + ("" if variant is None else "+" + variant), "light_err_mm": err,
            "worst_product_rel": worst, "space": r.settings.get("space"), "saturated": r.settings.get("saturated"),
            "terms": r.model["terms"], "cpu_s": best}


def main() -> int:
    parser = argparse.ArgumentParser(prog="noisy_jpeg.py", description=__doc__.split("\n\n")[0])
    parser.add_argument("--repeat", type=int, default=3, help="fits per case; the least CPU time counts")
    parser.add_argument("--json", type=Path, help="write the rows here")
    args = parser.parse_args()
    names = sorted(p.name for p in FIXTURES.iterdir() if p.name.startswith("direct-") and (p / "scene.json").exists())
    rows = []
    print("| case | light error (mm) | worst product (%) | space | clip level | CPU (ms) |")
    print("|---|---|---|---|---|---|")
    for variant in (None, "noise", "jpeg"):
        for name in names:
            row = run(name, variant, args.repeat)
            rows.append(row)
            sat = "-" if row["saturated"] is None else f"{row['saturated']:.3f}"
            print(f"| {row['case']} | {row['light_err_mm']:.1f} | {100 * row['worst_product_rel']:.2f} | "
                  f"{row['space']} | {sat} | {1e3 * row['cpu_s']:.0f} |", flush=True)
    print()
    for variant in ("clean", "noise", "jpeg"):
        sel = [r for r in rows if (r["case"].split("+") + ["clean"])[1] == variant]
        e = [r["light_err_mm"] for r in sel]
        print(f"{variant}: light median {np.median(e):.1f} mm, max {max(e):.1f} mm; "
              f"CPU median {1e3 * np.median([r['cpu_s'] for r in sel]):.0f} ms")
    if args.json:
        args.json.write_text(json.dumps(rows, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
