"""One job of a batch: its parsed line (:class:`Job`), the hash of its inputs, and :func:`run_job`, which
loads, fits and (optionally) writes one job's outputs and returns a plain, picklable :class:`JobResult`."""

from __future__ import annotations

import hashlib
import json
import math
import os
import shutil
import stat
import time
from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from .._files import staging_dir
from ..errors import RtloopError
from ..fit.files import SCENE_CARD, fit_inputs, load_inputs, referenced
from ..fit.lights import LightsFit
from .fields import FIT_OPTIONS, READ_OPTIONS, check_id, check_options, check_path, check_seed
from .folder import mark, may_replace

__all__ = ["FIT_OPTIONS", "Job", "JobResult", "as_job", "job_hash", "load_jobs", "run_job"]

_ALIASES = {"loss_space": "space", "image": "photo"}
#: The most bytes of a JOBS file read.
MAX_JOBS_FILE = 1 << 30


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
    A lights fit's job (the ``lights`` option, or a scene with a ``lights`` list) records ``lights`` (each
    light with its error bars, as result.json's ``fit_report.lights``) and its ``products`` (per object, per
    light then the constant term, RGB); its ``light``, ``x`` and ``fitness`` are None.
    ``fit`` is the full FitResult (or LightsFit) for in-process jobs (None on Ray and for failed jobs)."""

    id: str
    status: str
    hash: str
    seed: int = 0
    light: dict[str, Any] | None = None
    products: dict[str, Any] | None = None
    x: dict[str, float] | None = None
    fitness: float | None = None
    evaluations: int | None = None
    error: str | None = None
    seconds: float = 0.0
    lights: list[dict[str, Any]] | None = None
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
            **({"lights": self.lights} if self.lights is not None else {}),
        })


def as_job(item: Any, where: str = "job") -> Job:
    """A :class:`Job` from a Job or a dict (a line of JOBS.jsonl), every field checked the same way for
    both; ``where`` names it in errors."""
    if isinstance(item, Job):
        item = {"id": item.id, "scene": item.scene, "photo": item.photo, "seed": item.seed, "mask": item.mask,
                **(item.options if isinstance(item.options, dict) else {"options": item.options})}
    if not isinstance(item, dict):
        raise RtloopError(f"{where}: expected an object with id, scene and photo, got {type(item).__name__}")
    d = {_ALIASES.get(k, k): v for k, v in item.items()}
    for key in ("id", "scene", "photo"):
        if key not in d:
            raise RtloopError(f"{where}: missing '{key}'")
    jid = check_id(d.pop("id"), where)
    scene, photo = check_path(d.pop("scene"), where, "scene"), check_path(d.pop("photo"), where, "photo")
    mask = check_path(d.pop("mask", None), where, "mask", optional=True)
    seed = check_seed(d.pop("seed", 0), where)
    return Job(jid, scene, photo, seed, mask, check_options(d, where))  # type: ignore[arg-type]


def _no_duplicates(pairs: list[tuple[str, Any]]) -> dict[str, Any]:
    d: dict[str, Any] = {}
    for k, v in pairs:
        if k in d:
            raise RtloopError(f"field {k[:60]!r} given twice")
        d[k] = v
    return d


def parse_line(line: str, where: str) -> Any:
    """One JSON line: duplicate fields, nesting past Python's limit and huge numbers are one line each."""
    try:
        return json.loads(line, object_pairs_hook=_no_duplicates)
    except json.JSONDecodeError as e:
        raise RtloopError(f"{where}: not JSON ({e.msg} at column {e.colno})") from None
    except RtloopError as e:
        raise RtloopError(f"{where}: {e}") from None
    except RecursionError:
        raise RtloopError(f"{where}: not JSON this program reads (nested too deep)") from None
    except ValueError as e:  # a number past Python's digit limit
        raise RtloopError(f"{where}: not JSON this program reads ({' '.join(str(e).split())[:100]})") from None


def _read_jobs_file(path: Path) -> str:
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK | os.O_CLOEXEC)
    except OSError as e:
        raise RtloopError(f"{path}: cannot read ({e.strerror or e})") from None
    try:
        info = os.fstat(fd)
        if not stat.S_ISREG(info.st_mode):
            raise RtloopError(f"{path}: not a regular file")
        if info.st_size > MAX_JOBS_FILE:
            raise RtloopError(f"{path}: larger than {MAX_JOBS_FILE} bytes")
        with os.fdopen(os.dup(fd), "rb") as fh:
            data = fh.read(MAX_JOBS_FILE + 1)
    except OSError as e:
        raise RtloopError(f"{path}: cannot read ({e.strerror or e})") from None
    finally:
        os.close(fd)
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError:
        raise RtloopError(f"{path}: not UTF-8 text") from None


def load_jobs(path: str | os.PathLike[str]) -> list[Job]:
    """The jobs of a JOBS.jsonl file (one JSON object a line; blank lines and lines starting with # skipped).
    Relative paths are taken relative to the file's directory. Ids must be unique."""
    path = Path(path)
    text = _read_jobs_file(path)
    base = path.parent
    jobs: list[Job] = []
    seen: dict[str, int] = {}
    for n, line in enumerate(text.splitlines(), 1):
        if not line.strip() or line.lstrip().startswith("#"):
            continue
        where = f"{path}:{n}"
        job = as_job(parse_line(line, where), where)
        if job.id in seen:
            raise RtloopError(f"{where}: id {job.id!r} already used on line {seen[job.id]}")
        seen[job.id] = n

        def rel(p: str | None) -> str | None:
            return None if p is None else str(base / p) if not os.path.isabs(p) else p

        options = dict(job.options)
        if isinstance(options.get("grey_card"), dict):
            options["grey_card"] = {**options["grey_card"], "mask": rel(options["grey_card"]["mask"])}
        jobs.append(Job(job.id, rel(job.scene), rel(job.photo), job.seed, rel(job.mask), options))  # type: ignore[arg-type]
    return jobs


def _file_digest(h: Any, label: str, path: str | None) -> None:
    """Feed ``path``'s bytes to ``h``; a file that is not a regular one (a FIFO, a device) is not read."""
    h.update(label.encode() + b"\0")
    if path is None:
        h.update(b"none\0")
        return
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK | os.O_CLOEXEC)
    except OSError as e:
        h.update(f"unreadable:{e.errno}\0".encode())
        return
    try:
        if not stat.S_ISREG(os.fstat(fd).st_mode):
            h.update(b"not-a-regular-file\0")
            return
        h.update(b"file\0")
        for chunk in iter(lambda: os.read(fd, 1 << 20), b""):
            h.update(chunk)
    except OSError as e:
        h.update(f"unreadable:{e.errno}\0".encode())
    finally:
        os.close(fd)


def _card(options: dict[str, Any]) -> Any:
    """A job's ``grey_card`` option as :func:`rtloop.fit.files.load_inputs` takes it."""
    if "grey_card" not in options:
        return SCENE_CARD
    card = options["grey_card"]
    return None if not card else (card["mask"], card["reflectance"])


def job_hash(job: Job, common: dict[str, Any] | None = None,
             warm: tuple[float, dict[str, float]] | None = None) -> str:
    """SHA-256 (hex, 16 digits) of what decides a job's result: the bytes of the scene, the photo, the mask
    and grey card the fit reads (given, or the ones the scene names), the seed, the options (the job's over
    ``common``) and, for a warm-started job, the fraction and the values it starts from. A re-run skips a job
    whose id and hash are recorded."""
    h = hashlib.sha256(b"rtloop-batch-2\0")
    options = {**(common or {}), **job.options, "seed": job.seed}
    _file_digest(h, "scene", job.scene)
    _file_digest(h, "photo", job.photo)
    try:
        mask, card = referenced(job.scene, job.mask, _card(options))
    except RtloopError as e:
        h.update(f"unresolved:{e}\0".encode())
        mask, card = job.mask, None
    _file_digest(h, "mask", mask)
    _file_digest(h, "card", None if card is None else card[0])
    h.update(json.dumps(options, sort_keys=True, default=str).encode())
    if warm is not None:
        h.update(b"warm\0" + json.dumps([warm[0], warm[1]], sort_keys=True).encode())
    return h.hexdigest()[:16]


def _light(scene: Any) -> dict[str, Any]:
    from ..scene import scene_to_dict

    return scene_to_dict(scene)["light"]


def run_job(job: Job, *, threads: int | None = None, options: dict[str, Any] | None = None,
            out: str | os.PathLike[str] | None = None, images: bool = True, final_scale: int = 4,
            final_spp: int = 16, snapshot_every: int = 5, keep_fit: bool = True, hash: str | None = None,
            warm: dict[str, float] | None = None, warm_fraction: float = 0.1) -> JobResult:
    """Load and fit one job (``options`` under the job's own) on ``threads`` threads, by the path a single
    ``rtloop-fit`` takes (:mod:`rtloop.fit.files`: the mask and grey card the scene names unless the job
    gives its own); with ``out``, write its outputs into ``out``/<id>/ as ``rtloop-fit`` does (staged, moved
    into place whole, marked as the batch's; a folder there the batch did not write is never replaced):
    result.json and, with ``images``, objective.png, final.png, best_per_generation.csv and a snapshot every
    ``snapshot_every`` generations (the last two need a callback per generation: ``images`` False keeps
    the search free of the GIL).
    ``warm`` (fit values by name, e.g. the previous frame's) starts the search for the light's position (or
    direction) in bounds narrowed to +-``warm_fraction`` of their range around it. A failure (RtloopError,
    an unreadable file, a bad option) becomes a result with status "error"; other exceptions propagate."""
    t0 = time.perf_counter()
    digest = hash if hash is not None else job_hash(job, options)
    opts = {**(options or {}), **job.options}
    read = {k: opts.pop(k) for k in READ_OPTIONS if k in opts}
    card = _card(read)
    read.pop("grey_card", None)
    staged: Path | None = None
    try:
        if out is not None:
            may_replace(Path(out) / job.id)
        inputs = load_inputs(job.scene, job.photo, mask=job.mask, grey_card=card, **read)
        cold = inputs.scene
        several = opts.get("lights") not in (None, 1) or "lights" in inputs.scene.to_dict()
        if warm:
            inputs.scene = _warm_scene(inputs.scene, warm, warm_fraction)
        log = None
        if out is not None:
            from ..cli.outputs import GenerationLog

            staged = staging_dir(Path(out) / job.id, "rtloop-tmp")
            if images and not several:  # the lights fit logs no generations
                log = GenerationLog(staged, inputs.scene, snapshot_every)
        try:
            result = fit_inputs(inputs, seed=job.seed, threads=threads, callback=log, **opts)
        finally:
            if log is not None:
                log.close()
        if isinstance(result, LightsFit) and log is not None:  # the default fit kept a further light
            from ..cli.outputs import set_aside_one_light_log

            set_aside_one_light_log(staged)  # type: ignore[arg-type]
        several = several or isinstance(result, LightsFit)
        if warm:
            from ..fit.bounds import restore_bounds

            result.scene = restore_bounds(result.scene, cold)
        if several:
            return _lights_result(job, digest, result, inputs, staged, out, images, final_scale, final_spp, opts,
                                  keep_fit, t0)
        if staged is not None:
            _write_outputs(staged, Path(out), job, result, inputs, read, images, final_scale, final_spp)  # type: ignore[arg-type]
        return JobResult(job.id, "ok", digest, job.seed, light=_light(result.scene), products=result.products,
                         x=result.x, fitness=result.fitness, evaluations=result.evaluations,
                         seconds=time.perf_counter() - t0, fit=result if keep_fit else None)
    except (RtloopError, OSError, TypeError, ValueError, OverflowError) as e:
        return JobResult(job.id, "error", digest, job.seed, error=_message(job, e),
                         seconds=time.perf_counter() - t0)
    finally:
        if staged is not None and os.path.lexists(staged):
            shutil.rmtree(staged, ignore_errors=True)


def _lights_result(job: Job, digest: str, fit: Any, inputs: Any, staged: Path | None, out: Any, images: bool,
                   scale: int, spp: int, opts: dict[str, Any], keep_fit: bool, t0: float) -> JobResult:
    """A lights fit's job: its outputs written as ``rtloop-fit --lights`` writes them, and its record."""
    from .._files import move_into_place
    from ..cli.lights import lights_document, write_lights

    asked = opts.get("lights")
    if staged is not None:
        write_lights(staged, fit, inputs.image, asked=asked, seed=job.seed, final_scale=scale, final_spp=spp,
                     images=images)
        mark(staged)
        target = Path(out) / job.id
        move_into_place(staged, target, may_replace(target), "rtloop")
    report = lights_document(fit, asked=asked, seed=job.seed)["fit_report"]
    return JobResult(job.id, "ok", digest, job.seed, products=report["products"], evaluations=fit.evaluations,
                     seconds=time.perf_counter() - t0, lights=report["lights"], fit=fit if keep_fit else None)


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


def _write_outputs(tmp: Path, out: Path, job: Job, result: Any, inputs: Any, read: dict[str, Any],
                   images: bool, scale: int, spp: int) -> None:
    """Complete the staged ``tmp`` with result.json (and objective.png, final.png), mark it as the batch's
    and move it into place as ``out``/<id>/ (replacing an older one the batch wrote)."""
    from .._files import move_into_place
    from ..cli.outputs import input_paths, write_final, write_result

    target = out / job.id
    write_result(tmp, result, input_paths(job.scene, job.photo, read.get("response", "srgb"),
                                          read.get("crop", False), inputs.mask_path))
    if images:
        reframed = getattr(result, "reframed", None)  # framing="correct": the photo as the fit saw it
        write_final(tmp, result, inputs.image if reframed is None else reframed[0], scale, spp)
    mark(tmp)
    move_into_place(tmp, target, may_replace(target), "rtloop")


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
