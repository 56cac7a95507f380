"""Shared fixtures: tiny scenes built in code, and the path to ../shared (tests skip without it, and fail
under CI=true, where it must be present)."""

from __future__ import annotations

import copy
import json
import os
from pathlib import Path

import numpy as np
import pytest

from scenes import BALL_ON_FLOOR, centred_start, floor, matte_start, sphere  # noqa: F401

REPO = Path(__file__).resolve().parents[1]
SHARED_SCENES = REPO.parent / "shared" / "scenes"
EXAMPLE = REPO / "examples" / "yellow-ball"


@pytest.fixture
def ball_scene() -> dict:
    """The paper's scene (sphere on a floor, one light) at 64x48, as a fresh dict."""
    return copy.deepcopy(BALL_ON_FLOOR)


def example_scene(width: int, height: int) -> dict:
    """The yellow-ball example (its camera, objects and fit section, its neutral start) at width x height."""
    d = json.loads((EXAMPLE / "scene_input.json").read_text(encoding="utf-8"))
    d["image"] = {"width": width, "height": height}
    return d


def example_truth(width: int, height: int) -> dict:
    """``example_scene`` with a known light and albedos: what its test photos are rendered from."""
    d = example_scene(width, height)
    d["light"].update(position=[2.0, 4.0, -1.5], intensity=40.0)
    d["objects"][0]["material"]["albedo"] = [0.8, 0.7, 0.1]
    d["objects"][1]["material"]["albedo"] = [0.4, 0.5, 0.6]
    return d


def wrong_start(truth: dict) -> dict:
    """The truth's geometry with a wrong light and wrong colours (what a user would hand the fit)."""
    start = copy.deepcopy(truth)
    start["light"]["position"] = [0.0, 4.25, 0.0]
    start["light"]["intensity"] = 20.0
    for o in start["objects"]:
        o["material"]["albedo"] = [0.5, 0.5, 0.5]
    return start


def scene_products(d: dict) -> dict[str, np.ndarray]:
    """Each object's light colour x intensity x exposure x albedo, by name."""
    light = np.array(d["light"]["color"]) * d["light"]["intensity"] * d.get("exposure", 1.0)
    return {o["name"]: light * np.array(o["material"]["albedo"]) for o in d["objects"]}


def sunlit(truth: dict, direction: list[float]) -> dict:
    """Light ``truth`` (in place) by a directional light along ``direction``, its direction and intensity
    free, and return the start a user would hand the fit: the light straight overhead, grey albedos."""
    truth["light"] = {"type": "directional", "direction": direction, "intensity": 2.5}
    truth["fit"].pop("light.position")
    truth["fit"]["light.direction"] = {"min": [-1, 0.05, -1], "max": [1, 1, 1]}
    truth["fit"]["light.intensity"] = {"min": 0.1, "max": 20}
    start = copy.deepcopy(truth)
    start["light"]["direction"] = [0.0, 1.0, 0.0]
    for o in start["objects"]:
        o["material"]["albedo"] = [0.5, 0.5, 0.5]
    return start


#: The accuracy group (marker ``accuracy``): the files whose tests fit or render photos from an independent
#: renderer (or real photos' stand-ins) and hold the result against their ground truth; slower than the unit
#: tests. ``pytest -m "not accuracy"`` runs the unit tests alone; CI runs both.
ACCURACY = frozenset({
    "test_photos.py", "test_edges.py", "test_coat.py", "test_camera.py", "test_lights.py", "test_onephoto.py",
    "test_noisy_jpeg_photos.py", "test_coverage.py", "test_hard_cases.py", "test_environment.py",
    "test_interreflection.py", "test_highlights.py", "test_ambient_environment.py", "test_error_bars.py",
    "test_render_reference.py", "test_light_distance.py", "test_residual_structure.py", "test_framing.py",
    "test_linear_photos.py", "test_default_lights.py",
})


def pytest_collection_modifyitems(config, items) -> None:
    for item in items:
        if item.path.name in ACCURACY:
            item.add_marker(pytest.mark.accuracy)


def missing(what: str) -> None:
    """Skip a test whose input ``what`` is absent, or fail it under CI (``CI`` set, as .ci/run sets it)."""
    if os.environ.get("CI", "").lower() not in ("", "0", "false"):
        pytest.fail(f"{what} (required when CI is set)")
    pytest.skip(what)


def shared_case(name: str) -> Path:
    path = SHARED_SCENES / name
    if not path.is_dir():
        missing(f"{path} not found: the reference scenes live in ../shared/scenes beside the repo")
    return path


def shared_case_names() -> list[str]:
    if not SHARED_SCENES.is_dir():
        return ["(none: ../shared/scenes absent)"]
    return sorted(p.name for p in SHARED_SCENES.iterdir() if (p / "scene.json").is_file())
