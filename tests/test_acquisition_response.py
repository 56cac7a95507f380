"""Photos through a chosen camera response (rtloop.acquisition.response): gamma, tables, RAW-like
16-bit TIFF with black and white levels, and the same decoding and resizing rules as load_image."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import colour
import cv2
import numpy as np
import pytest

import rtloop
from rtloop.acquisition import AcquisitionError, load_photo, parse_response, photo_info


def write16(path: Path, rgb: np.ndarray) -> Path:
    assert cv2.imwrite(str(path), np.ascontiguousarray(rgb[:, :, ::-1].astype(np.uint16)))
    return path


@pytest.fixture
def codes16() -> np.ndarray:
    rng = np.random.default_rng(3)
    return rng.integers(0, 65536, size=(6, 8, 3)).astype(np.uint16)


def test_srgb_and_linear_responses_against_colour_science(tmp_path: Path, codes16) -> None:
    """The 16-bit codes decoded by rtloop against an independent implementation of IEC 61966-2-1
    (colour-science's sRGB decoding) and against the plain ratio for "linear"; and load_image reads the
    same file the same way."""
    path = write16(tmp_path / "a.png", codes16)
    v = codes16 / 65535.0
    np.testing.assert_allclose(load_photo(path, response="srgb"), colour.cctf_decoding(v, function="sRGB"),
                               rtol=1e-5, atol=1e-7)
    np.testing.assert_allclose(load_photo(path, response="linear"), v, rtol=1e-6, atol=1e-8)
    for response in ("srgb", "linear"):
        np.testing.assert_array_equal(load_photo(path, response=response),
                                      rtloop.load_image(path, (8, 6), response=response))


def test_gamma_response(tmp_path: Path, codes16) -> None:
    path = write16(tmp_path / "g.png", codes16)
    got = load_photo(path, response="gamma:2.2")
    np.testing.assert_allclose(got, (codes16 / 65535.0) ** 2.2, rtol=1e-5, atol=1e-7)
    assert parse_response(1.8).gamma == 1.8 and parse_response("2.4").kind == "gamma"


def test_table_response_csv_one_curve_and_per_channel(tmp_path: Path) -> None:
    codes = np.array([[[0, 64, 128], [192, 255, 32]]], np.uint8)
    path = tmp_path / "t.png"
    assert cv2.imwrite(str(path), codes[:, :, ::-1])
    table = tmp_path / "curve.csv"
    table.write_text("code,linear\n0,0\n128,0.2\n255,0.8\n")  # normalised: top -> 1
    got = load_photo(path, response=table)
    expected_one = np.interp(codes / 255.0, [0, 128 / 255, 1], [0, 0.25, 1.0])
    np.testing.assert_allclose(got, expected_one, atol=2e-5)
    per_channel = tmp_path / "rgb.csv"
    per_channel.write_text("0,0,0,0\n255,1,0.5,0.25\n")  # channel gains kept, brightest channel -> 1
    got = load_photo(path, response=per_channel)
    np.testing.assert_allclose(got, codes / 255.0 * np.array([1, 0.5, 0.25]), atol=2e-5)


def test_table_response_json_debevec_shape(tmp_path: Path) -> None:
    """cv2.createCalibrateDebevec returns (256, 1, 3): one linear value per 8-bit code and channel."""
    curve = np.linspace(0, 1, 256) ** 2.0
    table = np.repeat(curve[:, None, None], 3, axis=2)
    path = tmp_path / "debevec.json"
    path.write_text(json.dumps({"linear": table.tolist()}))
    image = tmp_path / "i.png"
    codes = np.arange(0, 256, 5, dtype=np.uint8).reshape(1, -1)
    assert cv2.imwrite(str(image), codes)
    got = load_photo(image, response=path)
    np.testing.assert_allclose(got[0, :, 0], (codes[0] / 255.0) ** 2, atol=2e-5)


def test_raw_like_16bit_tiff_with_black_and_white_levels(tmp_path: Path) -> None:
    """A 12-bit sensor's linear counts in a 16-bit TIFF: black 256, white 4095."""
    rng = np.random.default_rng(4)
    linear = rng.uniform(0, 1, (10, 12, 3))
    counts = np.round(256 + linear * (4095 - 256)).astype(np.uint16)
    path = write16(tmp_path / "raw.tiff", counts)
    info = photo_info(path)
    assert info["dtype"] == "uint16" and (info["width"], info["height"]) == (12, 10)
    got = load_photo(path, response="linear", black_level=256, white_level=4095)
    np.testing.assert_allclose(got, linear, atol=1 / 3839)
    with pytest.raises(AcquisitionError, match="black level 5000 and white level 4095"):
        load_photo(path, response="linear", black_level=5000, white_level=4095)


def test_resizing_happens_after_linearising(tmp_path: Path) -> None:
    """A black/white checker of a gamma-2 camera averages to linear 0.5 (not to the decoded mean code)."""
    checker = (np.indices((8, 8)).sum(axis=0) % 2 * 255).astype(np.uint8)
    path = tmp_path / "checker.png"
    assert cv2.imwrite(str(path), checker)
    got = load_photo(path, (2, 2), response="gamma:2.0")
    np.testing.assert_allclose(got, 0.5, atol=1e-6)
    with pytest.raises(AcquisitionError, match="aspect ratios differ"):
        load_photo(path, (4, 2), response="gamma:2.0")
    assert load_photo(path, (4, 2), response="gamma:2.0", crop=True).shape == (2, 4, 3)


@pytest.mark.parametrize(
    ("spec", "content", "message"),
    [
        ("nonsense", None, "not a known response and no such file"),
        ("gamma:9", None, "between 0.2 and 5"),
        ("gamma:abc", None, "is not a number"),
        ("down.csv", "0,0\n128,0.5\n255,0.4\n", "must not decrease"),
        ("short.csv", "0,0\n128,0.5\n", "must span the codes"),
        ("ragged.csv", "0,0\n128\n255,1\n", "same 1, 2, 3 or 4 numbers"),
        ("bad.json", "{oops", "cannot read the response table"),
    ],
)
def test_bad_responses_are_clear_errors(tmp_path: Path, spec: str, content: str | None, message: str) -> None:
    if content is not None:
        (tmp_path / spec).write_text(content)
        spec = str(tmp_path / spec)
    with pytest.raises(AcquisitionError, match=message):
        parse_response(spec)


def test_missing_photo_is_a_clear_error(tmp_path: Path) -> None:
    with pytest.raises(AcquisitionError, match="no such file"):
        load_photo(tmp_path / "nope.png", response="gamma:2.2")


def test_raw_without_rawpy_is_a_clear_error(tmp_path: Path, monkeypatch) -> None:
    path = tmp_path / "IMG_0001.CR2"
    path.write_bytes(b"not looked at")
    monkeypatch.setitem(sys.modules, "rawpy", None)  # import rawpy raises ImportError
    with pytest.raises(AcquisitionError, match=r"IMG_0001\.CR2: a camera RAW file.*rawpy.*rtloop\[raw\]"):
        load_photo(path)


def test_raw_file_libraw_cannot_read_is_a_clear_error(tmp_path: Path) -> None:
    pytest.importorskip("rawpy")
    path = tmp_path / "broken.nef"
    path.write_bytes(b"\x00" * 64)
    with pytest.raises(AcquisitionError, match=r"broken\.nef: LibRaw cannot read it"):
        load_photo(path)


def _flat_dng(path: Path, code: int, w: int = 64, h: int = 48, bits: int = 12) -> Path:
    """A flat grey RGGB DNG (identity colour matrix, neutral as-shot white) written by pidng."""
    core = pytest.importorskip("pidng.core")
    defs = pytest.importorskip("pidng.defs")
    t, tag = core.DNGTags(), core.Tag
    for key, value in [
        (tag.ImageWidth, w), (tag.ImageLength, h), (tag.TileWidth, w), (tag.TileLength, h),
        (tag.Orientation, defs.Orientation.Horizontal),
        (tag.PhotometricInterpretation, defs.PhotometricInterpretation.Color_Filter_Array),
        (tag.SamplesPerPixel, 1), (tag.BitsPerSample, bits), (tag.CFARepeatPatternDim, [2, 2]),
        (tag.CFAPattern, defs.CFAPattern.RGGB), (tag.BlackLevel, 0), (tag.WhiteLevel, (1 << bits) - 1),
        (tag.ColorMatrix1, [[1, 1], [0, 1], [0, 1], [0, 1], [1, 1], [0, 1], [0, 1], [0, 1], [1, 1]]),
        (tag.CalibrationIlluminant1, defs.CalibrationIlluminant.D65), (tag.AsShotNeutral, [[1, 1]] * 3),
        (tag.Make, "rtloop"), (tag.Model, "test"), (tag.DNGVersion, defs.DNGVersion.V1_4),
        (tag.DNGBackwardVersion, defs.DNGVersion.V1_2), (tag.PreviewColorSpace, defs.PreviewColorSpace.sRGB),
    ]:
        t.set(key, value)
    r = core.RAW2DNG()
    r.options(t, path="", compress=False)
    r.convert(np.full((h, w), code, np.uint16), filename=str(path.with_suffix("")))
    return path


@pytest.mark.parametrize("code", [500, 1000, 2000])
def test_dng_is_read_linear(tmp_path: Path, code: int) -> None:
    """A DNG through rawpy: code / white level, no tone curve (the closed form), at any size asked."""
    pytest.importorskip("rawpy")
    path = _flat_dng(tmp_path / "flat.dng", code)
    img = load_photo(path)
    assert img.shape == (48, 64, 3)
    assert np.allclose(img, code / 4095, atol=2e-4)
    assert np.allclose(load_photo(path, (32, 24)), code / 4095, atol=2e-4)
