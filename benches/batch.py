"""Many photos: fits per second of a batch, in-process and on a local Ray, against a shell loop of
``rtloop-fit``; and what a warm start saves on a sequence of frames.

    python benches/batch.py [--jobs 200] [--out benches/results] [--no-ray]

The photos are rendered by rtloop from the yellow-ball example scene (128x96) with its true light
moved along a slow path (2 cm a frame), so every fit has a known answer. Measured:
  1. in-process ``rtloop.fit_many`` with 2 fits x 1 thread, 3 x 1 and 1 fit x 2 threads (the default
     method), fits/s and the process's CPU time per fit;
  2. ``rtloop-fit --batch ... --no-images`` end to end (start-up included);
  3. the same on a local Ray (``ray.init(num_cpus=...)``; the start of Ray reported apart), if installed;
  4. a shell loop of ``rtloop-fit SCENE PHOTO --out DIR`` on 10 of the jobs, extrapolated per job;
  5. warm starts on the sequence: cold, warm (bounds +-10 % around the previous light) with the same
     budget, and warm with a smaller search: evaluations, fits/s and the light position error.
Writes ``batch.md`` into ``--out``.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

import rtloop

REPO = Path(__file__).resolve().parents[1]
EXAMPLE = REPO / "examples" / "yellow-ball"


def make_photos(where: Path, n: int) -> tuple[Path, list[Path], list[list[float]]]:
    scene_path = EXAMPLE / "scene_input.json"
    truth = json.loads((EXAMPLE / "scene.json").read_text(encoding="utf-8"))
    start = np.array(truth["light"]["position"])
    photos, lights = [], []
    for i in range(n):
        pos = start + 0.02 * i * np.array([np.cos(i / 40), 0.3, np.sin(i / 40)])  # 2 cm a frame
        truth["light"]["position"] = pos.tolist()
        p = where / f"frame{i:04d}.png"
        rtloop.save_image(p, rtloop.render(rtloop.load_scene(truth)))
        photos.append(p)
        lights.append(pos.tolist())
    return scene_path, photos, lights


def jobs_for(scene: Path, photos: list[Path]) -> list[dict]:
    return [{"id": f"frame{i:04d}", "scene": str(scene), "photo": str(p), "seed": i} for i, p in enumerate(photos)]


def timed(fn) -> tuple[float, object]:
    t = time.perf_counter()
    value = fn()
    return time.perf_counter() - t, value


def position_errors(results, lights) -> list[float]:
    by_id = {r.id: r for r in results}
    return [float(np.linalg.norm(np.array(by_id[f"frame{i:04d}"].light["position"]) - np.array(t)))
            for i, t in enumerate(lights) if f"frame{i:04d}" in by_id]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--jobs", type=int, default=200)
    ap.add_argument("--loop-jobs", type=int, default=10)
    ap.add_argument("--out", type=Path, default=REPO / "benches" / "results")
    ap.add_argument("--no-ray", action="store_true")
    args = ap.parse_args()
    from rtloop.batch.local import cores, plan

    ncores = cores()
    rows: list[tuple[str, str]] = []
    notes: list[str] = []
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(p for p in (str(REPO / "python"),
                                                                     os.environ.get("PYTHONPATH")) if p)}
    with tempfile.TemporaryDirectory() as tmp_name:
        tmp = Path(tmp_name)
        scene, photos, lights = make_photos(tmp, args.jobs)
        jobs = jobs_for(scene, photos)
        list(rtloop.fit_many(jobs[:4]))  # warm up: pools, caches

        def local(workers: int, threads: int, **kw: object) -> tuple[float, float, list]:
            cpu = time.process_time()
            dt, res = timed(lambda: list(rtloop.fit_many(jobs, workers=workers, threads=threads, **kw)))
            return dt, (time.process_time() - cpu) / len(res), res

        per_fit = {}
        loads = [os.getloadavg()[0]]
        configs = ((ncores, 1), (ncores + 1, 1), (1, ncores)) if ncores > 1 else ((1, 1),)
        for w, t in configs:
            dt, cpu, res = local(w, t)
            assert all(r.ok for r in res), [r.error for r in res if not r.ok][:3]
            per_fit[(w, t)] = dt / len(res)
            rows.append((f"in-process fit_many, {w} fit{'s' if w > 1 else ''} x {t} thread{'s' if t > 1 else ''}"
                         + (" (the default)" if (w, t) == plan(None, None) else ""),
                         f"{len(res) / dt:.1f}", f"{cpu * 1000:.1f}"))
            if (w, t) == plan(None, None):
                errs = position_errors(res, lights)
        dt, cpu, res = local(ncores, 1, options={"uncertainty": False})
        rows.append((f"in-process fit_many, {ncores} x 1, uncertainty off (no Gauss-Newton sigma)",
                     f"{len(res) / dt:.1f}", f"{cpu * 1000:.1f}"))
        loads.append(os.getloadavg()[0])
        bad = sum(e > 0.05 for e in errs)
        notes.append(f"light position error (in-process): median {statistics.median(errs) * 1000:.2f} mm, "
                     f"max {max(errs) * 1000:.2f} mm over {len(errs)} fits ({bad} beyond 5 cm: a wrong basin)")

        out = tmp / "batch-out"
        jobs_file = tmp / "jobs.jsonl"
        jobs_file.write_text("".join(json.dumps(j) + "\n" for j in jobs), encoding="utf-8")
        dt, proc = timed(lambda: subprocess.run(
            [sys.executable, "-m", "rtloop.cli", "--batch", str(jobs_file), "--out", str(out), "--no-images",
             "-q"], env=env, check=False))
        assert proc.returncode == 0
        batch_cli = args.jobs / dt
        rows.append(("rtloop-fit --batch --no-images (start-up included)", f"{batch_cli:.1f}", ""))

        ray_rate = None
        if not args.no_ray:
            try:
                import ray
            except ImportError:
                notes.append("Ray: not installed (pip install '.[ray]')")
            else:
                os.environ["PYTHONPATH"] = env["PYTHONPATH"]
                t_init, _ = timed(lambda: ray.init(num_cpus=ncores, logging_level="warning",
                                                   log_to_driver=False, include_dashboard=False))
                list(rtloop.fit_many(jobs[:4], "ray"))  # the workers start and import rtloop
                dt, res = timed(lambda: list(rtloop.fit_many(jobs, "ray")))
                assert all(r.ok for r in res)
                ray_rate = len(res) / dt
                rows.append((f"local Ray, {ncores} CPUs, 1 task per job (num_cpus=1)", f"{ray_rate:.1f}", ""))
                notes.append(f"Ray: ray.init took {t_init:.1f} s and the first tasks (workers starting) are "
                             "left out of the rate")
                ray.shutdown()

        loop = jobs[: args.loop_jobs]
        command = ["rtloop-fit"] if shutil.which("rtloop-fit") else [sys.executable, "-m", "rtloop.cli"]

        def shell_loop() -> None:
            for j in loop:
                subprocess.run([*command, j["scene"], j["photo"], "--out", str(tmp / "loop" / j["id"]), "--seed",
                                str(j["seed"]), "-q"], env=env, check=True, stdout=subprocess.DEVNULL)
        dt, _ = timed(shell_loop)
        loop_rate = len(loop) / dt
        rows.append((f"shell loop of rtloop-fit (all outputs; {len(loop)} jobs, extrapolated per job)",
                     f"{loop_rate:.2f}", ""))

        # warm starts over the sequence (in order, one fit at a time on all cores)
        warm_rows = []
        for name, kw in (("cold, in order", {"warm_start": False, "workers": 1, "threads": ncores}),
                         ("warm, same budget", {"warm_start": True}),
                         ("warm, generations 8 and polish 100", {"warm_start": True,
                                                                 "options": {"generations": 8, "polish": 100}})):
            dt, res = timed(lambda kw=kw: list(rtloop.fit_many(jobs, **kw)))
            assert all(r.ok for r in res)
            errs = position_errors(res, lights)
            evals = statistics.mean(r.evaluations for r in res)
            warm_rows.append((name, f"{len(res) / dt:.1f}", f"{evals:.0f}", f"{statistics.median(errs) * 1000:.2f}",
                              f"{max(errs) * 1000:.2f}"))

    best_local = max(per_fit, key=lambda k: -per_fit[k])
    lines = [
        "# Many photos: batch fits",
        "",
        (f"`python benches/batch.py --jobs {args.jobs}`: {args.jobs} photos of the yellow-ball scene (128x96) "
         "rendered by rtloop with the light moved 2 cm a frame; the default method (rtloop protocol); "
         f"{platform.processor() or platform.machine()}, {ncores} cores, Python {platform.python_version()}."),
        "",
        "| how | fits/s | CPU ms per fit (all threads) |",
        "|---|---:|---:|",
        *(f"| {a} | {b} | {c} |" for a, b, c in rows),
        "",
        (f"The machine's load average (1 min) was {loads[0]:.1f} before the in-process rows and "
         f"{loads[1]:.1f} after (other work shares the {ncores} cores: the CPU time per fit is the steadier "
         "figure)."),
        "",
        f"In-process (best: {best_local[0]} x {best_local[1]}) is {1 / per_fit[best_local] / loop_rate:.0f}x "
        f"the shell loop; `rtloop-fit --batch` end to end {batch_cli / loop_rate:.0f}x"
        + (f"; local Ray {ray_rate / loop_rate:.0f}x" if ray_rate else "") + ".",
        "",
        *(f"- {n}" for n in notes),
        "",
        "## Warm starts (the frames in order, one fit at a time on all cores)",
        "",
        "| start | fits/s | evaluations per fit | median light error (mm) | max light error (mm) |",
        "|---|---:|---:|---:|---:|",
        *(f"| {' | '.join(r)} |" for r in warm_rows),
        "",
    ]
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "batch.md").write_text("\n".join(lines), encoding="utf-8")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
