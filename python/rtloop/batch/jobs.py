"""One job of a batch: its parsed line (:class:`Job`), the hash of its inputs, and :func:`run_job`, which
loads, fits and (optionally) writes one job's outputs and returns a plain, picklable :class:`JobResult`."""

from __future__ import annotations

import hashlib
import json
import math
import os
import re
import shutil
import time
import warnings
from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from .._files import staging_dir
from ..errors import RtloopError

__all__ = ["FIT_OPTIONS", "Job", "JobResult", "as_job", "job_hash", "load_jobs", "run_job"]

#: Per-job options passed on to :func:`rtloop.fit` (``loss_space`` is the CLI's name for ``space``).
FIT_OPTIONS = ("protocol", "population", "generations", "f", "cr", "norm", "space", "optimizer", "polish",
               "clip", "uncertainty", "pixels_per_object", "environment", "interreflection",
               "highlights")
#: Per-job options of how the photo is read.
READ_OPTIONS = ("response", "crop")
_ALIASES = {"loss_space": "space", "image": "photo"}
_ID = re.compile(r"[A-Za-z0-9_+-][A-Za-z0-9._+-]{0,127}")


@dataclass(frozen=True)
class Job:
    """One photo to fit: ``id`` (also its output directory's name), the scene and photo paths, an optional
    seed and mask, and per-job options (:data:`FIT_OPTIONS`, ``response``, ``crop``)."""

    id: str
    scene: str
    photo: str
    seed: int = 0
    mask: str | None = None
    options: dict[str, Any] = field(default_factory=dict)

    def plain(self) -> dict[str, Any]:
        """The job as a JSON line's object."""
        d: dict[str, Any] = {"id": self.id, "scene": self.scene, "photo": self.photo, "seed": self.seed}
        if self.mask is not None:
            d["mask"] = self.mask
        return {**d, **self.options}


@dataclass
class JobResult:
    """What a job produced: ``status`` "ok" or "error" (then ``error`` holds the message), the fitted
    ``light`` (as in result.json), ``products`` and ``x``, the ``fitness``, and the job's ``seconds``.
    ``fit`` is the full FitResult for in-process jobs (None on Ray and for failed jobs)."""

    id: str
    status: str
    hash: str
    seed: int = 0
    light: dict[str, Any] | None = None
    products: dict[str, list[float]] | None = None
    x: dict[str, float] | None = None
    fitness: float | None = None
    evaluations: int | None = None
    error: str | None = None
    seconds: float = 0.0
    fit: Any = None

    @property
    def ok(self) -> bool:
        return self.status == "ok"

    def record(self) -> dict[str, Any]:
        """The line of results.jsonl (everything but ``fit``)."""
        from .._files import jsonable

        return jsonable({
            "id": self.id, "status": self.status, "hash": self.hash, "seed": self.seed, "light": self.light,
            "products": self.products, "x": self.x, "fitness": self.fitness, "evaluations": self.evaluations,
            "error": self.error, "seconds": round(self.seconds, 6),
        })


def as_job(item: Any, where: str = "job") -> Job:
    """A :class:`Job` from a Job or a dict (a line of JOBS.jsonl); ``where`` names it in errors."""
    if isinstance(item, Job):
        return item
    if not isinstance(item, dict):
        raise RtloopError(f"{where}: expected an object with id, scene and photo, got {type(item).__name__}")
    d = {_ALIASES.get(k, k): v for k, v in item.items()}
    for key in ("id", "scene", "photo"):
        if key not in d:
            raise RtloopError(f"{where}: missing '{key}'")
    jid = d.pop("id")
    if isinstance(jid, int) and not isinstance(jid, bool):
        jid = str(jid)
    if not isinstance(jid, str) or not _ID.fullmatch(jid):
        raise RtloopError(f"{where}: id {jid!r} must be 1-128 letters, digits, '_', '+', '-' or '.' "
                          "(not starting with '.'): it names the job's output directory")
    for key in ("scene", "photo", "mask"):
        if key in d and d[key] is not None and not isinstance(d[key], (str, os.PathLike)):
            raise RtloopError(f"{where}: '{key}' must be a path (a string)")
    seed = d.pop("seed", 0)
    if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
        raise RtloopError(f"{where}: 'seed' must be a whole number >= 0, got {seed!r}")
    scene, photo, mask = str(d.pop("scene")), str(d.pop("photo")), d.pop("mask", None)
    unknown = sorted(set(d) - set(FIT_OPTIONS) - set(READ_OPTIONS))
    if unknown:
        known = ", ".join(("id", "scene", "photo", "seed", "mask", *READ_OPTIONS, *FIT_OPTIONS))
        raise RtloopError(f"{where}: unknown field{'s' if len(unknown) > 1 else ''} "
                          f"{', '.join(map(repr, unknown))} (known: {known})")
    return Job(jid, scene, photo, seed, None if mask is None else str(mask), d)


def load_jobs(path: str | os.PathLike[str]) -> list[Job]:
    """The jobs of a JOBS.jsonl file (one JSON object a line; blank lines and lines starting with # skipped).
    Relative paths are taken relative to the file's directory. Ids must be unique."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as e:
        raise RtloopError(f"{path}: cannot read ({e.strerror or e})") from None
    except UnicodeDecodeError:
        raise RtloopError(f"{path}: not UTF-8 text") from None
    base = path.parent
    jobs: list[Job] = []
    seen: dict[str, int] = {}
    for n, line in enumerate(text.splitlines(), 1):
        if not line.strip() or line.lstrip().startswith("#"):
            continue
        where = f"{path}:{n}"
        try:
            item = json.loads(line)
        except json.JSONDecodeError as e:
            raise RtloopError(f"{where}: not JSON ({e.msg} at column {e.colno})") from None
        job = as_job(item, where)
        if job.id in seen:
            raise RtloopError(f"{where}: id {job.id!r} already used on line {seen[job.id]}")
        seen[job.id] = n

        def rel(p: str | None) -> str | None:
            return None if p is None else str(base / p) if not os.path.isabs(p) else p

        jobs.append(Job(job.id, rel(job.scene), rel(job.photo), job.seed, rel(job.mask), job.options))  # type: ignore[arg-type]
    return jobs


def _file_digest(h: Any, label: str, path: str | None) -> None:
    h.update(label.encode() + b"\0")
    if path is None:
        h.update(b"none\0")
        return
    try:
        with open(path, "rb") as fh:
            h.update(b"file\0")
            for chunk in iter(lambda: fh.read(1 << 20), b""):
                h.update(chunk)
    except OSError as e:
        h.update(f"unreadable:{e.errno}\0".encode())


def job_hash(job: Job, common: dict[str, Any] | None = None) -> str:
    """SHA-256 (hex, 16 digits) of what decides a job's result: the scene, photo and mask files' bytes, the
    seed and the options (the job's over ``common``). A re-run skips a job whose id and hash are recorded."""
    h = hashlib.sha256(b"rtloop-batch-1\0")
    _file_digest(h, "scene", job.scene)
    _file_digest(h, "photo", job.photo)
    _file_digest(h, "mask", job.mask)
    options = {**(common or {}), **job.options, "seed": job.seed}
    h.update(json.dumps(options, sort_keys=True, default=str).encode())
    return h.hexdigest()[:16]


def _light(scene: Any) -> dict[str, Any]:
    from ..scene import scene_to_dict

    return scene_to_dict(scene)["light"]


def run_job(job: Job, *, threads: int | None = None, options: dict[str, Any] | None = None,
            out: str | os.PathLike[str] | None = None, images: bool = True, final_scale: int = 4,
            final_spp: int = 16, snapshot_every: int = 5, keep_fit: bool = True, hash: str | None = None,
            warm: dict[str, float] | None = None, warm_fraction: float = 0.1) -> JobResult:
    """Load and fit one job (``options`` under the job's own) on ``threads`` threads; with ``out``, write
    its outputs into ``out``/<id>/ as ``rtloop-fit`` does (staged, moved into place whole): result.json
    and, with ``images``, objective.png, final.png, best_per_generation.csv and a snapshot every
    ``snapshot_every`` generations (the last two need a callback per generation: ``images`` False keeps
    the search free of the GIL).
    ``warm`` (fit values by name, e.g. the previous frame's) starts the search for the light's position (or
    direction) in bounds narrowed to +-``warm_fraction`` of their range around it. A failure (RtloopError,
    an unreadable file, a bad option) becomes a result with status "error"; other exceptions propagate."""
    import rtloop

    t0 = time.perf_counter()
    digest = hash if hash is not None else job_hash(job, options)
    opts = {**(options or {}), **job.options}
    read = {k: opts.pop(k) for k in READ_OPTIONS if k in opts}
    staged: Path | None = None
    try:
        scene = rtloop.load_scene(job.scene)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            image = rtloop.load_image(job.photo, scene, **read)
            mask = None if job.mask is None else rtloop.load_mask(job.mask, scene, crop=read.get("crop", False))
        if warm:
            scene = _warm_scene(scene, warm, warm_fraction)
        log = None
        if out is not None:
            from ..cli.outputs import GenerationLog

            staged = staging_dir(Path(out) / job.id, "rtloop-tmp")
            if images:
                log = GenerationLog(staged, scene, snapshot_every)
        try:
            result = rtloop.fit(scene, image, seed=job.seed, threads=threads, mask=mask, callback=log, **opts)
        finally:
            if log is not None:
                log.close()
        if warm:
            from ..fit.bounds import restore_bounds

            result.scene = restore_bounds(result.scene, rtloop.load_scene(job.scene))
        if staged is not None:
            _write_outputs(staged, Path(out), job, result, image, read, images, final_scale, final_spp)  # type: ignore[arg-type]
        return JobResult(job.id, "ok", digest, job.seed, light=_light(result.scene), products=result.products,
                         x=result.x, fitness=result.fitness, evaluations=result.evaluations,
                         seconds=time.perf_counter() - t0, fit=result if keep_fit else None)
    except (RtloopError, OSError, TypeError, ValueError) as e:
        return JobResult(job.id, "error", digest, job.seed, error=_message(job, e),
                         seconds=time.perf_counter() - t0)
    finally:
        if staged is not None and os.path.lexists(staged):
            shutil.rmtree(staged, ignore_errors=True)


def _message(job: Job, e: BaseException) -> str:
    if isinstance(e, OSError) and e.filename:
        return f"{e.filename}: {e.strerror or e}"
    text = " ".join(str(e).split())
    if isinstance(e, TypeError):  # a per-job option of the wrong kind, as rtloop.fit reports it
        return f"job {job.id}: bad option: {text}"
    return text


def _warm_scene(scene: Any, warm: dict[str, float], fraction: float) -> Any:
    """``scene`` with its light's position (or direction) set to ``warm`` and its bounds narrowed around it."""
    from ..fit.bounds import narrowed

    # the light's geometry only: its intensity (and colour) trade off against the albedos, and the fit
    # splits those products inside the scene's own bounds
    paths = [p for p in scene.fit_paths if p in ("light.position", "light.direction")]
    names = scene.param_names(paths)
    if not paths or any(n not in warm for n in names):
        return scene
    lo_hi = [b for p in paths for b in scene.bounds([p])]
    values = [min(max(warm[n], lo), hi) for n, (lo, hi) in zip(names, lo_hi)]
    if not all(math.isfinite(v) for v in values):
        return scene
    return narrowed(scene.with_params(values, paths), paths, fraction)


def _write_outputs(tmp: Path, out: Path, job: Job, result: Any, image: Any, read: dict[str, Any],
                   images: bool, scale: int, spp: int) -> None:
    """Complete the staged ``tmp`` with result.json (and objective.png, final.png) and move it into place
    as ``out``/<id>/ (replacing an older one)."""
    from .._files import move_into_place
    from ..cli.outputs import input_paths, write_final, write_result

    target = out / job.id
    write_result(tmp, result, input_paths(job.scene, job.photo, read.get("response", "srgb"),
                                          read.get("crop", False), job.mask))
    if images:
        write_final(tmp, result, image, scale, spp)
    move_into_place(tmp, target, os.path.lexists(target), "rtloop")


def jobs_from(items: Iterable[Any]) -> list[Job]:
    """Jobs from Job objects or dicts, checked (unique ids)."""
    jobs, seen = [], set()
    for i, item in enumerate(items):
        job = as_job(item, f"job {i}")
        if job.id in seen:
            raise RtloopError(f"job {i}: id {job.id!r} used twice")
        seen.add(job.id)
        jobs.append(job)
    return jobs
