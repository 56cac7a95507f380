"""Malformed scenes raise rtloop.SceneError naming the offending field; optional fields get defaults."""

from __future__ import annotations

import copy
import json
import math
import re

import numpy as np
import pytest

import rtloop
from conftest import BALL_ON_FLOOR, sphere


def valid_scene() -> dict:
    """The example scene of the scene-format specification (objects[0] = ball, objects[1] = floor)."""
    return {
        "image": {"width": 32, "height": 24},
        "camera": {"position": [0, 1.6, -6], "look_at": [0, 0.8, 0], "up": [0, 1, 0], "vfov_deg": 35},
        "light": {"position": [2, 4, -1.5], "intensity": 40.0, "color": [1, 1, 1]},
        "ambient": [0, 0, 0],
        "background": [0, 0, 0],
        "exposure": 1.0,
        "objects": [
            {
                "name": "ball",
                "shape": "sphere",
                "center": [0, 1, 0],
                "radius": 1,
                "material": {"albedo": [0.8, 0.7, 0.1], "specular": 0.0, "shininess": 0.0},
            },
            {
                "name": "floor",
                "shape": "plane",
                "point": [0, 0, 0],
                "normal": [0, 1, 0],
                "material": {"albedo": [0.5, 0.5, 0.5]},
            },
        ],
        "fit": copy.deepcopy(BALL_ON_FLOOR["fit"]),
    }


def test_valid_example_scene_loads():
    sc = rtloop.load_scene(valid_scene())
    assert (sc.width, sc.height) == (32, 24)
    d = sc.to_dict()
    assert set(d["fit"]) == set(valid_scene()["fit"])
    assert [o["name"] for o in d["objects"]] == ["ball", "floor"]


def test_error_hierarchy():
    assert issubclass(rtloop.SceneError, rtloop.RtloopError)
    assert issubclass(rtloop.RtloopError, Exception)


# Each case: (id, mutation of valid_scene(), expected message). The expectation is a list of
# alternatives; an alternative is a string that must appear, or a tuple of strings that must all appear.
def _set(path, value):
    def mutate(s):
        node = s
        for k in path[:-1]:
            node = node[k]
        node[path[-1]] = value

    return mutate


def _del(path):
    def mutate(s):
        node = s
        for k in path[:-1]:
            node = node[k]
        del node[path[-1]]

    return mutate


def _seq(*fs):
    def mutate(s):
        for f in fs:
            f(s)

    return mutate


def _fit(key, bounds):
    return _set(["fit", key], bounds)


def _duplicate_names(s):
    s["objects"][1]["name"] = "ball"


CASES = [
    ("unknown-shape", _set(["objects", 0, "shape"], "cube"), ["objects[0].shape"]),
    ("unknown-shape-plane-slot", _set(["objects", 1, "shape"], "torus"), ["objects[1].shape"]),
    ("negative-radius", _set(["objects", 0, "radius"], -1.0), ["objects[0].radius"]),
    ("zero-radius", _set(["objects", 0, "radius"], 0), ["objects[0].radius"]),
    ("zero-normal", _set(["objects", 1, "normal"], [0, 0, 0]), ["objects[1].normal"]),
    ("zero-up", _set(["camera", "up"], [0, 0, 0]), ["camera.up"]),
    (
        "up-parallel-looking-down",
        _seq(_set(["camera", "position"], [0, 5, 0]), _set(["camera", "look_at"], [0, 0, 0])),
        ["camera.up"],
    ),
    ("up-parallel-to-view", _set(["camera", "up"], [0, -1.6, 12]), ["camera.up"]),
    ("up-antiparallel-to-view", _set(["camera", "up"], [0, 0.8, -6]), ["camera.up"]),
    (
        "position-equals-look-at",
        _set(["camera", "look_at"], [0, 1.6, -6]),
        ["camera.look_at", "camera.position"],
    ),
    ("vfov-zero", _set(["camera", "vfov_deg"], 0), ["camera.vfov_deg"]),
    ("vfov-negative", _set(["camera", "vfov_deg"], -20), ["camera.vfov_deg"]),
    ("vfov-180", _set(["camera", "vfov_deg"], 180), ["camera.vfov_deg"]),
    ("vfov-over-180", _set(["camera", "vfov_deg"], 250), ["camera.vfov_deg"]),
    ("bounds-scalar-min-gt-max", _fit("light.intensity", {"min": 10, "max": 1}), ['fit["light.intensity"]']),
    (
        "bounds-vector-min-gt-max",
        _fit("light.position", {"min": [-8, 5, -8], "max": [8, 1, 8]}),
        ['fit["light.position"]'],
    ),
    (
        "bounds-albedo-min-gt-max",
        _fit("objects.floor.albedo", {"min": [0, 0.9, 0], "max": [1, 0.1, 1]}),
        ['fit["objects.floor.albedo"]'],
    ),
    (
        "fit-unknown-light-field",
        _fit("light.colour", {"min": [0, 0, 0], "max": [1, 1, 1]}),
        ['fit["light.colour"]'],
    ),
    (
        "fit-unknown-object",
        _fit("objects.cube.albedo", {"min": [0, 0, 0], "max": [1, 1, 1]}),
        ['fit["objects.cube.albedo"]'],
    ),
    ("fit-unknown-top-level", _fit("sun.position", {"min": 0, "max": 1}), ['fit["sun.position"]']),
    ("light-position-2-numbers", _set(["light", "position"], [2, 4]), ["light.position"]),
    ("camera-position-2-numbers", _set(["camera", "position"], [0, 1.6]), ["camera.position"]),
    ("center-4-numbers", _set(["objects", 0, "center"], [0, 1, 0, 1]), ["objects[0].center"]),
    (
        "albedo-2-numbers",
        _set(["objects", 1, "material", "albedo"], [0.5, 0.5]),
        ["objects[1].material.albedo"],
    ),
    ("intensity-string", _set(["light", "intensity"], "forty"), ["light.intensity"]),
    ("radius-string", _set(["objects", 0, "radius"], "1"), ["objects[0].radius"]),
    ("position-component-string", _set(["light", "position"], [2, "4", -1.5]), ["light.position"]),
    ("sphere-without-radius", _del(["objects", 0, "radius"]), ["objects[0].radius"]),
    ("sphere-without-center", _del(["objects", 0, "center"]), ["objects[0].center"]),
    ("plane-without-normal", _del(["objects", 1, "normal"]), ["objects[1].normal"]),
    ("camera-without-look-at", _del(["camera", "look_at"]), ["camera.look_at", ("camera", "look_at")]),
    ("light-without-intensity", _del(["light", "intensity"]), ["light.intensity", ("light", "intensity")]),
    ("nan-intensity", _set(["light", "intensity"], float("nan")), ["light.intensity"]),
    ("inf-light-position", _set(["light", "position"], [2, math.inf, -1.5]), ["light.position"]),
    ("nan-radius", _set(["objects", 0, "radius"], float("nan")), ["objects[0].radius"]),
    ("negative-intensity", _set(["light", "intensity"], -5.0), ["light.intensity"]),
    ("duplicate-names", _duplicate_names, ["objects[1].name"]),
    ("zero-width", _set(["image", "width"], 0), ["image.width"]),
    ("negative-width", _set(["image", "width"], -64), ["image.width"]),
    ("zero-height", _set(["image", "height"], 0), ["image.height"]),
]


def _matches(msg: str, expect) -> bool:
    for alt in expect:
        needles = (alt,) if isinstance(alt, str) else alt
        if all(n in msg for n in needles):
            return True
    return False


@pytest.mark.parametrize("mutate, expect", [c[1:] for c in CASES], ids=[c[0] for c in CASES])
def test_malformed_scene_raises_scene_error_naming_the_field(mutate, expect):
    s = valid_scene()
    mutate(s)
    with pytest.raises(rtloop.SceneError) as info:
        rtloop.load_scene(s)
    msg = str(info.value)
    assert _matches(msg, expect), f"message {msg!r} does not name {expect}"


@pytest.mark.parametrize("mutate, expect", [c[1:] for c in CASES[:6]], ids=[c[0] for c in CASES[:6]])
def test_malformed_scene_file_raises_scene_error_too(tmp_path, mutate, expect):
    s = valid_scene()
    mutate(s)
    path = tmp_path / "bad_scene.json"
    path.write_text(json.dumps(s, indent=2))
    with pytest.raises(rtloop.SceneError) as info:
        rtloop.load_scene(str(path))
    assert _matches(str(info.value), expect), str(info.value)


def test_missing_file_names_the_path(tmp_path):
    path = tmp_path / "no_such_scene.json"
    with pytest.raises((rtloop.RtloopError, FileNotFoundError)) as info:
        rtloop.load_scene(str(path))
    assert "no_such_scene.json" in str(info.value)


def test_invalid_json_names_file_and_line(tmp_path):
    path = tmp_path / "broken_scene.json"
    text = json.dumps(valid_scene(), indent=2).splitlines()
    # line 3 (1-based) is `"width": 32,` inside "image"; break it
    assert '"width"' in text[2]
    text[2] = text[2].replace(":", "::")
    path.write_text("\n".join(text) + "\n")
    with pytest.raises(rtloop.RtloopError) as info:
        rtloop.load_scene(str(path))
    msg = str(info.value)
    assert "broken_scene.json" in msg, msg
    assert re.search(r"line\s*3\b|:3\b", msg), msg


def test_minimal_scene_gets_defaults():
    minimal = {
        "image": {"width": 16, "height": 12},
        "camera": {"position": [0, 1, -5], "look_at": [0, 1, 0], "up": [0, 1, 0], "vfov_deg": 40},
        "light": {"position": [1, 4, -2], "intensity": 30},
        "objects": [sphere("ball", [0, 1, 0], 1, [0.5, 0.4, 0.3])],
    }
    before = copy.deepcopy(minimal)
    sc = rtloop.load_scene(minimal)
    assert minimal == before
    assert (sc.width, sc.height) == (16, 12)
    d = sc.to_dict()
    np.testing.assert_allclose(d["ambient"], [0, 0, 0])
    np.testing.assert_allclose(d["background"], [0, 0, 0])
    assert d["exposure"] == pytest.approx(1.0)
    np.testing.assert_allclose(d["light"]["color"], [1, 1, 1])
    np.testing.assert_allclose(d["light"]["position"], [1, 4, -2])
    assert d["light"]["intensity"] == pytest.approx(30.0)
    mat = d["objects"][0]["material"]
    np.testing.assert_allclose(mat["albedo"], [0.5, 0.4, 0.3])
    assert mat["specular"] == pytest.approx(0.0)
    assert mat["shininess"] == pytest.approx(0.0)
    assert d.get("fit") == {}
    np.testing.assert_allclose(d["camera"]["position"], [0, 1, -5])
    assert d["camera"]["vfov_deg"] == pytest.approx(40.0)
    assert d["objects"][0]["radius"] == pytest.approx(1.0)

    # to_dict() is itself a valid scene that round-trips, and the scene renders.
    again = rtloop.load_scene(json.loads(json.dumps(d))).to_dict()
    assert again == d
    img = np.asarray(rtloop.render(sc))
    assert img.shape == (12, 16, 3) and np.all(np.isfinite(img))


@pytest.mark.parametrize("bad", [42, None, [1, 2], 3.5, b"{}", object()])
def test_a_scene_of_the_wrong_type_is_an_rtloop_error(bad):
    """Not a path, dict, JSON text or Scene: an RtloopError (one line from the CLI) that is also a
    TypeError, as Python expects of a wrong argument type."""
    with pytest.raises(rtloop.SceneTypeError, match=rf"^scene: expected a path, a dict or a Scene, not {type(bad).__name__}$") as e:
        rtloop.load_scene(bad)
    assert isinstance(e.value, rtloop.RtloopError) and isinstance(e.value, TypeError)
