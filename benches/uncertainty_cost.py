"""What the default uncertainty adds to a fit, and what its sigma is: per photo the work ``rtloop.fit`` does
for ``uncertainty=True`` beyond ``uncertainty=False`` (``estimate_uncertainty`` with the fit's compared
render, as ``rtloop.fit`` calls it: the pixel-centre values at the optimum, Gauss-Newton and the block
sandwich), timed alone.

Cases: the Mitsuba photos of ``tests/fixtures/photos``, those without interreflection (the direct ones,
environment, gloss) and those whose fit takes the bounce (whose Jacobian renders it: medians apart). Each
is fitted once (default fit); then its uncertainty is
computed ``--runs`` times in a subprocess per build and thread count, the builds alternating over
``--rounds``; CPU time (all threads: ``time.process_time``) and wall time, the least over all runs (the
machine is shared: the least is the cost without interference). ``--baseline DIR`` (a ``python/`` folder
with its package and extension, e.g. of the commit before a change) adds its times and the ratio of its
sigma to this build's: the light position's sandwich sigma (largest axis) and the products' Gauss-Newton
sigma, the "error reached" of a change to how the sigma is computed. Writes
``benches/results/uncertainty_cost.md``.

Usage (from the repository root, with the extension built)::

    python benches/uncertainty_cost.py
    python benches/uncertainty_cost.py --rounds 3 --runs 15 --baseline /tmp/base/python
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
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
PHOTOS = REPO / "tests" / "fixtures" / "photos"
OUT = REPO / "benches" / "results" / "uncertainty_cost.md"


def cases() -> list[Path]:
    """The Mitsuba photos."""
    return sorted(p for p in PHOTOS.iterdir() if (p / "objective.png").exists())


def worker(runs: int) -> dict[str, dict[str, object]]:
    """Per case: the least CPU and wall ms of the uncertainty a default fit adds, and its sigma."""
    import warnings

    import numpy as np

    import rtloop
    from rtloop import _native
    from rtloop.uncertainty import estimate_uncertainty

    warnings.simplefilter("ignore")
    out: dict[str, dict[str, object]] = {}
    for case in cases():
        scene = rtloop.load_scene(case / "scene_input.json")
        photo = rtloop.load_image(case / "objective.png", scene)
        result = rtloop.fit(scene, photo, uncertainty=False)
        s = result.scene
        footprint = result.settings.get("footprint", "off") != "off"
        # As rtloop.fit passes them: the compared render (its goodness render, which the fit needs anyway) and
        # the pixel centres; a fit with the footprint renders both in one pass where the build has it
        # (_native.render_centre_and_footprint), whose extra over the footprint render alone is the
        # uncertainty's and is timed with it; an older build's uncertainty renders the centres itself.
        pair = getattr(_native, "render_centre_and_footprint", None) if footprint else None
        compared = _native.render(s, s.width, s.height, 1, footprint)
        at_optimum = None if footprint else compared
        cpu, wall, u = [], [], {}
        for _ in range(runs):
            c0, w0 = time.process_time(), time.perf_counter()
            if pair is not None:
                at_optimum, compared = pair(s)
            u = estimate_uncertainty(result, np.asarray(photo, np.float64), render=at_optimum, compared=compared)
            wall.append(time.perf_counter() - w0)
            cpu.append(time.process_time() - c0)
        if pair is not None:  # less the footprint render the fit makes with or without the uncertainty
            alone_c, alone_w = [], []
            for _ in range(runs):
                c0, w0 = time.process_time(), time.perf_counter()
                _native.render(s, s.width, s.height, 1, True)
                alone_w.append(time.perf_counter() - w0)
                alone_c.append(time.process_time() - c0)
            wall = [w - min(alone_w) for w in wall]
            cpu = [c - min(alone_c) for c in cpu]
        robust = u.get("robust") or {}
        out[case.name] = {"cpu_ms": 1e3 * min(cpu), "wall_ms": 1e3 * min(wall),
                          "bounce": bool(s.to_dict().get("interreflection", False)),
                          "wall_median_ms": 1e3 * statistics.median(wall),
                          "light_m": robust.get("light_position_m"),
                          "products": {k: v for k, v in (u.get("product_sigma") or {}).items() if v is not None}}
    return out


def run(pythonpath: str, threads: int, runs: int) -> dict[str, dict[str, object]]:
    env = {**os.environ, "PYTHONPATH": pythonpath, "RAYON_NUM_THREADS": str(threads)}
    done = subprocess.run([sys.executable, __file__, "--worker", str(runs)], env=env, check=True,
                          capture_output=True, text=True)
    return json.loads(done.stdout.strip().splitlines()[-1])


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--rounds", type=int, default=2)
    ap.add_argument("--runs", type=int, default=10)
    ap.add_argument("--baseline", help="a python/ folder of another build to compare with")
    ap.add_argument("--worker", type=int, help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.worker is not None:
        print(json.dumps(worker(args.worker)))
        return 0
    builds = {"this": str(REPO / "python")}
    if args.baseline:
        builds["baseline"] = str(Path(args.baseline).resolve())
    best: dict[tuple[str, int], dict[str, dict[str, object]]] = {}
    for rnd in range(args.rounds):
        for threads in (1, 2):
            for name, path in builds.items():
                got = run(path, threads, args.runs)
                key = (name, threads)
                if key not in best:
                    best[key] = got
                else:
                    for case, row in got.items():
                        b = best[key][case]
                        for m in ("cpu_ms", "wall_ms"):
                            b[m] = min(b[m], row[m])
                print(f"round {rnd + 1}/{args.rounds}, {threads} thread(s), {name}: done", file=sys.stderr, flush=True)
    names = list(best[("this", 1)])
    load = os.getloadavg()
    lines = ["# What the default uncertainty adds to a fit (benches/uncertainty_cost.py)", "",
             (f"Machine: {platform.machine()}, {os.cpu_count()} logical CPUs, shared (load {load[0]:.1f} / "
              f"{load[1]:.1f} / {load[2]:.1f} at the end). {args.rounds} rounds x {args.runs} runs per build and "
              "thread count, alternating; the least over all runs, ms. 'cpu' is all threads' CPU time."), ""]
    head = "| photo | bounce | 1 thread: cpu | 2 threads: cpu | 2 threads: wall |"
    sep = "|---|---|---|---|---|"
    if args.baseline:
        head += " baseline 1 thread: cpu | baseline 2 threads: wall | light sigma, this / baseline | products sigma, this / baseline (range) |"
        sep += "---|---|---|---|"
    lines += [head, sep]
    for case in names:
        a1, a2 = best[("this", 1)][case], best[("this", 2)][case]
        row = (f"| {case} | {'yes' if a1['bounce'] else 'no'} | {a1['cpu_ms']:.1f} | {a2['cpu_ms']:.1f} | "
               f"{a2['wall_ms']:.1f} |")
        if args.baseline:
            b1, b2 = best[("baseline", 1)][case], best[("baseline", 2)][case]
            light = (f"{a1['light_m'] / b1['light_m']:.4f}" if a1["light_m"] and b1["light_m"] else "-")
            ratios = [a1["products"][k] / b1["products"][k] for k in a1["products"]
                      if b1["products"].get(k)]
            prod = f"{min(ratios):.4f}-{max(ratios):.4f}" if ratios else "-"
            row += f" {b1['cpu_ms']:.1f} | {b2['wall_ms']:.1f} | {light} | {prod} |"
        lines.append(row)
    lines.append("")
    for bounce, label in ((False, "without interreflection"), (True, "whose fit takes the bounce")):
        group = [c for c in names if bool(best[("this", 1)][c]["bounce"]) == bounce]
        if not group:
            continue
        med = {k: statistics.median(float(v[c]["wall_ms" if k[1] == 2 else "cpu_ms"]) for c in group)
               for k, v in best.items()}
        lines.append(f"Medians over the {len(group)} photos {label}: " + ", ".join(
            f"{name} {threads} thread(s) {'wall' if threads == 2 else 'cpu'} {med[(name, threads)]:.1f} ms"
            for name, threads in best) + ".")
    lines.append("")
    OUT.write_text("\n".join(lines))
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
