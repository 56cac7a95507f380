"""Goodness of fit (rtloop.fit.goodness): the noise estimate against known noise, and the verdict against
photos whose model is known to be complete or not (the Mitsuba fixtures with and without the terms)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import rtloop
from rtloop import cli
from rtloop.fit.goodness import EXPLAINED_RATIO, noise_sigma

PHOTOS = Path(__file__).resolve().parent / "fixtures" / "photos"


@pytest.mark.parametrize("sigma", [0.002, 0.01, 0.03])
def test_noise_sigma_recovers_known_noise_on_shaded_images(sigma):
    """White noise over smooth shading and a sharp edge: the estimate within 10 % of the truth."""
    rng = np.random.default_rng(1)
    y, x = np.mgrid[0:96, 0:128] / 96.0
    base = 0.2 + 0.3 * x + 0.1 * y**2
    base[30:60, 40:80] += 0.3  # an object's silhouette
    img = np.repeat(base[..., None], 3, axis=2) + rng.normal(0, sigma, (96, 128, 3))
    assert noise_sigma(img) == pytest.approx(np.full(3, sigma), rel=0.1)


def _fit(case: str, **kw):
    scene = rtloop.load_scene(PHOTOS / case / "scene_input.json")
    photo = rtloop.load_image(PHOTOS / case / "objective.png", scene)
    return rtloop.fit(scene, photo, uncertainty=False, **kw)


@pytest.mark.parametrize("case", ["direct-side", "direct-overhead"])
def test_a_photo_the_model_explains_says_so(case):
    g = _fit(case).report()["goodness"]
    assert g["ratio"] < EXPLAINED_RATIO and g["verdict"] == "the model explains this photo to the noise level"


@pytest.mark.parametrize(("case", "where"), [("env-overhead", "floor"), ("bounce-red-ball", "ball")])
def test_a_model_missing_a_term_is_told_and_where(case, where):
    """The same photos fitted with the environment and the bounce off: the verdict says the model does not
    explain them, naming where most of the excess lies (the floor under an environment, a ball lit by the
    floor's bounce); with the terms on (the default), the verdict is that it does."""
    g = _fit(case, environment="off", interreflection="off", highlights="off").goodness
    assert g["ratio"] >= EXPLAINED_RATIO
    assert g["verdict"].startswith(f"the residual is {g['ratio']:.2g}x the noise floor")
    assert f"of the excess on {where}" in g["verdict"]
    assert max(g["per_object"], key=lambda n: g["per_object"][n]["share_of_excess"]) == where
    assert _fit(case).goodness["ratio"] < EXPLAINED_RATIO < g["ratio"]


def test_cli_prints_the_verdict(tmp_path, capsys):
    """rtloop-fit: stdout has the goodness line, and a photo its model does not explain is a warning on
    stderr."""
    case = PHOTOS / "env-overhead"
    code = cli.main([str(case / "scene_input.json"), str(case / "objective.png"), "--out", str(tmp_path / "o"),
                     "--environment", "off", "--interreflection", "off", "--highlights", "off",
                     "--final-scale", "1", "--final-spp", "1", "--snapshot-every", "0"])
    out = capsys.readouterr()
    assert code == 0, out.err
    assert "goodness of fit: " in out.out
    assert "rtloop-fit: warning: the residual is " in out.err


def test_a_photo_saturated_everywhere_has_a_verdict_not_an_error():
    """No unsaturated pixel: nothing to judge by, said so (ratio None), and the fit still returns."""
    scene = rtloop.load_scene(PHOTOS / "direct-side" / "scene_input.json")
    photo = np.full((scene.height, scene.width, 3), 2.0, np.float32)
    with pytest.warns(rtloop.RtloopWarning):
        g = rtloop.fit(scene, photo, uncertainty=False, population=4, generations=1).goodness
    assert g["ratio"] is None and g["verdict"].startswith("no unsaturated pixel")
