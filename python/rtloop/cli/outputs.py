"""The files one fit leaves in its output directory (result.json, best_per_generation.csv, snapshots/,
objective.png, final.png), written by ``rtloop-fit`` and by every job of a batch (``rtloop-fit --batch``)."""

from __future__ import annotations

import csv
import os
import re
from pathlib import Path
from typing import Any, Self

import numpy as np

import rtloop
from rtloop import _native
from rtloop._files import write_json
from rtloop.acquisition.raw import is_raw, raw_settings
from rtloop.uncertainty.bootstrap import replicate_of

__all__ = ["GenerationLog", "input_paths", "render_final", "result_json", "set_aside_one_light_log", "write_final",
           "write_result"]

_SAFE_NAME = re.compile(r"[^A-Za-z0-9_+-]+")

#: Most pixels of snapshots GenerationLog renders in one pass (their float32 images are held together).
_SNAPSHOT_PIXELS = 1 << 22


def result_json(result: Any, inputs: dict[str, Any]) -> dict[str, Any]:
    """result.json's content: the fitted scene in the scene format plus ``fit_report`` (with ``inputs``)."""
    report = result.report()
    report["inputs"] = inputs
    data = rtloop.scene_to_dict(result.scene)
    data["fit_report"] = report
    return data


def write_result(out: Path, result: Any, inputs: dict[str, Any]) -> None:
    """Write ``out``/result.json."""
    write_json(out / "result.json", result_json(result, inputs))


def render_final(scene: Any, scale: int, spp: int) -> np.ndarray:
    """final.png's image: ``scene`` at ``scale`` times its size, with ``spp`` samples in each pixel that
    has an edge (another object, a shadow's border) or where the colour bends, and the centre sample
    elsewhere (on a linear ramp, the pixel's average). Within a fraction of an 8-bit step of the uniform
    ``spp`` render for a few times less work (tests/test_outputs.py holds it to a many-sample render)."""
    width, height = scene.width * scale, scene.height * scale
    (image,), _, _ = _native.render_layers([scene], width, height, spp, spp > 1, 0, None, "curvature")
    return image


def write_final(out: Path, result: Any, image: np.ndarray, scale: int, spp: int) -> None:
    """Write ``out``/objective.png (the photo as the fit saw it) and ``out``/final.png (the fitted scene at
    ``scale`` times the scene's size, ``spp`` samples per pixel where it has an edge: :func:`render_final`)."""
    rtloop.save_image(out / "objective.png", image)
    rtloop.save_image(out / "final.png", render_final(result.scene, scale, spp))


def input_paths(scene: Any, image: Any, response: str, crop: bool, mask: Any) -> dict[str, Any]:
    """The ``inputs`` record of result.json: absolute paths and how the photo was read."""
    rec = {
        "scene": os.path.abspath(scene),
        "image": os.path.abspath(image),
        "response": response,
        "crop": bool(crop),
        "mask": None if mask is None else os.path.abspath(mask),
    }
    if is_raw(image):  # read by LibRaw: the response does not apply; its white balance is recorded
        rec["response"] = "raw"
        rec["raw"] = raw_settings(image)
    return rec


class GenerationLog:
    """A fit's callback writing ``out``/best_per_generation.csv (one row per generation of every stage:
    stage, generation, evaluations, fitness, every fit parameter's value in the best individual) and,
    every ``every`` generations (0: never), the best individual rendered into ``out``/snapshots/.

    The snapshots are rendered when the log is closed, not in the callback (which holds up the search):
    all in one pass of the renderer, each distinct individual once (the best often stays the same for
    generations). A ``with`` block left by an exception writes none."""

    def __init__(self, out: Path, scene: Any, every: int):
        self.scene, self.every = scene, every
        self.snapshots = out / "snapshots"
        self.snapshots.mkdir()
        self._pending: list[tuple[str, tuple[float, ...]]] = []
        self._fh = open(out / "best_per_generation.csv", "w", newline="", encoding="utf-8")  # noqa: SIM115 (closed by close / the with)
        self._csv = csv.writer(self._fh)
        self._csv.writerow(["stage", "generation", "evaluations", "fitness", *scene.param_names()])

    def __call__(self, info: Any) -> np.ndarray | None:
        """Log one generation of the fit's search; returns its parameters as float64 (the block bootstrap's
        refits are not logged: None)."""
        if replicate_of(info.stage) is not None:
            return None
        params = np.asarray(info.params, dtype=np.float64)
        self._csv.writerow([info.stage, info.generation, info.evaluations, repr(float(info.fitness)),
                            *(repr(float(v)) for v in params)])
        if self.every and info.generation % self.every == 0:
            stage = _SAFE_NAME.sub("_", info.stage)
            self._pending.append((f"{stage}_gen{info.generation:04d}.bmp", tuple(params.tolist())))
        return params

    def write_snapshots(self) -> None:
        """Render and save the snapshots logged so far."""
        pending, self._pending = self._pending, []
        distinct = list(dict.fromkeys(p for _, p in pending))
        per_pass = max(1, _SNAPSHOT_PIXELS // (self.scene.width * self.scene.height))
        shots: dict[tuple[float, ...], np.ndarray] = {}
        for i in range(0, len(distinct), per_pass):
            chunk = distinct[i:i + per_pass]
            images, _ = _native.render_many([self.scene.with_params(list(p)) for p in chunk])
            shots.update(zip(chunk, images))
        for name, params in pending:
            rtloop.save_image(self.snapshots / name, shots[params])

    def close(self) -> None:
        """Write the snapshots and close the CSV."""
        try:
            self.write_snapshots()
        finally:
            self._fh.close()

    def __enter__(self) -> Self:
        return self

    def __exit__(self, kind: object, *exc: object) -> None:
        if kind is not None:
            self._pending.clear()
        self.close()


def set_aside_one_light_log(out: Path) -> None:
    """Where the default fit kept a further light: the one-light search's log (best_per_generation.csv,
    snapshots/), which the test started from, moved into ``out``/one_light/, so that the top level holds
    the lights fit's files alone."""
    aside = out / "one_light"
    aside.mkdir()
    for name in ("best_per_generation.csv", "snapshots"):
        if (out / name).exists():
            (out / name).rename(aside / name)
