#!/usr/bin/env python3
"""The lights fit's cost: a one-light photo through the default fit and through the lights path, and a
two-light fit against one-light fits of the same photo. CPU seconds per fit (all threads of the process,
``threads=1``), the least of ``--runs`` runs; writes benches/results/lights.md headed by its command.

Usage: ``PYTHONPATH=python python3 benches/lights_timing.py [--runs N] [--out FILE]``.
"""

from __future__ import annotations

import argparse
import platform
import sys
import time
import warnings
from pathlib import Path

import rtloop
from rtloop.fit.lights import fit_lights

REPO = Path(__file__).resolve().parents[1]
ONE = REPO / "tests" / "fixtures" / "photos" / "direct-side"
TWO = REPO / "tests" / "fixtures" / "lights" / "key-fill-25"
DEFAULT_HEADING = "# `PYTHONPATH=python python3 benches/default_lights_timing.py"


def cpu(fn, runs: int) -> float:
    best = float("inf")
    for _ in range(runs):
        t = time.process_time()
        fn()
        best = min(best, time.process_time() - t)
    return best


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--out", type=Path, default=REPO / "benches" / "results" / "lights.md")
    a = ap.parse_args(argv)
    warnings.simplefilter("ignore")
    rows = []
    for name, folder in (("one light (direct-side)", ONE), ("key + fill 25 % (key-fill-25)", TWO)):
        si = str(folder / "scene_input.json")
        scene = rtloop.load_scene(si)
        image = rtloop.load_image(folder / "objective.png", scene)
        t_default = cpu(lambda: rtloop.fit(si, image, seed=0, threads=1), a.runs)
        t_lights1 = cpu(lambda: fit_lights(scene, image, 1, seed=0, threads=1), a.runs)
        t_lights1_bare = cpu(lambda: fit_lights(scene, image, 1, seed=0, threads=1, errors=False), a.runs)
        t_lights2 = cpu(lambda: fit_lights(scene, image, 2, seed=0, threads=1), a.runs)
        rows.append((name, t_default, t_lights1, t_lights1_bare, t_lights2))
        print(name, t_default, t_lights1, t_lights1_bare, t_lights2, file=sys.stderr)
    command = "PYTHONPATH=python python3 benches/lights_timing.py" + (f" --runs {a.runs}" if a.runs != 3 else "")
    lines = [f"# `{command}`", "",
             f"CPU seconds per fit (all threads, `threads=1`), least of {a.runs} runs, seed 0; {platform.machine()}, "
             f"2 cores shared with other jobs, Python {platform.python_version()}. Default fit: `rtloop.fit` with its "
             "defaults (the rtloop protocol, its uncertainty included). Lights path: `fit_lights` with its defaults "
             "(the staged search of python/rtloop/fit/lights_search.py), with and without its error bars.", "",
             "| photo | default fit | lights path, 1 light | same, no error bars | lights path, 2 lights | "
             "1 light: lights / default | 2 lights / default | 2 lights / lights 1 |",
             "|---|---|---|---|---|---|---|---|"]
    for name, d, l1, l1b, l2 in rows:
        lines.append(f"| {name} | {d:.2f} | {l1:.2f} | {l1b:.2f} | {l2:.2f} | {l1 / d:.2f} | {l2 / d:.2f} | "
                     f"{l2 / l1:.2f} |")
    # benches/default_lights_timing.py's section stays as it is
    rest = a.out.read_text().partition(DEFAULT_HEADING)[2] if a.out.is_file() else ""
    a.out.write_text("\n".join(lines) + "\n" + (f"\n{DEFAULT_HEADING}{rest}" if rest else ""))
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
