"""``rtloop-fit --batch JOBS.jsonl --out DIR``: many fits, in-process or on Ray, into DIR/results.jsonl
(appended a whole line at a time) and DIR/<id>/; a re-run skips the jobs already finished."""

from __future__ import annotations

import argparse
import signal
import sys
import threading
import time
from pathlib import Path
from typing import Any, TextIO

import rtloop
from rtloop._files import recover_leftovers_in
from rtloop.batch import fit_many, load_jobs, shared_options, to_run
from rtloop.batch.folder import LOCK, MARKER, Results, check_targets, locked
from rtloop.batch.on_ray import RAY_HINT
from rtloop.fit import PROTOCOLS
from rtloop.fit.protocol import LIMITS, max_threads

from .args import Parser, UsageError, generations, int_at_least, int_in, norm, vignetting
from .fit import MAX_SIZE
from .lights import lights_count

__all__ = ["main"]

PROG = "rtloop-fit"

DESCRIPTION = """\
Fit many photos: JOBS is a JSON-lines file, one job a line:
  {"id": "shot-001", "scene": "scene.json", "photo": "shot-001.png", "seed": 1}
with optional "mask" and per-job fit options ("protocol", "population",
"generations", "norm", "loss_space", "response", "crop", "footprint",
"lights", ...);
relative paths are relative to JOBS. Each job is fitted as rtloop-fit fits
its scene and photo: the mask and the grey card the scene names (written by
rtloop-scene) are used unless the job gives "mask", or "grey_card" (false: none;
{"mask": "card.png", "reflectance": 0.18}: that card). Jobs run in-process
(one fit per core, each on one thread, by default), with --processes on worker
processes (for 4 or more cores), or with --ray as Ray tasks on a cluster.
"""

EPILOG = f"""\
files written into DIR:
  results.jsonl     one line per finished job: id, status (ok/error), hash (of
                    the scene, photo, mask and grey card bytes, seed, options
                    and a warm start's values), seed, light (as in
                    result.json), products, x (the fitted values), fitness,
                    evaluations, error, seconds; each line is appended whole
                    (written, flushed and fsynced)
  <id>/result.json  as rtloop-fit writes it; unless --no-images also as
                    rtloop-fit: <id>/objective.png, <id>/final.png,
                    <id>/best_per_generation.csv and <id>/snapshots/ (the last
                    two from a callback per generation: --no-images is the
                    fast path); <id>/{MARKER} marks the folder as the batch's:
                    a job whose folder would replace anything else in DIR is
                    refused before any fit
  {LOCK}
                    held while a batch runs: a second batch on DIR stops

A re-run with the same DIR skips every job whose id and hash are already in
results.jsonl, so an interrupted batch (Ctrl-C, a killed machine) resumes
where it stopped; a job recorded as failed is counted as failed again (exit
status 1) unless --retry-failed runs it again. With --warm-start the recorded
frames are skipped up to the first to run, which starts from the last one's
light, as in an uninterrupted run.

exit status: 0 every job ok, 1 a job failed (now or before) or bad input, 2 bad
command line, 130 interrupted (Ctrl-C), 143 terminated (SIGTERM).
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
    p.add_argument("--workers", type=int_in(1, 4096), metavar="N",
                   help="concurrent fits in-process (default: cores / threads)")
    p.add_argument("--threads", type=int_in(1, max_threads()), metavar="N",
                   help="threads per fit (default 1; on Ray the task's num_cpus)")
    p.add_argument("--processes", action="store_true",
                   help="run the fits on worker processes instead of threads: a fit holds Python's GIL for "
                   "about 40 %% of its time, so threads run at most about 2.5 fits at once; take it where 3 or "
                   "more fits run at once (4 or more cores; start-up about 0.3 s)")
    p.add_argument("--ray", nargs="?", const="", default=None, metavar="ADDRESS",
                   help="run the jobs as Ray tasks on the cluster at ADDRESS (e.g. ray://head:10001 or "
                   "auto); without ADDRESS, a running local cluster or a new local Ray")
    p.add_argument("--max-retries", type=int_in(0, 1000), default=3, metavar="N",
                   help="with --ray: times a job is retried when its worker dies (default 3)")
    p.add_argument("--warm-start", action="store_true",
                   help="frames of a sequence: run the jobs in order, each light search in bounds narrowed "
                   "around the previous job's light")
    p.add_argument("--no-uncertainty", action="store_true",
                   help="skip the Gauss-Newton sigma of each fit (the fitted values are the same; ~1.5x the fits/s "
                   "on a small photo)")
    p.add_argument("--retry-failed", action="store_true", help="run again the jobs recorded as failed (without "
                   "it they are counted as failed again and the exit status is 1)")
    p.add_argument("--protocol", choices=sorted(PROTOCOLS), help="every job's protocol (a job's own wins)")
    p.add_argument("--population", type=int_in(*LIMITS["population"]), metavar="N")
    p.add_argument("--generations", type=generations, metavar="N|N1,N2")
    p.add_argument("--norm", type=norm, metavar="NORM", help="auto (default), l1, l2, huber or huber:H, as rtloop-fit's --norm")
    p.add_argument("--loss-space", choices=("auto", "linear", "srgb"))
    p.add_argument("--environment", choices=("auto", "on", "off"), help="the occluded environment term "
                   "(default auto: added when the photo shows it)")
    p.add_argument("--interreflection", choices=("auto", "on", "off"), help="one diffuse bounce between the "
                   "objects (default auto: added when the photo shows it)")
    p.add_argument("--highlights", choices=("auto", "off"), help="free a matte sphere's specular lobe when the "
                   "photo shows a highlight (default auto)")
    p.add_argument("--footprint", nargs="?", choices=("auto", "silhouette", "on", "off"), const="on",
                   help="every job's pixel footprint mode, as rtloop-fit's --footprint (default auto)")
    p.add_argument("--framing", choices=("check", "correct", "off"),
                   help="every job's framing check, as rtloop-fit's --framing (default check)")
    p.add_argument("--vignetting", type=vignetting, metavar="auto|on|off|K1,K2",
                   help="every job's lens falloff, as rtloop-fit's --vignetting (default auto)")
    p.add_argument("--tone-curve", choices=("auto", "on", "off"),
                   help="every job's tone-curve term, as rtloop-fit's --tone-curve (default auto)")
    p.add_argument("--lights", type=lights_count, metavar="N|auto",
                   help="every job's number of lights, as rtloop-fit's --lights (a job's own \"lights\" field "
                   "wins); such a job writes the lights fit's result.json, and its results.jsonl line lists "
                   "\"lights\" with their error bars")
    p.add_argument("--response", choices=("srgb", "linear"))
    p.add_argument("--final-scale", type=int_in(1, MAX_SIZE), default=4, metavar="K")
    p.add_argument("--final-spp", type=int_in(1, rtloop.MAX_SPP), default=16, metavar="S")
    p.add_argument("--quiet", "-q", action="store_true", help="no progress on stderr")
    return p


def _error(message: object) -> None:
    print(f"{PROG}: error: {' '.join(str(message).split())}", file=sys.stderr, flush=True)


# --- progress --------------------------------------------------------------------------------------------


class Progress:
    """done/failed/ETA on stderr: one updating line on a terminal, else a line every 5 s and at the end."""

    def __init__(self, stream: TextIO, enabled: bool, total: int, skipped: int, failed_before: int = 0):
        self.stream, self.enabled, self.total, self.skipped = stream, enabled, total, skipped
        self.failed_before = failed_before
        self.tty = enabled and bool(getattr(stream, "isatty", lambda: False)())
        self.start = time.perf_counter()
        self.last = self.start
        self.done = self.failed = 0

    def line(self) -> str:
        dt = time.perf_counter() - self.start
        rate = self.done / dt if dt > 0 else 0.0
        text = f"{PROG}: batch: {self.done}/{self.total} done, {self.failed} failed"
        if self.skipped - self.failed_before:
            text += f", {self.skipped - self.failed_before} already done"
        if self.failed_before:
            text += f", {self.failed_before} failed before (run with --retry-failed to retry)"
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
                      ("highlights", "highlights"), ("footprint", "footprint"), ("framing", "framing"),
                      ("vignetting", "vignetting"), ("tone_curve", "tone"), ("lights", "lights")):
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


def _wants_help(argv: list[str] | None) -> bool:
    """``-h``/``--help`` anywhere before ``--``: ``rtloop-fit --batch --help`` prints the help (argparse
    would take --help for JOBS and fail)."""
    args = sys.argv[1:] if argv is None else argv
    head = args[:args.index("--")] if "--" in args else args
    return any(a in ("-h", "--help") for a in head)


def _main(argv: list[str] | None) -> int:
    parser = _build_parser()
    if _wants_help(argv):
        parser.print_help()
        return 0
    try:
        args = parser.parse_args(argv)
    except UsageError as e:
        _error(e)
        return 2
    except SystemExit as e:
        return int(e.code or 0)
    if args.processes and (args.ray is not None or args.warm_start):
        _error("--processes: not with --ray (it runs the jobs as Ray tasks)" if args.ray is not None else
               "--processes: not with --warm-start (it runs the jobs in order, in one process)")
        return 2
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
        with locked(out):
            return _run(args, jobs, out)
    except rtloop.RtloopError as e:
        _error(e)
        return 1
    except OSError as e:
        _error(f"{e.filename or out}: {e.strerror or e}")
        return 1


def _run(args: argparse.Namespace, jobs: list[Any], out: Path) -> int:
    """The batch, with the output folder locked."""
    recover_leftovers_in(out)  # the staged DIR/<id>/ of jobs a killed run had in flight
    check_targets(out, [j.id for j in jobs])
    results = Results(out / "results.jsonl")
    progress: Progress | None = None
    try:
        skip = results.skip(args.retry_failed)
        options = shared_options(_options(args))
        todo, _ = to_run(jobs, options, skip, warm_start=args.warm_start, fitted=results.fitted())
        todo_ids = {j.id for j, _ in todo}
        failed_before = sum(1 for j in jobs if j.id not in todo_ids and results.done[j.id].get("status") != "ok")
        engine = "ray" if args.ray is not None else "processes" if args.processes else "local"
        run = fit_many(jobs, engine, workers=args.workers, threads=args.threads, options=options,
                       out=out, images=not args.no_images, final_scale=args.final_scale,
                       final_spp=args.final_spp, snapshot_every=args.snapshot_every, skip=skip,
                       warm_start=args.warm_start, address=args.ray or None, max_retries=args.max_retries,
                       fitted=results.fitted())
        progress = Progress(sys.stderr, not args.quiet, len(todo), len(jobs) - len(todo), failed_before)
        for r in run:
            results.append(r.record())
            progress.update(r.ok)
        progress.finish(f"; results in {out / 'results.jsonl'}")
        return 1 if progress.failed or failed_before else 0
    except _Terminated:
        if progress is not None:
            progress.finish(" (terminated)")
        return 128 + signal.SIGTERM
    except KeyboardInterrupt:
        if progress is not None:
            progress.finish(" (interrupted; run again to resume)")
        return 130
    except rtloop.RtloopError as e:
        if progress is not None:
            progress.finish(" (stopped)")
        _error(e)
        return 1
    finally:
        results.close()
