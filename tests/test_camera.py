"""The camera between the scene and the file (rtloop.fit.camera): vignetting and a tone curve, on Mitsuba
renders passed through a camera's processing (tests/fixtures/camera, tools/make_camera_photos.py), scored
against their truth."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import rtloop
from rtloop.errors import RtloopError

FIXTURES = Path(__file__).parent / "fixtures" / "camera"
PHOTOS = Path(__file__).parent / "fixtures" / "photos"


def _load(folder: Path) -> tuple[rtloop.Scene, np.ndarray, dict, dict]:
    scene = rtloop.load_scene(folder / "scene_input.json")
    image = rtloop.load_image(folder / "objective.png", scene)
    return scene, image, json.loads((folder / "scene.json").read_text()), json.loads((folder / "meta.json").read_text())


def _errors(res: rtloop.FitResult, truth: dict) -> tuple[float, float, float]:
    """Light error (m), worst product error and worst product error up to one common scale (relative to
    each object's largest true product), as ../shared/tools/score_result.py measures them."""
    fitted = res.scene.to_dict()
    light = float(np.linalg.norm(np.subtract(fitted["light"]["position"], truth["light"]["position"])))

    def products(s: dict) -> np.ndarray:
        rgb = float(s["light"]["intensity"]) * np.array(s["light"].get("color", [1, 1, 1]), float)
        return np.array([rgb * np.array(o["material"]["albedo"], float) for o in s["objects"]])

    f, t = products(fitted), products(truth)
    k = math.exp(float(np.mean(np.log(t / f))))
    worst = max(float(np.max(np.abs(a - b)) / np.max(b)) for a, b in zip(f, t))
    scaled = max(float(np.max(np.abs(k * a - b)) / np.max(b)) for a, b in zip(f, t))
    return light, worst, scaled


def _falloff(scene: rtloop.Scene, k1: float, k2: float) -> np.ndarray:
    """cos^4 x (1 + k1 r^2 + k2 r^4) of a pinhole with the scene's vertical field of view, r = 1 at the
    corner (written here from the camera, independently of the package)."""
    h, w = scene.height, scene.width
    f = (h / 2) / math.tan(math.radians(scene.to_dict()["camera"]["vfov_deg"]) / 2)
    yy, xx = np.mgrid[0:h, 0:w]
    px, py = xx + 0.5 - w / 2, yy + 0.5 - h / 2
    cos = f / np.sqrt(f * f + px * px + py * py)
    r2 = (px * px + py * py) / ((w / 2) ** 2 + (h / 2) ** 2)
    return cos**4 * (1 + k1 * r2 + k2 * r2 * r2)


def _fit_choosing(name: str, term: str) -> tuple[rtloop.FitResult, dict, dict, dict]:
    """The default fit of fixture ``name``, whose camera model must have chosen ``term`` alone: (result, its
    camera model, the truth, the fixture's meta)."""
    scene, image, truth, meta = _load(FIXTURES / name)
    res = rtloop.fit(scene, image, uncertainty=False)
    cam = res.model["camera"]
    assert cam["terms"] == [term]
    return res, cam, truth, meta


@pytest.mark.parametrize("name", ["blue-ball-vignette", "orange-ball-vignette"])
def test_vignetting_is_chosen_and_fitted_with_the_light(name):
    res, cam, truth, meta = _fit_choosing(name, "vignetting")
    assert cam["evidence"]["vignetting"]["selected"] and not cam["evidence"]["tone"]["selected"]
    light, worst, _ = _errors(res, truth)
    # without the term: 7.7 and 119 cm, the floor's products 27 % and 52 % off
    assert light < 0.01
    assert worst < 0.02
    k = cam["vignetting"]
    assert (k["k1"], k["k2"]) == pytest.approx((meta["post"]["k1"], meta["post"]["k2"]), abs=0.03)


@pytest.mark.parametrize("name", ["blue-ball-tone", "orange-ball-tone"])
def test_tone_curve_is_chosen_and_fitted_with_the_light(name):
    res, cam, truth, _ = _fit_choosing(name, "tone")
    light, _, scaled = _errors(res, truth)
    # without the term: 100 cm off, products 47 % and 39 % off; the curve's top (its scale) is weakly
    # determined, the colours relative to each other are
    assert light < 0.05
    assert scaled < 0.05
    curve = np.array(cam["tone"]["linear_at_knots"])
    assert (np.diff(curve) >= 0).all() and curve[0] == 0 and curve[-1] == pytest.approx(1.0)
    # the truth's curve: gamma 2.2 under the S-curve u^a / (u^a + (1 - u)^a), inverted at the knots
    v = np.clip(np.array(cam["tone"]["knots"]), 1e-9, 1 - 1e-9)
    q = (v / (1 - v)) ** (1 / 1.5)
    true = (q / (1 + q)) ** 2.2
    assert np.max(np.abs(curve - true)) < 0.1


@pytest.mark.parametrize("source", ["k1,k2", "flat field"])
def test_a_given_falloff_divides_the_photo(source):
    scene, image, truth, meta = _load(FIXTURES / "blue-ball-vignette")
    k1, k2 = meta["post"]["k1"], meta["post"]["k2"]
    if source == "k1,k2":
        res = rtloop.fit(scene, image, vignetting=(k1, k2), uncertainty=False)
    else:
        flat = 0.8 * _falloff(scene, k1, k2)  # a flat white target, exposed below white
        res = rtloop.fit(scene, image, flat_field=np.repeat(flat[..., None], 3, axis=2).astype(np.float32),
                         uncertainty=False)
    assert res.model["camera"]["terms"] == ["vignetting"]
    light, worst, _ = _errors(res, truth)
    assert light < 0.01
    assert worst < 0.02


@pytest.mark.parametrize("name", ["direct-overhead", "direct-two-balls", "env-overhead", "bounce-red-ball"])
def test_photos_without_a_camera_keep_the_ordinary_fit_bit_for_bit(name):
    scene, image, _, _ = _load(PHOTOS / name)
    auto = rtloop.fit(scene, image, uncertainty=False)
    off = rtloop.fit(scene, image, uncertainty=False, vignetting="off", tone="off")
    assert auto.model["camera"]["terms"] == []
    assert auto.x == off.x
    assert auto.products == off.products


@pytest.mark.parametrize("name", ["blue-ball-bayer", "orange-ball-bayer"])
def test_sensor_noise_and_demosaicing_select_no_camera_term(name):
    """A noisy sensor's demosaiced JPEG: no camera term, and the linear loss, its errors not alike in code
    values (the dark pixels' read noise and clipping at 0 are many codes), which the sRGB loss would follow."""
    scene, image, truth, _ = _load(FIXTURES / name)
    res = rtloop.fit(scene, image, uncertainty=False)
    assert res.model["camera"]["terms"] == []
    space = res.model["space"]
    assert space["used"] == "linear" and space["codes"]["alike"] is False, space
    light, worst, _ = _errors(res, truth)
    assert light < 0.02 and worst < 0.03
    srgb, _, _ = _errors(rtloop.fit(scene, image, uncertainty=False, space="srgb"), truth)
    assert light < srgb


def test_codes_alike_tells_a_jpegs_errors_from_a_sensors():
    """A residual of one size in code values (a JPEG's quantisation) is alike in the dark and the bright
    pixels; a sensor's read noise in linear values, clipped at 0, is many codes in the dark ones."""
    from rtloop._srgb import decode, encode
    from rtloop.fit.jpeg import codes_alike

    rng = np.random.default_rng(0)
    render = np.repeat(np.linspace(0.0, 0.9, 96 * 128).reshape(96, 128, 1), 3, axis=2)
    jpeg = decode(np.clip(encode(render) + rng.normal(0.0, 1.5, render.shape) / 255.0, 0.0, 1.0))
    sensor = np.clip(render + rng.normal(0.0, 0.006, render.shape), 0.0, 1.0)
    assert codes_alike(render, jpeg, None, None)["alike"] is True
    evidence = codes_alike(render, sensor, None, None)
    assert evidence["alike"] is False and evidence["dark_spread_codes"] > 3 * evidence["bright_spread_codes"]
    assert codes_alike(render, sensor, np.arange(100), None)["alike"] is None  # too few pixels to tell


def test_linear_images_stay_linear_and_show_their_vignetting():
    scene, _, truth, meta = _load(FIXTURES / "blue-ball-vignette")
    linear = np.load(FIXTURES / "blue-ball-linear.npz")["linear"].astype(np.float32)
    vignetted = np.minimum(linear * _falloff(scene, meta["post"]["k1"], meta["post"]["k2"])[..., None], 1.0)
    res = rtloop.fit(scene, vignetted.astype(np.float32), uncertainty=False)
    assert "tone" not in res.model["camera"]["evidence"]  # float (linear) data: no tone curve is tested
    assert res.model["camera"]["terms"] == ["vignetting"]
    light, worst, _ = _errors(res, truth)
    assert light < 0.01 and worst < 0.02


@pytest.mark.parametrize("kwargs, field", [
    ({"vignetting": "maybe"}, "vignetting"), ({"vignetting": (1.0,)}, "vignetting"),
    ({"vignetting": (math.nan, 0.0)}, "vignetting"), ({"vignetting": (-2.0, 0.0)}, "vignetting"),
    ({"tone": "srgb"}, "tone"), ({"flat_field": np.ones((3, 3), np.float32)}, "flat_field"),
    ({"flat_field": np.zeros((96, 128), np.float32)}, "flat_field"),
    ({"flat_field": np.ones((96, 128), np.uint8)}, "flat_field"),
    ({"flat_field": np.ones((96, 128), np.float32), "vignetting": (0.0, 0.0)}, "flat_field"),
])
def test_bad_camera_arguments_name_the_argument(kwargs, field):
    scene, image, _, _ = _load(FIXTURES / "blue-ball-vignette")
    with pytest.raises(RtloopError, match=f"^{field}: "):
        rtloop.fit(scene, image, uncertainty=False, **kwargs)


def test_cli_prints_the_camera_and_takes_the_flags(tmp_path, capsys):
    from rtloop.cli.fit import main

    folder = FIXTURES / "orange-ball-tone"
    assert main([str(folder / "scene_input.json"), str(folder / "objective.png"), "--out", str(tmp_path / "a"),
                 "--uncertainty", "off", "--vignetting", "off", "-q"]) == 0
    out = capsys.readouterr().out
    assert "camera: tone" in out and "tone: added" in out
    report = json.loads((tmp_path / "a" / "result.json").read_text())["fit_report"]
    assert report["model"]["camera"]["terms"] == ["tone"]
    assert "vignetting" not in report["model"]["camera"]["evidence"]
    assert main([str(folder / "scene_input.json"), str(folder / "objective.png"), "--out", str(tmp_path / "b"),
                 "--vignetting", "1,x", "-q"]) == 2
    assert "--vignetting" in capsys.readouterr().err


def test_cli_flat_field_file(tmp_path, capsys):
    import cv2

    from rtloop.cli.fit import main

    folder = FIXTURES / "blue-ball-vignette"
    scene, _, truth, meta = _load(folder)
    flat = (0.8 * _falloff(scene, meta["post"]["k1"], meta["post"]["k2"])).astype(np.float32)
    cv2.imwrite(str(tmp_path / "flat.tiff"), np.repeat(flat[..., None], 3, axis=2))  # float TIFF: linear
    assert main([str(folder / "scene_input.json"), str(folder / "objective.png"), "--out", str(tmp_path / "a"),
                 "--flat-field", str(tmp_path / "flat.tiff"), "--uncertainty", "off", "-q"]) == 0
    assert "from the flat field" in capsys.readouterr().out
    fitted = json.loads((tmp_path / "a" / "result.json").read_text())
    assert np.linalg.norm(np.subtract(fitted["light"]["position"], truth["light"]["position"])) < 0.01
    assert main([str(folder / "scene_input.json"), str(folder / "objective.png"), "--out", str(tmp_path / "b"),
                 "--flat-field", str(tmp_path / "missing.png"), "-q"]) == 1
    assert "missing.png" in capsys.readouterr().err


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), extra=st.integers(1, 12), cols=st.integers(1, 12),
       start=st.lists(st.booleans(), min_size=12, max_size=12))
def test_nnls_from_any_start_is_the_cold_solution_and_scipys(seed, extra, cols, start):
    """The camera terms' non-negative least squares (more equations than unknowns, as its normal
    equations' factor with the scale's row has: one solution) started from a guessed positive set (the
    previous light's, in the searches) ends at the cold start's solution bit for bit, and at scipy's within
    rounding."""
    from scipy.optimize import nnls as scipy_nnls

    from rtloop.fit.camera import nnls

    rng = np.random.default_rng(seed)
    a = rng.normal(size=(cols + extra, cols))
    rows = cols + extra
    b = rng.normal(size=rows) + a @ rng.normal(size=cols)
    cold = nnls(a, b)
    warm = nnls(a, b, start=np.array(start[:cols]))
    reference = scipy_nnls(a, b)[0]
    assert (cold >= 0).all()
    np.testing.assert_array_equal(warm, cold)
    scale = np.linalg.norm(b) + np.linalg.norm(a) * np.linalg.norm(reference)
    assert np.linalg.norm(a @ cold - b) <= np.linalg.norm(a @ reference - b) + 1e-9 * scale


def test_rendered_pixels_are_the_renders_and_an_outside_pixel_is_named():
    """``_native.render_pixels`` (the camera terms' renders of every few pixels) is the whole render's pixels
    bit for bit, with the footprint and without; a pixel outside the image is a one-line error."""
    from rtloop import _native

    scene = rtloop.load_scene(PHOTOS / "direct-side" / "scene_input.json")
    idx = np.arange(0, scene.width * scene.height, 7, dtype=np.uint32)[::-1].copy()
    for footprint in (False, True):
        whole = _native.render(scene, scene.width, scene.height, 1, footprint).reshape(-1, 3)
        np.testing.assert_array_equal(_native.render_pixels(scene, idx, footprint), whole[idx])
    with pytest.raises(RtloopError, match=r"^render_pixels: pixel 12288 is outside the 12288 of a 128x96 image$"):
        _native.render_pixels(scene, np.array([12288], np.uint32))
