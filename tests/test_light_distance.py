"""The light's distance and direction from the subject with their sigmas (rtloop.uncertainty.light): the
split of a known covariance, and a far light over a lone ball reported as not determined where a lamp
beside a ball on a floor is."""

from __future__ import annotations

import copy
import math
import warnings

import numpy as np
import pytest

import rtloop
from conftest import BALL_ON_FLOOR
from rtloop.uncertainty.light import DISTANCE_DETERMINED, light_distance

NAMES = ["light.position.x", "light.position.y", "light.position.z", "products.ball.r"]
SCENE = {"light": {"position": [0.0, 0.0, 10.0]}, "objects": [{"shape": "sphere", "center": [0, 0, 0]}]}


def _split(cov):
    return light_distance(NAMES, np.asarray(cov, float), np.arange(4), np.ones(4, bool), SCENE)


def test_an_isotropic_covariance_splits_into_the_same_sigma_along_and_across():
    out = _split(np.diag([0.01, 0.01, 0.01, 1.0]))
    assert out["distance_m"] == pytest.approx(10.0)
    assert out["distance_sigma_m"] == pytest.approx(0.1)
    assert out["direction_sigma_deg"] == pytest.approx(math.degrees(0.1 / 10.0))
    assert out["distance_determined"]


def test_a_sigma_along_the_line_beyond_the_bound_is_not_determined_and_says_why():
    cov = np.diag([1e-4, 1e-4, (DISTANCE_DETERMINED * 10.0 * 1.01) ** 2, 1.0])
    out = _split(cov)
    assert not out["distance_determined"] and "direction, not how far" in out["why"]
    # across the line only the x and y sigmas count: 0.01 m at 10 m
    assert out["direction_sigma_deg"] == pytest.approx(math.degrees(0.01 / 10.0))


def test_no_sphere_or_no_free_position_gives_no_record():
    assert light_distance(NAMES, np.eye(4), np.arange(4), np.ones(4, bool), {"light": {"position": [0, 0, 1]},
                                                                            "objects": []}) is None
    assert light_distance(["products.ball.r"], np.eye(1), np.arange(1), np.ones(1, bool), SCENE) is None


def _fit(truth, start_light):
    photo = rtloop.render(truth)
    photo = np.clip(photo + np.random.default_rng(2).normal(0, 0.004, photo.shape), 0, None).astype(np.float32)
    scene = copy.deepcopy(truth)
    scene["light"]["position"] = start_light
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", rtloop.RtloopWarning)
        return rtloop.fit(scene, photo).uncertainty["robust"]["light_distance"]


def test_a_lamp_beside_a_ball_on_a_floor_has_its_distance_determined():
    out = _fit(copy.deepcopy(BALL_ON_FLOOR), [0.0, 3.0, -2.0])
    assert out["distance_determined"] and out["distance_sigma_m"] < 0.05 * out["distance_m"]


def test_a_far_light_over_a_lone_ball_has_a_direction_and_no_distance():
    truth = copy.deepcopy(BALL_ON_FLOOR)
    truth["objects"] = truth["objects"][:1]
    truth["light"] = {"position": [120.0, 180.0, -90.0], "intensity": 70.0 * 240.0 ** 2 / 4.5 ** 2}
    truth["fit"] = {"light.position": {"min": [-300, 0.5, -300], "max": [300, 300, 300]},
                    "objects.ball.albedo": {"min": [0, 0, 0], "max": [1, 1, 1]}}
    out = _fit(truth, [0.0, 3.0, -2.0])
    assert not out["distance_determined"]
    assert out["direction_sigma_deg"] is not None


def _far_light_sigma(box: float) -> dict:
    """The Gauss-Newton direction sigma at the truth of a noisy photo of a lone ball under a light 24 m away,
    the light's position free in a box of +-``box`` m."""
    truth = copy.deepcopy(BALL_ON_FLOOR)
    truth["objects"] = truth["objects"][:1]
    truth["light"] = {"position": [12.0, 18.0, -9.0], "intensity": 70.0 * 24.0 ** 2 / 4.5 ** 2}
    truth["fit"] = {"light.position": {"min": [-box, 0.5, -box], "max": [box, box, box]},
                    "objects.ball.albedo": {"min": [0, 0, 0], "max": [1, 1, 1]}}
    photo = rtloop.render(truth)
    photo = np.clip(photo + np.random.default_rng(5).normal(0, 0.004, photo.shape), 0, None).astype(np.float32)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", rtloop.RtloopWarning)
        return rtloop.estimate_uncertainty(rtloop.load_scene(truth), photo)["light_distance"]


def test_a_far_lights_direction_sigma_does_not_depend_on_how_wide_its_box_is():
    """The finite-difference step of a light's position is a small angle seen from the subject, not a
    fraction of the box: a box of +-1000 m around a light 24 m away must give the direction sigma a box of
    +-40 m gives (with steps of a thousandth of the box, 2 m at 24 m, it was several times off)."""
    wide, tight = _far_light_sigma(1000.0), _far_light_sigma(40.0)
    assert tight["direction_sigma_deg"] > 0
    assert wide["direction_sigma_deg"] == pytest.approx(tight["direction_sigma_deg"], rel=0.05)
