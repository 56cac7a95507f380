"""Glossy objects in the lights fit: an object with a Blinn–Phong lobe (its specular and shininess given)
has one more column per light, fitted in closed form with the rest. Photos rendered by rtloop from a truth
the fit does not see, 8-bit; the lobe's formula is the renderer's (tests/lights.rs checks the closed form
against a render to rounding)."""

from __future__ import annotations

import copy
import json
import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import rtloop

FIXTURES = Path(__file__).resolve().parent / "fixtures" / "lights"
LOBES = {"red": (0.6, 40.0), "blue": (0.3, 15.0)}


def glossy_photo() -> tuple[dict, np.ndarray, dict]:
    """lamp-window's truth with glossy balls, rendered and quantised to 8 bits; its input with the balls'
    shininess as the truth's and a specular guess."""
    truth = json.loads((FIXTURES / "lamp-window" / "scene.json").read_text())
    truth.pop("environment")
    d = json.loads((FIXTURES / "lamp-window" / "scene_input.json").read_text())
    for scene in (truth, d):
        for o in scene["objects"]:
            if o["name"] in LOBES:
                specular, shininess = LOBES[o["name"]]
                o["material"].update(specular=specular if scene is truth else 0.2, shininess=shininess)
    image = np.round(np.clip(rtloop.render(rtloop.load_scene(truth)), 0, 1) * 255) / 255
    return truth, image.astype(np.float32), d


def errors(res, truth: dict) -> list[float]:
    return [float(np.linalg.norm(np.subtract(f["position"], t["position"]))) for f, t in zip(res.lights, truth["lights"])]


def test_a_glossy_ball_s_lobe_is_fitted_with_the_lights():
    truth, image, d = glossy_photo()
    res = rtloop.fit(d, image, seed=0)
    lamp, window = errors(res, truth)
    assert lamp < 0.02 and window < 0.05, (lamp, window)
    written = {o["name"]: o["material"] for o in rtloop.scene_to_dict(res.scene)["objects"]}
    for name, (specular, _) in LOBES.items():
        assert abs(written[name]["specular"] - specular) < 0.05 * specular, (name, written[name])
    assert written["floor"]["specular"] == 0.0
    assert len(res.products["red"]) == 5 and res.products["floor"][3:] == [[0.0] * 3] * 2
    # the same photo with the balls taken as matte: the highlights pull the lights off
    matte = copy.deepcopy(d)
    for o in matte["objects"]:
        o["material"].pop("specular", None)
    assert max(errors(rtloop.fit(matte, image, seed=0), truth)) > 3 * max(lamp, window)


def test_too_many_lights_for_a_glossy_object_is_one_line_naming_it():
    _, image, d = glossy_photo()
    with pytest.raises(rtloop.RtloopError, match=r"objects\.red\.specular") as e:
        rtloop.fit(d, image, lights=5, seed=0)
    assert "\n" not in str(e.value)


def test_a_free_shininess_is_refused_in_one_line_naming_it():
    _, image, d = glossy_photo()
    d["fit"]["objects.red.shininess"] = {"min": 1, "max": 100}
    with pytest.raises(rtloop.RtloopError, match=r"objects\.red\.shininess") as e:
        rtloop.fit(d, image, seed=0)
    assert "\n" not in str(e.value)


@settings(max_examples=12, deadline=None, derandomize=True, suppress_health_check=list(HealthCheck))
@given(st.floats(0.0, 5.0), st.floats(0.0, 500.0), st.integers(1, 3))
def test_any_lobe_fits_finite_or_refuses_in_one_line(specular, shininess, lights):
    """Any specular and shininess in range, any count of lights: the fit's lights, products and written
    specular are finite and non-negative."""
    small = json.loads((FIXTURES / "lamp-window" / "scene_input.json").read_text())
    small["image"] = {"width": 24, "height": 18}
    small["objects"][0]["material"].update(specular=specular, shininess=shininess)
    image = np.clip(rtloop.render(rtloop.load_scene(small)), 0, 1).astype(np.float32)
    try:
        res = rtloop.fit(small, image, lights=max(lights, 2), seed=0, population=4, generations=1)
    except rtloop.RtloopError as e:
        assert "\n" not in str(e)
        return
    assert all(math.isfinite(v) and v >= 0 for rows in res.products.values() for row in rows for v in row)
    for o in rtloop.scene_to_dict(res.scene)["objects"]:
        assert math.isfinite(o["material"]["specular"]) and o["material"]["specular"] >= 0
