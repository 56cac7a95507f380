"""The loss's norm chosen from the photo (``norm="auto"``, the default; rtloop.fit.norm): the residual statistic
against noise of known size, the L1 fit kept where the photo gives no reason to leave it (a photo that is not a
linear camera file, a sparse residual), and the L2 refit where a linear file's residual is dense."""

from __future__ import annotations

import copy
import warnings
from pathlib import Path

import numpy as np
import pytest

import rtloop
from conftest import BALL_ON_FLOOR
from rtloop.fit.norm import (DENSE_MEDIAN_Z, FINEST_STEP, dense_residual, linear_file, pixel_errors,
                             representable_pixels)

PHOTOS = Path(__file__).resolve().parent / "fixtures" / "photos"
NO_JPEG = [0.0, 0.0, 0.0]


def _fit(scene, photo, **kw):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", rtloop.RtloopWarning)
        return rtloop.fit(scene, photo, uncertainty=False, **kw)


def test_noise_alone_is_not_dense_and_a_misfit_everywhere_is():
    truth = rtloop.render(BALL_ON_FLOOR)
    sigma = 12 * FINEST_STEP
    rng = np.random.default_rng(1)
    photo = (truth + rng.normal(0, sigma, truth.shape)).astype(np.float32)
    alone = dense_residual(truth, photo, None, None, [sigma] * 3, NO_JPEG)
    # |N(0, 1)|'s median is 0.674; the 16-bit step adds 1/12 of a step's variance (negligible here)
    assert alone["median_z"] == pytest.approx(0.674, abs=0.03)
    assert not alone["dense"]
    misfit = dense_residual(truth * np.float32(1.03) + np.float32(4 * sigma), photo, None, None, [sigma] * 3, NO_JPEG)
    assert misfit["median_z"] > 2 * DENSE_MEDIAN_Z and misfit["dense"]


def test_pixel_errors_are_the_8_bit_step_on_codes_and_the_noise_elsewhere():
    codes = np.array([[[0, 128, 255]]], np.uint8)
    photo = rtloop.srgb_to_linear(codes)
    err8 = pixel_errors(photo, codes, [0.0] * 3, NO_JPEG)
    # at code 128 the step is decode(128.5/255) - decode(127.5/255), its rounding error step / sqrt(12)
    step = ((128.5 / 255 + 0.055) / 1.055) ** 2.4 - ((127.5 / 255 + 0.055) / 1.055) ** 2.4
    assert err8[0, 1] == pytest.approx(step / np.sqrt(12), rel=1e-4)
    noisy = pixel_errors(photo, None, [0.01, 0.02, 0.03], NO_JPEG)
    assert noisy[0] == pytest.approx([0.01, 0.02, 0.03], rel=1e-3)


def _linear_file(image: np.ndarray) -> np.ndarray:
    """``image`` as a linear 16-bit file stores it and ``load_image(..., response="linear")`` reads it back."""
    return (np.round(np.clip(image, 0, 1) * 65535) / 65535).astype(np.float32)


def _srgb_file(image: np.ndarray) -> np.ndarray:
    """``image`` as a 16-bit sRGB file stores it, read back."""
    from rtloop._srgb import decode, encode

    return decode(np.round(encode(np.clip(image, 0, 1).astype(np.float32)) * 65535) / 65535).astype(np.float32)


def test_a_linear_file_is_told_from_srgb_files_and_computed_arrays():
    truth = rtloop.render(BALL_ON_FLOOR)
    assert linear_file(_linear_file(truth))
    assert linear_file((np.arange(256, dtype=np.float32) / 255).reshape(-1, 1, 1) * np.ones(3, np.float32))
    assert not linear_file(truth)
    assert not linear_file(_srgb_file(truth))
    assert not linear_file(rtloop.srgb_to_linear(np.arange(256, dtype=np.uint8)))
    off = _linear_file(truth)
    off[10, 10, 1] += np.float32(0.5 / 65535)
    assert not linear_file(off)


def test_a_computed_render_is_not_a_linear_file_and_keeps_l1():
    result = _fit(copy.deepcopy(BALL_ON_FLOOR), rtloop.render(BALL_ON_FLOOR), generations=2, polish=20, norm="auto")
    assert result.model["norm"]["used"] == "l1" and result.settings["norm"] == "l1"
    assert result.model["norm"]["linear_file"] is False and "not a linear camera file" in result.model["norm"]["why"]


def test_a_noise_free_linear_file_keeps_l1():
    photo = _linear_file(rtloop.render(BALL_ON_FLOOR))
    result = _fit(copy.deepcopy(BALL_ON_FLOOR), photo, generations=2, polish=20, norm="auto")
    assert result.model["norm"]["used"] == "l1" and result.model["norm"]["linear_file"] is True
    assert result.model["norm"]["median_z"] is None and "no noise" in result.model["norm"]["why"]


def test_an_8_bit_srgb_photo_keeps_the_l1_fit_bit_for_bit():
    case = PHOTOS / "direct-side"
    scene = rtloop.load_scene(case / "scene_input.json")
    photo = rtloop.load_image(case / "objective.png", scene)
    auto, l1 = _fit(scene, photo, norm="auto"), _fit(scene, photo, norm="l1")
    assert auto.model["norm"]["used"] == "l1" and auto.model["norm"]["linear_file"] is False
    assert auto.x == l1.x


def _dense_photo():
    """BALL_ON_FLOOR's render through a camera that darkens it towards the right (a misfit everywhere that no
    light of the model makes), with a 16-bit camera's noise, as a linear 16-bit file."""
    truth = rtloop.render(BALL_ON_FLOOR)
    ramp = np.linspace(1.0, 0.8, truth.shape[1], dtype=np.float32)[None, :, None]
    noise = np.random.default_rng(3).normal(0, 10 * FINEST_STEP, truth.shape)
    return _linear_file(truth * ramp + noise)


# The photos below carry an exposure ramp across the frame that the model lacks; these tests are of the
# norm, on one light (lights=1): whether a further light may stand in for such a ramp is
# tests/test_default_lights.py's.
def test_a_dense_residual_is_refitted_in_l2_on_the_pixels_that_show_one_object():
    scene = copy.deepcopy(BALL_ON_FLOOR)
    result = _fit(scene, _dense_photo(), norm="auto", lights=1)
    chosen = result.model["norm"]
    assert chosen["used"] == "l2" and result.settings["norm"] == "l2"
    assert chosen["median_z"] >= DENSE_MEDIAN_Z
    outline = scene["image"]["width"] * scene["image"]["height"] - representable_pixels(rtloop.load_scene(scene),
                                                                                        None).size
    assert chosen["outline_pixels_left_out"] == outline > 0
    # the first fit's stage is kept in the record, the L2 fit's after it
    assert len(result.stages) >= 2
    # an explicit norm is never changed
    assert _fit(scene, _dense_photo(), norm="l1").settings["norm"] == "l1"
    assert "norm" not in _fit(scene, _dense_photo(), norm="l1").model


def test_the_same_dense_photo_as_an_srgb_file_keeps_l1_bit_for_bit():
    """Only a linear camera file is refitted: the same photo stored as 16-bit sRGB (a camera's processed
    output) keeps the L1 fit."""
    scene = copy.deepcopy(BALL_ON_FLOOR)
    photo = _srgb_file(_dense_photo())
    auto, l1 = _fit(scene, photo, lights=1), _fit(scene, photo, norm="l1", lights=1)
    assert auto.model["norm"]["used"] == "l1" and auto.model["norm"]["linear_file"] is False
    assert auto.x == l1.x


@pytest.mark.parametrize("bad", ["L2", "auto:1", "huber:0", "huber:inf", "", None, 1])
def test_a_bad_norm_is_one_rtloop_error_naming_it(bad):
    with pytest.raises(rtloop.RtloopError, match="norm"):
        rtloop.fit(BALL_ON_FLOOR, rtloop.render(BALL_ON_FLOOR), norm=bad)


def test_the_default_norm_is_auto():
    result = _fit(copy.deepcopy(BALL_ON_FLOOR), _dense_photo(), generations=2, polish=20)
    auto = _fit(copy.deepcopy(BALL_ON_FLOOR), _dense_photo(), generations=2, polish=20, norm="auto")
    assert result.model["norm"] == auto.model["norm"] and result.x == auto.x
