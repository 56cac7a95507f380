"""The native `projection_blocker` (rust/fitness/projected.rs, the one decision of whether the closed form
applies, which `rtloop.fit` asks) gives exactly the answer of the rules written again here in Python over the
scene dict, for scene / fit-section combinations covering every reason and the None case."""

from __future__ import annotations

import copy
import json

import pytest

import rtloop
from conftest import BALL_ON_FLOOR
from rtloop import _native


def _python_blocker(scene: rtloop.Scene, paths: list[str]) -> str | None:
    """The rules as docs/methods.md states them, written again over the scene dict (the oracle)."""
    d = scene.to_dict()
    if "light.position" not in paths and "light.direction" not in paths:
        return "neither light.position nor light.direction is free"
    ambient = any(v != 0 for v in d["ambient"]) or "ambient" in paths
    if ambient and (any(v != 0 for v in d.get("environment", (0, 0, 0))) or "environment" in paths):
        return "the scene has both ambient light and an environment"
    if ambient and d.get("interreflection"):
        return "the scene has ambient light and interreflection"
    allowed = {"light.position", "light.direction", "light.intensity", "ambient", "environment"}
    for o in d["objects"]:
        allowed |= {f"objects.{o['name']}.{m}" for m in ("albedo", "specular", "shininess")}
    extra = [p for p in paths if p not in allowed]
    if extra:
        return f"{', '.join(extra)} cannot be solved in closed form"
    if "light.intensity" in paths:
        fixed = [o["name"] for o in d["objects"] if f"objects.{o['name']}.albedo" not in paths]
        if fixed:
            return f"light.intensity is free but the albedo of {', '.join(fixed)} is fixed"
    return None


LIGHT = ["light.position", "light.intensity", "objects.ball.albedo", "objects.floor.albedo"]


def _scene(ambient=(0.0, 0.0, 0.0), ball_specular=0.0, floor_specular=0.0, directional=False,
           environment=(0.0, 0.0, 0.0), interreflection=False):
    d = copy.deepcopy(BALL_ON_FLOOR)
    d["ambient"] = list(ambient)
    d["environment"] = list(environment)
    d["interreflection"] = interreflection
    d["objects"][0]["material"].update(specular=ball_specular, shininess=20.0)
    d["objects"][1]["material"].update(specular=floor_specular, shininess=10.0)
    if directional:
        d["light"] = {"type": "directional", "direction": [0.3, 1.0, -0.2], "intensity": 2.0,
                      "color": [1.0, 1.0, 1.0]}
        d["fit"] = {k: v for k, v in d["fit"].items() if k != "light.position"}
    return _native.Scene(json.dumps(d))


CASES = [
    ("matte, default section", {}, LIGHT),
    ("light only", {}, ["light.position"]),
    ("no light free", {}, ["light.intensity", "objects.ball.albedo"]),
    ("ambient", {"ambient": (0.05, 0.05, 0.05)}, LIGHT),
    ("ambient in one channel", {"ambient": (0.0, 0.0, 0.01)}, ["light.position"]),
    ("ambient free", {}, [*LIGHT, "ambient"]),
    ("ambient and environment", {"ambient": (0.05, 0.05, 0.05), "environment": (0.1, 0.1, 0.1)}, LIGHT),
    ("ambient free, environment free", {}, [*LIGHT, "ambient", "environment"]),
    ("ambient and interreflection", {"ambient": (0.05, 0.05, 0.05), "interreflection": True}, LIGHT),
    ("environment free", {}, [*LIGHT, "environment"]),
    ("exposure free", {}, [*LIGHT, "exposure"]),
    ("two extras", {}, ["light.position", "ambient", "light.color", "exposure"]),
    ("unknown object", {}, ["light.position", "objects.cube.albedo"]),
    ("glossy, specular fixed", {"ball_specular": 0.4}, LIGHT),
    ("glossy, specular free", {"ball_specular": 0.4}, [*LIGHT, "objects.ball.specular"]),
    ("two glossy, one fixed", {"ball_specular": 0.4, "floor_specular": 0.2},
     [*LIGHT, "objects.ball.specular"]),
    ("intensity free, albedo fixed", {}, ["light.position", "light.intensity", "objects.ball.albedo"]),
    ("intensity free, no albedo", {}, ["light.position", "light.intensity"]),
    ("intensity fixed, albedo partly", {}, ["light.position", "objects.floor.albedo"]),
    ("directional", {"directional": True}, ["light.direction", "light.intensity", "objects.ball.albedo",
                                            "objects.floor.albedo", "objects.ball.shininess"]),
    ("directional, ambient", {"directional": True, "ambient": (0.1, 0.0, 0.0)}, ["light.direction"]),
]


@pytest.mark.parametrize(("name", "scene", "paths"), CASES, ids=[c[0] for c in CASES])
def test_native_blocker_equals_python(name, scene, paths):
    s = _scene(**scene)
    assert _native.projection_blocker(s, paths) == _python_blocker(s, paths)


def test_cases_cover_every_answer():
    answers = {_python_blocker(_scene(**s), p) for _, s, p in CASES}
    assert None in answers
    reasons = ["neither", "ambient light and an environment", "ambient light and interreflection",
               "cannot be solved", "albedo of"]
    for r in reasons:
        assert any(a and r in a for a in answers), r
