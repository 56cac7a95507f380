"""Defects benches/fuzz.py found, kept as regression cases."""

import pytest

import rtloop


def _scene() -> dict:
    return {
        "image": {"width": 8, "height": 6},
        "camera": {"position": [0, 1, -5], "look_at": [0, 0.5, 0], "vfov_deg": 40},
        "light": {"position": [2, 4, -2], "intensity": 50},
        "objects": [
            {
                "name": "ball",
                "shape": "sphere",
                "center": [0, 0.5, 0],
                "radius": 0.5,
                "material": {"albedo": [0.8, 0.3, 0.2]},
            },
        ],
    }


def test_a_scene_dict_that_contains_itself_is_a_scene_error():
    # It raised RecursionError from the NaN search (fuzz seed 0: a list put inside itself).
    scene = _scene()
    loop: list = [1]
    loop.append(loop)
    scene["camera"]["position"] = loop
    with pytest.raises(rtloop.SceneError, match="JSON"):
        rtloop.load_scene(scene)


def test_a_scene_dict_nested_past_the_recursion_limit_is_a_scene_error():
    scene = _scene()
    deep: list = []
    for _ in range(100_000):
        deep = [deep]
    scene["ambient"] = deep
    with pytest.raises(rtloop.SceneError):
        rtloop.load_scene(scene)
