"""The pixel footprint's accuracy and cost: ``rtloop.fit`` with ``footprint`` "off" (pixel centres), "auto"
(the default: the closed-form polish takes the footprint) and "on" (every search too).

Cases: the Mitsuba photos ``tests/fixtures/photos/direct-*`` and the reference scenes in ``../shared/scenes``
(all Mitsuba renders with a box pixel filter; ``noisy-*`` are reported apart, they are not clean). Each is
fitted with the default ``rtloop.fit`` (``uncertainty=False``: the fit itself) in each footprint mode, in
alternating subprocesses, ``--rounds`` times; light position error in mm against its ``scene.json``, fit
CPU time (all threads) the least of all rounds x ``--runs``, and the time ratios against "off" from that
one run. ``--baseline DIR`` adds a column set: the default fit of another build (a ``python/`` folder with
its package and extension, e.g. of the commit before a change). Writes ``benches/results/footprint.md``.

Usage (from the repository root, with the extension built)::

    python benches/footprint.py
    python benches/footprint.py --rounds 3 --runs 5 --baseline /tmp/base/python
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
SHARED = REPO.parent / "shared" / "scenes"
OUT = REPO / "benches" / "results" / "footprint.md"


def cases() -> list[Path]:
    """The direct Mitsuba photos, then the shared reference scenes (where present)."""
    found = sorted(p for p in PHOTOS.glob("direct-*") if (p / "objective.png").exists())
    if SHARED.is_dir():
        found += sorted(p for p in SHARED.iterdir() if (p / "scene_input.json").exists())
    return found


def worker(runs: int, footprint: str | None) -> dict[str, dict[str, float]]:
    """Fit every case with the rtloop on the path: light error (mm) and the fastest fit (ms)."""
    import numpy as np

    import rtloop

    out = {}
    for case in cases():
        truth = json.loads((case / "scene.json").read_text())
        scene = rtloop.load_scene(case / "scene_input.json")
        photo = rtloop.load_image(case / "objective.png", scene)
        best, result = float("inf"), None
        for _ in range(runs):
            t0 = time.process_time()
            kw = {"footprint": footprint} if footprint else {}
            result = rtloop.fit(scene, photo, uncertainty=False, **kw)
            best = min(best, time.process_time() - t0)
        fitted = np.array(result.scene.to_dict()["light"]["position"], float)
        err = float(np.linalg.norm(fitted - np.array(truth["light"]["position"], float)))
        out[case.name] = {"light_err_mm": 1000 * err, "fit_ms": 1000 * best}
    return out


def run_with(python_dir: str | None, runs: int, footprint: str | None) -> dict[str, dict[str, float]]:
    """`worker` in a subprocess importing rtloop from ``python_dir`` (this checkout's when None)."""
    env = dict(os.environ, PYTHONPATH=python_dir or str(REPO / "python"))
    cmd = [sys.executable, __file__, "--worker", "--runs", str(runs)] + (["--footprint", footprint] if footprint else [])
    text = subprocess.run(cmd, env=env, check=True, capture_output=True, text=True).stdout
    return json.loads(text.strip().splitlines()[-1])


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--baseline", metavar="DIR", help="python/ folder of a baseline build to compare with")
    parser.add_argument("--rounds", type=int, default=3, help="alternating rounds of both builds (default 3)")
    parser.add_argument("--runs", type=int, default=5, help="fits per case and round (default 5)")
    parser.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    parser.add_argument("--footprint", help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.worker:
        print(json.dumps(worker(args.runs, args.footprint)))
        return 0
    builds: dict[str, tuple[str | None, str | None]] = {m: (None, m) for m in ("off", "auto", "on")}
    if args.baseline:
        builds["baseline"] = (args.baseline, None)
    got: dict[str, list[dict[str, dict[str, float]]]] = {k: [] for k in builds}
    for _ in range(args.rounds):
        for name, (where, footprint) in builds.items():
            got[name].append(run_with(where, args.runs, footprint))
    names = list(got["off"][0])
    best = {k: {c: min(r[c]["fit_ms"] for r in rs) for c in names} for k, rs in got.items()}
    err = {k: {c: rs[0][c]["light_err_mm"] for c in names} for k, rs in got.items()}
    head = ["case"] + [f"light error {k} (mm)" for k in builds] + [f"fit {k} (ms)" for k in builds]
    head += [f"time {k} / off" for k in builds if k != "off"]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for c in names:
        row = [c] + [f"{err[k][c]:.2f}" for k in builds] + [f"{best[k][c]:.1f}" for k in builds]
        row += [f"{best[k][c] / best['off'][c]:.2f}" for k in builds if k != "off"]
        lines.append("| " + " | ".join(row) + " |")
    clean = [c for c in names if not c.startswith("noisy")]
    row = [f"**median, clean ({len(clean)})**"]
    row += [f"{statistics.median(err[k][c] for c in clean):.2f}" for k in builds]
    row += [f"{statistics.median(best[k][c] for c in clean):.1f}" for k in builds]
    row += [f"{sum(best[k][c] for c in clean) / sum(best['off'][c] for c in clean):.2f}" for k in builds if k != "off"]
    lines.append("| " + " | ".join(row) + " |")
    text = "\n".join(lines)
    machine = f"{platform.machine()}, {os.cpu_count()} cores, Python {platform.python_version()}"
    header = (f"# benches/footprint.py (default fit, uncertainty off; CPU time, least of {args.rounds} x {args.runs} fits; "
              f"{machine})\n\n")
    print(header + text)
    OUT.parent.mkdir(parents=True, exist_ok=True)
    OUT.write_text(header + text + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
