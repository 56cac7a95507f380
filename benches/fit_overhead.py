"""What a default fit of a clean direct photo costs besides its search and its uncertainty (the target:
a matte direct photo no slower than the fit before the image terms, +-10 %).

Cases: the eleven clean direct Mitsuba photos ``tests/fixtures/photos/direct-*``. Each is fitted with the
default ``rtloop.fit`` (uncertainty included) on one thread (``RAYON_NUM_THREADS=1``), in alternating
subprocesses of this checkout and of ``--baseline DIR`` (a ``python/`` folder with its package and extension,
e.g. of main), ``--rounds`` times with ``--runs`` fits per case each. Per fit the CPU time
(``time.process_time``) in all, in the search (``_native.optimize``), in the uncertainty
(``estimate_uncertainty``) and the rest (the post-fit analysis: goodness, JPEG blocking, noise,
quantisation floor, the render for them, the products' split, scene round trips); per case the least of all
rounds x runs of each; the medians over the cases and the ratios from this one run. The light error (mm,
against each ``scene.json``) must be the same for two builds where a change keeps every result.
``--baseline`` may be given more than once (``NAME=DIR``; the first is the one the ratios divide by).
``--footprint MODE`` adds a row of this checkout's fits with ``rtloop.fit(footprint=MODE)`` (what the pixel
footprint costs, against the error it buys).
Writes ``benches/results/fit_overhead.md`` (with ``--fixed-malloc``: ``fit_overhead_fixed_malloc.md``; with
``--footprint``: ``..._footprint.md``).

Usage (from the repository root, with the extension built)::

    python benches/fit_overhead.py --baseline main=/tmp/base/python --baseline baseline=/tmp/old/python
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import subprocess
import sys
import time
import warnings
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
PHOTOS = REPO / "tests" / "fixtures" / "photos"
OUT = REPO / "benches" / "results" / "fit_overhead.md"
PARTS = ("total", "search", "uncertainty", "rest")


def cases() -> list[Path]:
    """The clean direct Mitsuba photos."""
    return sorted(p for p in PHOTOS.glob("direct-*") if (p / "objective.png").exists())


def worker(runs: int, footprint: str | None = None) -> dict[str, dict[str, float]]:
    """Fit every case ``runs`` times with the rtloop on the path: the light error (mm) and, per part, the
    least CPU ms."""
    import numpy as np

    import rtloop
    import rtloop.uncertainty
    from rtloop import _native

    spent = {"search": 0.0, "uncertainty": 0.0}

    def timed(owner, name, part):
        inner = getattr(owner, name)

        def call(*args, **kwargs):
            t = time.process_time()
            try:
                return inner(*args, **kwargs)
            finally:
                spent[part] += time.process_time() - t
        setattr(owner, name, call)

    timed(_native, "optimize", "search")
    timed(rtloop.uncertainty, "estimate_uncertainty", "uncertainty")
    warnings.simplefilter("ignore")
    out = {}
    for case in cases():
        truth = json.loads((case / "scene.json").read_text())
        scene = rtloop.load_scene(case / "scene_input.json")
        photo = rtloop.load_image(case / "objective.png", scene)
        kw = {} if footprint is None else {"footprint": footprint}
        result = rtloop.fit(scene, photo, **kw)  # warm
        best = dict.fromkeys(PARTS, float("inf"))
        for _ in range(runs):
            spent.update(search=0.0, uncertainty=0.0)
            t0 = time.process_time()
            result = rtloop.fit(scene, photo, **kw)
            total = time.process_time() - t0
            got = {"total": total, **spent, "rest": total - spent["search"] - spent["uncertainty"]}
            best = {k: min(best[k], got[k]) for k in PARTS}
        fitted = np.array(result.scene.to_dict()["light"]["position"], float)
        err = float(np.linalg.norm(fitted - np.array(truth["light"]["position"], float)))
        out[case.name] = {"light_err_mm": 1000 * err, **{f"{k}_ms": 1000 * v for k, v in best.items()}}
    return out


#: ``--fixed-malloc``: glibc's mmap and trim thresholds held (8 MiB, 64 MiB) instead of adapting to the
#: process's history: a fit's large buffers then come from the heap every time, not from fresh pages (whose
#: first touches, 0 to 700 page faults per fit, vary from run to run with what was freed before).
FIXED_MALLOC = {"MALLOC_MMAP_THRESHOLD_": str(8 << 20), "MALLOC_TRIM_THRESHOLD_": str(64 << 20)}


def run_with(python_dir: str | None, runs: int, fixed_malloc: bool = False,
             footprint: str | None = None) -> dict[str, dict[str, float]]:
    """`worker` in a one-thread subprocess importing rtloop from ``python_dir`` (this checkout's when None)."""
    env = dict(os.environ, PYTHONPATH=python_dir or str(REPO / "python"), RAYON_NUM_THREADS="1",
               **(FIXED_MALLOC if fixed_malloc else {}))
    cmd = [sys.executable, __file__, "--worker", "--runs", str(runs)]
    cmd += ["--footprint", footprint] if footprint else []
    text = subprocess.run(cmd, env=env, check=True, capture_output=True, text=True).stdout
    return json.loads(text.strip().splitlines()[-1])


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--baseline", metavar="[NAME=]DIR", action="append", default=[],
                        help="python/ folder of a baseline build (its package and extension); required, repeatable")
    parser.add_argument("--rounds", type=int, default=3, help="alternating rounds of the builds (default 3)")
    parser.add_argument("--runs", type=int, default=5, help="fits per case and round (default 5)")
    parser.add_argument("--fixed-malloc", action="store_true",
                        help="hold glibc's mmap and trim thresholds (see FIXED_MALLOC)")
    parser.add_argument("--footprint", choices=("auto", "on", "off"), action="append", default=[],
                        help="also time this checkout's fits with this footprint mode (a row of its own, "
                             "interleaved with the others: the speed a footprint costs, with its error); "
                             "repeatable")
    parser.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.worker:
        print(json.dumps(worker(args.runs, args.footprint[0] if args.footprint else None)))
        return 0
    if not args.baseline:
        parser.error("--baseline DIR is required")
    builds: dict[str, str | None] = {}
    modes: dict[str, str | None] = {}  # a build's footprint mode (None: its default)
    for i, b in enumerate(args.baseline):
        name, _, where = b.rpartition("=")
        builds[name or ("baseline" if i == 0 else f"baseline{i + 1}")] = where
    builds["this"] = None
    for mode in args.footprint:
        builds[f"this, footprint {mode}"] = None
        modes[f"this, footprint {mode}"] = mode
    base = next(iter(builds))
    got: dict[str, list[dict[str, dict[str, float]]]] = {k: [] for k in builds}
    for _ in range(args.rounds):
        for name, where in builds.items():
            got[name].append(run_with(where, args.runs, args.fixed_malloc, modes.get(name)))
    names = list(got["this"][0])
    best = {k: {c: {p: min(r[c][f"{p}_ms"] for r in rs) for p in PARTS} for c in names} for k, rs in got.items()}
    err = {k: {c: rs[0][c]["light_err_mm"] for c in names} for k, rs in got.items()}
    med = {k: {p: statistics.median(best[k][c][p] for c in names) for p in PARTS} for k in builds}
    lines = ["| build | light error, median (mm) | " + " | ".join(f"{p} (ms)" for p in PARTS)
             + " | " + " | ".join(f"{p} / {base}" for p in PARTS) + " |", "|" + "---|" * (2 + 2 * len(PARTS))]
    for k, where in builds.items():
        label = "this checkout" + (f", footprint {modes[k]}" if k in modes else "")
        row = [f"{k} (`{where}`)" if where else label,
               f"{statistics.median(err[k][c] for c in names):.2f}"]
        row += [f"{med[k][p]:.1f}" for p in PARTS] + [f"{med[k][p] / med[base][p]:.2f}" for p in PARTS]
        lines.append("| " + " | ".join(row) + " |")
    lines += ["", "Per case (least CPU ms per default fit; light error in mm):", "",
              "| case | " + " | ".join(f"light error {k}" for k in builds) + " | "
              + " | ".join(f"total {k}" for k in builds) + " | " + " | ".join(f"rest {k}" for k in builds) + " |",
              "|" + "---|" * (1 + 3 * len(builds))]
    for c in names:
        row = [c] + [f"{err[k][c]:.2f}" for k in builds] + [f"{best[k][c]['total']:.1f}" for k in builds]
        row += [f"{best[k][c]['rest']:.1f}" for k in builds]
        lines.append("| " + " | ".join(row) + " |")
    same = all(err["this"][c] == err[base][c] for c in names)
    ratios = ", ".join(f"{p} {med['this'][p] / med[base][p]:.2f}" for p in PARTS)
    machine = f"{platform.machine()}, {os.cpu_count()} cores, Python {platform.python_version()}"
    header = (f"# benches/fit_overhead.py (default fit, one thread; CPU ms per fit, least of {args.rounds} x "
              f"{args.runs} fits per case, builds interleaved; medians over the {len(names)} clean direct "
              f"photos; {'glibc malloc thresholds held; ' if args.fixed_malloc else ''}{machine})\n\n"
              f"This checkout against {base}: medians' ratios {ratios}; light errors "
              f"{'identical' if same else 'DIFFERENT'}.\n\n")
    print(header + "\n".join(lines))
    out = OUT.with_name(OUT.stem + "_fixed_malloc.md") if args.fixed_malloc else OUT
    if args.footprint:
        out = out.with_name(out.stem + "_footprint.md")
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(header + "\n".join(lines) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
