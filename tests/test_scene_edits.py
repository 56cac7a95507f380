"""The native scene edits (Scene.with_bounds, with_fit, without_fit) give the scene the JSON route gives
(edit scene_to_dict, load_scene again), with the same validation errors; and optimize's typed result."""

from __future__ import annotations

import copy

import numpy as np
import pytest

import rtloop
from rtloop import _native
from rtloop.scene import load_scene, scene_to_dict


def _json_with_bounds(scene, changes):
    d = scene_to_dict(scene)
    for path, (lo, hi) in changes.items():
        d["fit"][path] = {"min": lo, "max": hi}
    return load_scene(d)


def _error(call):
    with pytest.raises(rtloop.SceneError) as e:
        call()
    return str(e.value)


def test_with_bounds_equals_the_json_route(ball_scene):
    scene = load_scene(ball_scene)
    for changes in (
        {"objects.ball.albedo": ([0.0, 0.25, 0.0], [1.5, 2.0, 3.0])},  # replaced
        {"light.intensity": (2.0, 100.5)},  # one component, numbers
        {"objects.floor.albedo": (0.0, 2.0)},  # one number for every component
        {"ambient": ([0, 0, 0], [0.5, 0.5, 0.5]), "exposure": (0.5, 2.0)},  # added, in canonical order
        {"objects.ball.specular": (0.0, 1.0), "objects.ball.shininess": (1.0, 200.0),
         "light.position": ([-1, 1, -1], [1, 2, 1])},
    ):
        native = scene.with_bounds(changes)
        assert native.to_json() == _json_with_bounds(scene, changes).to_json()
        assert native.fit_paths == _json_with_bounds(scene, changes).fit_paths
    assert scene.to_json() == load_scene(ball_scene).to_json()  # the original is unchanged
    assert scene.with_bounds({}).to_json() == scene.to_json()


def test_with_bounds_errors_equal_the_json_route(ball_scene):
    scene = load_scene(ball_scene)
    for changes in (
        {"objects.ball.albedo": ([0, 0, 0], [1, -1, 1])},  # min > max
        {"objects.ball.albedo": ([-0.5, 0, 0], [1, 1, 1])},  # below the physical limit
        {"objects.ball.albedo": ([0, 0], [1, 1])},  # wrong length
        {"objects.moon.albedo": (0, 1)},  # unknown object
        {"light.direction": ([0, 1, 0], [1, 1, 1])},  # a point light
        {"light.intensity": (1.0, float("nan"))},
        {"objects.floor.albedo": ([0, float("inf"), 0], [1, 1, 1])},
    ):
        native = _error(lambda c=changes: scene.with_bounds(c))
        assert native == _error(lambda c=changes: _json_with_bounds(scene, c))


def test_with_fit_and_without_fit_equal_the_json_route(ball_scene):
    original = load_scene(ball_scene)
    edited = original.with_bounds({"light.position": ([-1, 1, -1], [1, 2, 1])}).with_params(
        [1.0, 1.5, 0.5], ["light.position"])
    d = scene_to_dict(edited)
    d["fit"] = scene_to_dict(original)["fit"]
    assert edited.with_fit(original).to_json() == load_scene(d).to_json()
    d["fit"] = {}
    assert edited.without_fit().to_json() == load_scene(d).to_json()
    assert edited.without_fit().fit_paths == []
    # The other scene's fit is checked against this scene's objects, as load_scene checks it.
    other = copy.deepcopy(ball_scene)
    other["objects"][0]["name"] = "moon"
    other["fit"] = {"objects.moon.albedo": {"min": 0, "max": 1}}
    d = scene_to_dict(original)
    d["fit"] = other["fit"]
    assert _error(lambda: original.with_fit(load_scene(other))) == _error(lambda: load_scene(d))


def test_optimize_returns_a_typed_frozen_result(ball_scene):
    scene = load_scene(ball_scene)
    target = np.asarray(_native.render(scene), np.float32)
    spec = _native.FitnessSpec(["light.position"])
    out = _native.optimize(scene, target, spec, population=8, generations=2, seed=1)
    assert isinstance(out, _native.OptimizeResult)
    assert out.x.shape == (3,) and out.x.dtype == np.float64
    assert out.generations == 2 and out.evaluations == 8 * 3 and not out.stopped
    assert out.stop_reason == "max_generations" and out.polish is None
    assert out.products is None and out.lit_pixels is None and out.search_objectives is None
    assert len(out.objectives) == 1 and out.active_pixels > 0
    with pytest.raises(AttributeError):
        out.generations = 3
    with pytest.raises(TypeError):
        out["x"]  # no longer a dict
    polished = _native.optimize(scene, target, spec, population=8, generations=2, seed=1, method="lshade",
                                polish=20)
    evals, before, after = polished.polish
    assert 0 < evals <= 20 and after <= before
    assert polished.evaluations == 8 * 3 + evals
