"""The native fitness spec (``_native.FitnessSpec``, rust/python/spec.rs) that ``_native.evaluate``,
``_native.optimize`` and ``_native.held_out`` take, and its one builder (python/rtloop/fit/spec.py): every
field checked once, a bad value refused in one line that starts with the field's name (Hypothesis), what
depends on the scene checked per call, and a spec reused across calls giving the same values."""

from __future__ import annotations

import copy

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import rtloop
from conftest import BALL_ON_FLOOR
from rtloop import _native
from rtloop.fit.products import product_bounds
from rtloop.fit.spec import closed_form_spec, fitness_spec

SMALL = copy.deepcopy(BALL_ON_FLOOR)
SMALL["image"] = {"width": 16, "height": 12}
SCENE = rtloop.load_scene(SMALL)
PHOTO = np.asarray(rtloop.render(SMALL), np.float32)
BOUNDS = product_bounds(SCENE)
PIXELS = SCENE.width * SCENE.height

#: Per field, values the spec must refuse (each a wrong type, dtype, shape or name, or out of range).
BAD = {
    "paths": ["light.position", [1, 2], [["light.position"]], None, 3],
    "pixels": [np.zeros(3, np.int64), np.zeros((2, 2), np.uint32), [0, 1], 1.5],
    "loss": ["L1", "l1_projected ", "l2", 1, ["l1"]],
    "clip": [1, "yes", 0.0, [True]],
    "product_bounds": [np.zeros((2, 5, 2)), np.zeros((2, 4, 2), np.float32), np.zeros((4, 2)),
                       np.full((2, 4, 2), np.nan), np.array([[[1.0, 0.0]] * 4] * 2), "bounds"],
    "norm": ["L1", "huber:-1", "huber:nan", "huber:", "l3", 2],
    "space": ["sRGB", "gamma", 0],
    "footprint": [2, "on"],
    "frozen_bounce": [-1, 2**70, 1.5, "2"],
    "saturated": [0.0, -1.0, float("nan"), float("inf"), 1e300, "0.9"],
    "solve_margin": [-1, 2**70, 0.5, "1"],
}

ODD = st.one_of(st.none(), st.booleans(), st.integers(-(2**70), 2**70), st.floats(allow_nan=True),
                st.text(max_size=8), st.lists(st.integers(-3, 3), max_size=3),
                st.sampled_from([np.zeros((2, 3, 2)), np.zeros(4, np.uint32), np.zeros((2, 4, 2)), {}]))


def _build(field: str, value) -> _native.FitnessSpec:
    kw = {"loss": "l1_projected", "product_bounds": BOUNDS, field: value}
    return _native.FitnessSpec(kw.pop("paths", ["light.position"]), **kw)


@pytest.mark.parametrize(("field", "value"), [(f, v) for f, values in BAD.items() for v in values],
                         ids=lambda x: repr(x)[:24])
def test_a_bad_field_is_refused_in_one_line_naming_it(field, value):
    with pytest.raises(rtloop.RtloopError) as e:
        _build(field, value)
    assert str(e.value).startswith(f"{field}: ") and "\n" not in str(e.value)


@settings(max_examples=300, deadline=None, derandomize=True, suppress_health_check=list(HealthCheck))
@given(field=st.sampled_from(sorted(BAD)), value=ODD)
def test_any_value_of_a_field_builds_a_spec_or_is_refused_in_one_line_naming_it(field, value):
    """No value of one field panics, raises anything but RtloopError, or is refused naming another; a
    spec it builds evaluates to finite values or refuses in one line (a path or pixel the scene lacks, other
    paths than the population's columns)."""
    try:
        spec = _build(field, value)
    except rtloop.RtloopError as e:
        assert str(e).startswith(f"{field}: ") and "\n" not in str(e)
        return
    try:
        out = _native.evaluate(SCENE, PHOTO, np.array([[2.0, 4.0, -1.0]]), spec, threads=1)
    except (rtloop.RtloopError, ValueError) as e:  # a population of other columns than the paths have
        assert "\n" not in str(e)
        return
    assert np.isfinite(out).all()


@settings(max_examples=40, deadline=None, derandomize=True, suppress_health_check=list(HealthCheck))
@given(loss=st.sampled_from(["l1", "l1_rgb", "l1_projected"]),
       norm=st.sampled_from(["l1", "l2", "huber:0.05"]), space=st.sampled_from(["linear", "srgb"]),
       clip=st.booleans(), footprint=st.booleans(),
       margin=st.integers(0, 3), saturated=st.one_of(st.none(), st.floats(0.5, 1.0)),
       pixels=st.one_of(st.none(), st.lists(st.integers(0, PIXELS - 1), min_size=1, max_size=40,
                                            unique=True)))
def test_a_valid_spec_evaluates_finite_and_the_same_on_every_call(loss, norm, space, clip, footprint, margin,
                                                                    saturated, pixels):
    spec = fitness_spec(["light.position"], loss=loss, norm=norm, space=space, clip=clip, footprint=footprint,
                        solve_margin=margin, saturated=saturated,
                        pixels=None if pixels is None else sorted(pixels),
                        product_bounds=BOUNDS if loss == "l1_projected" else None)
    rows = np.array([[2.5, 4.5, -1.0], [-3.0, 2.0, 1.0]])
    first = _native.evaluate(SCENE, PHOTO, rows, spec, threads=1)
    assert np.isfinite(first).all() and first.shape[0] == 2
    assert np.array_equal(first, _native.evaluate(SCENE, PHOTO, rows, spec, threads=2))


def test_what_depends_on_the_scene_is_checked_per_call_in_one_line():
    """The spec knows no scene: its paths, its bounds' object count, the target's shape and the population's
    columns are checked when a call pairs it with one."""
    two = _native.FitnessSpec(["light.position"], loss="l1_projected", product_bounds=BOUNDS)
    one_ball = rtloop.load_scene({**SMALL, "objects": SMALL["objects"][:1],
                                  "fit": {"light.position": SMALL["fit"]["light.position"]}})
    outside = _native.FitnessSpec(["light.position"], pixels=np.array([PIXELS], np.uint32))
    cases = [
        (lambda: _native.evaluate(one_ball, PHOTO, np.zeros((1, 3)), two), "product_bounds has 2 objects"),
        (lambda: _native.evaluate(SCENE, PHOTO, np.zeros((1, 3)), _native.FitnessSpec(["light.nowhere"])),
         "light.nowhere"),
        (lambda: _native.evaluate(SCENE, PHOTO[:5], np.zeros((1, 3)), two), "objective image has shape"),
        (lambda: _native.evaluate(SCENE, PHOTO, np.zeros((1, 4)), two), "population has 4 columns"),
        (lambda: _native.held_out(SCENE, PHOTO, np.zeros(3), np.zeros(PIXELS, np.uint8),
                                  _native.FitnessSpec(["light.position"])), "spec: held-out losses need"),
        (lambda: _native.evaluate(SCENE, PHOTO, np.zeros((1, 3)), outside),
         f"pixel index {PIXELS} is outside"),
    ]
    for call, message in cases:
        with pytest.raises((rtloop.RtloopError, ValueError)) as e:
            call()
        assert message in str(e.value) and "\n" not in str(e.value)


def test_a_spec_reused_by_searches_gives_the_same_fit_as_a_fresh_one():
    """A call neither changes nor consumes its spec: the same seeded search twice on one spec, and once on a
    spec built anew, finds the same light bit for bit."""
    spec = _native.FitnessSpec(["light.position"], loss="l1_projected", product_bounds=BOUNDS)
    kw = {"population": 6, "generations": 3, "seed": 4, "method": "lshade", "polish": 10, "threads": 1}
    a = _native.optimize(SCENE, PHOTO, spec, **kw)
    b = _native.optimize(SCENE, PHOTO, spec, **kw)
    c = _native.optimize(SCENE, PHOTO, _native.FitnessSpec(["light.position"], loss="l1_projected",
                                                            product_bounds=BOUNDS), **kw)
    assert np.array_equal(a.x, b.x) and np.array_equal(a.x, c.x) and a.products == c.products


def test_the_builder_takes_any_integer_pixels_and_the_closed_form_spec_is_the_fits_own():
    """``fitness_spec`` hands the pixels over as uint32 and the bounds as float64, whatever they came as;
    ``closed_form_spec`` is the projected loss with the scene's product bounds (the environment's rows
    when asked)."""
    rows = np.array([[2.0, 4.0, -1.0]])
    pixels = np.arange(0, PIXELS, 3)
    want = _native.evaluate(SCENE, PHOTO, rows, _native.FitnessSpec(["light.position"],
                                                                     pixels=pixels.astype(np.uint32)))
    for given_pixels in (pixels.tolist(), pixels.astype(np.int64), pixels[::-1][::-1]):
        got = _native.evaluate(SCENE, PHOTO, rows, fitness_spec(["light.position"], pixels=given_pixels))
        assert np.array_equal(got, want)
    for environment in (False, True):
        spec = closed_form_spec(SCENE, ["light.position"], None, environment=environment, clip=True,
                                norm="l1", space="linear")
        manual = _native.FitnessSpec(["light.position"], loss="l1_projected",
                                     product_bounds=product_bounds(SCENE, environment))
        assert np.array_equal(_native.evaluate(SCENE, PHOTO, rows, spec),
                              _native.evaluate(SCENE, PHOTO, rows, manual))
        assert "loss=\"l1_projected\"" in repr(spec)
