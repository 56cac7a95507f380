"""Many photos: :func:`fit_many` fits a batch of jobs in-process (:mod:`.local`), on worker processes
(:mod:`.processes`) or as Ray tasks (:mod:`.on_ray`), yielding each job's :class:`JobResult` as it
finishes; a job is :mod:`.jobs`."""

from __future__ import annotations

import os
from collections.abc import Iterable, Iterator, Mapping
from typing import Any

from ..errors import RtloopError
from .fields import check_options
from .jobs import Job, JobResult, as_job, job_hash, jobs_from, load_jobs, run_job
from .local import plan

__all__ = ["ENGINES", "Job", "JobResult", "as_job", "fit_many", "job_hash", "load_jobs", "run_job", "to_run"]

#: Where the jobs run: threads of this process, worker processes, or Ray tasks.
ENGINES = ("local", "processes", "ray")


def fit_many(
    jobs: Iterable[Any],
    engine: str = "local",
    *,
    workers: int | None = None,
    threads: int | None = None,
    options: Mapping[str, Any] | None = None,
    out: Any = None,
    images: bool = True,
    final_scale: int = 4,
    final_spp: int = 16,
    snapshot_every: int = 5,
    skip: Mapping[str, str] | None = None,
    warm_start: bool = False,
    warm_fraction: float = 0.1,
    address: str | None = None,
    max_retries: int = 3,
    fitted: Mapping[str, Mapping[str, float]] | None = None,
) -> Iterator[JobResult]:
    """Fit every job; an iterator of :class:`JobResult` in the order they finish.

    ``jobs``: :class:`Job` objects or dicts like a line of JOBS.jsonl (``id``, ``scene``, ``photo``,
    optional ``seed`` (default 0), ``mask``, and options of :func:`rtloop.fit`: ``protocol``,
    ``population``, ``generations``, ``norm``, ``space``, ... and of :func:`rtloop.load_image`:
    ``response``, ``crop``). ``options`` apply to every job (a job's own win). A job's result equals
    ``rtloop.fit`` with the same seed; a failing job gives status "error" and the batch goes on.

    ``engine="local"``: ``workers`` concurrent fits of ``threads`` threads each (default one thread per
    fit, one fit per core), threads of this process. ``engine="processes"``: the same plan on worker
    processes (no fit waits for another's Python: the faster where 3 or more fits run at once; each
    result's ``fit`` is None, as on Ray). ``engine="ray"``: one Ray task per job with ``num_cpus=threads`` (default 1)
    on the cluster at ``address`` (None: a running one if any, else a local Ray), retried up to
    ``max_retries`` times if its worker dies. ``out``: write each job's result.json (and, with
    ``images``, objective.png, final.png, best_per_generation.csv and snapshots/ every
    ``snapshot_every`` generations, as ``rtloop-fit`` does) into ``out``/<id>/. ``skip``: ``{id: hash}`` of jobs already
    done (see :func:`job_hash`), left out. ``warm_start`` (local only): the jobs run in order (frames of
    a video), each light search in bounds narrowed to +-``warm_fraction`` around the previous ok job's
    light; its hash covers the values it starts from, so a resumed chain (``fitted``: ``{id: x}`` of the
    jobs recorded as ok) goes on from the recorded frames as an uninterrupted run does (see :func:`to_run`).
    Every job, a :class:`Job` or a dict, is checked the same way (its id names a folder inside ``out``).
    """
    if engine not in ENGINES:
        raise RtloopError(f"fit_many: engine must be one of {', '.join(map(repr, ENGINES))}, got {engine!r}")
    if isinstance(snapshot_every, bool) or not isinstance(snapshot_every, int) or snapshot_every < 0:
        raise RtloopError(f"fit_many: snapshot_every must be a whole number >= 0, got {snapshot_every!r}")
    for name, v in (("workers", workers), ("threads", threads)):
        if v is not None and (isinstance(v, bool) or not isinstance(v, int) or v < 1):
            raise RtloopError(f"fit_many: {name} must be a whole number >= 1, got {v!r}")
    common = shared_options(options)
    checked = jobs_from(jobs)
    todo, warm = to_run(checked, common, skip, warm_start=warm_start, warm_fraction=warm_fraction, fitted=fitted)
    kwargs = {"options": common, "out": out, "images": images, "final_scale": final_scale,
              "final_spp": final_spp, "snapshot_every": snapshot_every}
    if engine == "ray":
        if warm_start:
            raise RtloopError("fit_many: warm_start runs the jobs in order, in-process: use engine='local'")
        from .on_ray import run_ray

        return run_ray(todo, address=address, threads=threads or 1, max_retries=max_retries, **kwargs)
    from .local import cores, run_local

    n_workers, n_threads = plan(workers, threads)
    if engine == "processes":
        if warm_start:
            raise RtloopError("fit_many: warm_start runs the jobs in order, in one process: use engine='local'")
        from .processes import run_processes

        if out is not None:
            kwargs["out"] = os.path.abspath(out)
        return run_processes(todo, workers=n_workers, threads=n_threads, **kwargs)
    if warm_start:
        n_workers, n_threads = 1, threads or cores()
    return run_local(todo, workers=n_workers, threads=n_threads, warm_start=warm_start,
                     warm_fraction=warm_fraction, warm=warm, **kwargs)


def shared_options(options: Mapping[str, Any] | None) -> dict[str, Any]:
    """The options every job shares, checked as a job's are (a seed is each job's own)."""
    if options is None:
        return {}
    if not isinstance(options, Mapping):
        raise RtloopError(f"fit_many: options must be a mapping of option names, got {type(options).__name__}")
    common = dict(options)
    if "seed" in common:
        raise RtloopError("fit_many: options: 'seed' is each job's own: give it in the jobs")
    return check_options(common, "fit_many: options")


def to_run(jobs: list[Job], common: dict[str, Any], skip: Mapping[str, str] | None, *, warm_start: bool = False,
           warm_fraction: float = 0.1, fitted: Mapping[str, Mapping[str, float]] | None = None
           ) -> tuple[list[tuple[Job, str | None]], dict[str, float] | None]:
    """The ``(job, hash)`` pairs to run (those ``skip`` does not record with the same hash) and, with
    ``warm_start``, the values the first starts from. A warm-started chain skips its recorded frames up to the
    first one to run, taking each recorded ok frame's ``fitted`` values on; the frames after that one run
    (their hashes, None here, depend on the values found before them)."""
    if not warm_start:
        pairs = [(job, job_hash(job, common)) for job in jobs]
        return [(j, h) for j, h in pairs if skip is None or skip.get(j.id) != h], None
    warm: dict[str, float] | None = None
    for i, job in enumerate(jobs):
        digest = job_hash(job, common, None if warm is None else (warm_fraction, warm))
        if skip is None or skip.get(job.id) != digest:
            return [(job, digest)] + [(j, None) for j in jobs[i + 1:]], warm
        if fitted is not None and isinstance(fitted.get(job.id), Mapping):
            warm = dict(fitted[job.id])
    return [], warm
