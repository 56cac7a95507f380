"""The process engine: a pool of worker processes, each running whole fits, so that no fit waits for
another's Python (a fit holds the GIL for about 40 % of its time: threads in one process run at most about
2.5 fits' worth at once, whatever the cores; docs/batch.md). Workers fork from a server that has imported
rtloop once (``forkserver``; ``spawn`` where there is none), ignore Ctrl-C (the batch asks them to stop:
the running jobs finish, the queued ones are cancelled) and return plain results (``JobResult.fit`` None)."""

from __future__ import annotations

import multiprocessing
import signal
from collections.abc import Callable, Iterator
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from typing import Any

from .jobs import Job, JobResult
from .worker import plain_job, run_plain

__all__ = ["run_processes"]

#: What each worker imports once, before it forks for the pool (the fit and its files).
PRELOAD = ["rtloop", "rtloop.batch.worker"]


def _context() -> multiprocessing.context.BaseContext:
    """A start method without fork's hazards (a parent's threads, the renderer's pool among them, do not
    survive a fork): the fork server, where there is one, started with rtloop imported."""
    if "forkserver" in multiprocessing.get_all_start_methods():
        ctx = multiprocessing.get_context("forkserver")
        ctx.set_forkserver_preload(PRELOAD)
        return ctx
    return multiprocessing.get_context("spawn")


def _ignore_interrupt() -> None:
    """A worker's initializer: Ctrl-C reaches the whole process group, and the batch, not each worker,
    decides what stops."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)


def run_processes(jobs: list[tuple[Job, str]], *, workers: int, threads: int,
                  task: Callable[..., JobResult] = run_plain, **kwargs: Any) -> Iterator[JobResult]:
    """Run ``(job, hash)`` pairs on ``workers`` processes of ``threads`` threads each; yield results as they
    finish. A worker that dies (killed, out of memory) fails the jobs it had in flight, each with a
    one-line error, and a new pool takes the rest. Leaving the iterator early (or Ctrl-C) cancels the jobs
    not yet started and waits for the running ones. ``task``: the function run per job, importable by the
    workers (tests replace it)."""
    queue = iter(jobs)
    pool = ProcessPoolExecutor(max_workers=workers, mp_context=_context(), initializer=_ignore_interrupt)
    pending: dict[Future[JobResult], tuple[Job, str]] = {}

    def submit() -> bool:
        nxt = next(queue, None)
        if nxt is None:
            return False
        pending[pool.submit(task, plain_job(nxt[0]), nxt[1], threads, kwargs)] = nxt
        return True

    try:
        # Keep at most 2 x workers submitted, so a huge batch is not all queued up front.
        while len(pending) < 2 * workers and submit():
            pass
        while pending:
            done, _ = wait(pending, timeout=0.2, return_when=FIRST_COMPLETED)
            broken = False
            for f in done:
                job, digest = pending.pop(f)
                try:
                    yield f.result()
                except BrokenProcessPool as e:
                    broken = True
                    why = " ".join(str(e).split()) or "a worker process ended abruptly"
                    yield JobResult(job.id, "error", digest, job.seed, error=f"processes: {why}")
            if broken:  # every future of a broken pool fails: start a new one for the jobs not yet run
                retry = list(pending.values())
                pending.clear()
                pool.shutdown(wait=True, cancel_futures=True)
                pool = ProcessPoolExecutor(max_workers=workers, mp_context=_context(),
                                           initializer=_ignore_interrupt)
                queue = iter(retry + list(queue))
            while len(pending) < 2 * workers and submit():
                pass
    finally:
        pool.shutdown(wait=True, cancel_futures=True)
