"""Tests for rtloop.load_image (acquisition/objective.py): decoding, EXIF orientation, linearising, resizing.

Every test image is generated in ``tmp_path``. Expected values come from the sRGB formulas and
the EXIF specification written out here, not from the code under test.
"""

from __future__ import annotations

import re
import struct
import warnings
import zlib
from pathlib import Path
from types import SimpleNamespace

import cv2
import numpy as np
import pytest
from PIL import Image, ImageOps

from rtloop.acquisition.objective import load_image
from rtloop.errors import AcquisitionError

# --- reference formulas ---------------------------------------------------------------------


def srgb_to_linear(encoded: np.ndarray) -> np.ndarray:
    """IEC 61966-2-1 decoding of values in [0, 1]."""
    x = np.asarray(encoded, dtype=np.float64)
    return np.where(x <= 0.04045, x / 12.92, ((x + 0.055) / 1.055) ** 2.4)


def linear_to_srgb(linear: np.ndarray) -> np.ndarray:
    """IEC 61966-2-1 encoding of values in [0, 1]."""
    x = np.asarray(linear, dtype=np.float64)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * x ** (1 / 2.4) - 0.055)


# Largest slope of the sRGB decoding curve on [0, 1] (at 1): 2.4/1.055 * 1**1.4.
MAX_SLOPE = 2.4 / 1.055


def quantisation_bound(levels: int) -> float:
    """How far from the true linear value a decoded, rounded integer code can be."""
    return 0.5 / (levels - 1) * MAX_SLOPE + 1e-6


def assert_valid(result: np.ndarray, width: int, height: int) -> None:
    assert result.shape == (height, width, 3)
    assert result.dtype == np.float32
    assert result.flags.c_contiguous
    assert np.isfinite(result).all()


def save_png_rgb16(path: Path, rgb: np.ndarray) -> None:
    """Write a 16-bit RGB(A) PNG (Pillow cannot): OpenCV wants BGR(A) order."""
    order = [2, 1, 0, 3][: rgb.shape[2]]
    assert cv2.imwrite(str(path), np.ascontiguousarray(rgb[:, :, order]))


def error_match(path: Path) -> str:
    return re.escape(path.name)


# --- sRGB / linear values -------------------------------------------------------------------


def test_srgb_png_round_trip_within_8bit_quantisation(tmp_path: Path) -> None:
    rng = np.random.default_rng(1)
    linear = rng.uniform(0.0, 1.0, size=(12, 16, 3))
    linear[0, :4] = [[0, 0, 0], [1, 1, 1], [0.001, 0.002, 0.003], [0.5, 0.25, 0.75]]
    codes = np.round(linear_to_srgb(linear) * 255).astype(np.uint8)
    path = tmp_path / "known.png"
    Image.fromarray(codes, "RGB").save(path)

    result = load_image(path, (16, 12))

    assert_valid(result, 16, 12)
    assert np.abs(result - linear).max() <= quantisation_bound(256)
    # The exact curve applied to the stored codes, to float32 precision.
    np.testing.assert_allclose(result, srgb_to_linear(codes / 255), rtol=1e-6, atol=1e-7)


def test_srgb_anchor_values(tmp_path: Path) -> None:
    codes = np.array([[[0, 10, 128], [255, 64, 200]]], dtype=np.uint8)
    path = tmp_path / "anchors.png"
    Image.fromarray(codes, "RGB").save(path)

    result = load_image(path, (2, 1))

    # Published sRGB values: 128 -> 0.21586, 64 -> 0.05126, 200 -> 0.57758; 10 is on the linear toe.
    expected = [[[0.0, 10 / 255 / 12.92, 0.2158605], [1.0, 0.0512695, 0.5775804]]]
    np.testing.assert_allclose(result, expected, rtol=1e-5, atol=1e-7)


def test_16bit_png_keeps_16_bits(tmp_path: Path) -> None:
    rng = np.random.default_rng(2)
    linear = rng.uniform(0.0, 1.0, size=(8, 10, 3))
    codes = np.round(linear_to_srgb(linear) * 65535).astype(np.uint16)
    codes[0, 0] = [40000, 40001, 40002]  # neighbouring 16-bit codes, one 8-bit code
    path = tmp_path / "deep.png"
    save_png_rgb16(path, codes)

    result = load_image(path, (10, 8))

    assert_valid(result, 10, 8)
    bound = quantisation_bound(65536)
    assert bound < 2e-5  # 8-bit truncation would be off by up to ~4e-3
    assert np.abs(result[1:] - linear[1:]).max() <= bound
    np.testing.assert_allclose(result, srgb_to_linear(codes / 65535), rtol=2e-6, atol=1e-8)
    assert result[0, 0, 0] < result[0, 0, 1] < result[0, 0, 2]


def test_16bit_grey_png(tmp_path: Path) -> None:
    codes = np.array([[0, 1, 257, 40000], [40001, 65534, 65535, 12345]], dtype=np.uint16)
    path = tmp_path / "grey16.png"
    Image.fromarray(codes).save(path)  # Pillow mode I;16
    with Image.open(path) as image:
        assert image.mode == "I;16"

    result = load_image(path, (4, 2))

    expected = srgb_to_linear(codes / 65535)
    for channel in range(3):
        np.testing.assert_allclose(result[:, :, channel], expected, rtol=2e-6, atol=1e-9)


def test_response_linear_only_normalises(tmp_path: Path) -> None:
    codes16 = np.array([[[0, 1, 2], [1000, 32768, 65535]]], dtype=np.uint16)
    path16 = tmp_path / "raw16.png"
    save_png_rgb16(path16, codes16)
    codes8 = np.array([[[0, 1, 128], [200, 254, 255]]], dtype=np.uint8)
    path8 = tmp_path / "raw8.png"
    Image.fromarray(codes8, "RGB").save(path8)

    result16 = load_image(path16, (2, 1), response="linear")
    result8 = load_image(path8, (2, 1), response="linear")

    np.testing.assert_allclose(result16, codes16 / 65535, rtol=1e-6, atol=1e-9)
    np.testing.assert_allclose(result8, codes8 / 255, rtol=1e-6, atol=1e-9)


def test_channel_order_is_rgb(tmp_path: Path) -> None:
    codes = np.array([[[255, 0, 0], [0, 255, 0], [0, 0, 255]]], dtype=np.uint8)
    path = tmp_path / "rgb.png"
    Image.fromarray(codes, "RGB").save(path)

    result = load_image(path, (3, 1))

    np.testing.assert_array_equal(result[0], np.eye(3, dtype=np.float32))


# --- pixel formats --------------------------------------------------------------------------


def test_grey_is_replicated(tmp_path: Path) -> None:
    codes = np.arange(0, 240, 10, dtype=np.uint8).reshape(4, 6)
    path = tmp_path / "grey.png"
    Image.fromarray(codes, "L").save(path)

    result = load_image(path, (6, 4))

    assert_valid(result, 6, 4)
    for channel in range(3):
        np.testing.assert_allclose(result[:, :, channel], srgb_to_linear(codes / 255), rtol=1e-6, atol=1e-8)


def test_grey_alpha_drops_alpha(tmp_path: Path) -> None:
    grey = np.arange(0, 240, 10, dtype=np.uint8).reshape(4, 6)
    alpha = np.zeros_like(grey)
    alpha[::2] = 255
    path = tmp_path / "greyalpha.png"
    Image.fromarray(np.dstack([grey, alpha]), "LA").save(path)

    result = load_image(path, (6, 4))

    expected = np.repeat(srgb_to_linear(grey / 255)[:, :, None], 3, axis=2)
    np.testing.assert_allclose(result, expected, rtol=1e-6, atol=1e-8)


def test_rgba_drops_alpha(tmp_path: Path) -> None:
    rng = np.random.default_rng(3)
    rgb = rng.integers(0, 256, size=(5, 7, 3), dtype=np.uint8)
    alpha = rng.integers(0, 256, size=(5, 7, 1), dtype=np.uint8)
    alpha[0, 0] = 0  # fully transparent pixels keep their colour
    path = tmp_path / "rgba.png"
    Image.fromarray(np.concatenate([rgb, alpha], axis=2), "RGBA").save(path)

    result = load_image(path, (7, 5))

    np.testing.assert_allclose(result, srgb_to_linear(rgb / 255), rtol=1e-6, atol=1e-8)


def test_rgba_16bit_drops_alpha(tmp_path: Path) -> None:
    rgba = np.zeros((2, 3, 4), dtype=np.uint16)
    rgba[..., 0], rgba[..., 1], rgba[..., 2], rgba[..., 3] = 1000, 30001, 65535, 7
    path = tmp_path / "rgba16.png"
    save_png_rgb16(path, rgba)

    result = load_image(path, (3, 2), response="linear")

    np.testing.assert_allclose(
        result, np.broadcast_to([1000 / 65535, 30001 / 65535, 1.0], (2, 3, 3)), rtol=1e-6
    )


@pytest.mark.parametrize("transparency", [False, True])
def test_palette(tmp_path: Path, transparency: bool) -> None:
    colours = np.array([[255, 0, 0], [0, 128, 255], [10, 20, 30], [200, 200, 0]], dtype=np.uint8)
    indices = np.array([[0, 1, 2, 3], [3, 2, 1, 0], [1, 1, 0, 2]], dtype=np.uint8)
    image = Image.fromarray(indices, "P")
    image.putpalette(colours.ravel().tolist())
    path = tmp_path / "palette.png"
    if transparency:
        image.save(path, transparency=1)
    else:
        image.save(path)
    with Image.open(path) as image:
        assert image.mode == "P"

    result = load_image(path, (4, 3))

    np.testing.assert_allclose(result, srgb_to_linear(colours[indices] / 255), rtol=1e-6, atol=1e-8)


# --- file formats ---------------------------------------------------------------------------


def test_jpeg(tmp_path: Path) -> None:
    rgb = np.zeros((16, 16, 3), dtype=np.uint8)
    rgb[:8, :8] = [200, 40, 90]
    rgb[:8, 8:] = [30, 180, 60]
    rgb[8:, :8] = [128, 128, 128]
    rgb[8:, 8:] = [250, 250, 10]
    path = tmp_path / "photo.jpg"
    Image.fromarray(rgb, "RGB").save(path, quality=100, subsampling=0)

    result = load_image(path, (16, 16))

    assert_valid(result, 16, 16)
    # JPEG is lossy: compare block centres loosely in encoded units.
    encoded = linear_to_srgb(result)
    for y in (3, 11):
        for x in (3, 11):
            np.testing.assert_allclose(encoded[y, x], rgb[y, x] / 255, atol=4 / 255)


@pytest.mark.parametrize(("name", "seed"), [("picture.bmp", 4), ("picture.tif", 5)], ids=["bmp", "tiff_8bit"])
def test_lossless_8bit_formats(tmp_path: Path, name: str, seed: int) -> None:
    rng = np.random.default_rng(seed)
    rgb = rng.integers(0, 256, size=(6, 9, 3), dtype=np.uint8)
    path = tmp_path / name
    Image.fromarray(rgb, "RGB").save(path)

    result = load_image(path, (9, 6))

    np.testing.assert_allclose(result, srgb_to_linear(rgb / 255), rtol=1e-6, atol=1e-8)


def test_tiff_16bit(tmp_path: Path) -> None:
    codes = np.array([[[1, 2, 3], [40000, 40001, 65535]]], dtype=np.uint16)
    path = tmp_path / "deep.tiff"
    save_png_rgb16(path, codes)  # OpenCV picks TIFF from the suffix

    result = load_image(path, (2, 1), response="linear")

    np.testing.assert_allclose(result, codes / 65535, rtol=1e-6, atol=1e-10)


def test_cmyk_tiff_is_converted(tmp_path: Path) -> None:
    cmyk = np.array([[[0, 0, 0, 0], [255, 0, 0, 0], [0, 0, 0, 255]]], dtype=np.uint8)
    path = tmp_path / "print.tif"
    Image.fromarray(cmyk, "CMYK").save(path)

    result = load_image(path, (3, 1), response="linear")

    # white, cyan, black
    np.testing.assert_allclose(result[0], [[1, 1, 1], [0, 1, 1], [0, 0, 0]], atol=1e-6)


def test_pillow_fallback_tga(tmp_path: Path) -> None:
    rng = np.random.default_rng(9)
    rgb = rng.integers(0, 256, size=(5, 6, 3), dtype=np.uint8)
    path = tmp_path / "legacy.tga"
    Image.fromarray(rgb, "RGB").save(path)
    assert cv2.imdecode(np.fromfile(path, np.uint8), cv2.IMREAD_UNCHANGED) is None  # OpenCV can't

    result = load_image(path, (6, 5))

    np.testing.assert_allclose(result, srgb_to_linear(rgb / 255), rtol=1e-6, atol=1e-8)


def save_im(path: Path, image: Image.Image) -> None:
    """Pillow's IM format stores 16-bit, 32-bit integer and float grey, and OpenCV cannot read it."""
    Image.init()
    if "IM" not in Image.SAVE:
        pytest.skip("this Pillow cannot write IM files")
    image.save(path)


IM_DEPRECATED = pytest.mark.filterwarnings("ignore:IM image format is deprecated:DeprecationWarning")


@IM_DEPRECATED
def test_pillow_fallback_keeps_16_bits_and_floats(tmp_path: Path) -> None:
    codes = np.array([[5, 40000, 40001]], dtype=np.uint16)
    deep = tmp_path / "deep.im"
    save_im(deep, Image.fromarray(codes))
    floats = np.array([[0.25, 7.0, 0.0]], dtype=np.float32)
    radiance = tmp_path / "radiance.im"
    save_im(radiance, Image.fromarray(floats, "F"))
    assert cv2.imdecode(np.fromfile(deep, np.uint8), cv2.IMREAD_UNCHANGED) is None

    deep_result = load_image(deep, (3, 1), response="linear")
    radiance_result = load_image(radiance, (3, 1))

    np.testing.assert_allclose(deep_result[:, :, 1], codes / 65535, rtol=1e-6)
    np.testing.assert_array_equal(radiance_result[:, :, 2], floats)


@IM_DEPRECATED
def test_pillow_fallback_rejects_nan_and_wide_integers(tmp_path: Path) -> None:
    nan_path = tmp_path / "nan.im"
    save_im(nan_path, Image.fromarray(np.array([[0.5, np.nan]], dtype=np.float32), "F"))
    wide_path = tmp_path / "wide_int.im"
    save_im(wide_path, Image.fromarray(np.array([[5, 70000]], dtype=np.int32), "I"))

    assert "non-finite" in check_error(nan_path, (2, 1))
    assert "unsupported" in check_error(wide_path, (2, 1))


@pytest.mark.parametrize("response", ["srgb", "linear"])
def test_float_tiff_is_already_linear(tmp_path: Path, response: str) -> None:
    rgb = np.array([[[0.0, 0.25, 3.5], [1.0, 0.001, 0.5]]], dtype=np.float32)
    path = tmp_path / "radiance.tif"
    save_png_rgb16(path, rgb)
    grey = np.array([[0.1, 2.0, 0.0]], dtype=np.float32)
    grey_path = tmp_path / "radiance_grey.tif"
    Image.fromarray(grey, "F").save(grey_path)

    result = load_image(path, (2, 1), response=response)
    grey_result = load_image(grey_path, (3, 1), response=response)

    np.testing.assert_array_equal(result, rgb)
    np.testing.assert_array_equal(grey_result, np.repeat(grey[:, :, None], 3, axis=2))


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_float_tiff_non_finite_is_rejected(tmp_path: Path, bad: float) -> None:
    values = np.full((3, 3), 0.5, dtype=np.float32)
    values[1, 2] = bad
    path = tmp_path / "broken_float.tif"
    Image.fromarray(values, "F").save(path)

    with pytest.raises(AcquisitionError, match=error_match(path)) as info:
        load_image(path, (3, 3))
    assert "non-finite" in str(info.value)


# --- EXIF orientation -----------------------------------------------------------------------

# EXIF 2.3, tag 0x0112: the side of the displayed picture on which the stored 0th row and the
# stored 0th column lie.
EXIF_SIDES = {
    1: ("top", "left"),
    2: ("top", "right"),
    3: ("bottom", "right"),
    4: ("bottom", "left"),
    5: ("left", "top"),
    6: ("right", "top"),
    7: ("right", "bottom"),
    8: ("left", "bottom"),
}


def displayed(stored: np.ndarray, orientation: int) -> np.ndarray:
    """Place every stored pixel where the EXIF definition says a viewer shows it."""
    h, w = stored.shape[:2]
    row_side, col_side = EXIF_SIDES[orientation]
    sideways = row_side in ("left", "right")
    out = np.zeros(((w, h) if sideways else (h, w)) + stored.shape[2:], dtype=stored.dtype)
    for r in range(h):
        for c in range(w):
            if sideways:
                x = r if row_side == "left" else h - 1 - r
                y = c if col_side == "top" else w - 1 - c
            else:
                y = r if row_side == "top" else h - 1 - r
                x = c if col_side == "left" else w - 1 - c
            out[y, x] = stored[r, c]
    return out


def save_with_orientation(path: Path, rgb: np.ndarray, orientation: int, **options: object) -> None:
    exif = Image.Exif()
    exif[0x0112] = orientation
    Image.fromarray(rgb, "RGB").save(path, exif=exif, **options)


@pytest.mark.parametrize("orientation", range(1, 9))
def test_exif_orientation_png(tmp_path: Path, orientation: int) -> None:
    rng = np.random.default_rng(orientation)
    stored = rng.permutation(256)[: 3 * 5 * 3].reshape(3, 5, 3).astype(np.uint8)  # all distinct
    path = tmp_path / f"oriented{orientation}.png"
    save_with_orientation(path, stored, orientation)
    expected = displayed(stored, orientation)
    # The definition above agrees with Pillow's own transpose.
    with Image.open(path) as image:
        np.testing.assert_array_equal(np.asarray(ImageOps.exif_transpose(image)), expected)
    height, width = expected.shape[:2]

    result = load_image(path, SimpleNamespace(width=width, height=height), response="linear")

    np.testing.assert_array_equal(np.round(result * 255).astype(np.uint8), expected)


@pytest.mark.parametrize("orientation", range(1, 9))
def test_exif_orientation_jpeg(tmp_path: Path, orientation: int) -> None:
    palette = np.array(
        [[255, 0, 0], [0, 255, 0], [0, 0, 255], [255, 255, 0], [0, 255, 255], [255, 0, 255]], dtype=np.uint8
    )
    blocks = palette.reshape(2, 3, 3)  # 2 rows x 3 columns of 16-pixel blocks
    stored = np.repeat(np.repeat(blocks, 16, axis=0), 16, axis=1)
    path = tmp_path / f"oriented{orientation}.jpg"
    save_with_orientation(path, stored, orientation, quality=100, subsampling=0)
    # OpenCV's IMREAD_UNCHANGED leaves the pixels as stored; load_image must turn them itself.
    raw = cv2.imdecode(np.fromfile(path, np.uint8), cv2.IMREAD_UNCHANGED)
    assert raw.shape == stored.shape
    expected = displayed(stored, orientation)
    height, width = expected.shape[:2]

    result = load_image(path, (width, height), response="linear")

    for y in range(8, height, 16):
        for x in range(8, width, 16):
            np.testing.assert_allclose(result[y, x], expected[y, x] / 255, atol=0.05)


# --- resizing -------------------------------------------------------------------------------


def test_downsampling_averages_in_linear_light(tmp_path: Path) -> None:
    checker = np.indices((8, 8)).sum(axis=0) % 2 * 255
    rgb = np.repeat(checker[:, :, None], 3, axis=2).astype(np.uint8)
    path = tmp_path / "checker.png"
    Image.fromarray(rgb, "RGB").save(path)

    result = load_image(path, (4, 4))

    assert_valid(result, 4, 4)
    np.testing.assert_allclose(result, 0.5, atol=1e-6)
    # Averaging encoded values would have given code 127.5, i.e. about 0.21 linear.
    assert abs(srgb_to_linear(127.5 / 255) - 0.5) > 0.25


def test_downsampling_is_block_mean(tmp_path: Path) -> None:
    rng = np.random.default_rng(6)
    rgb = rng.integers(0, 256, size=(12, 18, 3), dtype=np.uint8)
    path = tmp_path / "random.png"
    Image.fromarray(rgb, "RGB").save(path)

    result = load_image(path, (6, 4))  # 3x3 blocks

    expected = srgb_to_linear(rgb / 255).reshape(4, 3, 6, 3, 3).mean(axis=(1, 3))
    np.testing.assert_allclose(result, expected, rtol=1e-5, atol=1e-6)


def test_upsampling_warns(tmp_path: Path) -> None:
    rgb = np.full((4, 6, 3), [10, 100, 250], dtype=np.uint8)
    path = tmp_path / "small.png"
    Image.fromarray(rgb, "RGB").save(path)

    with pytest.warns(UserWarning, match=error_match(path)):
        result = load_image(path, (12, 8))

    assert_valid(result, 12, 8)
    np.testing.assert_allclose(
        result, np.broadcast_to(srgb_to_linear(rgb[0, 0] / 255), (8, 12, 3)), rtol=1e-5
    )


def test_same_size_and_downsampling_do_not_warn(tmp_path: Path) -> None:
    path = tmp_path / "plain.png"
    Image.fromarray(np.zeros((8, 8, 3), dtype=np.uint8), "RGB").save(path)

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        load_image(path, (8, 8))
        load_image(path, (4, 4))


def test_small_aspect_difference_is_resized(tmp_path: Path) -> None:
    path = tmp_path / "almost.png"
    Image.fromarray(np.full((100, 200, 3), 255, dtype=np.uint8), "RGB").save(path)

    result = load_image(path, (199, 100))  # 0.5% narrower

    assert_valid(result, 199, 100)
    np.testing.assert_allclose(result, 1.0, atol=1e-6)


def test_wrong_aspect_ratio_is_an_error(tmp_path: Path) -> None:
    path = tmp_path / "wide.png"
    Image.fromarray(np.zeros((10, 20, 3), dtype=np.uint8), "RGB").save(path)

    with pytest.raises(AcquisitionError, match=error_match(path)) as info:
        load_image(path, (10, 10))
    message = str(info.value)
    assert "20x10" in message
    assert "10x10" in message
    assert "crop=True" in message


def test_crop_keeps_the_centre_of_a_wide_image(tmp_path: Path) -> None:
    rgb = np.zeros((20, 60, 3), dtype=np.uint8)
    rgb[:, 20:40] = [255, 128, 0]  # centre square
    path = tmp_path / "wide.png"
    Image.fromarray(rgb, "RGB").save(path)

    result = load_image(path, (10, 10), crop=True)

    assert_valid(result, 10, 10)
    np.testing.assert_allclose(
        result, np.broadcast_to(srgb_to_linear(np.array([1.0, 128 / 255, 0])), (10, 10, 3))
    )


def test_crop_keeps_the_centre_of_a_tall_image(tmp_path: Path) -> None:
    rgb = np.zeros((30, 10, 3), dtype=np.uint8)
    rgb[10:20] = [0, 0, 255]
    rgb[10, 0] = [0, 255, 0]  # top-left of the kept region
    path = tmp_path / "tall.png"
    Image.fromarray(rgb, "RGB").save(path)

    result = load_image(path, (10, 10), crop=True)

    expected = np.zeros((10, 10, 3), dtype=np.float32)
    expected[:, :, 2] = 1.0
    expected[0, 0] = [0, 1, 0]
    np.testing.assert_array_equal(result, expected)


def test_scene_object_and_tuple_agree(tmp_path: Path) -> None:
    path = tmp_path / "scene.png"
    Image.fromarray(np.random.default_rng(7).integers(0, 256, (6, 8, 3), dtype=np.uint8), "RGB").save(path)

    by_tuple = load_image(str(path), (4, 3))
    by_object = load_image(path, SimpleNamespace(width=4, height=3))

    assert_valid(by_tuple, 4, 3)
    np.testing.assert_array_equal(by_tuple, by_object)


# --- errors ---------------------------------------------------------------------------------


def check_error(path: Path, scene: object = (4, 4), **options: object) -> str:
    with pytest.raises(AcquisitionError, match=error_match(path)) as info:
        load_image(path, scene, **options)
    message = str(info.value)
    assert "\n" not in message
    return message


def test_missing_file(tmp_path: Path) -> None:
    assert "no such file" in check_error(tmp_path / "absent.png")


def test_directory(tmp_path: Path) -> None:
    folder = tmp_path / "folder.png"
    folder.mkdir()
    assert "directory" in check_error(folder)


def test_empty_file(tmp_path: Path) -> None:
    path = tmp_path / "empty.png"
    path.write_bytes(b"")
    assert "empty" in check_error(path)


def test_text_file_renamed_png(tmp_path: Path) -> None:
    path = tmp_path / "notes.png"
    path.write_text("this is not an image\nat all\n")
    check_error(path)


@pytest.mark.parametrize("suffix", ["png", "jpg"])
def test_truncated_file(tmp_path: Path, suffix: str) -> None:
    rgb = np.random.default_rng(8).integers(0, 256, (32, 32, 3), dtype=np.uint8)
    whole = tmp_path / f"whole.{suffix}"
    Image.fromarray(rgb, "RGB").save(whole)
    path = tmp_path / f"truncated.{suffix}"
    path.write_bytes(whole.read_bytes()[: whole.stat().st_size // 2])
    check_error(path)


def png_bytes(width: int, height: int) -> bytes:
    def chunk(kind: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))

    header = struct.pack(">IIBBBBB", width, height, 8, 2, 0, 0, 0)
    rows = b"".join(b"\0" + bytes(3 * width) for _ in range(height))
    return (
        b"\x89PNG\r\n\x1a\n"
        + chunk(b"IHDR", header)
        + chunk(b"IDAT", zlib.compress(rows))
        + chunk(b"IEND", b"")
    )


def test_hand_made_png_is_readable(tmp_path: Path) -> None:
    path = tmp_path / "handmade.png"
    path.write_bytes(png_bytes(4, 4))
    np.testing.assert_array_equal(load_image(path, (4, 4)), 0.0)


def test_zero_width_png(tmp_path: Path) -> None:
    path = tmp_path / "zerowidth.png"
    path.write_bytes(png_bytes(0, 4))
    check_error(path)


def test_zero_size_decoded_image(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    # No encoder writes an empty image and decoders reject one, so stand in for the decoder.
    path = tmp_path / "nothing.png"
    path.write_bytes(png_bytes(4, 4))
    monkeypatch.setattr(cv2, "imdecode", lambda data, flags: np.zeros((0, 4, 3), dtype=np.uint8))
    assert "zero size" in check_error(path)


def test_unknown_response(tmp_path: Path) -> None:
    path = tmp_path / "fine.png"
    path.write_bytes(png_bytes(4, 4))
    message = check_error(path, response="gamma2.2")
    assert "response" in message
    assert "gamma2.2" in message


@pytest.mark.parametrize("scene", [(0, 4), (4, -1), (4.0, 4), (4,), "4x4", SimpleNamespace(width=4)])
def test_invalid_scene(tmp_path: Path, scene: object) -> None:
    path = tmp_path / "fine.png"
    path.write_bytes(png_bytes(4, 4))
    check_error(path, scene)


def test_unsupported_sample_type(tmp_path: Path) -> None:
    path = tmp_path / "signed.tif"
    Image.fromarray(np.full((4, 4), -5, dtype=np.int32), "I").save(path)
    assert "unsupported" in check_error(path)
