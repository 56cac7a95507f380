"""The shared helpers: sRGB both ways (rtloop._srgb), safe writes (rtloop._files), the edge test and the
saturation threshold (rtloop._pixels)."""

from __future__ import annotations

import json
import os
import stat
from pathlib import Path

import numpy as np
import pytest

from rtloop import _files, _pixels, _srgb


def test_srgb_known_values_and_round_trip():
    # IEC 61966-2-1: the linear segment below 0.0031308, 0.5 encodes to 0.735357, 1 to 1.
    x = np.array([0.0, 0.002, 0.0031308, 0.18, 0.5, 1.0, 2.0, -1.0])
    enc = _srgb.encode(x, np.float64)
    assert enc[:2] == pytest.approx([0.0, 0.02584])
    assert enc[4] == pytest.approx(0.7353569830524495, rel=1e-12)
    assert enc[5] == enc[6] == pytest.approx(1.0, abs=1e-15) and enc[7] == 0.0  # clipped
    assert _srgb.decode(enc[:6]) == pytest.approx(x[:6], rel=1e-12, abs=1e-15)
    assert list(_srgb.encode8(x, np.float64)) == [0, 7, 10, 118, 188, 255, 255, 0]


def test_srgb_keeps_the_callers_precision():
    x = np.linspace(0, 1, 101, dtype=np.float32)
    assert _srgb.encode(x).dtype == np.float32 and _srgb.decode(x).dtype == np.float32
    assert _srgb.encode(x, np.float64).dtype == np.float64
    # float32 arithmetic is not float64 arithmetic rounded: a caller that asked for float32 gets it.
    assert not np.array_equal(_srgb.encode(x).astype(np.float64), _srgb.encode(x, np.float64))


def test_write_bytes_is_atomic_and_leaves_nothing_behind(tmp_path):
    path = tmp_path / "a" / "f.bin"
    with pytest.raises(FileNotFoundError):
        _files.write_bytes(path, b"x")
    _files.write_bytes(path, b"one", parents=True)
    _files.write_text(path, "two")
    assert path.read_text(encoding="utf-8") == "two"
    assert os.listdir(path.parent) == ["f.bin"]
    assert stat.S_IMODE(path.stat().st_mode) == 0o666 & ~_files.umask()


def test_jsonable_and_write_json(tmp_path):
    value = {1: np.float32(0.5), "a": [np.int64(3), (np.bool_(True), float("nan"))], "b": np.array([1.0, np.inf])}
    assert _files.jsonable(value) == {"1": 0.5, "a": [3, [True, None]], "b": [1.0, None]}
    _files.write_json(tmp_path / "d" / "x.json", value)
    assert json.loads((tmp_path / "d" / "x.json").read_text(encoding="utf-8"))["b"] == [1.0, None]


def test_staged_directory_replaces_the_old_one_whole(tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    (out / "old.txt").write_text("old", encoding="utf-8")
    tmp = _files.staging_dir(out, "test")
    assert tmp.parent == tmp_path and tmp.name.startswith(".out.test-")
    assert stat.S_IMODE(tmp.stat().st_mode) == 0o777 & ~_files.umask()
    (tmp / "new.txt").write_text("new", encoding="utf-8")
    assert _files.move_into_place(tmp, out, True, "test") is None
    assert os.listdir(out) == ["new.txt"] and sorted(os.listdir(tmp_path)) == ["out"]
    with pytest.raises(_files.PlaceError, match="cannot move the results into place"):
        _files.move_into_place(tmp_path / "missing", tmp_path / "other", False, "test")


def test_edges_are_the_4_neighbour_boundaries():
    labels = np.full((5, 6), -1)
    labels[1:4, 1:3] = 0
    e = _pixels.edges(labels)
    # Every pixel of the 3x2 block touches the background, and so do its 4-neighbours outside it; the
    # corners diagonal to it and the far column do not.
    assert e[1:4, 1:3].all() and e[1:4, 0].all() and e[1:4, 3].all() and e[0, 1:3].all() and e[4, 1:3].all()
    assert not e[0, 0] and not e[4, 3] and not e[:, 4:].any()
    assert _pixels.SATURATED == 0.999


def test_products_split_back_and_bounds():
    """fit/products.py: the products written back as albedos and an intensity give those products again;
    the intensity stays at the scene's value unless an albedo would exceed its bound."""
    import rtloop
    from rtloop.fit import products as products_module

    d = json.loads((Path(__file__).resolve().parents[1] / "examples/yellow-ball/scene_input.json").read_text(
        encoding="utf-8"))
    scene = rtloop.load_scene(d)
    bounds = products_module.product_bounds(scene)
    assert bounds.shape == (2, 4, 2)
    assert bounds[0, :3].tolist() == [[0.0, 400.0]] * 3 and bounds[:, 3].tolist() == [[0.0, 0.0]] * 2
    for rows, intensity in (([[4.0, 3.0, 1.0], [2.0, 2.0, 2.0]], 20.0), ([[30.0, 3.0, 1.0], [2.0, 2.0, 2.0]], 30.0)):
        split = products_module.split_products(scene, rows, scene)
        assert split.get_params(["light.intensity"]) == [intensity]
        got = products_module.products(split)
        assert got["ball"] == pytest.approx(rows[0], rel=1e-15) and got["floor"] == pytest.approx(rows[1], rel=1e-15)


def test_code_values_are_the_formula_at_every_8_bit_code():
    """The 256 linear values an 8-bit photo can hold: the exact formula's, as load_image decodes a file."""
    from rtloop.acquisition.objective import _lookup_table

    want = _srgb.decode(np.arange(256, dtype=np.float64) / 255).astype(np.float32)
    assert np.array_equal(_srgb.code_values().view(np.uint32), want.view(np.uint32))
    assert np.array_equal(_lookup_table(256, "srgb").view(np.uint32), want.view(np.uint32))
    assert not _srgb.code_values().flags.writeable


def test_codes8_finds_the_codes_of_exactly_those_values():
    """codes8: the codes of an image of code values (any shape, any strides); None as soon as one value is
    not bit for bit a code's: either float32 neighbour of every code's value, a negative zero, a negative,
    values above 1, NaN, infinity, a subnormal, another dtype."""
    rng = np.random.default_rng(0)
    codes = rng.integers(0, 256, (24, 32, 3)).astype(np.uint8)
    x = _srgb.code_values()[codes]
    assert np.array_equal(_srgb.codes8(x), codes) and _srgb.codes8(x).dtype == np.uint8
    assert np.array_equal(_srgb.codes8(x[:, ::3]), codes[:, ::3])
    assert np.array_equal(_srgb.codes8(_srgb.code_values()), np.arange(256))
    for direction in (-np.inf, np.inf):
        near = np.nextafter(_srgb.code_values(), np.float32(direction))
        for v in near:
            y = x.copy()
            y[3, 4, 1] = v
            assert _srgb.codes8(y) is None, v
    for v in (-0.0, -_srgb.code_values()[9], 1.5, np.nan, np.inf, 1e-40):
        y = x.copy()
        y[0, 0, 0] = v
        assert _srgb.codes8(y) is None, v
    assert _srgb.codes8(x.astype(np.float64)) is None
    assert _srgb.codes8(np.zeros((0, 3), np.float32)) is None


def test_per_code_is_the_function_of_the_values_bit_for_bit():
    """per_code(fn, codes) is fn(values) itself (computed once per code), for each precision's transfer
    functions."""
    rng = np.random.default_rng(1)
    codes = rng.integers(0, 256, (40, 50, 3)).astype(np.uint8)
    x = _srgb.code_values()[codes]
    for fn in (_encode32, _encode64_decode):
        got, want = _srgb.per_code(fn, codes), fn(x)
        assert got.dtype == want.dtype and np.array_equal(got.view(np.uint8), want.view(np.uint8)), fn


def _encode32(x):
    return _srgb.encode(x, np.float32)


def _encode64_decode(x):
    return _srgb.decode(_srgb.encode(x, np.float64) * 0.5)
