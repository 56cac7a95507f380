"""Property tests (Hypothesis): mutated scenes, fit() arguments and image arrays either work or raise
an RtloopError; what works renders finite pixels and fits inside the scene's bounds. Bounded and derandomised so
CI runs the same few hundred cases every time."""

from __future__ import annotations

import copy
import math

import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import rtloop
from conftest import BALL_ON_FLOOR

SMALL = copy.deepcopy(BALL_ON_FLOOR)
SMALL["image"] = {"width": 16, "height": 12}
PHOTO = rtloop.render(SMALL)

PROPS = settings(max_examples=150, deadline=None, derandomize=True,
                 suppress_health_check=[HealthCheck.too_slow])

#: Numbers an adversary would write: ordinary, zero, negative, tiny, huge, non-finite.
NUMBERS = st.one_of(
    st.floats(-10, 10), st.sampled_from([0.0, -0.0, 1e-300, -1e-300, 1e8, 1.0000001e8, 1e20, 1e300, -1e300]),
    st.sampled_from([math.nan, math.inf, -math.inf]), st.floats(allow_nan=True, allow_infinity=True),
)

#: (where, how many numbers) of every numeric field of SMALL and its fit section.
FIELDS = [
    (("camera", "position"), 3), (("camera", "look_at"), 3), (("camera", "up"), 3), (("camera", "vfov_deg"), 0),
    (("light", "position"), 3), (("light", "intensity"), 0), (("light", "color"), 3),
    (("objects", 0, "center"), 3), (("objects", 0, "radius"), 0), (("objects", 0, "material", "albedo"), 3),
    (("objects", 1, "point"), 3), (("objects", 1, "normal"), 3), (("ambient",), 3), (("exposure",), 0),
    (("fit", "light.position", "min"), 3), (("fit", "light.position", "max"), 3),
    (("fit", "light.intensity", "min"), 0), (("fit", "light.intensity", "max"), 0),
    (("fit", "objects.ball.albedo", "max"), 3),
]


@st.composite
def mutated_scenes(draw) -> dict:
    d = copy.deepcopy(SMALL)
    for _ in range(draw(st.integers(1, 3))):
        where, n = draw(st.sampled_from(FIELDS))
        node = d
        for k in where[:-1]:
            node = node[k]
        node[where[-1]] = draw(NUMBERS) if n == 0 else draw(st.lists(NUMBERS, min_size=n, max_size=n))
    return d


@PROPS
@given(mutated_scenes())
def test_a_mutated_scene_loads_and_renders_finite_or_is_a_scene_error(d):
    try:
        scene = rtloop.load_scene(d)
    except rtloop.SceneError:
        return
    img = rtloop.render(scene, 8, 6)
    assert np.isfinite(img).all()
    assert (rtloop.object_ids(scene, 8, 6) >= -1).all()


def _argument(valid, invalid):
    """Valid four times in five: most drawn fits then run, and each run meets a few invalid arguments."""
    return st.one_of(valid, valid, valid, valid, invalid)


ARGS = st.fixed_dictionaries({}, optional={
    "seed": _argument(st.integers(0, 2**64 - 1), st.one_of(st.integers(max_value=-1), st.integers(2**64),
                                                           st.floats(), st.text(max_size=2))),
    "threads": _argument(st.integers(1, 4), st.one_of(st.integers(max_value=0), st.integers(2**20), st.floats())),
    "population": _argument(st.integers(4, 8), st.one_of(st.integers(max_value=3), st.integers(10**5 + 1),
                                                         st.booleans())),
    "generations": _argument(st.one_of(st.integers(0, 2), st.tuples(st.integers(0, 2), st.integers(0, 2))),
                             st.one_of(st.integers(max_value=-1), st.tuples(st.integers(0, 2)),
                                       st.lists(st.integers(0, 2), min_size=3, max_size=3), st.floats())),
    "f": _argument(st.floats(0.01, 2.0), st.one_of(st.floats(max_value=0.0), st.floats(min_value=2.0001),
                                                   st.just(math.nan))),
    "cr": _argument(st.floats(0.0, 1.0), st.one_of(st.floats(max_value=-1e-9), st.floats(min_value=1.0001),
                                                   st.just(math.nan))),
    "polish": _argument(st.integers(0, 20), st.one_of(st.integers(max_value=-1), st.integers(10**6 + 1))),
    "protocol": _argument(st.sampled_from(["rtloop", "paper"]), st.just("fast")),
    "norm": _argument(st.sampled_from(["l1", "l2", "huber", "huber:0.1"]), st.sampled_from(["huber:-1", "bogus"])),
})


@PROPS
@given(ARGS)
def test_fit_arguments_work_or_raise_rtloop_error(kw):
    kw.setdefault("generations", 1)
    kw.setdefault("population", 4)
    kw.setdefault("polish", 5)
    try:
        with _quiet():
            result = rtloop.fit(SMALL, PHOTO, uncertainty=False, **kw)
    except rtloop.RtloopError:
        return
    s = result.scene
    for v, (lo, hi) in zip(s.get_params(), s.bounds()):
        assert lo <= v <= hi
    assert all(math.isfinite(v) for row in result.products.values() for v in row)


@PROPS
@given(st.sampled_from(["float32", "float64", "float16", "uint8", "uint16", "int64", "bool", "complex64"]),
       st.sampled_from([(12, 16, 3), (12, 16), (12, 16, 4), (16, 12, 3), (0, 0, 3)]),
       st.sampled_from([0.0, 1.0, -1.0, 300.0, math.nan, math.inf]))
def test_image_arrays_work_or_raise_rtloop_error(dtype, shape, fill):
    with np.errstate(invalid="ignore"):
        image = np.full(shape, 0.5, dtype=np.float64)
        if image.size:
            image.flat[0] = fill
        image = image.astype(dtype)
    try:
        with _quiet():
            result = rtloop.fit(SMALL, image, generations=1, population=4, polish=2, uncertainty=False)
    except rtloop.RtloopError:
        return
    assert np.dtype(dtype).kind == "f" and shape == (12, 16, 3) and math.isfinite(fill)
    assert all(math.isfinite(v) for v in result.x.values())


class _quiet:
    """RtloopWarnings (doubted inputs) are expected here."""

    def __enter__(self):
        import warnings

        self._w = warnings.catch_warnings()
        self._w.__enter__()
        warnings.simplefilter("ignore", rtloop.RtloopWarning)

    def __exit__(self, *exc):
        return self._w.__exit__(*exc)
