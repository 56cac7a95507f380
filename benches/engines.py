"""Threads against worker processes for a batch: how much of a fit holds Python's GIL (which caps how many fits
threads of one process run at once), and fits/s of ``rtloop.fit_many`` on each engine with the error reached.

    python benches/engines.py [--jobs 60] [--rounds 2] [--out benches/results]

1. The GIL's share: the default fits of the mixed jobs one after another on one thread, the CPU time inside
   the native calls that release the GIL (the search, the renders, the uncertainty's columns) against the
   whole CPU time (CPU time, not wall: steadier on a shared machine). Threads of one process then run at most
   1 / share fits' worth at once, whatever the cores.
2. ``fit_many`` on ``--jobs`` mixed jobs (as ``benches/outputs.py``: the reference scenes in turn, a seed each),
   no files, ``engine="local"`` (threads) and ``engine="processes"`` alternately, ``--rounds`` times each: fits/s
   (the process pool's start-up included) and the median light error against the scenes' truth.
Writes ``engines.md`` into ``--out``.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from outputs import REPO, mixed_jobs  # noqa: E402

#: The native calls that release the GIL while they run.
RELEASING = ("optimize", "evaluate", "fd_columns", "render", "render_centre_and_footprint", "render_pixels",
             "render_many", "render_layers", "held_out", "lights_solve", "object_ids")


def gil_share(jobs: list[dict]) -> tuple[float, float]:
    """(the share of a fit's CPU time outside the GIL-releasing calls, CPU ms per fit) over ``jobs`` on one
    thread."""
    from rtloop import _native
    from rtloop.fit.files import fit_inputs, load_inputs

    inside = [0.0]
    originals = {n: getattr(_native, n) for n in RELEASING if hasattr(_native, n)}

    def timed(f):
        def call(*a, **k):
            t = time.process_time()
            try:
                return f(*a, **k)
            finally:
                inside[0] += time.process_time() - t
        return call

    for n, f in originals.items():
        setattr(_native, n, timed(f))
    try:
        for j in jobs[:4]:  # warm: imports, caches
            fit_inputs(load_inputs(j["scene"], j["photo"]), seed=j["seed"], threads=1)
        inside[0], t = 0.0, time.process_time()
        for j in jobs:
            fit_inputs(load_inputs(j["scene"], j["photo"]), seed=j["seed"], threads=1)
        cpu = time.process_time() - t
    finally:
        for n, f in originals.items():
            setattr(_native, n, f)
    return 1.0 - inside[0] / cpu, 1000 * cpu / len(jobs)


def light_error_mm(result, job: dict) -> float:
    truth = json.loads((Path(job["scene"]).parent / "scene.json").read_text())["light"]["position"]
    return 1000 * float(np.linalg.norm(np.subtract(result.light["position"], truth)))


def rate(jobs: list[dict], engine: str) -> tuple[float, float]:
    import rtloop

    t = time.perf_counter()
    res = list(rtloop.fit_many(jobs, engine))
    dt = time.perf_counter() - t
    assert all(r.ok for r in res), [r.error for r in res if not r.ok][:3]
    by_id = {j["id"]: j for j in jobs}
    return len(res) / dt, statistics.median(light_error_mm(r, by_id[r.id]) for r in res)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--jobs", type=int, default=60)
    ap.add_argument("--rounds", type=int, default=2)
    ap.add_argument("--out", type=Path, default=REPO / "benches" / "results")
    args = ap.parse_args()
    jobs = mixed_jobs(args.jobs)
    share, ms = gil_share(jobs[:max(8, args.jobs // 3)])
    rows = {"local": [], "processes": []}
    for _ in range(args.rounds):
        for engine in rows:
            rows[engine].append(rate(jobs, engine))
    load = os.getloadavg()[0]
    text = [f"# `python benches/engines.py --jobs {args.jobs} --rounds {args.rounds}`: threads against worker "
            "processes", "",
            f"{platform.machine()}, {os.cpu_count()} cores, Python {platform.python_version()}; load average "
            f"(1 min) at the end {load:.1f}.", "",
            f"A default fit of the mixed jobs (one thread, {ms:.0f} ms of CPU each) holds the GIL for {100 * share:.0f} % "
            f"of its CPU time: threads of one process run at most {1 / share:.1f} fits' worth at once.", "",
            f"`rtloop.fit_many`, {args.jobs} mixed jobs (the reference scenes in turn, a seed each), no files, one "
            "fit per core; each round both engines, one after the other:", "",
            "| engine | fits/s per round | median light error (mm) |", "|---|---|---:|"]
    for engine, runs in rows.items():
        text.append(f"| {engine} | {', '.join(f'{r:.1f}' for r, _ in runs)} | {runs[0][1]:.2f} |")
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "engines.md").write_text("\n".join(text) + "\n", encoding="utf-8")
    print("\n".join(text))


if __name__ == "__main__":
    main()
