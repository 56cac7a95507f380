"""Linear camera files with truth (tests/fixtures/linear, rendered by Mitsuba 3: tools/make_linear_photos.py):
a coated (roughplastic) and a matte ball under one far light, 16-bit linear with shot and read noise, read
as ``--response linear --mask``. The default fit's light direction against the truth, the coat chosen on the
coated ball, and the L2 refit on a linear file whose residual is dense."""

from __future__ import annotations

import json
import warnings
from pathlib import Path

import numpy as np
import pytest

import rtloop

LINEAR = Path(__file__).resolve().parent / "fixtures" / "linear"


def _fit(case: str, uncertainty: bool = False, **kw):
    folder = LINEAR / case
    scene = rtloop.load_scene(folder / "scene_input.json")
    photo = rtloop.load_image(folder / "objective.png", scene, response="linear")
    mask = rtloop.load_mask(folder / "mask.png", scene)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", rtloop.RtloopWarning)
        result = rtloop.fit(scene, photo, mask=mask, uncertainty=uncertainty, **kw)
    d = np.asarray(result.scene.to_dict()["light"]["position"], float)
    t = np.asarray(json.loads((folder / "truth.json").read_text())["direction"], float)
    error = float(np.degrees(np.arccos(np.clip(d @ t / np.linalg.norm(d) / np.linalg.norm(t), -1, 1))))
    return result, error


@pytest.mark.parametrize("case", ["coat-02", "coat-10"])
def test_a_coated_ball_under_a_far_light_is_fitted_with_the_coat(case):
    """The lobes are compared at the light found without one, which the highlight pulls towards itself: there
    Blinn-Phong wins and its refit ends 2.8-3.2 deg off. The coat, tried again from the refitted light, wins
    and puts the light within half a degree."""
    result, error = _fit(case)
    assert result.model["evidence"]["specular"]["lobe"] == "coat"
    assert "coat" in result.scene.to_dict()["objects"][0]["material"]
    assert error < 0.5


@pytest.mark.parametrize("case", ["coat-02", "coat-10", "matte-03", "matte-10"])
def test_the_direction_bar_covers_the_truth_with_the_coats_roughness_carried(case):
    """The reported direction bar (``bars.light_distance.direction_sigma_deg``) holds the true direction within
    3 sigma. On the coated balls the fit chose the coat's roughness from the photo and holds it while it
    refits the light: it is a nuisance parameter of the bars (rtloop.uncertainty.nuisance.held_terms). With it
    held as known coat-10's light, 0.145 deg off, was 3.7 sigma out (a bar of 0.039 deg); with it carried the
    bar is 0.18 deg. The matte balls' bars are untouched (0.03 deg, the light 0.03 deg off)."""
    result, error = _fit(case, uncertainty=True, tone="linear")
    u = result.uncertainty
    sigma = u["bars"]["light_distance"]["direction_sigma_deg"]
    assert sigma is not None and error <= 3 * sigma
    coated = "coat" in result.scene.to_dict()["objects"][0]["material"]
    assert ("objects.ball.roughness" in (u.get("nuisance") or {}).get("names", [])) == coated
    if not coated:
        assert sigma < 0.1


@pytest.mark.parametrize("case", ["matte-03", "matte-10"])
def test_a_matte_ball_in_a_linear_file_is_refitted_in_l2_and_within_a_tenth_of_a_degree(case):
    result, error = _fit(case)
    assert result.model["norm"]["linear_file"] is True and result.model["norm"]["used"] == "l2"
    assert error < 0.1


def test_the_same_photo_read_as_srgb_is_not_a_linear_file():
    folder = LINEAR / "matte-03"
    scene = rtloop.load_scene(folder / "scene_input.json")
    photo = rtloop.load_image(folder / "objective.png", scene)  # as an sRGB file
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", rtloop.RtloopWarning)
        result = rtloop.fit(scene, photo, mask=rtloop.load_mask(folder / "mask.png", scene), uncertainty=False)
    assert result.model["norm"]["linear_file"] is False and result.model["norm"]["used"] == "l1"
