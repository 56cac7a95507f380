"""Goodness of fit (rtloop.fit.goodness): the noise estimate against known noise, and the verdict against
photos whose model is known to be complete or not (the Mitsuba fixtures with and without the terms)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import rtloop
from rtloop import cli
from rtloop.fit.goodness import EXPLAINED_RATIO, noise_sigma

PHOTOS = Path(__file__).resolve().parent / "fixtures" / "photos"


@pytest.mark.parametrize("sigma", [0.002, 0.01, 0.03])
def test_noise_sigma_recovers_known_noise_on_shaded_images(sigma):
    """White noise over smooth shading and a sharp edge: the estimate within 10 % of the truth."""
    rng = np.random.default_rng(1)
    y, x = np.mgrid[0:96, 0:128] / 96.0
    base = 0.2 + 0.3 * x + 0.1 * y**2
    base[30:60, 40:80] += 0.3  # an object's silhouette
    img = np.repeat(base[..., None], 3, axis=2) + rng.normal(0, sigma, (96, 128, 3))
    assert noise_sigma(img) == pytest.approx(np.full(3, sigma), rel=0.1)


def _fit(case: str, **kw):
    scene = rtloop.load_scene(PHOTOS / case / "scene_input.json")
    photo = rtloop.load_image(PHOTOS / case / "objective.png", scene)
    return rtloop.fit(scene, photo, uncertainty=False, **kw)


@pytest.mark.parametrize("case", ["direct-side", "direct-overhead"])
def test_a_photo_the_model_explains_says_so(case):
    g = _fit(case).report()["goodness"]
    assert g["ratio"] < EXPLAINED_RATIO and g["verdict"] == "the model explains this photo to the noise level"


@pytest.mark.parametrize(("case", "where"), [("env-overhead", "floor"), ("bounce-red-ball", "ball")])
def test_a_model_missing_a_term_is_told_and_where(case, where):
    """The same photos fitted with the environment and the bounce off: the verdict says the model does not
    explain them, naming where most of the excess lies (the floor under an environment, a ball lit by the
    floor's bounce); with the terms on (the default), the verdict is that it does. The camera's terms are off
    too: a tone curve can stand in for a missing room light (docs/camera.md), and the model tested here is
    one that lacks both."""
    g = _fit(case, environment="off", interreflection="off", highlights="off", vignetting="off", tone="off").goodness
    assert g["ratio"] >= EXPLAINED_RATIO
    assert g["verdict"].startswith(f"the residual is {g['ratio']:.2g}x the noise floor")
    assert f"of the excess on {where}" in g["verdict"]
    assert max(g["per_object"], key=lambda n: g["per_object"][n]["share_of_excess"]) == where
    assert _fit(case).goodness["ratio"] < EXPLAINED_RATIO < g["ratio"]


def test_cli_prints_the_verdict(tmp_path, capsys):
    """rtloop-fit: stdout has the goodness line, and a photo its model does not explain is a warning on
    stderr."""
    case = PHOTOS / "env-overhead"
    code = cli.main([str(case / "scene_input.json"), str(case / "objective.png"), "--out", str(tmp_path / "o"),
                     "--environment", "off", "--interreflection", "off", "--highlights", "off",
                     "--tone-curve", "off", "--vignetting", "off", "--final-scale", "1", "--final-spp", "1", "--snapshot-every", "0"])
    out = capsys.readouterr()
    assert code == 0, out.err
    assert "goodness of fit: " in out.out
    assert "rtloop-fit: warning: the residual is " in out.err


def test_a_photo_saturated_everywhere_has_a_verdict_not_an_error():
    """No unsaturated pixel: nothing to judge by, said so (ratio None), and the fit still returns."""
    scene = rtloop.load_scene(PHOTOS / "direct-side" / "scene_input.json")
    photo = np.full((scene.height, scene.width, 3), 2.0, np.float32)
    with pytest.warns(rtloop.RtloopWarning):
        g = rtloop.fit(scene, photo, uncertainty=False, population=4, generations=1).goodness
    assert g["ratio"] is None and g["verdict"].startswith("no unsaturated pixel")


# JPEG blocking. direct-side's JPEGs set JPEG_ERROR_OVER_BLOCKING; these are other clean photos.
JPEG_CASES = ["direct-overhead", "direct-three-balls", "direct-near-small"]


def _jpeg(codes: np.ndarray, quality: int | None) -> np.ndarray:
    """``codes`` (uint8 RGB) through Pillow's JPEG at ``quality`` (None: as they are)."""
    if quality is None:
        return codes
    import io

    from PIL import Image

    buf = io.BytesIO()
    Image.fromarray(codes).save(buf, "JPEG", quality=quality)
    return np.asarray(Image.open(buf).convert("RGB"))


def _png_codes(case: str) -> np.ndarray:
    from PIL import Image

    return np.asarray(Image.open(PHOTOS / case / "objective.png").convert("RGB"))


@pytest.mark.parametrize("case", JPEG_CASES)
def test_jpeg_blocking_estimates_the_jpegs_own_error(case):
    """The 8x8 grid's jumps measure the JPEG's error: on the PNG nothing is detected (the grid is arbitrary
    there); on the same photo saved as JPEG at qualities 85, 50 and 30 it is, and the estimated RMS error
    per channel is within a factor of 2 of the actual one (JPEG codes minus PNG codes)."""
    from rtloop._srgb import decode
    from rtloop.fit.goodness import jpeg_blocking

    png = _png_codes(case)
    none = jpeg_blocking(decode(png / 255.0))
    assert not none["detected"] and none["error_codes"] == [0.0, 0.0, 0.0], none
    for q in (85, 50, 30):
        codes = _jpeg(png, q)
        b = jpeg_blocking(decode(codes / 255.0))
        actual = np.sqrt(((codes.astype(float) - png) ** 2).reshape(-1, 3).mean(axis=0))
        ratio = np.array(b["error_codes"]) / actual
        assert b["detected"], (q, b)
        assert np.all((ratio > 0.5) & (ratio < 2.0)), (q, ratio.round(2))


@pytest.mark.parametrize("case", JPEG_CASES)
def test_a_jpeg_of_a_clean_photo_is_explained_to_the_noise_level(case, monkeypatch):
    """The truth's render against the photo saved as JPEG (qualities 85, 50, 30): with the blocking in the
    floor the verdict is "explained", the ratio no higher than the PNG's (measured 0.7-1.0 against 1.8-2.5);
    without it (the factor set to 0) the JPEG's error looks like 4-14x the floor, a model error."""
    import importlib

    from rtloop._srgb import decode

    gm = importlib.import_module("rtloop.fit.goodness")
    truth = rtloop.Scene((PHOTOS / case / "scene.json").read_text())
    png = _png_codes(case)
    base = gm.goodness(truth, decode(png / 255.0).astype(np.float32), None)
    for q in (85, 50, 30):
        photo = decode(_jpeg(png, q) / 255.0).astype(np.float32)
        g = gm.goodness(truth, photo, None)
        assert g["jpeg_blocking"]["detected"]
        assert g["ratio"] < EXPLAINED_RATIO and g["ratio"] <= 1.2 * base["ratio"], (q, g["ratio"], base["ratio"])
        assert g["verdict"].startswith("the model explains")
    monkeypatch.setattr(gm, "JPEG_ERROR_OVER_BLOCKING", 0.0)
    blind = gm.goodness(truth, decode(_jpeg(png, 50) / 255.0).astype(np.float32), None)
    assert blind["ratio"] > EXPLAINED_RATIO


def _jpeg_blocking_phases_by_loop(image: np.ndarray) -> np.ndarray:
    """The blocking's per-phase means as numpy did them: per phase, the mean of its pairs' clipped squared
    jumps, gathered by a mask (the reference for the core's loop, ``_native.jpeg_phases``)."""
    from rtloop._srgb import encode
    from rtloop.fit.goodness import JPEG_BLOCK, JPEG_EDGE_CODES

    codes = encode(np.clip(np.asarray(image, np.float32), 0.0, 1.0), np.float32) * np.float32(255.0)
    phases = np.zeros((JPEG_BLOCK, 3))
    for c in (codes, codes.transpose(1, 0, 2)):
        d = np.diff(c, axis=1)
        jump = d[:, 1:-1] - 0.5 * (d[:, :-2] + d[:, 2:])
        sq = np.minimum(jump * jump, np.float32(JPEG_EDGE_CODES ** 2))
        phase = np.arange(1, d.shape[1] - 1) % JPEG_BLOCK
        for k in range(JPEG_BLOCK):
            phases[k] += sq[:, phase == k].reshape(-1, 3).mean(axis=0, dtype=np.float64) / 2
    return phases


def _noise_medians_by_numpy(image: np.ndarray) -> np.ndarray:
    """Immerkaer's median absolute response as numpy did it (the reference for ``_native.noise_medians``)."""
    x = np.asarray(image, np.float32)
    dx = x[:, :-2] - 2 * x[:, 1:-1] + x[:, 2:]
    acc = dx[:-2] - 2 * dx[1:-1] + dx[2:]
    return np.median(np.abs(acc).reshape(-1, 3), axis=0)


def _odd_images():
    """Images of every size modulo the 8-pixel grid (odd and even pixel counts), noisy, flat in steps, out of
    [0, 1], and as 8-bit codes."""
    rng = np.random.default_rng(4)
    for h, w in [(24, 24), (25, 31), (33, 40), (96, 128), (47, 61), (71, 24), (24, 97)]:
        for img in (rng.random((h, w, 3)), np.round(rng.random((h, w, 3)) * 4) / 4,
                    1.2 * rng.random((h, w, 3)) - 0.1, rng.integers(0, 256, (h, w, 3)) / 255.0):
            yield img.astype(np.float32)


def test_the_core_blocking_phases_are_numpys_bit_for_bit():
    """The core's per-phase loop gives numpy's per-phase means to the last bit."""
    import importlib

    from rtloop import _native

    gm = importlib.import_module("rtloop.fit.goodness")  # (the module: rtloop.fit.goodness is the function)
    for img in _odd_images():
        codes = gm.encoded(img) * np.float32(255.0)
        got = _native.jpeg_phases(codes, gm.JPEG_BLOCK, np.float32(gm.JPEG_EDGE_CODES ** 2))
        assert np.array_equal(got, _jpeg_blocking_phases_by_loop(img)), img.shape


def test_the_core_noise_medians_are_numpys_bit_for_bit():
    """The core's Immerkaer loop and median give numpy's to the last bit (even and odd counts, ties, a NaN)."""
    from rtloop import _native

    for img in _odd_images():
        assert np.array_equal(_native.noise_medians(img), _noise_medians_by_numpy(img)), img.shape
    img = np.full((5, 6, 3), 0.5, np.float32)
    img[2, 3, 1] = np.nan
    got = _native.noise_medians(img)
    assert got[0] == 0.0 and np.isnan(got[1]) and got[2] == 0.0


@pytest.mark.parametrize("case", ["direct-side", "direct-low-left", "direct-three-balls"])
def test_the_8_bit_codes_give_the_same_numbers(case):
    """Where the photo is 8-bit codes (a PNG, a JPEG as load_image decodes them), the goodness, the JPEG
    blocking and the quantisation floor from the codes' tables are those computed from the values, bit for
    bit (masked too)."""
    import importlib

    from rtloop._srgb import code_values, codes8
    from rtloop.fit.selection import quantisation_floor

    gm = importlib.import_module("rtloop.fit.goodness")
    truth = rtloop.Scene((PHOTOS / case / "scene.json").read_text())
    png = _png_codes(case)
    use = np.arange(0, truth.width * truth.height, 3, dtype=np.uint32)
    for codes in (png, _jpeg(png, 50)):
        photo = rtloop.load_image(PHOTOS / case / "objective.png", truth) if codes is png else \
            code_values()[codes]
        c = codes8(photo)
        assert c is not None and np.array_equal(c, codes)
        enc = gm.encoded(photo, c)
        assert np.array_equal(enc.view(np.uint32), gm.encoded(photo).view(np.uint32))
        assert gm.jpeg_blocking(photo, enc) == gm.jpeg_blocking(photo)
        for pixels in (None, use):
            assert quantisation_floor(photo, pixels, c) == quantisation_floor(photo, pixels)
            assert gm.goodness(truth, photo, pixels, codes=c, encoding=enc) == gm.goodness(truth, photo, pixels)


@pytest.mark.parametrize("space", ["linear", "srgb"])
@pytest.mark.parametrize("norm", ["l1", "l2", "huber", "huber:0.0005"])
def test_the_quantisation_floor_is_the_rounding_error_in_each_norm(norm, space):
    """explained_ratio measures a residual in multiples of the 8-bit rounding error, alike in every norm
    and loss space: an exact model of an 8-bit photo (the residual is the rounding itself) is 1, one whose
    residual is twice the rounding 2 (L2's loss would be 4x the floor; Huber's between 2x and 4x). The
    rounding error is uniform over a code step on the encodings, not quite in linear units: a few per
    cent."""
    from rtloop._srgb import decode, encode
    from rtloop.fit.selection import explained_ratio

    rng = np.random.default_rng(3)
    truth = rng.uniform(0.0, 1.0, (96, 128, 3))
    photo = decode(np.round(encode(truth) * 255) / 255).astype(np.float32)
    use = np.arange(0, 96 * 128, 2, dtype=np.uint32)
    h = {"huber": 0.02, "huber:0.0005": 0.0005}.get(norm)

    def penalty(d):
        if norm == "l1":
            return np.abs(d)
        if norm == "l2":
            return d * d
        a = np.abs(d)
        return np.where(a <= h, 0.5 * d * d / h, a - 0.5 * h)

    for scale in (1.0, 2.0):
        if space == "srgb":
            d = scale * (encode(truth) - encode(photo.astype(np.float64)))
        else:
            d = scale * (truth - photo.astype(np.float64))
        loss = float(penalty(d.reshape(-1, 3)[use]).sum())
        floor, ratio = explained_ratio(loss, photo, use, norm=norm, space=space)
        assert floor > 0 and ratio == pytest.approx(scale, rel=0.05), (scale, ratio)


def test_the_clip_level_of_a_photo_drowned_in_noise_stays_a_level_the_core_takes():
    from conftest import BALL_ON_FLOOR
    from rtloop.fit.goodness import CLIP_LEVEL_FLOOR, clip_level

    assert clip_level([0.8, 0.8, 0.8], {"error_codes": [0, 0, 0]}) == CLIP_LEVEL_FLOOR
    photo = rtloop.render(BALL_ON_FLOOR) + np.random.default_rng(0).normal(0, 0.6, (48, 64, 3)).astype(np.float32)
    result = rtloop.fit(BALL_ON_FLOOR, np.clip(photo, 0, None), generations=1, polish=5, uncertainty=False)
    assert result.settings["saturated"] == CLIP_LEVEL_FLOOR


def test_structure_below_the_verdicts_threshold_is_measured_and_widens_the_bars():
    """A residual 1-3x the floor is "explained" by the verdict, but its smooth part is still what the model
    lacks: the photo of a fitted scene times a gentle brightness ramp (a 0.8 % tilt across the image, the
    kind of smooth misfit a slightly wrong light leaves) has its structure measured per object, with no
    diagnosis, and the error bars widen by it (uncertainty.bars.model_lacks); the same photo without the ramp
    keeps the sandwich's bars."""
    from rtloop.fit.goodness import goodness
    from rtloop.uncertainty.bars import model_lacks

    result = _fit("direct-side")
    scene = result.scene
    model = np.asarray(rtloop.render(scene), np.float32)
    x = np.linspace(-1.0, 1.0, model.shape[1], dtype=np.float32)[None, :, None]
    base = goodness(scene, model, None)
    ramp = goodness(scene, model * (1.0 + 0.008 * x), None)
    assert 1.0 < ramp["ratio"] < EXPLAINED_RATIO, ramp["ratio"]
    assert ramp["verdict"] == "the model explains this photo to the noise level" and "diagnosis" not in ramp
    assert model_lacks(ramp) > 1.0 > model_lacks(base), (model_lacks(ramp), model_lacks(base))
