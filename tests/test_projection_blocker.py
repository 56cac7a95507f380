"""The native `projection_blocker` (rust/fitness/projected.rs) gives exactly the answer of Python's
`fit._projection_blocker` for scene / fit-section combinations covering every reason and the None case."""

from __future__ import annotations

import copy
import json

import pytest

from conftest import BALL_ON_FLOOR
from rtloop import _native
from rtloop.fit import _projection_blocker

LIGHT = ["light.position", "light.intensity", "objects.ball.albedo", "objects.floor.albedo"]


def _scene(ambient=(0.0, 0.0, 0.0), ball_specular=0.0, floor_specular=0.0, directional=False):
    d = copy.deepcopy(BALL_ON_FLOOR)
    d["ambient"] = list(ambient)
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
    ("exposure free", {}, [*LIGHT, "exposure"]),
    ("two extras", {}, ["light.position", "ambient", "light.color"]),
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
    assert _native.projection_blocker(s, paths) == _projection_blocker(s, paths)


def test_cases_cover_every_answer():
    answers = {_projection_blocker(_scene(**s), p) for _, s, p in CASES}
    assert None in answers
    reasons = ["neither", "ambient", "cannot be solved", "highlight", "albedo of"]
    for r in reasons:
        assert any(a and r in a for a in answers), r
