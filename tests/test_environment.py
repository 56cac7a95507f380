"""The occluded environment term (photos as cameras take them): scene field, renderer, kernel, closed form,
automatic selection. The sky view factor itself is tested against Monte Carlo in
rust/render/environment.rs; the renderer against Mitsuba 3 in tests/test_photos.py."""

from __future__ import annotations

import json

import numpy as np
import pytest

import rtloop
from rtloop import _native


def _scene(environment=None, fit=None, two=False, **light) -> dict:
    d = {
        "image": {"width": 64, "height": 48},
        "camera": {"position": [0.0, 1.6, -6.0], "look_at": [0.0, 0.8, 0.0], "up": [0.0, 1.0, 0.0],
                   "vfov_deg": 35.0},
        "light": {"position": light.get("position", [2.0, 4.0, -1.5]), "intensity": light.get("intensity", 60.0),
                  "color": [1.0, 1.0, 1.0]},
        "objects": [
            {"name": "ball", "shape": "sphere", "center": [-0.6 if two else 0.0, 1.0, 0.0], "radius": 1.0,
             "material": {"albedo": [0.7, 0.3, 0.2]}},
            {"name": "floor", "shape": "plane", "point": [0.0, 0.0, 0.0], "normal": [0.0, 1.0, 0.0],
             "material": {"albedo": [0.6, 0.6, 0.55]}},
        ],
    }
    if two:
        d["objects"].insert(1, {"name": "ball2", "shape": "sphere", "center": [1.4, 0.6, 0.5], "radius": 0.6,
                                "material": {"albedo": [0.2, 0.4, 0.7]}})
    if environment is not None:
        d["environment"] = environment
    if fit is not None:
        d["fit"] = fit
    return d


def _user_fit(d: dict) -> dict:
    """The fit section a user writes today: light position and intensity, every albedo."""
    fit = {"light.position": {"min": [-8, 0.5, -8], "max": [8, 8, 8]}, "light.intensity": {"min": 1, "max": 400}}
    for o in d["objects"]:
        fit[f"objects.{o['name']}.albedo"] = {"min": [0, 0, 0], "max": [1, 1, 1]}
    return fit


def _photo(truth: dict, footprint: bool = True) -> np.ndarray:
    """rtloop's render of ``truth`` as a camera stores it: clipped at 1; with ``footprint`` (as the default
    fit models pixels) or at pixel centres (as the fitness evaluates with its default)."""
    return np.minimum(_native.render(rtloop.Scene(json.dumps(truth)), None, None, 1, footprint), 1.0)


def _start(truth: dict, fit: dict) -> rtloop.Scene:
    d = json.loads(json.dumps(truth))
    d.pop("environment", None)
    d.pop("interreflection", None)
    d["light"] = {**d["light"], "position": [0.0, 4.0, 0.0], "intensity": 20.0}
    for o in d["objects"]:
        o["material"] = {"albedo": [0.5, 0.5, 0.5]}
    d["fit"] = fit
    return rtloop.Scene(json.dumps(d))


def test_scene_field_is_checked_and_round_trips():
    d = _scene(environment=[0.05, 0.06, 0.08])
    assert rtloop.Scene(json.dumps(d)).to_dict()["environment"] == [0.05, 0.06, 0.08]
    # absent when zero, so scenes without it are written as before
    assert "environment" not in rtloop.Scene(json.dumps(_scene())).to_dict()
    for bad in ([-0.1, 0, 0], [float("nan"), 0, 0], [0, 0]):
        with pytest.raises(rtloop.RtloopError, match="environment"):
            rtloop.Scene(json.dumps({**d, "environment": bad}))


def test_render_adds_albedo_times_environment_times_sky_view():
    """A lone ball (nothing occludes it) gains exactly albedo x environment everywhere; with the floor,
    the floor darkens under the ball and the ball's underside darkens (it sees the floor, not the sky)."""
    env = np.array([0.05, 0.06, 0.08])
    lone = _scene()
    lone["objects"] = lone["objects"][:1]
    with_env = _native.render(rtloop.Scene(json.dumps({**lone, "environment": list(env)})))
    without = _native.render(rtloop.Scene(json.dumps(lone)))
    ids = _native.object_ids(rtloop.Scene(json.dumps(lone)))
    gain = (with_env - without)[ids == 0]
    np.testing.assert_allclose(gain, np.broadcast_to(env * [0.7, 0.3, 0.2], gain.shape), rtol=1e-5, atol=1e-7)
    assert np.all(with_env[ids == -1] == 0)  # the background (sky pixels) stays what it is

    d = _scene()
    ids = _native.object_ids(rtloop.Scene(json.dumps(d)))
    gain = (_native.render(rtloop.Scene(json.dumps({**d, "environment": list(env)})))
            - _native.render(rtloop.Scene(json.dumps(d))))[..., 2] / 0.55 / env[2]  # the floor's sky view
    floor = gain[ids == 1]
    assert floor.min() < 0.5 and floor.max() > 0.9 and floor.max() <= 1 + 1e-5
    # the floor just below the ball's silhouette (bottom rows of the ball) is darker than at the image edge
    rows = np.nonzero((ids == 0).any(axis=1))[0]
    below = gain[rows[-1] + 1, ids[rows[-1] + 1] == 1]
    assert below.min() < gain[-1, 0]


@pytest.mark.parametrize("two", [False, True], ids=["one-ball", "two-balls"])
def test_kernel_and_closed_form_reproduce_the_render(two):
    """At the true scene, the kernel's direct loss (the two-stage method) and the closed-form loss with
    the environment column are both zero: the fitness models exactly what the renderer renders."""
    truth = _scene(environment=[0.05, 0.06, 0.08], two=two)
    truth["fit"] = {"light.position": {"min": [-8, 0.5, -8], "max": [8, 8, 8]}}
    scene = rtloop.Scene(json.dumps(truth))
    photo = _photo(truth, footprint=False)
    x = np.array([truth["light"]["position"]], float)
    direct = _native.evaluate(scene, photo, x, _native.FitnessSpec(["light.position"], loss="l1"))[0, 0]
    assert direct < 1e-4 * photo.sum()
    from rtloop.fit.products import product_bounds

    def closed_form(environment: bool) -> float:
        spec = _native.FitnessSpec(["light.position"], loss="l1_projected",
                                   product_bounds=product_bounds(scene, environment))
        return _native.evaluate(scene, photo, x, spec)[0, 0]

    closed = closed_form(True)
    assert closed < 1e-4 * photo.sum()
    without = closed_form(False)
    assert without > 100 * max(closed, 1e-6)


@pytest.mark.parametrize("two", [False, True], ids=["one-ball", "two-balls"])
def test_auto_adds_the_environment_and_finds_the_truth(two):
    """A photo with an occluded environment, fitted with the fit section a user writes today: the default
    fit adds the term, finds the light and the products the image determines, and renders the photo."""
    truth = _scene(environment=[0.05, 0.06, 0.08], two=two, position=[1.5, 3.5, -2.0])
    photo = _photo(truth)
    off = rtloop.fit(_start(truth, _user_fit(truth)), photo, environment="off", uncertainty=False)
    r = rtloop.fit(_start(truth, _user_fit(truth)), photo, uncertainty=False)
    assert r.model["terms"] == ["direct", "environment"]
    ev = r.model["evidence"]["environment"]
    assert ev["selected"] and ev["gain"] > 0.05 and ev["delta_bic"] > 0
    got = np.array(r.scene.to_dict()["light"]["position"])
    err = np.linalg.norm(got - truth["light"]["position"])
    err_off = np.linalg.norm(np.array(off.scene.to_dict()["light"]["position"]) - truth["light"]["position"])
    assert err < 1e-3, err
    assert err_off > 20 * err  # without the term the light is off: the term is what finds it
    d = r.scene.to_dict()
    intensity = d["light"]["intensity"]
    for o_fit, o_true in zip(d["objects"], truth["objects"]):
        np.testing.assert_allclose(np.array(o_fit["material"]["albedo"]) * intensity,
                                   np.array(o_true["material"]["albedo"]) * truth["light"]["intensity"], rtol=1e-3)
        # the environment's products (environment x albedo) are what the image determines with it
        np.testing.assert_allclose(np.array(o_fit["material"]["albedo"]) * d["environment"],
                                   np.array(o_true["material"]["albedo"]) * truth["environment"], rtol=2e-3,
                                   atol=1e-6)
    np.testing.assert_allclose(np.minimum(_native.render(r.scene, None, None, 1, True), 1), photo, atol=2e-3)


def test_auto_leaves_a_direct_photo_alone():
    """A photo with no environment light: 'auto' adds nothing and gives exactly the 'off' fit. A clean
    render is explained to its quantisation floor, so no term is even tested; with sensor noise the
    tests run and reject the term."""
    truth = _scene(position=[-2.0, 4.5, -1.0])
    photo = _photo(truth)
    auto = rtloop.fit(_start(truth, _user_fit(truth)), photo, uncertainty=False)
    off = rtloop.fit(_start(truth, _user_fit(truth)), photo, environment="off", uncertainty=False)
    assert auto.model["terms"] == ["direct"] and auto.model["residual"]["ratio"] < 3
    assert "skipped" in auto.model and not auto.model["evidence"]
    assert auto.x == off.x and len(auto.stages) == 1
    noisy = np.clip(photo + np.random.default_rng(5).normal(0, 0.01, photo.shape), 0, 1).astype(np.float32)
    r = rtloop.fit(_start(truth, _user_fit(truth)), noisy, uncertainty=False)
    assert r.model["residual"]["ratio"] > 3 and "skipped" not in r.model
    assert not r.model["evidence"]["environment"]["selected"]
    assert r.model["terms"] == ["direct"] and len(r.stages) == 1


def test_on_fits_a_zero_environment_on_a_direct_photo():
    truth = _scene(position=[-2.0, 4.5, -1.0])
    photo = _photo(truth)
    r = rtloop.fit(_start(truth, _user_fit(truth)), photo, environment="on", uncertainty=False)
    assert r.model["terms"] == ["direct", "environment"]
    assert np.linalg.norm(np.array(r.scene.to_dict()["light"]["position"]) - truth["light"]["position"]) < 1e-3
    assert max(r.scene.to_dict().get("environment", [0, 0, 0])) < 1e-4


def test_free_environment_with_a_known_lamp_is_absolute():
    """With the lamp's intensity known (not fitted), the albedos and the environment radiance are
    determined absolutely, and the closed form solves the environment named in the fit section."""
    truth = _scene(environment=[0.05, 0.06, 0.08], position=[1.5, 3.5, -2.0])
    fit = _user_fit(truth)
    del fit["light.intensity"]
    fit["environment"] = {"min": [0, 0, 0], "max": [1, 1, 1]}
    start = _start(truth, fit).to_dict()
    start["light"]["intensity"] = truth["light"]["intensity"]
    photo = _photo(truth)
    r = rtloop.fit(rtloop.Scene(json.dumps(start)), photo, uncertainty=False)
    assert r.settings["method"] == "projected"
    np.testing.assert_allclose(r.scene.to_dict()["environment"], truth["environment"], rtol=1e-3)
    for o_fit, o_true in zip(r.scene.to_dict()["objects"], truth["objects"]):
        np.testing.assert_allclose(o_fit["material"]["albedo"], o_true["material"]["albedo"], rtol=1e-3)


def test_two_stage_method_fits_a_given_environment():
    """The paper's protocol (no closed form) renders the scene's environment in its loss: with the true
    environment given, it finds the light as on a direct photo."""
    truth = _scene(environment=[0.05, 0.06, 0.08], position=[1.5, 3.5, -2.0])
    start = _start(truth, _user_fit(truth)).to_dict()
    start["environment"] = truth["environment"]
    photo = _photo(truth, footprint=False)  # the two stages shade pixel centres
    r = rtloop.fit(rtloop.Scene(json.dumps(start)), photo, protocol="paper", generations=(60, 60), population=30,
                   uncertainty=False)
    assert r.model["terms"] == ["direct", "environment"]
    assert np.linalg.norm(np.array(r.scene.to_dict()["light"]["position"]) - truth["light"]["position"]) < 0.15


def test_bad_mode_names_the_argument():
    truth = _scene()
    with pytest.raises(rtloop.RtloopError, match="environment"):
        rtloop.fit(_start(truth, _user_fit(truth)), np.zeros((48, 64, 3), np.float32), environment="yes")
