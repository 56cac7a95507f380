"""What a user waits for: the wall time of one ``rtloop-fit`` with its default outputs, and fits/s of a
batch with and without them.

    python benches/outputs.py [--runs 15] [--jobs 60] [--out benches/results] [--python DIR]

1. ``rtloop-fit examples/yellow-ball/scene_input.json examples/yellow-ball/objective.png --out DIR`` as a
   fresh process, ``--runs`` times: least and median wall time; the same with ``--snapshot-every 0
   --final-spp 1 --final-scale 1`` (outputs at their cheapest), and ``import rtloop.cli.fit`` alone.
2. ``rtloop.fit_many`` on ``--jobs`` mixed jobs (the reference scenes in ../shared/scenes in turn, each
   with its own seed; the example scene where those are absent), the default plan: no files, result.json
   only (``images=False``) and the default outputs (objective.png, final.png, best_per_generation.csv,
   snapshots/): fits/s and the process's CPU ms per fit.
``--python DIR`` measures another checkout's package (its ``python/`` folder, e.g. to compare with main).
Writes ``outputs.md`` into ``--out``. Wall times on a shared machine vary: each row is the least of its runs
(the median beside it).
"""

from __future__ import annotations

import argparse
import os
import platform
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
EXAMPLE = REPO / "examples" / "yellow-ball"
SHARED = REPO.parent / "shared" / "scenes"


def wall(cmd: list[str], runs: int, env: dict[str, str], fresh: Path | None = None) -> list[float]:
    times = []
    for i in range(runs):
        args = [*cmd, "--out", str(fresh / f"run{i}")] if fresh is not None else cmd
        t = time.perf_counter()
        subprocess.run(args, env=env, check=True, stdout=subprocess.DEVNULL)
        times.append(time.perf_counter() - t)
    return times


def _where(path: str) -> str:
    """A package's folder, relative to the repository when inside it."""
    folder = Path(path).resolve().parent
    return str(folder.relative_to(REPO)) if folder.is_relative_to(REPO) else str(folder)


def mixed_jobs(n: int) -> list[dict]:
    cases = sorted(p for p in SHARED.iterdir() if (p / "scene_input.json").is_file()) if SHARED.is_dir() else []
    if not cases:
        cases = [EXAMPLE]
    return [{"id": f"job{i:03d}", "scene": str(cases[i % len(cases)] / "scene_input.json"),
             "photo": str(cases[i % len(cases)] / "objective.png"), "seed": i} for i in range(n)]


def rate(jobs: list[dict], **kw: object) -> tuple[float, float]:
    import rtloop

    cpu, t = time.process_time(), time.perf_counter()
    res = list(rtloop.fit_many(jobs, **kw))
    dt = time.perf_counter() - t
    assert all(r.ok for r in res), [r.error for r in res if not r.ok][:3]
    return len(res) / dt, 1000 * (time.process_time() - cpu) / len(res)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--runs", type=int, default=15)
    ap.add_argument("--jobs", type=int, default=60)
    ap.add_argument("--out", type=Path, default=REPO / "benches" / "results")
    ap.add_argument("--python", type=Path, default=REPO / "python", help="the package to measure")
    args = ap.parse_args()
    sys.path.insert(0, str(args.python.resolve()))
    import rtloop

    env = {**os.environ, "PYTHONPATH": os.pathsep.join(p for p in (str(args.python.resolve()),
                                                                     os.environ.get("PYTHONPATH")) if p)}
    fit_cmd = [sys.executable, "-m", "rtloop.cli", str(EXAMPLE / "scene_input.json"),
               str(EXAMPLE / "objective.png"), "-q"]
    rows: list[tuple[str, str, str]] = []
    with tempfile.TemporaryDirectory() as tmp_name:
        tmp = Path(tmp_name)
        wall(fit_cmd, 2, env, tmp / "warm")  # bytecode caches, page cache
        for label, extra in (("rtloop-fit, default outputs", []),
                             ("rtloop-fit, --snapshot-every 0 --final-scale 1 --final-spp 1",
                              ["--snapshot-every", "0", "--final-scale", "1", "--final-spp", "1"])):
            t = wall(fit_cmd + extra, args.runs, env, tmp / label.split(",")[1].strip().replace(" ", "_"))
            rows.append((label, f"{min(t):.3f}", f"{statistics.median(t):.3f}"))
        t = wall([sys.executable, "-c", "import rtloop.cli.fit"], args.runs, env)
        rows.append(("python -c 'import rtloop.cli.fit'", f"{min(t):.3f}", f"{statistics.median(t):.3f}"))
        t = wall([sys.executable, "-c", "pass"], args.runs, env)
        rows.append(("python -c pass", f"{min(t):.3f}", f"{statistics.median(t):.3f}"))

        jobs = mixed_jobs(args.jobs)
        list(rtloop.fit_many(jobs[:4]))  # warm up: pools, caches
        batch = []
        for label, kw in (("no files (out=None)", {}),
                          ("result.json only (images=False)", {"out": tmp / "json", "images": False}),
                          ("default outputs", {"out": tmp / "all"})):
            fits, cpu = rate(jobs, **kw)
            batch.append((label, f"{fits:.1f}", f"{cpu:.1f}"))
    cases = sorted({Path(j["scene"]).parent.name for j in jobs})
    text = [f"# `python benches/outputs.py --runs {args.runs} --jobs {args.jobs}`: one rtloop-fit, a batch's outputs",
            "",
            f"What a user waits for (package: {_where(rtloop.__file__)}); "
            f"{platform.machine()}, "
            f"{os.cpu_count()} cores, Python {platform.python_version()}; load average (1 min) at the end "
            f"{os.getloadavg()[0]:.1f}.",
            "",
            "## One rtloop-fit on examples/yellow-ball (a fresh process each run)",
            "",
            "| command | least wall (s) | median wall (s) |",
            "|---|---:|---:|",
            *(f"| {a} | {b} | {c} |" for a, b, c in rows),
            "",
            f"## rtloop.fit_many, {len(jobs)} jobs ({', '.join(cases)} in turn, one seed each), default plan",
            "",
            "| outputs | fits/s | CPU ms per fit |",
            "|---|---:|---:|",
            *(f"| {a} | {b} | {c} |" for a, b, c in batch),
            ""]
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "outputs.md").write_text("\n".join(text), encoding="utf-8")
    print("\n".join(text))


if __name__ == "__main__":
    main()
