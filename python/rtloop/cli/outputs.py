"""The files one fit leaves in its output directory (result.json, objective.png, final.png), written by
``rtloop-fit`` and by every job of a batch (``rtloop-fit --batch``)."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import numpy as np

import rtloop
from rtloop._files import write_json
from rtloop.acquisition.raw import is_raw, raw_settings

__all__ = ["input_paths", "result_json", "write_final", "write_result"]


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


def write_final(out: Path, result: Any, image: np.ndarray, scale: int, spp: int) -> None:
    """Write ``out``/objective.png (the photo as the fit saw it) and ``out``/final.png (the fitted scene at
    ``scale`` times the scene's size, ``spp`` samples per pixel)."""
    scene = result.scene
    rtloop.save_image(out / "objective.png", image)
    final = rtloop.render(scene, scene.width * scale, scene.height * scale, spp)
    rtloop.save_image(out / "final.png", final)


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
