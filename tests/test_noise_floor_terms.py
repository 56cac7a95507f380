"""The environment's and the bounce's gains measured beyond the photo's noise floor (python/rtloop/fit/excess.py):
the floor against the error of noise whose truth is known, and noisy 8-bit renders of the Mitsuba photos'
truths by rtloop itself, whose room light the fit must take (and a direct photo's, which has none, it must
not)."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

import rtloop
from rtloop._srgb import decode, encode
from rtloop.fit.excess import FLOOR_SHARE, excess_gain, noise_floor
from rtloop.fit.goodness import encoded, jpeg_blocking, noise_sigma

PHOTOS = Path(__file__).resolve().parent / "fixtures" / "photos"


def _codes(linear: np.ndarray) -> np.ndarray:
    """``linear`` clipped to [0, 1], sRGB-encoded and rounded to 8 bits, decoded back (as load_image reads a PNG)."""
    return decode(np.round(255.0 * encode(np.clip(linear, 0.0, 1.0))) / 255.0).astype(np.float32)


@pytest.mark.parametrize("level", [0.05, 0.3])
def test_the_floor_is_the_mean_error_of_noise_whose_truth_is_known(level):
    """A flat grey under Gaussian noise of 1 % of white, 8-bit: the floor summed over the pixels is the L1
    error of the noisy photo against the grey itself, in linear units and on the encodings."""
    truth = np.full((96, 128, 3), level)
    photo = _codes(truth + np.random.default_rng(3).normal(0.0, 0.01, truth.shape))
    sigma, blocking, enc = noise_sigma(photo), jpeg_blocking(photo), encoded(photo)
    for space, err in (("linear", np.abs(photo - truth)), ("srgb", np.abs(encode(photo) - encode(truth)))):
        floor = noise_floor(enc, sigma, blocking, None, norm="l1", space=space)
        assert floor == pytest.approx(float(err.sum()), rel=0.1), space
    every_other = np.arange(0, photo.shape[0] * photo.shape[1], 2, dtype=np.uint32)
    half = noise_floor(enc, sigma, blocking, every_other, norm="l1", space="linear")
    assert half == pytest.approx(float(np.abs(photo - truth).reshape(-1, 3)[every_other].sum()), rel=0.1)
    assert noise_floor(enc, sigma, blocking, None, norm="l2", space="linear") is None


LOSSES = st.one_of(st.just(0.0), st.floats(1e-9, 1e9))


@given(LOSSES, LOSSES, st.one_of(st.none(), LOSSES))
def test_the_gain_beyond_the_floor_is_finite_and_at_most_ten_times_the_gain_of_the_whole_loss(l0, l1, floor):
    g = excess_gain(l0, l1, floor)
    raw = (l0 - l1) / l0 if l0 > 0 else 0.0
    assert math.isfinite(g)
    if floor is None or floor == 0.0 or l0 == 0.0:
        assert g == pytest.approx(raw)
    else:
        assert g == pytest.approx((l0 - l1) / max(l0 - floor, (1.0 - FLOOR_SHARE) * l0))
        assert abs(raw) <= abs(g) * (1 + 1e-12) <= abs(raw) / (1.0 - FLOOR_SHARE) * (1 + 1e-9) + 1e-300


def _noisy_truth(case: str, seed: int, sigma: float, bounce: bool) -> tuple[rtloop.Scene, np.ndarray, np.ndarray,
                                                                                 dict]:
    """The Mitsuba case's truth rendered by rtloop (16 spp, with the bounce where ``bounce``) under seeded
    Gaussian noise ``sigma``, 8-bit: the scene the user writes, the photo, the true light and the truth."""
    truth = json.loads((PHOTOS / case / "scene.json").read_text())
    t = {k: v for k, v in truth.items() if k != "fit"}
    t["interreflection"] = bounce
    clean = np.asarray(rtloop.render(t, spp=16), np.float64)
    photo = _codes(clean + np.random.default_rng(seed).normal(0.0, sigma, clean.shape))
    scene = rtloop.load_scene(PHOTOS / case / "scene_input.json")
    return scene, photo, np.asarray(truth["light"]["position"]), truth


@pytest.mark.parametrize("seed", [1, 2])
def test_a_dim_room_light_under_sensor_noise_is_taken_and_the_lamp_found(seed):
    """lamp-side's truth (a lamp 3.95 m away at 20 deg, a bluish room at 5 % of the lit floor, one bounce)
    rendered by rtloop with noise of 1 % of white: the noise is 60-80 % of the loss, so the room light lowers
    the whole loss by 1-2 % only, but removes over a tenth of the loss beyond the noise. Taken, the lamp is
    found within the room-light photos' 2 cm (judged against the whole loss, it was left out and the lamp
    ended 46-51 mm off)."""
    scene, photo, light, truth = _noisy_truth("lamp-side", seed, 0.01, bounce=True)
    result = rtloop.fit(scene, photo, uncertainty=False)
    ev = result.model["evidence"]["environment"]
    assert "environment" in result.model["terms"], ev
    assert ev["gain"] >= 0.05 > ev["gain_of_loss"]
    assert ev["noise_floor"] == result.model["residual"]["test_noise_floor"] > 0
    err = float(np.linalg.norm(np.asarray(result.scene.to_dict()["light"]["position"]) - light))
    assert err < 0.02
    env = np.asarray(result.scene.to_dict()["environment"])
    assert np.allclose(env, truth["environment"], rtol=0.3)


def test_a_direct_photo_under_sensor_noise_takes_no_room_light():
    """direct-side's truth (one lamp, no room light, no bounce modelled) under noise of 2 % of white: the
    noise is nearly all of the loss, and neither the environment nor the bounce is taken."""
    scene, photo, light, _ = _noisy_truth("direct-side", 1, 0.02, bounce=False)
    result = rtloop.fit(scene, photo, uncertainty=False)
    assert not {"environment", "interreflection"} & set(result.model["terms"]), result.model["evidence"]
    err = float(np.linalg.norm(np.asarray(result.scene.to_dict()["light"]["position"]) - light))
    assert err < 0.02
