"""``rtloop-fit --batch JOBS.jsonl --out DIR``: many fits, in-process or on Ray, into DIR/results.jsonl
(appended a whole line at a time) and DIR/<id>/; a re-run skips the jobs already finished."""

from __future__ import annotations

import argparse
import json
import os
import signal
import sys
import threading
import time
from pathlib import Path
from typing import Any, TextIO

import rtloop
from rtloop._files import recover_leftovers_in
from rtloop.batch import fit_many, load_jobs
from rtloop.batch.on_ray import RAY_HINT
from rtloop.fit import PROTOCOLS

from .args import Parser, UsageError, generations, int_at_least

__all__ = ["main"]

PROG = "rtloop-fit"

DESCRIPTION = """\
Fit many photos: JOBS is a JSON-lines file, one job a line:
  {"id": "shot-001", "scene": "scene.json", "photo": "shot-001.png", "seed": 1}
with optional "mask" and per-job fit options ("protocol", "population",
"generations", "norm", "loss_space", "response", "crop", ...); relative paths
are relative to JOBS. Jobs run in-process (one fit per core, each on one
thread, by default) or, with --ray, as Ray tasks on a cluster.
"""

EPILOG = """\
files written into DIR:
  results.jsonl     one line per finished job: id, status (ok/error), hash (of
                    the scene, photo and mask bytes, seed and options), seed,
                    light (as in result.json), products, x (the fitted
                    values), fitness, evaluations, error, seconds; each line is
                    appended whole (written, flushed and fsynced)
  <id>/result.json  as rtloop-fit writes it; unless --no-images also as
                    rtloop-fit: <id>/objective.png, <id>/final.png,
                    <id>/best_per_generation.csv and <id>/snapshots/ (the last
                    two from a callback per generation: --no-images is the
                    fast path)

A re-run with the same DIR skips every job whose id and hash are already in
results.jsonl (a failed one too, unless --retry-failed), so an interrupted
batch (Ctrl-C, a killed machine) resumes where it stopped.

exit status: 0 every job ok, 1 a job failed or bad input, 2 bad command line,
130 interrupted (Ctrl-C), 143 terminated (SIGTERM).
"""



class _Terminated(KeyboardInterrupt):
    """SIGTERM, handled like Ctrl-C."""


def _build_parser() -> Parser:
    p = Parser(prog=PROG, description=DESCRIPTION, epilog=EPILOG,
               formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--batch", metavar="JOBS", type=Path, required=True, help="the jobs (JSON lines)")
    p.add_argument("--out", "-o", metavar="DIR", type=Path, required=True,
                   help="output directory (created; an existing one is resumed)")
    p.add_argument("--no-images", action="store_true", help="per job, write result.json only (no objective.png, "
                   "final.png, best_per_generation.csv, snapshots/)")
    p.add_argument("--snapshot-every", type=int_at_least(0, "a whole number >= 0"), default=5, metavar="N",
                   help="render each job's best individual every N generations into <id>/snapshots/ (0: none; "
                   "default 5)")
    p.add_argument("--workers", type=int_at_least(1, "a whole number >= 1"), metavar="N",
                   help="concurrent fits in-process (default: cores / threads)")
    p.add_argument("--threads", type=int_at_least(1, "a whole number >= 1"), metavar="N",
                   help="threads per fit (default 1; on Ray the task's num_cpus)")
    p.add_argument("--ray", nargs="?", const="", default=None, metavar="ADDRESS",
                   help="run the jobs as Ray tasks on the cluster at ADDRESS (e.g. ray://head:10001 or "
                   "auto); without ADDRESS, a running local cluster or a new local Ray")
    p.add_argument("--max-retries", type=int_at_least(0, "a whole number >= 0"), default=3, metavar="N",
                   help="with --ray: times a job is retried when its worker dies (default 3)")
    p.add_argument("--warm-start", action="store_true",
                   help="frames of a sequence: run the jobs in order, each light search in bounds narrowed "
                   "around the previous job's light")
    p.add_argument("--no-uncertainty", action="store_true",
                   help="skip the Gauss-Newton sigma of each fit (the fitted values are the same; ~1.5x the fits/s "
                   "on a small photo)")
    p.add_argument("--retry-failed", action="store_true", help="run again the jobs recorded as failed")
    p.add_argument("--protocol", choices=sorted(PROTOCOLS), help="every job's protocol (a job's own wins)")
    p.add_argument("--population", type=int_at_least(4, "a whole number >= 4"), metavar="N")
    p.add_argument("--generations", type=generations, metavar="N|N1,N2")
    p.add_argument("--norm", metavar="NORM", help="l1 (default), l2, huber or huber:H")
    p.add_argument("--loss-space", choices=("auto", "linear", "srgb"))
    p.add_argument("--environment", choices=("auto", "on", "off"), help="the occluded environment term "
                   "(default auto: added when the photo shows it)")
    p.add_argument("--interreflection", choices=("auto", "on", "off"), help="one diffuse bounce between the "
                   "objects (default auto: added when the photo shows it)")
    p.add_argument("--highlights", choices=("auto", "off"), help="free a matte sphere's specular lobe when the "
                   "photo shows a highlight (default auto)")
    p.add_argument("--response", choices=("srgb", "linear"))
    p.add_argument("--final-scale", type=int_at_least(1, "a whole number >= 1"), default=4, metavar="K")
    p.add_argument("--final-spp", type=int_at_least(1, "a whole number >= 1"), default=16, metavar="S")
    p.add_argument("--quiet", "-q", action="store_true", help="no progress on stderr")
    return p


def _error(message: object) -> None:
    print(f"{PROG}: error: {' '.join(str(message).split())}", file=sys.stderr, flush=True)


# --- results.jsonl ---------------------------------------------------------------------------------------


class Results:
    """DIR/results.jsonl: the records already there, and whole-line appends (one write, then fsync)."""

    def __init__(self, path: Path):
        self.path = path
        self.done: dict[str, dict[str, Any]] = {}
        if path.exists():
            data = path.read_bytes()
            end = data.rfind(b"\n") + 1
            if end < len(data):  # a torn last line (a crash mid-write elsewhere): drop it
                with open(path, "r+b") as fh:
                    fh.truncate(end)
            for line in data[:end].decode("utf-8", "replace").splitlines():
                try:
                    rec = json.loads(line)
                except json.JSONDecodeError:
                    continue
                if isinstance(rec, dict) and isinstance(rec.get("id"), str):
                    self.done[rec["id"]] = rec
        self.fd = os.open(path, os.O_WRONLY | os.O_APPEND | os.O_CREAT, 0o666)

    def skip(self, retry_failed: bool) -> dict[str, str]:
        return {i: r["hash"] for i, r in self.done.items()
                if isinstance(r.get("hash"), str) and (r.get("status") == "ok" or not retry_failed)}

    def append(self, record: dict[str, Any]) -> None:
        data = (json.dumps(record, allow_nan=False) + "\n").encode("utf-8")
        view = memoryview(data)
        while view:
            view = view[os.write(self.fd, view):]
        os.fsync(self.fd)

    def close(self) -> None:
        os.close(self.fd)


# --- progress --------------------------------------------------------------------------------------------


class Progress:
    """done/failed/ETA on stderr: one updating line on a terminal, else a line every 5 s and at the end."""

    def __init__(self, stream: TextIO, enabled: bool, total: int, skipped: int):
        self.stream, self.enabled, self.total, self.skipped = stream, enabled, total, skipped
        self.tty = enabled and bool(getattr(stream, "isatty", lambda: False)())
        self.start = time.perf_counter()
        self.last = self.start
        self.done = self.failed = 0

    def line(self) -> str:
        dt = time.perf_counter() - self.start
        rate = self.done / dt if dt > 0 else 0.0
        text = f"{PROG}: batch: {self.done}/{self.total} done, {self.failed} failed"
        if self.skipped:
            text += f", {self.skipped} already done"
        if self.done:
            eta = (self.total - self.done) / rate if rate > 0 else 0.0
            text += f", {rate:.1f} fits/s, {dt:.1f}s" + (f", ETA {eta:.1f}s" if self.done < self.total else "")
        return text

    def update(self, ok: bool) -> None:
        self.done += 1
        self.failed += not ok
        now = time.perf_counter()
        if not self.enabled:
            return
        if self.tty and now - self.last >= 0.1:
            self.stream.write("\r" + self.line() + "\x1b[K")
            self.stream.flush()
            self.last = now
        elif not self.tty and now - self.last >= 5.0:
            print(self.line(), file=self.stream, flush=True)
            self.last = now

    def finish(self, suffix: str = "") -> None:
        if self.enabled:
            if self.tty:
                self.stream.write("\r\x1b[K")
            print(self.line() + suffix, file=self.stream, flush=True)


# --- the run ---------------------------------------------------------------------------------------------


def _options(args: argparse.Namespace) -> dict[str, Any]:
    opts: dict[str, Any] = {}
    for key, name in (("protocol", "protocol"), ("population", "population"), ("generations", "generations"),
                      ("norm", "norm"), ("loss_space", "space"), ("response", "response"),
                      ("environment", "environment"), ("interreflection", "interreflection"),
                      ("highlights", "highlights")):
        value = getattr(args, key)
        if value is not None:
            opts[name] = value
    if args.no_uncertainty:
        opts["uncertainty"] = False
    return opts


def main(argv: list[str] | None = None) -> int:
    """``rtloop-fit --batch``; returns the exit status."""
    previous = None
    if threading.current_thread() is threading.main_thread():
        previous = signal.signal(signal.SIGTERM, _on_sigterm)
    try:
        return _main(argv)
    finally:
        if previous is not None:
            signal.signal(signal.SIGTERM, previous)


def _on_sigterm(signum: int, frame: Any) -> None:
    raise _Terminated()


def _main(argv: list[str] | None) -> int:
    try:
        args = _build_parser().parse_args(argv)
    except UsageError as e:
        _error(e)
        return 2
    except SystemExit as e:  # --help
        return int(e.code or 0)
    if args.ray is not None:
        if args.warm_start:
            _error("--warm-start runs the jobs in order in-process: not with --ray")
            return 2
        try:
            import ray  # noqa: F401
        except ImportError:
            _error(f"--ray: {RAY_HINT}")
            return 1
    out: Path = args.out
    try:
        jobs = load_jobs(args.batch)
        out.mkdir(parents=True, exist_ok=True)
        recover_leftovers_in(out)  # the staged DIR/<id>/ of jobs a killed run had in flight
        results = Results(out / "results.jsonl")
    except rtloop.RtloopError as e:
        _error(e)
        return 1
    except OSError as e:
        _error(f"{e.filename or out}: {e.strerror or e}")
        return 1
    progress: Progress | None = None
    try:
        skip = results.skip(args.retry_failed)
        engine = "ray" if args.ray is not None else "local"
        run = fit_many(jobs, engine, workers=args.workers, threads=args.threads, options=_options(args),
                       out=out, images=not args.no_images, final_scale=args.final_scale,
                       final_spp=args.final_spp, snapshot_every=args.snapshot_every, skip=skip, warm_start=args.warm_start,
                       address=args.ray or None, max_retries=args.max_retries)
        total = _count_todo(jobs, skip, _options(args)) if skip else len(jobs)
        progress = Progress(sys.stderr, not args.quiet, total, len(jobs) - total)
        for r in run:
            results.append(r.record())
            progress.update(r.ok)
        progress.finish(f"; results in {out / 'results.jsonl'}")
        return 1 if progress.failed else 0
    except _Terminated:
        if progress is not None:
            progress.finish(" (terminated)")
        return 128 + signal.SIGTERM
    except KeyboardInterrupt:
        if progress is not None:
            progress.finish(" (interrupted; run again to resume)")
        return 130
    except rtloop.RtloopError as e:
        _error(e)
        return 1
    finally:
        results.close()


def _count_todo(jobs: list[Any], skip: dict[str, str], options: dict[str, Any]) -> int:
    from rtloop.batch import job_hash

    return sum(1 for j in jobs if skip.get(j.id) != job_hash(j, options))
