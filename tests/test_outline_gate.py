"""The outline gate (docs/methods.md, "Pixel footprint"): a default fit takes the outline pixels averaged
over sub-pixel rays only where its photo shows it needs them, judged against truth the fit did not see."""

from __future__ import annotations

import dataclasses
import importlib
import json
from pathlib import Path

import numpy as np
import pytest

import rtloop
from scenes import BACKLIT_BALL, matte_start, supersampled_photo

#: The fit package (``rtloop.fit`` the attribute is the function).
FIT = importlib.import_module("rtloop.fit")
PHOTOS = Path(__file__).resolve().parent / "fixtures" / "photos"


def _photo(name: str):
    scene = rtloop.load_scene(PHOTOS / name / "scene_input.json")
    truth = json.loads((PHOTOS / name / "scene.json").read_text())["light"]["position"]
    return scene, rtloop.load_image(PHOTOS / name / "objective.png", scene), truth


def _error(result, truth) -> float:
    return float(np.linalg.norm(np.subtract([result.x[f"light.position.{a}"] for a in "xyz"], truth)))


def _without_gate(monkeypatch):
    """Fits from here on keep every outline at its pixel centre (the plan's outline gate held off)."""
    plan_fit = FIT.plan_fit
    monkeypatch.setattr(FIT, "plan_fit",
                        lambda *a, **k: dataclasses.replace(plan_fit(*a, **k), silhouettes="off"))


def test_the_gate_fires_on_a_ball_over_a_dark_floor_and_moves_the_light_towards_the_truth(monkeypatch):
    """A ball over a floor of albedo 0.03 (Mitsuba, box filter): the outline pixels are half the fit's loss,
    the gate takes them averaged, and the light comes closer to the truth than with them at pixel centres."""
    scene, photo, truth = _photo("edge-dark-floor")
    gated = rtloop.fit(scene, photo, seed=0, uncertainty=False)
    record = gated.model["outlines"]
    assert record["used"] == "integrated" and record["evidence"]["fired"] and record["evidence"]["kept"], record
    assert gated.settings["silhouettes"] is True
    _without_gate(monkeypatch)
    centres = rtloop.fit(scene, photo, seed=0, uncertainty=False)
    assert centres.settings["silhouettes"] is False
    assert _error(gated, truth) < 0.8 * _error(centres, truth), (_error(gated, truth), _error(centres, truth))


def _ball_product_error(result, truth: dict) -> float:
    """The worst relative error over RGB of the ball's product (intensity x light colour x albedo)."""
    def product(scene: dict) -> np.ndarray:
        ball = next(o for o in scene["objects"] if o["name"] == "ball")
        light = scene["light"]
        return light["intensity"] * np.array(light.get("color", [1, 1, 1])) * np.array(ball["material"]["albedo"])
    t = product(truth)
    return float(np.max(np.abs(product(result.scene.to_dict()) - t)) / np.max(t))


def test_the_gate_fires_on_a_ball_lit_from_behind_and_measures_its_colour_on_the_rim(monkeypatch):
    """rtloop's own 16x16-supersampled render of a ball lit from behind (the side the camera sees lit on a
    rim along its outline), rounded to 8 bits: nearly all the ball's lit pixels are on its outline, the gate
    fires, and the ball's colour, measured on the rim, comes far closer to the truth than with the outlines
    at pixel centres (where the rim's pixels are mostly unlit); the light stays within 1 cm."""
    photo, start = supersampled_photo(BACKLIT_BALL), rtloop.load_scene(matte_start(BACKLIT_BALL))
    gated = rtloop.fit(start, photo, seed=0, uncertainty=False)
    evidence = gated.model["outlines"]["evidence"]
    assert evidence["outline_share"] >= 0.5 and evidence["fired"] and evidence["kept"], evidence
    assert _error(gated, BACKLIT_BALL["light"]["position"]) < 0.01
    _without_gate(monkeypatch)
    centres = rtloop.fit(start, photo, seed=0, uncertainty=False)
    gated_err, centres_err = _ball_product_error(gated, BACKLIT_BALL), _ball_product_error(centres, BACKLIT_BALL)
    assert gated_err < 0.5 * centres_err, (gated_err, centres_err)


def test_the_gate_does_not_fire_on_a_clean_direct_photo(monkeypatch):
    """A ball lit from the side (Mitsuba): the outlines are a small part of the loss and of the ball's light;
    the gate does not fire and the fit is the one with the gate held off, bit for bit."""
    scene, photo, _ = _photo("direct-side")
    gated = rtloop.fit(scene, photo, seed=0, uncertainty=False)
    record = gated.model["outlines"]
    assert record["used"] == "centres" and not record["evidence"]["fired"], record
    _without_gate(monkeypatch)
    centres = rtloop.fit(scene, photo, seed=0, uncertainty=False)
    assert gated.x == centres.x and gated.fitness == centres.fitness


def test_footprint_silhouette_forces_the_outlines_and_a_bad_value_is_refused_in_one_line():
    scene, photo, _ = _photo("direct-side")
    forced = rtloop.fit(scene, photo, seed=0, uncertainty=False, footprint="silhouette", population=8,
                        generations=2)
    assert forced.model["outlines"]["used"] == "integrated" and forced.settings["silhouettes"] is True
    for bad in ("silhouettes", 2, None):
        with pytest.raises(rtloop.RtloopError, match=r"^footprint: ") as e:
            rtloop.fit(scene, photo, uncertainty=False, footprint=bad)
        assert "\n" not in str(e.value)
    with pytest.raises(rtloop.RtloopError, match=r"^footprint: "):
        rtloop.render(scene, footprint="outline")


def test_the_silhouette_render_differs_from_the_footprint_render_on_outlines_only():
    """``render(footprint="silhouette")`` changes only pixels whose 4-neighbours show another object."""
    scene = rtloop.load_scene(BACKLIT_BALL)
    plain, outlined = rtloop.render(scene, footprint=True), rtloop.render(scene, footprint="silhouette")
    ids = rtloop._native.object_ids(scene)
    edge = np.zeros(ids.shape, bool)
    edge[1:] |= ids[1:] != ids[:-1]
    edge[:-1] |= ids[1:] != ids[:-1]
    edge[:, 1:] |= ids[:, 1:] != ids[:, :-1]
    edge[:, :-1] |= ids[:, 1:] != ids[:, :-1]
    changed = np.abs(outlined - plain).max(axis=2) > 0
    assert changed.any() and not (changed & ~edge).any()


def test_the_native_silhouettes_option_refuses_a_bad_value_in_one_line():
    from rtloop.fit.spec import fitness_spec

    scene, photo, _ = _photo("direct-side")
    spec = fitness_spec(scene.fit_paths, loss="l1", footprint=True)
    for bad in ("silhouette", "", "AUTO"):
        with pytest.raises(rtloop.RtloopError, match=r"^silhouettes: must be 'auto', 'on' or 'off'") as e:
            rtloop._native.optimize(scene, photo, spec, population=4, generations=1, silhouettes=bad)
        assert "\n" not in str(e.value)
