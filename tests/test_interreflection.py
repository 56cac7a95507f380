"""One diffuse bounce between the objects (issue "Photos as they are"): scene field, renderer, kernel,
closed form with its gauge, automatic selection. Against Mitsuba's path tracer in tests/test_photos.py;
the gather geometry in rust/render/bounce.rs."""

from __future__ import annotations

import json

import numpy as np
import pytest

import rtloop
from rtloop import _native
from rtloop.fit.products import product_bounds
from test_environment import _photo, _scene, _start, _user_fit


def _bounced(**kw) -> dict:
    d = _scene(**kw)
    d["interreflection"] = True
    return d


def test_scene_field_is_checked_and_round_trips():
    assert rtloop.Scene(json.dumps(_bounced())).to_dict()["interreflection"] is True
    assert "interreflection" not in rtloop.Scene(json.dumps(_scene())).to_dict()
    with pytest.raises(rtloop.RtloopError, match="interreflection"):
        rtloop.Scene(json.dumps({**_scene(), "interreflection": "yes"}))


def test_render_lights_the_underside_and_tints_the_floor():
    """The bounce only adds light; the ball's underside (dark under an overhead lamp) gains the most, and
    the white floor next to a red ball turns red (its red gains more than its blue)."""
    d = _bounced(position=[0.0, 5.0, -0.5])
    plain = _native.render(rtloop.Scene(json.dumps({**d, "interreflection": False})))
    bounced = _native.render(rtloop.Scene(json.dumps(d)))
    ids = _native.object_ids(rtloop.Scene(json.dumps(d)))
    gain = bounced - plain
    assert gain.min() >= -1e-6
    rows = np.nonzero((ids == 0).any(axis=1))[0]
    bottom = gain[rows[-3]][ids[rows[-3]] == 0].mean()
    top = gain[rows[2]][ids[rows[2]] == 0].mean()
    assert bottom > 5 * top
    floor = gain[ids == 1]
    assert floor[:, 0].sum() > 2 * floor[:, 2].sum()  # ball albedo [0.7, 0.3, 0.2] on a grey floor


@pytest.mark.parametrize("env", [None, [0.05, 0.06, 0.08]], ids=["direct", "environment"])
@pytest.mark.parametrize("two", [False, True], ids=["one-ball", "two-balls"])
def test_kernel_and_closed_form_reproduce_the_render(two, env):
    truth = _bounced(environment=env, two=two)
    truth["fit"] = {"light.position": {"min": [-8, 0.5, -8], "max": [8, 8, 8]}}
    scene = rtloop.Scene(json.dumps(truth))
    photo = _photo(truth, footprint=False)
    x = np.array([truth["light"]["position"]], float)
    direct = _native.evaluate(scene, ["light.position"], photo, x, loss="l1")[0, 0]
    closed = _native.evaluate(scene, ["light.position"], photo, x, loss="l1_projected",
                              product_bounds=product_bounds(scene, env is not None))[0, 0]
    plain = rtloop.Scene(json.dumps({**truth, "interreflection": False}))
    without = _native.evaluate(plain, ["light.position"], photo, x, loss="l1")[0, 0]
    assert direct < 1e-5 * photo.sum() and closed < 1e-5 * photo.sum()
    assert without > 1e4 * max(direct, closed)


@pytest.mark.parametrize("two", [False, True], ids=["one-ball", "two-balls"])
def test_auto_adds_the_bounce_and_measures_the_intensity(two):
    """A photo with interreflection, the fit section a user writes today: the default fit adds the term,
    finds the light, and, since a bounce is as bright as the albedos themselves, the light's intensity
    and the albedos, not only their products (the user's scene says intensity 20; the truth is 60)."""
    truth = _bounced(two=two, position=[1.5, 3.5, -2.0])
    photo = _photo(truth)
    r = rtloop.fit(_start(truth, _user_fit(truth)), photo, uncertainty=False)
    assert "interreflection" in r.model["terms"]
    assert r.model["evidence"]["interreflection"]["selected"]
    d = r.scene.to_dict()
    assert d["interreflection"] is True
    assert np.linalg.norm(np.subtract(d["light"]["position"], truth["light"]["position"])) < 1e-3
    assert d["light"]["intensity"] == pytest.approx(60.0, rel=5e-3)
    for o_fit, o_true in zip(d["objects"], truth["objects"]):
        np.testing.assert_allclose(o_fit["material"]["albedo"], o_true["material"]["albedo"], rtol=5e-3, atol=1e-3)


def test_off_and_one_object():
    truth = _bounced(position=[1.5, 3.5, -2.0])
    off = rtloop.fit(_start(truth, _user_fit(truth)), _photo(truth), interreflection="off", uncertainty=False)
    assert "interreflection" not in off.model["terms"] and "interreflection" not in off.model["evidence"]
    lone = _scene()
    lone["objects"] = lone["objects"][:1]
    r = rtloop.fit(_start(lone, _user_fit(lone)), _photo(lone), uncertainty=False)
    assert "interreflection" not in r.model["evidence"]  # nothing to bounce between


def test_bad_mode_names_the_argument():
    truth = _scene()
    with pytest.raises(rtloop.RtloopError, match="interreflection"):
        rtloop.fit(_start(truth, _user_fit(truth)), np.zeros((48, 64, 3), np.float32), interreflection="yes")


def test_on_fits_the_bounce_without_testing_it():
    truth = _bounced(position=[1.5, 3.5, -2.0])
    r = rtloop.fit(_start(truth, _user_fit(truth)), _photo(truth), interreflection="on", uncertainty=False)
    assert "interreflection" in r.model["terms"] and "interreflection" not in r.model["evidence"]
    assert r.scene.to_dict()["interreflection"] is True
    assert np.linalg.norm(np.subtract(r.scene.to_dict()["light"]["position"], truth["light"]["position"])) < 1e-3


def test_same_result_on_any_thread_count():
    """Every term's path (the tests, the bounce's fixed point, the refit) is deterministic for a seed."""
    truth = _bounced(environment=[0.05, 0.06, 0.08], two=True, position=[1.5, 3.5, -2.0])
    photo = _photo(truth)
    fits = [rtloop.fit(_start(truth, _user_fit(truth)), photo, seed=4, threads=t, uncertainty=False) for t in (1, 2, 3)]
    assert fits[0].model["terms"] == ["direct", "environment", "interreflection"]
    for r in fits[1:]:
        assert r.x == fits[0].x and r.model == fits[0].model
