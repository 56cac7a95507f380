"""Per-parameter uncertainty (Gauss-Newton at the optimum) against what the fit actually does: the spread of
fitted values over noise realisations of one scene, the noise level, hidden objects, repeated seeds."""

from __future__ import annotations

import copy
import json

import numpy as np
import pytest

import rtloop
from rtloop.uncertainty import estimate_uncertainty

LIGHT = ["light.position.x", "light.position.y", "light.position.z"]


def _start(truth: dict) -> dict:
    """The truth's geometry with a wrong light and wrong colours (what a user would hand the fit)."""
    start = copy.deepcopy(truth)
    start["light"]["position"] = [0.0, 4.25, 0.0]
    start["light"]["intensity"] = 20.0
    for o in start["objects"]:
        o["material"]["albedo"] = [0.5, 0.5, 0.5]
    return start


def _photo(clean: np.ndarray, sigma: float, noise_seed: int) -> np.ndarray:
    """rtloop's render plus Gaussian noise of standard deviation ``sigma``, saturated at 1 like a camera."""
    noise = np.random.default_rng(noise_seed).normal(0.0, 1.0, clean.shape)
    return np.minimum(clean + sigma * noise, 1.0).astype(np.float32)


def _truth_products(truth: dict) -> dict[str, np.ndarray]:
    light = np.array(truth["light"]["color"]) * truth["light"]["intensity"] * truth.get("exposure", 1.0)
    return {o["name"]: light * np.array(o["material"]["albedo"]) for o in truth["objects"]}


def test_sigma_matches_the_spread_over_noise_realisations(ball_scene):
    """20 noisy photos of one scene, each fitted: the estimated sigma of every light coordinate (and of a
    product) agrees with the actual spread of the fitted values within a factor of 2, and the errors
    divided by their own sigma look like unit normals.

    Why a factor of 2 and not equality: the spread of 20 values is itself uncertain by about
    1/sqrt(2 x 19) = 16 %; the fit minimises L1 for the light (for Gaussian noise up to sqrt(pi/2) = 1.25
    times the spread of least squares, which the formula describes); the fit also sees the shadow-edge
    pixels that the linearisation leaves out (they can only narrow the spread); and the optimiser adds a
    little scatter of its own (test_seed_spread_...: far below sigma). Measured: ratios spread / sigma of
    0.82 to 1.15, rms of error / sigma 0.80 to 1.27, largest |error| / sigma 2.7 of 80.
    """
    truth = ball_scene
    clean = rtloop.render(truth)
    start = _start(truth)
    want = np.array(truth["light"]["position"] + [_truth_products(truth)["ball"][0]])
    names = LIGHT + ["products.ball.r"]
    fitted, sigmas = [], []
    for k in range(20):
        photo = _photo(clean, 0.01, noise_seed=100 + k)
        result = rtloop.fit(start, photo, seed=k)
        u = estimate_uncertainty(result, photo)
        assert u["method"] == "gauss-newton" and u["parametrization"] == "products"
        assert u["warnings"] == []
        assert 0.009 < u["residual_rms"] < 0.011, "the residuals are the noise"
        fitted.append([result.x[n] for n in LIGHT] + [result.products["ball"][0]])
        sigmas.append([u["sigma"][n] for n in names])
    fitted, sigmas = np.array(fitted), np.array(sigmas)
    spread = fitted.std(axis=0, ddof=1)
    predicted = sigmas.mean(axis=0)
    # sigma barely changes between realisations: it is a property of the scene and the noise level.
    assert np.all(sigmas.std(axis=0) < 0.05 * predicted)
    ratio = spread / predicted
    assert np.all((ratio > 0.5) & (ratio < 2.0)), dict(zip(names, ratio.round(3)))
    z = (fitted - want) / sigmas
    rms_z = np.sqrt((z**2).mean(axis=0))
    assert np.all((rms_z > 0.5) & (rms_z < 2.0)), dict(zip(names, rms_z.round(3)))
    assert np.abs(z).max() < 4.5
    # Millimetres at 1 % noise on a 64x48 image (about 5 mm in x and y, 3 mm in z).
    assert np.all((predicted[:3] > 1e-3) & (predicted[:3] < 2e-2))


def test_sigma_scales_linearly_with_the_noise_level(ball_scene):
    truth = ball_scene
    clean = rtloop.render(truth)
    start = _start(truth)
    out = {}
    for level in (0.01, 0.04):
        photo = _photo(clean, level, noise_seed=5)  # the same noise pattern, scaled
        out[level] = estimate_uncertainty(rtloop.fit(start, photo, seed=2), photo)
    assert out[0.04]["residual_rms"] / out[0.01]["residual_rms"] == pytest.approx(4.0, rel=0.1)
    for name, s in out[0.01]["sigma"].items():
        assert out[0.04]["sigma"][name] / s == pytest.approx(4.0, rel=0.1), name  # measured 4.03-4.07


def test_a_hidden_sphere_is_not_determined(ball_scene):
    truth = ball_scene
    truth["objects"].append({"name": "hidden", "shape": "sphere", "center": [0, 1, 3], "radius": 0.5,
                             "material": {"albedo": [0.3, 0.3, 0.3]}})
    truth["fit"]["objects.hidden.albedo"] = {"min": [0, 0, 0], "max": [1, 1, 1]}
    assert not (rtloop.object_ids(truth) == 2).any(), "the ball hides the sphere behind it"
    photo = _photo(rtloop.render(truth), 0.01, noise_seed=3)
    result = rtloop.fit(_start(truth), photo, seed=1)
    u = estimate_uncertainty(result, photo)
    for c in "rgb":
        assert u["sigma"][f"products.hidden.{c}"] is None
    hidden = [w for w in u["warnings"] if "products.hidden" in w]
    assert len(hidden) == 1 and "not determined" in hidden[0]
    k = u["names"].index("products.hidden.r")
    assert all(v is None for v in u["correlation"][k])
    # Everything else is still determined.
    for name in LIGHT + ["products.ball.r", "products.floor.g"]:
        assert u["sigma"][name] is not None and 0 < u["sigma"][name] < 0.5, name
    # The result is plain JSON (None -> null), with the correlation matrix in ``names`` order.
    text = json.dumps(u, allow_nan=False)
    back = json.loads(text)
    assert back["sigma"]["products.hidden.g"] is None
    assert len(back["correlation"]) == len(back["names"]) == len(back["sigma"])


def test_intensity_against_albedo_is_reported_when_scene_parameters_are_asked_for(ball_scene):
    """With the scene's own parameters (intensity and albedos) only their products are determined: all of
    them are reported as not determined, and the light's sigma is the same as with products (the
    undetermined combination is left free, not held fixed)."""
    truth = ball_scene
    photo = _photo(rtloop.render(truth), 0.01, noise_seed=4)
    result = rtloop.fit(_start(truth), photo, seed=1)
    assert result.identifiability["degenerate"]
    own = estimate_uncertainty(result, photo, params="scene")
    products = estimate_uncertainty(result, photo)
    assert own["parametrization"] == "scene"
    undetermined = [n for n, s in own["sigma"].items() if s is None]
    assert set(undetermined) == {"light.intensity"} | {
        f"objects.{o}.albedo.{c}" for o in ("ball", "floor") for c in "rgb"}
    assert any("light.intensity" in w and "combination" in w for w in own["warnings"])
    for name in LIGHT:
        assert own["sigma"][name] == pytest.approx(products["sigma"][name], rel=0.02)


def test_seed_spread_is_the_optimiser_not_the_data(ball_scene):
    """The issue asks for a cross-check against repeated seeds. Refitting one photo with different seeds
    measures only how well the optimiser converges, not what the photo determines:

    - noise-free photo: the seeds agree to about 1e-7 m and the fit reproduces the photo exactly, so
      s = 0 and sigma = 0 (with a warning): both say "exact", and the seed spread, not sigma, is the
      floor of what the fit resolves;
    - photo with 1 % noise: the seeds still agree to ~1e-4 m (measured 2e-5 to 1e-4 m), 50 to 170 times
      below sigma (3 to 5e-3 m), while the fitted light misses the truth by 0.7 to 1.4 sigma. The seed spread would grossly understate the
      error; sigma is the number to report (test_sigma_matches_...: it matches the noise spread).
    """
    truth = ball_scene
    clean = rtloop.render(truth)
    start = _start(truth)
    for level in (0.0, 0.01):
        photo = _photo(clean, level, noise_seed=7)
        fitted, sigmas, warnings = [], [], []
        for seed in range(5):
            result = rtloop.fit(start, photo, seed=seed)
            u = estimate_uncertainty(result, photo)
            fitted.append([result.x[n] for n in LIGHT])
            sigmas.append([u["sigma"][n] for n in LIGHT])
            warnings += u["warnings"]
        fitted, sigmas = np.array(fitted), np.array(sigmas).mean(axis=0)
        seed_spread = fitted.std(axis=0, ddof=1)
        if level == 0.0:
            assert np.all(seed_spread < 1e-5) and np.all(sigmas < 1e-5)
            assert any("noise-free" in w for w in warnings)
            assert np.all(np.abs(fitted.mean(axis=0) - truth["light"]["position"]) < 1e-5)
        else:
            assert np.all(seed_spread < 0.1 * sigmas), (seed_spread, sigmas)
            assert warnings == []
            assert np.all(np.abs(fitted.mean(axis=0) - truth["light"]["position"]) < 4 * sigmas)


def test_bad_input_is_rejected(ball_scene):
    photo = np.minimum(rtloop.render(ball_scene), 1.0)
    result = rtloop.fit(ball_scene, photo, seed=0)
    with pytest.raises(rtloop.RtloopError, match="shape"):
        estimate_uncertainty(result, photo[:-1])
    with pytest.raises(rtloop.RtloopError, match="params"):
        estimate_uncertainty(result, photo, params="magic")
    with pytest.raises(rtloop.RtloopError, match="step"):
        estimate_uncertainty(result, photo, step={"light.position.w": 0.01})
