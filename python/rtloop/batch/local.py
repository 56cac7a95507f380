"""The in-process engine: a pool of worker threads, each running whole fits with the GIL released, the
pool size and each fit's threads (its rayon pool and numpy's BLAS) chosen together so that workers x
threads = the cores."""

from __future__ import annotations

import os
from collections.abc import Iterator
from concurrent.futures import FIRST_COMPLETED, Future, ThreadPoolExecutor, wait
from contextlib import AbstractContextManager
from functools import cache
from typing import Any

from .._opencv import leave_stderr_alone
from .jobs import Job, JobResult, job_hash, run_job

__all__ = ["blas_threads", "cores", "plan", "run_local"]


def cores() -> int:
    """The cores this process may run on."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not Linux
        return os.cpu_count() or 1


@cache
def _blas() -> Any:
    from threadpoolctl import ThreadpoolController

    return ThreadpoolController()  # finds the loaded BLAS once (0.6 ms a look)


def blas_threads(n: int) -> AbstractContextManager[Any]:
    """numpy's BLAS on ``n`` threads while inside (process-wide; as before on leaving)."""
    return _blas().limit(limits=n, user_api="blas")


def plan(workers: int | None, threads: int | None) -> tuple[int, int]:
    """(concurrent fits, threads per fit): by default one thread per fit and one fit per core (a small
    photo's fit gains little from a second thread; docs/batch.md has the measurement)."""
    n = cores()
    if workers is None and threads is None:
        return n, 1
    if workers is None:
        return max(1, n // threads), threads  # type: ignore[operator]
    if threads is None:
        return workers, max(1, n // workers)
    return workers, threads


def run_local(jobs: list[tuple[Job, str | None]], *, workers: int, threads: int, warm_start: bool,
              **kwargs: Any) -> Iterator[JobResult]:
    """Run ``(job, hash)`` pairs; yield results as they finish. With ``warm_start`` the jobs run one after
    another in order, each starting from the previous ok job's light (the first from ``warm``; a hash None is
    the job's with the values it starts from). Leaving the iterator early (or
    Ctrl-C) cancels the jobs not yet started and waits for the running ones. numpy's BLAS runs on
    ``threads`` threads meanwhile (process-wide): its idle threads spin, and with a fit per core the spin
    cost up to a fifth of the batch's CPU time (docs/batch.md)."""
    with blas_threads(threads):
        yield from _run(jobs, workers=workers, threads=threads, warm_start=warm_start, **kwargs)


def _run(jobs: list[tuple[Job, str | None]], *, workers: int, threads: int, warm_start: bool,
         warm: dict[str, float] | None = None, **kwargs: Any) -> Iterator[JobResult]:
    if warm_start:
        fraction = kwargs["warm_fraction"]
        for job, digest in jobs:
            if digest is None:
                digest = job_hash(job, kwargs["options"], None if warm is None else (fraction, warm))
            r = run_job(job, threads=threads, hash=digest, warm=warm, **kwargs)
            if r.ok:
                warm = r.x
            yield r
        return
    pool = ThreadPoolExecutor(max_workers=workers, thread_name_prefix="rtloop-batch",
                              initializer=leave_stderr_alone)  # the progress line shares fd 2
    try:
        pending: set[Future[JobResult]] = set()
        queue = iter(jobs)
        # Keep at most 2 x workers submitted, so a huge batch is not all queued up front.
        for job, digest in queue:
            pending.add(pool.submit(run_job, job, threads=threads, hash=digest, **kwargs))
            if len(pending) >= 2 * workers:
                break
        while pending:
            done, pending = wait(pending, timeout=0.2, return_when=FIRST_COMPLETED)
            for f in done:
                yield f.result()
                nxt = next(queue, None)
                if nxt is not None:
                    pending.add(pool.submit(run_job, nxt[0], threads=threads, hash=nxt[1], **kwargs))
    finally:
        pool.shutdown(wait=True, cancel_futures=True)
