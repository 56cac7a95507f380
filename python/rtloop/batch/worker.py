"""A job run in another process (a Ray task, a worker of the process pool): the job's plain fields in, its
paths made absolute by the caller, a plain JobResult out (no FitResult: it holds native objects)."""

from __future__ import annotations

import os
from typing import Any

from .jobs import Job, JobResult, run_job
from .local import blas_threads

__all__ = ["plain_job", "run_plain"]


def run_plain(job: dict[str, Any], digest: str, threads: int, kwargs: dict[str, Any]) -> JobResult:
    """One job from its plain fields (:func:`plain_job`), numpy's BLAS on ``threads`` meanwhile (a worker
    process is not started with OMP_NUM_THREADS)."""
    with blas_threads(threads):
        return run_job(Job(**job), threads=threads, hash=digest, keep_fit=False, **kwargs)


def plain_job(job: Job) -> dict[str, Any]:
    """The job's fields for another process, its paths made absolute here (a worker's working directory is
    not necessarily the caller's)."""
    options = dict(job.options)
    if isinstance(options.get("grey_card"), dict):
        options["grey_card"] = {**options["grey_card"], "mask": os.path.abspath(options["grey_card"]["mask"])}
    return {"id": job.id, "scene": os.path.abspath(job.scene), "photo": os.path.abspath(job.photo),
            "seed": job.seed, "mask": None if job.mask is None else os.path.abspath(job.mask),
            "options": options}
