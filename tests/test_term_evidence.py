"""A term's evidence: the environment and a lobe are nested in the direct model (their products at 0 give
it), so their best loss is never above the loss without them; the closed form's least-squares products can
score above it in L1, and the evidence says so and why (python/rtloop/fit/selection.py)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

import rtloop
from rtloop.fit.selection import closed_form_loss

LIGHTS = Path(__file__).resolve().parent / "fixtures" / "lights"


def test_a_nested_term_never_raises_the_loss_and_the_raise_is_explained():
    """key-fill-10: a key and a fill light fitted as one light. The environment column's least-squares
    products raise the L1 loss at the light found; the evidence keeps that loss, says why, and bounds the
    term's own best loss by the loss without it. The reason checked independently: in L2, the norm the
    products are solved in, the same column lowers the loss."""
    scene = rtloop.load_scene(LIGHTS / "key-fill-10" / "scene_input.json")
    photo = np.asarray(rtloop.load_image(LIGHTS / "key-fill-10" / "objective.png", scene), np.float32)
    result = rtloop.fit(scene, photo, uncertainty=False, lights=1)
    ev = result.model["evidence"]["environment"]
    assert ev["loss_with"] > ev["loss_without"]  # the raise this evidence must explain
    assert ev["nested"] is True and ev["raised"] is True and not ev["selected"]
    assert ev["loss_with_nested"] == ev["loss_without"]
    assert "least squares" in ev["why_raised"]
    stage = result.stages[0]
    at = scene.with_params(list(stage.x), stage.paths)
    kw = {"clip": True, "space": "linear", "threads": None, "saturated": result.settings["saturated"]}
    l2 = [closed_form_loss(at, stage.paths, [list(stage.x)], photo, None, environment=e, norm="l2", **kw)[0]
          for e in (False, True)]
    l1 = [closed_form_loss(at, stage.paths, [list(stage.x)], photo, None, environment=e, norm="l1", **kw)[0]
          for e in (False, True)]
    assert l2[1] <= l2[0] and l1[1] > l1[0]
    bounce = result.model["evidence"]["interreflection"]
    assert bounce["nested"] is False and bounce["loss_with_nested"] == bounce["loss_with"]
    if bounce["raised"]:
        assert "not nested" in bounce["why_raised"]


def test_every_nested_term_on_the_light_photos_is_bounded_by_the_loss_without_it():
    for case in ("key-fill-25", "soft-10"):
        scene = rtloop.load_scene(LIGHTS / case / "scene_input.json")
        photo = rtloop.load_image(LIGHTS / case / "objective.png", scene)
        result = rtloop.fit(scene, photo, uncertainty=False, lights=1)
        for term, ev in getattr(result, "model", {}).get("evidence", {}).items():
            if ev["nested"]:
                assert ev["loss_with_nested"] <= ev["loss_without"], (case, term)
