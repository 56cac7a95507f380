"""Property tests of the default fit's number of lights (:mod:`rtloop.fit.more_lights`): on photos of one
ball under a key light and a second light anywhere in the fit box, of any power down to none, with or without
noise, the default fit either is the one-light fit (``lights=1``) unchanged, with the further lights it
tried and why it refused them, or the lights fit whose evidence keeps each light it adds; never an
exception, never a non-finite value."""

from __future__ import annotations

import copy
import json
import math
import warnings

import numpy as np
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st

import rtloop
from conftest import BALL_ON_FLOOR
from rtloop.fit.lights import AUTO_GAIN

SMALL = copy.deepcopy(BALL_ON_FLOOR)
SMALL["image"] = {"width": 32, "height": 24}
SMALL["fit"].pop("light.intensity")


def _photo(second: list[float], power: float, noise: float, seed: int) -> np.ndarray:
    d = copy.deepcopy(SMALL)
    key = d.pop("light")
    d["lights"] = [{"name": "key", **key}, {"name": "fill", "position": second, "intensity": power * key["intensity"]}]
    photo = np.asarray(rtloop.render(d), np.float32)
    if noise:
        photo = np.clip(photo + np.random.default_rng(seed).normal(0, noise, photo.shape), 0, None)
    return photo.astype(np.float32)


def _report(result: rtloop.FitResult) -> str:
    r = result.report()
    r.pop("seconds")
    r["stages"] = [{k: v for k, v in s.items() if k != "seconds"} for s in r["stages"]]
    r["model"] = {k: v for k, v in r["model"].items() if k != "lights"}
    return json.dumps(r, sort_keys=True)


@settings(max_examples=20, deadline=None, derandomize=True, suppress_health_check=[HealthCheck.too_slow])
@given(second=st.tuples(st.floats(-8, 8), st.floats(0.5, 8), st.floats(-8, 8)),
       power=st.sampled_from([0.0, 0.05, 0.25, 1.0]), noise=st.sampled_from([0.0, 0.0, 0.01]),
       seed=st.integers(0, 3))
def test_the_default_is_the_one_light_fit_or_a_lights_fit_its_evidence_keeps(second, power, noise, seed):
    photo = _photo(list(second), power, noise, seed)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", rtloop.RtloopWarning)
        default = rtloop.fit(SMALL, photo, seed=seed, uncertainty=False)
        one = rtloop.fit(SMALL, photo, seed=seed, uncertainty=False, lights=1)
    if isinstance(default, rtloop.FitResult):
        assert _report(default) == _report(one) and default.scene.to_dict() == one.scene.to_dict()
        tested = default.model.get("lights")
        event("one light, a further one tried" if tested and tested["tried"] else "one light")
        if tested is not None:
            assert tested["fires"] and tested["kept"] == 1 and tested["why"]
            assert all(not e["kept"] for e in tested["evidence"][1:])
            json.dumps(tested, allow_nan=False)
        return
    event(f"{len(default.lights)} lights")
    assert default.gate["fires"] and default.gate["kept"] == len(default.lights) >= 2
    ev = default.evidence
    kept = [e for e in ev if e["kept"]]
    assert len(kept) == 1 and kept[0]["lights"] == len(default.lights)
    for before, after in zip(ev, ev[1:]):
        if after is kept[0] or after["lights"] < kept[0]["lights"]:
            assert after["held_out"] < (1 - AUTO_GAIN) * before["held_out"] and after["passes"]
    for light in default.lights:
        assert all(math.isfinite(v) for v in light["position"]) and math.isfinite(light["intensity"])
    assert all(math.isfinite(v) for rows in default.products.values() for row in rows for v in row)
