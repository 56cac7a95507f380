"""The goodness verdict per object: fine, zero-mean residual (a textured floor, noise) is told from smooth
residual a shading could absorb (a light held 7 cm off, a lens's vignetting, a camera's tone curve, room
light or a bounce the fit leaves out), on the Mitsuba photos with their truth (python/rtloop/fit/structure.py).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import rtloop
from rtloop import _native
from rtloop._srgb import decode, encode
from rtloop.fit.goodness import EXPLAINED_RATIO

PHOTOS = Path(__file__).resolve().parent / "fixtures" / "photos"


#: The fits of a model that lacks what the photo has: the camera's terms off too, since a fitted vignetting
#: or tone curve takes up a vignetted or tone-curved photo (and can stand in for a room light left out).
NO_CAMERA = {"vignetting": "off", "tone": "off"}


def _case(name: str):
    scene = rtloop.load_scene(PHOTOS / name / "scene_input.json")
    photo = np.asarray(rtloop.load_image(PHOTOS / name / "objective.png", scene), np.float32)
    return scene, photo, rtloop.load_scene(PHOTOS / name / "scene.json")


def _codes(x: np.ndarray) -> np.ndarray:
    """Linear values through 8-bit sRGB codes and back (a PNG of them)."""
    return decode(np.round(encode(np.clip(x, 0.0, 1.0)) * 255.0) / 255.0).astype(np.float32)


def textured_floor(photo: np.ndarray, truth, amplitude: float = 0.3, seed: int = 0) -> np.ndarray:
    """The photo with the floor's albedo varied per pixel by a uniform factor 1 +- ``amplitude`` (mean 1): a
    fine texture, exact for direct light (each floor pixel's radiance is its albedo times its irradiance)."""
    ids = np.asarray(_native.object_ids(truth)).reshape(photo.shape[:2])
    factor = 1.0 + amplitude * np.random.default_rng(seed).uniform(-1.0, 1.0, photo.shape[:2])
    out = photo.copy()
    floor = ids == truth.object_names.index("floor")
    out[floor] *= factor[floor][:, None]
    return _codes(out)


def vignetted(photo: np.ndarray) -> np.ndarray:
    """A lens's radial falloff, the corners at 40 % of the centre."""
    h, w = photo.shape[:2]
    yy, xx = np.mgrid[0:h, 0:w]
    r2 = ((xx - (w - 1) / 2) ** 2 + (yy - (h - 1) / 2) ** 2) / ((w / 2) ** 2 + (h / 2) ** 2)
    return _codes(photo * (1.0 - 0.6 * r2)[..., None])


def tone_curved(photo: np.ndarray) -> np.ndarray:
    """An S-shaped tone curve on the sRGB codes (not the sRGB curve the loader undoes)."""
    e = encode(np.clip(photo, 0.0, 1.0))
    return _codes(decode(np.clip(e + 0.12 * np.sin(2 * np.pi * e), 0.0, 1.0)))


def _flagged(g: dict) -> dict:
    """The objects whose residual exceeds the noise-floor factor, with what the verdict calls them."""
    return {n: g["explained"][n] for n, v in g["per_object"].items()
            if v["ratio"] >= EXPLAINED_RATIO and n in g["explained"]}


@pytest.mark.parametrize("case", ["direct-side", "direct-two-balls"])
def test_a_finely_textured_floor_is_explained_as_texture(case):
    """The light is right and the floor finely textured: the residual is several times the noise floor
    (the plain verdict flags it), and the verdict calls it texture/noise, on the floor, in the report too."""
    scene, photo, truth = _case(case)
    result = rtloop.fit(scene, textured_floor(photo, truth), uncertainty=False)
    g = result.report()["goodness"]
    assert g["ratio"] >= EXPLAINED_RATIO
    assert g["explained"]["floor"] == "texture/noise"
    assert g["per_object"]["floor"]["structure"]["structured"] is False
    assert "floor: explained: texture/noise" in g["diagnosis"]
    assert g["fine_only"] is True and g["verdict"].startswith("the model explains this photo: the residual is ")
    assert "fine and zero-mean on floor" in g["verdict"]
    # and the light it found is right (the texture did not move it)
    err = np.linalg.norm(np.subtract(result.scene.to_dict()["light"]["position"], truth.to_dict()["light"]["position"]))
    assert err < 0.02


def _light_held_off(scene, truth, offset=(0.05, 0.0, 0.05)):
    d = scene.to_dict()
    d["light"]["position"] = (np.asarray(truth.to_dict()["light"]["position"]) + offset).tolist()
    del d["fit"]["light.position"]
    return rtloop.load_scene(d)


@pytest.mark.parametrize("case", ["direct-side", "direct-overhead"])
@pytest.mark.parametrize("wrong", ["light held 7 cm off", "vignetting", "tone curve"])
def test_a_wrong_model_is_not_called_texture(case, wrong):
    """A light held 7 cm from the truth, a vignetted photo, a tone-curved one: every object whose residual
    exceeds the floor is called structured (never texture/noise), and at least one is."""
    scene, photo, truth = _case(case)
    if wrong == "light held 7 cm off":
        scene = _light_held_off(scene, truth)
    else:
        photo = vignetted(photo) if wrong == "vignetting" else tone_curved(photo)
    g = rtloop.fit(scene, photo, uncertainty=False, **NO_CAMERA).goodness
    flagged = _flagged(g)
    assert flagged, g["per_object"]
    assert all(v != "texture/noise" for v in flagged.values()), flagged
    assert "not explained" in g["diagnosis"]
    assert "fine_only" not in g and "the model does not explain this photo" in g["verdict"]


@pytest.mark.parametrize("case", ["env-overhead", "bounce-red-ball"])
def test_a_term_left_out_is_not_called_texture(case):
    scene, photo, _ = _case(case)
    g = rtloop.fit(scene, photo, uncertainty=False, environment="off", interreflection="off",
                   highlights="off", **NO_CAMERA).goodness
    flagged = _flagged(g)
    assert flagged and all(v != "texture/noise" for v in flagged.values()), flagged


def test_noise_is_explained_as_texture_or_within_the_floor():
    """2 % Gaussian noise on a clean photo: no object is called structured."""
    scene, photo, _ = _case("direct-two-balls")
    noisy = np.clip(photo + np.random.default_rng(0).normal(0, 0.02, photo.shape), 0, 1).astype(np.float32)
    g = rtloop.fit(scene, noisy, uncertainty=False).goodness
    assert all(v == "texture/noise" for v in g.get("explained", {}).values())


def test_the_vignetting_is_named_on_the_floor():
    """Where one cause explains the smooth residual clearly (a vignetted floor), it is named."""
    scene, photo, _ = _case("direct-overhead")
    g = rtloop.fit(scene, vignetted(photo), uncertainty=False, **NO_CAMERA).goodness
    assert g["explained"]["floor"] == "vignetting"
    assert g["per_object"]["floor"]["structure"]["causes"]["vignetting"] >= 0.5


LIGHTS = Path(__file__).resolve().parent / "fixtures" / "lights"


@pytest.mark.parametrize("case", ["key-fill-10", "three-lights"])
def test_a_second_light_is_not_called_texture(case):
    """Photos with a fill light (10 % of the key) or three lamps fitted as one light: every flagged object's
    residual is structured."""
    scene = rtloop.load_scene(LIGHTS / case / "scene_input.json")
    g = rtloop.fit(scene, rtloop.load_image(LIGHTS / case / "objective.png", scene), uncertainty=False,
                   lights=1).goodness
    flagged = _flagged(g)
    assert flagged and all(v != "texture/noise" for v in flagged.values()), flagged


def test_rtloop_fit_prints_what_the_residual_is(tmp_path, capsys):
    """rtloop-fit on a photo whose room light the fit leaves out: the summary and the warning say, per object,
    what the residual is."""
    from rtloop import cli

    case = PHOTOS / "env-overhead"
    code = cli.main([str(case / "scene_input.json"), str(case / "objective.png"), "--out", str(tmp_path / "o"),
                     "--environment", "off", "--interreflection", "off", "--highlights", "off",
                     "--vignetting", "off", "--tone-curve", "off",
                     "--final-scale", "1", "--final-spp", "1", "--snapshot-every", "0"])
    out = capsys.readouterr()
    assert code == 0, out.err
    assert "  residual by object: ball: not explained" in out.out
    assert "rtloop-fit: residual by object: " in out.err


def test_rtloop_fit_does_not_warn_about_texture(tmp_path, capsys):
    """rtloop-fit on a photo whose floor is finely textured: the verdict says the model explains it, and
    there is no warning."""
    from PIL import Image

    from rtloop import cli
    from rtloop._srgb import encode

    scene, photo, truth = _case("direct-side")
    path = tmp_path / "textured.png"
    Image.fromarray(np.round(encode(np.clip(textured_floor(photo, truth), 0, 1)) * 255).astype(np.uint8)).save(path)
    code = cli.main([str(PHOTOS / "direct-side" / "scene_input.json"), str(path), "--out", str(tmp_path / "o"),
                     "--final-scale", "1", "--final-spp", "1", "--snapshot-every", "0"])
    out = capsys.readouterr()
    assert code == 0, out.err
    assert "the model explains this photo: the residual is" in out.out
    assert "warning" not in out.err, out.err


def test_the_box_mean_over_an_objects_pixels_against_a_direct_sum():
    from rtloop.fit.structure import _box_mean

    rng = np.random.default_rng(0)
    x, w = rng.random((20, 30, 7)), rng.random((20, 30)) > 0.4
    want = np.zeros_like(x)
    for i in range(20):
        for j in range(30):
            sl = (slice(max(i - 3, 0), i + 4), slice(max(j - 3, 0), j + 4))
            if w[sl].any():
                want[i, j] = x[sl][w[sl]].mean(axis=0)
    assert np.allclose(_box_mean(x, w, 7), want, rtol=0, atol=1e-12)
