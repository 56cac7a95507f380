"""The Ray engine: one task per job (``num_cpus`` = the fit's threads), the native objects built inside
the task from the job's plain fields, results collected with ``ray.wait`` as they finish, a task whose
worker dies retried ``max_retries`` times."""

from __future__ import annotations

import os
from collections.abc import Callable, Iterator
from typing import Any

from ..errors import RtloopError
from .jobs import Job, JobResult
from .worker import plain_job as _plain
from .worker import run_plain as _task

__all__ = ["RAY_HINT", "run_ray"]

RAY_HINT = "Ray is not installed: pip install 'rtloop[ray]' (or pip install 'ray>=2.9')"


#: How long a cluster's address may take to accept a connection before the batch gives up.
CONNECT_TIMEOUT_S = 10.0


def _probe(address: str | None) -> None:
    """Refuse at once, in one line, a ``host:port`` (or ``ray://host:port``) address where nothing accepts a
    TCP connection within CONNECT_TIMEOUT_S: ray.init would retry for many minutes without a word."""
    import socket
    from urllib.parse import urlsplit

    if not address or address == "auto":
        return
    try:
        parts = urlsplit(address if "://" in address else f"tcp://{address}")
        host, port = parts.hostname, parts.port
    except ValueError:
        raise RtloopError(f"ray: {address!r} is not an address (host:port)") from None
    if host is None or port is None:
        return
    try:
        socket.create_connection((host, port), timeout=CONNECT_TIMEOUT_S).close()
    except OSError as e:
        why = "no answer" if isinstance(e, TimeoutError) else (e.strerror or str(e))
        raise RtloopError(f"ray: cannot connect to the cluster at {address} ({why} within "
                          f"{CONNECT_TIMEOUT_S:g} s)") from None


def run_ray(jobs: list[tuple[Job, str]], *, address: str | None, threads: int, max_retries: int,
            task: Callable[..., JobResult] = _task, **kwargs: Any) -> Iterator[JobResult]:
    """Run ``(job, hash)`` pairs as Ray tasks; yield results as they finish. Connects to the cluster at
    ``address`` unless Ray is already initialised (None: a running cluster if ``RAY_ADDRESS`` names one,
    else a local Ray). Paths in the jobs must be readable on the workers (a shared filesystem), and so
    must ``out``. ``task`` is the function run per job (tests replace it)."""
    try:
        import ray
    except ImportError:
        raise RtloopError(f"engine='ray': {RAY_HINT}") from None
    if not ray.is_initialized():
        _probe(address)
        try:
            ray.init(address=address or None, logging_level="warning", log_to_driver=False)
        except ConnectionError as e:
            raise RtloopError(f"ray: cannot connect to the cluster at {address!r}: {e}") from None
    if kwargs.get("out") is not None:
        kwargs = {**kwargs, "out": os.path.abspath(kwargs["out"])}
    remote = ray.remote(task).options(num_cpus=threads, max_retries=max_retries, retry_exceptions=False)
    return _collect(ray, remote, jobs, threads, kwargs)


def _collect(ray: Any, remote: Any, jobs: list[tuple[Job, str]], threads: int,
             kwargs: dict[str, Any]) -> Iterator[JobResult]:
    # Keep a few tasks per CPU in flight: enough to keep the cluster busy, few enough that the driver
    # does not hold a huge batch's references at once.
    cpus = max(1, int(ray.cluster_resources().get("CPU", 1)))
    limit = max(4, 4 * cpus // threads)
    queue = iter(jobs)
    which: dict[Any, tuple[Job, str]] = {}
    kw = ray.put(kwargs)

    def submit() -> bool:
        nxt = next(queue, None)
        if nxt is None:
            return False
        which[remote.remote(_plain(nxt[0]), nxt[1], threads, kw)] = nxt
        return True

    try:
        while len(which) < limit and submit():
            pass
        while which:
            ready, _ = ray.wait(list(which), num_returns=1, timeout=0.5)
            for ref in ready:
                job, digest = which.pop(ref)
                try:
                    yield ray.get(ref)
                except ray.exceptions.RayError as e:  # the worker died more than max_retries times
                    first = str(e).strip().splitlines()[0] if str(e).strip() else type(e).__name__
                    yield JobResult(job.id, "error", digest, job.seed, error=f"ray: {first}")
                submit()
    finally:
        # Closed early (Ctrl-C, a consumer that stops): the tasks in flight (at most ``limit``) are left to
        # finish or to end with the driver, which Ray does for a driver that exits. They are not cancelled:
        # ray.cancel racing a task's completion aborts the driver inside Ray ("Tried to complete task that
        # was not pending", ray-project/ray#54738), and a task finishing late only writes a complete
        # DIR/<id>/ that results.jsonl does not list, which a resumed batch fits again.
        which.clear()
