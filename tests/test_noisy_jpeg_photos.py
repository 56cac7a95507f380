"""Noisy and JPEG photos (the targets: light within 3 cm on every photo, median within 1.5 cm),
made here from the clean direct Mitsuba photos of tests/fixtures/photos as studies/coverage.py makes them:
2 % Gaussian noise (linear, seed 0, clipped to [0, 1]) and the PNG re-saved as JPEG quality 40 (Pillow's
defaults: 4:2:0 chroma). Before the fix the default fit put the light of direct-low-left's noisy variant
545 mm off (its clipped floor pixels, scattered below 1 by the noise, read as measurements by the
closed-form solve) and the JPEG variants 14-86 mm off (median 24.5 mm: JPEG's errors, alike in code values,
weighed by the linear loss where they are largest). Against the truth the fit never saw."""

from __future__ import annotations

import importlib.util
import json
import warnings
from pathlib import Path

import numpy as np
import pytest

import rtloop
from rtloop._pixels import SATURATED
from rtloop.fit import JPEG_CHROMA_MARGIN
from rtloop.fit.products import products_of
from rtloop.fit.goodness import CLIPPED_SIGMAS, clip_level, jpeg_blocking, noise_sigma

PHOTOS = Path(__file__).parent / "fixtures" / "photos"
BENCH = Path(__file__).resolve().parents[1] / "studies" / "coverage.py"
DIRECT = sorted(p.name for p in PHOTOS.iterdir() if p.name.startswith("direct-") and (p / "objective.png").exists())


def _coverage_bench():
    """studies/coverage.py, whose ``photo_of`` makes the variants (one copy of how they are made)."""
    spec = importlib.util.spec_from_file_location("coverage_bench", BENCH)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _variant(name: str, scene: rtloop.Scene, kind: str) -> np.ndarray:
    return np.asarray(_coverage_bench().photo_of(PHOTOS / name, scene, kind), np.float32)


def _light_error(name: str, result: rtloop.FitResult) -> float:
    truth = json.loads((PHOTOS / name / "scene.json").read_text())["light"]["position"]
    return float(np.linalg.norm(np.subtract(result.scene.to_dict()["light"]["position"], truth)))


def _worst_product(name: str, result: rtloop.FitResult) -> float:
    """The largest colour product error (exposure x intensity x colour x albedo, per object and channel),
    relative to the object's largest true product (../shared/tools/score_result.py's measure)."""
    truth = products_of(json.loads((PHOTOS / name / "scene.json").read_text()))
    return max(abs(result.products[o][c] - truth[o][c]) / max(truth[o]) for o in truth for c in range(3))


def _fit(name: str, kind: str, **kw) -> rtloop.FitResult:
    scene = rtloop.load_scene(PHOTOS / name / "scene_input.json")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", rtloop.RtloopWarning)  # the noisy variants' clipped values
        return rtloop.fit(scene, _variant(name, scene, kind), uncertainty=False, **kw)


def test_noisy_grazing_light_within_3cm():
    """direct-low-left (a light 10 deg above the floor) with 2 % noise: 545 mm off before (its saturated
    floor pixels, 1 minus |noise|, taken as measurements of a floor far brighter than 1), 12.5 mm after."""
    r = _fit("direct-low-left", "noise")
    assert r.settings["saturated"] < SATURATED
    assert _light_error("direct-low-left", r) < 0.03


@pytest.fixture(scope="module")
def variant_fits() -> dict[str, dict[str, rtloop.FitResult]]:
    return {kind: {name: _fit(name, kind) for name in DIRECT} for kind in ("noise", "jpeg")}


@pytest.fixture(scope="module")
def variant_errors(variant_fits) -> dict[str, dict[str, float]]:
    out: dict[str, dict[str, float]] = {"noise": {}, "jpeg": {}}
    for kind, errs in out.items():
        for name, r in variant_fits[kind].items():
            errs[name] = _light_error(name, r)
            # the loss space: sRGB for the JPEGs (direct light explains them), linear for the noise
            assert r.settings["space"] == ("srgb" if kind == "jpeg" else "linear"), (name, kind, r.model)
    return out


def test_jpeg_products_leave_out_the_chroma_mixed_pixels(variant_fits):
    """A detected JPEG's products are solved without the pixels within JPEG_CHROMA_MARGIN of another
    object (4:2:0 chroma mixes their colours); the noisy photos (no JPEG blocking) keep every interior
    pixel."""
    assert {r.settings["solve_margin"] for r in variant_fits["jpeg"].values()} == {JPEG_CHROMA_MARGIN}
    assert {r.settings.get("solve_margin", 0) for r in variant_fits["noise"].values()} == {0}


def test_a_png_with_a_faint_grid_keeps_every_interior_pixel():
    """direct-back-left's PNG shows a significant 8-pixel grid (0.57 codes, 5.2 standard deviations), below
    the one code RMS that makes a photo a JPEG here: its fit is the clean one (no solve margin)."""
    scene = rtloop.load_scene(PHOTOS / "direct-back-left" / "scene_input.json")
    photo = rtloop.load_image(PHOTOS / "direct-back-left" / "objective.png", scene)
    assert jpeg_blocking(photo)["detected"]
    r = rtloop.fit(scene, photo, uncertainty=False)
    assert "solve_margin" not in r.settings and r.settings["space"] == "linear"


def test_jpeg_products_median_within_3_percent(variant_fits):
    """The worst colour product per JPEG-40 photo (against the truth the fit never saw): median 3.6 %
    (0.5-7.3 %) before the pixels that 4:2:0 chroma mixes across a silhouette were left out of the
    products' solve, 2.5 % (0.3-6.5 %) after; the per-photo figure is the next test's."""
    worst = {name: _worst_product(name, r) for name, r in variant_fits["jpeg"].items()}
    assert len(worst) >= 11
    assert np.median(list(worst.values())) < 0.03, worst


@pytest.mark.xfail(strict=True, reason="every product within 3 % on JPEG-40: inside a small ball a "
                   "JPEG-40's colour is quantised per 16 x 16 block (chroma DC), up to 1.4 codes, 2-4 % of a "
                   "product; direct-low-left, -three-low, -two-overhead and -side stay 3.2-6.5 % off")
def test_jpeg_products_within_3_percent(variant_fits):
    worst = {name: _worst_product(name, r) for name, r in variant_fits["jpeg"].items()}
    assert max(worst.values()) < 0.03, worst


@pytest.mark.parametrize("kind", ["noise", "jpeg"])
def test_noise_and_jpeg_variants_within_3cm_median_15mm(variant_errors, kind):
    """Measured after the fix: noise 2.3-12.7 mm (median 6.1), JPEG-40 1.5-23.1 mm (median 11.7; with the
    chroma margin 1.9-22.6 mm, median 11.5); before: noise up to 545 mm, JPEG 4.9-46.7 mm (median 22.6)."""
    errs = variant_errors[kind]
    assert len(errs) >= 11
    assert max(errs.values()) < 0.03, errs
    assert np.median(list(errs.values())) < 0.015, errs


def test_clip_level_follows_the_photo_error():
    """The level is 1 - CLIPPED_SIGMAS x the error at 1; a clean photo keeps SATURATED."""
    flat = np.full((40, 40, 3), 0.3, np.float32)
    assert clip_level(noise_sigma(flat), jpeg_blocking(flat)) == SATURATED
    rng = np.random.default_rng(3)
    noisy = flat + rng.normal(0.0, 0.02, flat.shape).astype(np.float32)
    sigma = noise_sigma(noisy)
    assert np.allclose(sigma, 0.02, rtol=0.1)
    assert clip_level(sigma, jpeg_blocking(noisy)) == pytest.approx(1 - CLIPPED_SIGMAS * sigma.max())


def test_a_jpeg_that_needs_more_terms_stays_linear():
    """lamp-desk (a JPEG 85 phone-like photo: desk lamp, room light, gloss): the sRGB loss weighs up the dark
    pixels where the point light's hard shadow errs (light 10 -> 30 mm measured), so its terms keep it linear."""
    scene = rtloop.load_scene(PHOTOS / "lamp-desk" / "scene_input.json")
    r = rtloop.fit(scene, rtloop.load_image(PHOTOS / "lamp-desk" / "objective.png", scene), uncertainty=False)
    assert len(r.model["terms"]) > 1
    assert r.settings["space"] == "linear" and r.model["space"]["used"] == "linear"


def test_space_is_checked():
    scene = rtloop.load_scene(PHOTOS / "direct-side" / "scene_input.json")
    with pytest.raises(rtloop.RtloopError, match="space: unknown loss space 'log'.*auto"):
        rtloop.fit(scene, np.zeros((scene.height, scene.width, 3), np.float32), space="log")
