"""What the camera terms' test costs a photo that needs neither term: the default fit against the same fit
with ``vignetting="off", tone="off"`` on the Mitsuba photos in ``tests/fixtures/photos``, wall time per fit
(median of RUNS, alternating the two so that the machine's load meets both alike).

Usage (from the repository root, with the extension built)::

    python benches/camera_overhead.py [--runs 5] [--cases direct-side env-overhead]
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
import warnings
from pathlib import Path

import rtloop

FIXTURES = Path(__file__).resolve().parents[1] / "tests" / "fixtures" / "photos"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--runs", type=int, default=5)
    ap.add_argument("--cases", nargs="*")
    args = ap.parse_args(argv)
    warnings.simplefilter("ignore")
    command = " ".join(["python benches/camera_overhead.py", *(argv if argv is not None else sys.argv[1:])])
    print(f"# What the camera test costs (`{command}`)\n")
    print("| photo | camera terms | off (s) | auto (s) | auto / off |")
    print("|---|---|---|---|---|")
    ratios = []
    for folder in sorted(p for p in FIXTURES.iterdir() if p.is_dir()):
        if args.cases and folder.name not in args.cases:
            continue
        scene = rtloop.load_scene(folder / "scene_input.json")
        image = rtloop.load_image(folder / "objective.png", scene)
        times: dict[str, list[float]] = {"off": [], "auto": []}
        terms = None
        for _ in range(args.runs):
            for mode in ("off", "auto"):
                t0 = time.perf_counter()
                res = rtloop.fit(scene, image, vignetting=mode, tone=mode)
                times[mode].append(time.perf_counter() - t0)
                if mode == "auto":
                    terms = res.model["camera"].get("terms")
        off, auto = statistics.median(times["off"]), statistics.median(times["auto"])
        ratios.append(auto / off)
        print(f"| {folder.name} | {','.join(terms) or '-'} | {off:.3f} | {auto:.3f} | {auto / off:.2f} |", flush=True)
    print(f"\nmedian auto / off: {statistics.median(ratios):.2f}, max {max(ratios):.2f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
