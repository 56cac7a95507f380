"""The pixel footprint's accuracy and cost: ``rtloop.fit`` with pixel centres and with ``footprint=True``.

Cases: the Mitsuba photos ``tests/fixtures/photos/direct-*`` and the reference scenes in ``../shared/scenes``
(all Mitsuba renders with a box pixel filter; ``noisy-*`` are reported apart, they are not clean). Each is
fitted with the default ``rtloop.fit`` (``uncertainty=False``: the fit itself) with pixel centres
("centre") and with the footprint ("footprint"), in alternating subprocesses, ``--rounds`` times; light
position error in mm against its ``scene.json``, fit time the fastest of all rounds x ``--runs``, and the
time ratio footprint / centre from that one run. ``--baseline DIR`` adds a third column set: the default
fit of another build (a ``python/`` folder with its package and extension, e.g. of the commit before the
footprint). Writes ``benches/results/footprint.md``.

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


def worker(runs: int, footprint: bool) -> dict[str, dict[str, float]]:
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
            t0 = time.perf_counter()
            kw = {"footprint": True} if footprint else {}
            result = rtloop.fit(scene, photo, uncertainty=False, **kw)
            best = min(best, time.perf_counter() - t0)
        fitted = np.array(result.scene.to_dict()["light"]["position"], float)
        err = float(np.linalg.norm(fitted - np.array(truth["light"]["position"], float)))
        out[case.name] = {"light_err_mm": 1000 * err, "fit_ms": 1000 * best}
    return out


def run_with(python_dir: str | None, runs: int, footprint: bool) -> dict[str, dict[str, float]]:
    """`worker` in a subprocess importing rtloop from ``python_dir`` (this checkout's when None)."""
    env = dict(os.environ, PYTHONPATH=python_dir or str(REPO / "python"))
    cmd = [sys.executable, __file__, "--worker", "--runs", str(runs)] + (["--footprint"] if footprint else [])
    text = subprocess.run(cmd, env=env, check=True, capture_output=True, text=True).stdout
    return json.loads(text.strip().splitlines()[-1])


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--baseline", metavar="DIR", help="python/ folder of a baseline build to compare with")
    parser.add_argument("--rounds", type=int, default=3, help="alternating rounds of both builds (default 3)")
    parser.add_argument("--runs", type=int, default=5, help="fits per case and round (default 5)")
    parser.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    parser.add_argument("--footprint", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.worker:
        print(json.dumps(worker(args.runs, args.footprint)))
        return 0
    builds: dict[str, tuple[str | None, bool]] = {"centre": (None, False), "footprint": (None, True)}
    if args.baseline:
        builds["baseline"] = (args.baseline, False)
    got: dict[str, list[dict[str, dict[str, float]]]] = {k: [] for k in builds}
    for _ in range(args.rounds):
        for name, (where, footprint) in builds.items():
            got[name].append(run_with(where, args.runs, footprint))
    names = list(got["centre"][0])
    best = {k: {c: min(r[c]["fit_ms"] for r in rs) for c in names} for k, rs in got.items()}
    err = {k: {c: rs[0][c]["light_err_mm"] for c in names} for k, rs in got.items()}
    head = ["case"] + [f"light error {k} (mm)" for k in builds] + [f"fit {k} (ms)" for k in builds]
    head.append("time footprint / centre")
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for c in names:
        row = [c] + [f"{err[k][c]:.2f}" for k in builds] + [f"{best[k][c]:.1f}" for k in builds]
        row.append(f"{best['footprint'][c] / best['centre'][c]:.2f}")
        lines.append("| " + " | ".join(row) + " |")
    clean = [c for c in names if not c.startswith("noisy")]
    row = [f"**median, clean ({len(clean)})**"]
    row += [f"{statistics.median(err[k][c] for c in clean):.2f}" for k in builds]
    row += [f"{statistics.median(best[k][c] for c in clean):.1f}" for k in builds]
    row.append(f"{sum(best['footprint'][c] for c in clean) / sum(best['centre'][c] for c in clean):.2f}")
    lines.append("| " + " | ".join(row) + " |")
    text = "\n".join(lines)
    machine = f"{platform.machine()}, {os.cpu_count()} cores, Python {platform.python_version()}"
    header = (f"# benches/footprint.py (default fit, uncertainty off; fastest of {args.rounds} x {args.runs} fits; "
              f"{machine})\n\n")
    print(header + text)
    OUT.parent.mkdir(parents=True, exist_ok=True)
    OUT.write_text(header + text + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
