"""The in-process engine: a pool of worker threads, each running whole fits with the GIL released, the
pool size and each fit's threads chosen together so that workers x threads = the cores."""

from __future__ import annotations

import os
from collections.abc import Iterator
from concurrent.futures import FIRST_COMPLETED, Future, ThreadPoolExecutor, wait
from typing import Any

from .._opencv import leave_stderr_alone
from .jobs import Job, JobResult, run_job

__all__ = ["cores", "plan", "run_local"]


def cores() -> int:
    """The cores this process may run on."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not Linux
        return os.cpu_count() or 1


def plan(workers: int | None, threads: int | None) -> tuple[int, int]:
    """(concurrent fits, threads per fit): by default one thread per fit and one fit per core (a small
    photo's fit gains little from a second thread; README "Many photos" has the measurement)."""
    n = cores()
    if workers is None and threads is None:
        return n, 1
    if workers is None:
        return max(1, n // threads), threads  # type: ignore[operator]
    if threads is None:
        return workers, max(1, n // workers)
    return workers, threads


def run_local(jobs: list[tuple[Job, str]], *, workers: int, threads: int, warm_start: bool,
              **kwargs: Any) -> Iterator[JobResult]:
    """Run ``(job, hash)`` pairs; yield results as they finish. With ``warm_start`` the jobs run one after
    another in order, each starting from the previous ok job's light. Leaving the iterator early (or
    Ctrl-C) cancels the jobs not yet started and waits for the running ones."""
    if warm_start:
        warm: dict[str, float] | None = None
        for job, digest in jobs:
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
