"""White balance from a grey card and colour correction from a ColorChecker, in linear light
(rtloop.acquisition.colour)."""

from __future__ import annotations

import colour
import numpy as np
import pytest

from rtloop.acquisition import (
    AcquisitionError,
    ColourCorrection,
    colorchecker_correction,
    grey_card_balance,
    mcc_available,
)
from rtloop.acquisition import colour as colour_module
from rtloop.acquisition.colour import COLORCHECKER_SRGB8

LUMA = np.array([0.2126, 0.7152, 0.0722])
CAST = np.array([1.25, 1.0, 0.62])  # a warm lamp / wrong camera white balance, per channel


def srgb8_to_linear(v: np.ndarray) -> np.ndarray:
    x = np.asarray(v, dtype=np.float64) / 255.0
    return np.where(x <= 0.04045, x / 12.92, ((x + 0.055) / 1.055) ** 2.4)


def scene_with_card() -> tuple[np.ndarray, tuple[int, int, int, int]]:
    """A linear photo under a coloured light: a grey floor, a grey card, a yellow patch."""
    rng = np.random.default_rng(0)
    img = np.full((120, 160, 3), 0.35) * CAST
    card = (20, 30, 40, 30)
    x, y, w, h = card
    img[y : y + h, x : x + w] = 0.18 * CAST
    img[60:100, 100:140] = np.array([0.7, 0.55, 0.08]) * CAST
    img = img * (1 + rng.normal(0, 0.01, img.shape))
    return img.astype(np.float32), card


def test_grey_card_makes_the_card_neutral_and_keeps_brightness() -> None:
    photo, card = scene_with_card()
    wb = grey_card_balance(photo, card)
    out = wb.apply(photo)
    x, y, w, h = card
    mean = out[y : y + h, x : x + w].reshape(-1, 3).mean(axis=0)
    assert np.ptp(mean) / mean.mean() < 0.005  # neutral
    before = photo[y : y + h, x : x + w].reshape(-1, 3).mean(axis=0)
    assert mean @ LUMA == pytest.approx(before @ LUMA, rel=1e-3)  # brightness as shot
    # The yellow patch gets its true colour back, up to the card's brightness scale.
    patch = out[60:100, 100:140].reshape(-1, 3).mean(axis=0)
    truth = np.array([0.7, 0.55, 0.08])
    np.testing.assert_allclose(patch / patch[1], truth / truth[1], rtol=0.01)
    assert wb.report()["source"] == "grey card"
    assert grey_card_balance(photo, "20,30,40,30").matrix == pytest.approx(wb.matrix)


@pytest.mark.parametrize(
    ("rect", "mutate", "message"),
    [
        ((150, 100, 40, 40), None, "reaches outside the 160x120 photo"),
        ("1,2,3", None, "expected X,Y,W,H"),
        ((20, 30, 40, 30), "clip", "clipped"),
        ((20, 30, 40, 30), "dark", "almost black"),
        ((0, 0, 160, 120), None, "not uniform"),
    ],
)
def test_grey_card_errors(rect, mutate, message: str) -> None:
    photo, _ = scene_with_card()
    if mutate == "clip":
        photo[30:60, 20:60] = 1.0
    elif mutate == "dark":
        photo[30:60, 20:60] = 0.0
    elif rect == (0, 0, 160, 120):
        photo[:, :80] *= 0.2
    with pytest.raises(AcquisitionError, match=message):
        grey_card_balance(photo, rect)


def chart_photo() -> np.ndarray:
    """A ColorChecker Classic on a mid-grey wall, under a cast, mixed channels and a little noise."""
    ref = srgb8_to_linear(COLORCHECKER_SRGB8)
    h, w = 600, 800
    img = np.full((h, w, 3), 0.18)
    x0, y0, ps, gap = 150, 120, 70, 14
    img[y0 - gap : y0 + 4 * (ps + gap), x0 - gap : x0 + 6 * (ps + gap)] = 0.02
    for i in range(24):
        r, c = divmod(i, 6)
        img[
            y0 + r * (ps + gap) : y0 + r * (ps + gap) + ps, x0 + c * (ps + gap) : x0 + c * (ps + gap) + ps
        ] = ref[i]
    mix = np.array([[1.1, 0.05, 0.0], [0.05, 0.95, 0.03], [0.0, 0.1, 0.6]]) * 0.8
    rng = np.random.default_rng(0)
    out = img.reshape(-1, 3) @ mix
    return (out.reshape(h, w, 3) + rng.normal(0, 0.002, (h, w, 3))).astype(np.float32)


@pytest.mark.skipif(not mcc_available(), reason="this OpenCV has no contrib 'mcc' module (cv2.mcc)")
def test_colorchecker_correction() -> None:
    photo = chart_photo()
    cc = colorchecker_correction(photo)
    assert cc.details["patches_used"] == 24
    assert cc.details["chromaticity_rms_before"] > 0.05
    assert cc.details["chromaticity_rms_after"] < 0.005
    out = cc.apply(photo)
    # The white patch (row 4, column 1) comes out neutral.
    white = out[120 + 3 * 84 + 20 : 120 + 3 * 84 + 50, 150 + 20 : 150 + 50].reshape(-1, 3).mean(axis=0)
    assert np.ptp(white) / white.mean() < 0.01


def test_colorchecker_not_found_or_mcc_missing(monkeypatch) -> None:
    blank = np.full((200, 300, 3), 0.2, np.float32)
    if mcc_available():
        with pytest.raises(AcquisitionError, match="no ColorChecker"):
            colorchecker_correction(blank)
    monkeypatch.setattr(colour_module, "mcc_available", lambda: False)
    with pytest.raises(AcquisitionError, match=r"contrib module 'mcc' \(cv2.mcc\).*--grey-card"):
        colorchecker_correction(blank)


def test_identity() -> None:
    img = np.random.default_rng(1).uniform(0, 1, (10, 10, 3)).astype(np.float32)
    np.testing.assert_array_equal(ColourCorrection.identity().apply(img), img)


def test_colorchecker_values_match_published_reference_data() -> None:
    """rtloop's ColorChecker table (X-Rite's sRGB values, written into the module) against independent
    published data: colour-science's "ColorChecker24 - After November 2014" (X-Rite's CIE xyY under D50),
    compared in CIELAB with CIE Delta E 2000 after a Bradford adaptation. sRGB's 8-bit rounding and its
    gamut (the yellow and cyan patches lie outside it) leave up to about 3; a swapped or mistyped patch
    is well over 10."""
    cc = colour.CCS_COLOURCHECKERS["ColorChecker24 - After November 2014"]
    reference = colour.xyY_to_XYZ(np.array(list(cc.data.values())))
    ours = colour.sRGB_to_XYZ(COLORCHECKER_SRGB8 / 255.0, illuminant=cc.illuminant,
                              chromatic_adaptation_transform="Bradford")
    de = colour.delta_E(colour.XYZ_to_Lab(ours, cc.illuminant), colour.XYZ_to_Lab(reference, cc.illuminant),
                        method="CIE 2000")
    assert de.shape == (24,)
    assert de.max() < 4.0, np.round(de, 2)
    assert np.median(de) < 2.0, np.round(de, 2)
