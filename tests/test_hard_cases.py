"""Hard cases: each must neither crash nor return NaN, and must degrade gracefully.

Every objective here is made from a known scene (rendered by rtloop, then damaged the way a camera or a
file would damage it), so the fit is judged against ground truth it never saw.
"""

from __future__ import annotations

import copy
import io
import json

import numpy as np
import pytest
from PIL import Image

import rtloop
from conftest import centred_start as _start, sunlit
from rtloop import _native


def _light_err(result, truth: dict) -> float:
    return float(np.linalg.norm(np.array(result.scene.to_dict()["light"]["position"]) - truth["light"]["position"]))


def _product_err(result, truth: dict, skip: tuple[str, ...] = ()) -> float:
    fitted = result.scene.to_dict()
    worst = 0.0
    for o, f in zip(truth["objects"], fitted["objects"]):
        if o["name"] in skip:
            continue
        want = truth["light"]["intensity"] * np.array(o["material"]["albedo"])
        got = fitted["light"]["intensity"] * np.array(f["material"]["albedo"])
        worst = max(worst, float(np.max(np.abs(got - want)) / np.max(want)))
    return worst


def _photo(truth: dict) -> np.ndarray:
    """rtloop's render of ``truth`` as the default fit models a camera's pixels (the pixel footprint),
    clipped at 1."""
    return np.minimum(rtloop.render(truth, footprint=True), 1.0)


def _through_file(linear: np.ndarray, fmt: str, scene, **save) -> np.ndarray:
    """Encode as an 8-bit sRGB file (PNG or JPEG) and read back through rtloop's acquisition."""
    x = np.clip(linear, 0, 1)
    srgb = np.where(x <= 0.0031308, 12.92 * x, 1.055 * x ** (1 / 2.4) - 0.055)
    buf = io.BytesIO()
    Image.fromarray(np.round(srgb * 255).astype(np.uint8)).save(buf, fmt, **save)
    return buf.getvalue()


def _load_bytes(data: bytes, suffix: str, scene, tmp_path) -> np.ndarray:
    path = tmp_path / f"photo{suffix}"
    path.write_bytes(data)
    return rtloop.load_image(path, scene)


def _check(result) -> None:
    d = result.scene.to_dict()
    values = [*d["light"]["position"], d["light"]["intensity"]] + [v for o in d["objects"] for v in o["material"]["albedo"]]
    assert np.all(np.isfinite(values)), d
    assert np.isfinite(result.fitness)


@pytest.mark.parametrize("name, light", [
    ("light 5 cm above the floor", [0.8, 0.05, -0.6]),
    ("light behind the sphere (rim light, shadow toward the camera)", [0.3, 2.5, 4.0]),
    ("light almost straight overhead (tiny shadow)", [0.05, 7.0, 0.05]),
    ("grazing light on the floor", [7.5, 0.6, 1.0]),
])
def test_hard_light_positions_are_recovered(ball_scene, name, light):
    truth = ball_scene
    truth["light"]["position"] = light
    truth["fit"]["light.position"]["min"] = [-8, 0.02, -8]
    result = rtloop.fit(_start(truth), _photo(truth), seed=1)
    _check(result)
    # Noise-free and rendered by rtloop: held to the 1 mm / 0.2 % targets even here.
    assert _light_err(result, truth) < 0.001, name
    undetermined = result.identifiability.get("undetermined", [])
    if "behind" in name:
        # Only the ball's rim is lit, in a few pixels the terminator crosses: a camera integrates a sliver of
        # light there (the footprint), and that sliver is enough for the ball's colour.
        ids = rtloop._native.object_ids(rtloop.load_scene(truth))
        assert 0 < int((_photo(truth)[ids == 0].max(axis=1) > 0).sum()) <= 10
        assert undetermined == []
        assert _product_err(result, truth) < 0.002, name
        # Shaded at pixel centres no visible pixel of the ball is lit: its colour is not in such a photo,
        # and rtloop says so (the start's albedo kept).
        centres = np.minimum(rtloop.render(truth), 1.0)
        assert not (centres[ids == 0] > 0).any()
        plain = rtloop.fit(_start(truth), centres, seed=1, footprint="off")
        assert _light_err(plain, truth) < 0.001, name
        assert plain.identifiability.get("undetermined", []) == ["objects.ball.albedo"]
        assert plain.scene.to_dict()["objects"][0]["material"]["albedo"] == [0.5, 0.5, 0.5]
        assert _product_err(plain, truth, skip=("ball",)) < 0.002, name
    else:
        assert undetermined == []
        assert _product_err(result, truth) < 0.002, name


def test_light_inside_the_sphere_or_under_the_floor_is_a_losing_candidate_not_a_crash(ball_scene):
    truth = ball_scene
    photo = _photo(truth)
    scene = rtloop.load_scene(truth)
    paths = ["light.position", "light.intensity"]
    candidates = np.array([
        [0.0, 1.0, 0.0, 70.0],    # at the sphere's centre
        [0.0, 1.99, 0.0, 70.0],   # just inside its top
        [0.0, -1.0, 0.0, 70.0],   # under the floor
        [0.0, 0.0, -3.0, 70.0],   # in the floor plane
        [2.5, 4.5, -1.0, 70.0],   # the truth
    ])
    losses = _native.evaluate(scene, photo, candidates, _native.FitnessSpec(paths))[:, 0]
    assert np.all(np.isfinite(losses))
    assert np.argmin(losses) == 4
    # A search box that contains the sphere's inside and the space under the floor still finds the light.
    truth["fit"]["light.position"]["min"] = [-8, -3, -8]
    result = rtloop.fit(_start(truth), photo, seed=2)
    _check(result)
    assert _light_err(result, truth) < 0.001


@pytest.mark.parametrize("space", ["linear", "srgb"])
def test_very_dim_photo(ball_scene, tmp_path, space):
    """In both loss spaces. Measured (studies/loss_space.py, seeds 0-4): linear 4.4-5.1 mm and 0.30-0.34 %,
    sRGB 7.5-7.6 mm and 0.47-0.48 %: comparing code values does not help with a quantised dim photo."""
    truth = ball_scene
    truth["light"]["intensity"] = 1.5  # brightest pixel about 0.03: a handful of 8-bit levels
    photo = _photo(truth)
    assert photo.max() < 0.05
    scene = rtloop.load_scene(_start(truth))
    loaded = _load_bytes(_through_file(photo, "PNG", scene), ".png", scene, tmp_path)
    result = rtloop.fit(scene, loaded, seed=3, space=space)
    _check(result)
    assert result.settings["space"] == space
    assert _light_err(result, truth) < 0.05
    assert _product_err(result, truth) < 0.05


def test_partly_saturated_photo(ball_scene):
    truth = ball_scene
    truth["light"]["intensity"] = 250.0
    photo = _photo(truth)
    clipped = (photo >= 1.0).any(axis=2).mean()
    assert clipped > 0.1, f"only {clipped:.0%} of pixels saturated"
    result = rtloop.fit(_start(truth), photo, seed=4)
    _check(result)
    assert _light_err(result, truth) < 0.001
    assert _product_err(result, truth) < 0.002


@pytest.mark.parametrize("noise_seed", [5, 6, 7])
def test_strong_noise(ball_scene, noise_seed):
    """Noise 2.5 times the shared noisy-blue case's, on the saturated photo, at the paper's 128x96: the
    light to 5 cm, the colours to the documented 2 % (measured 0.9-2.0 % over these three noise draws, so
    the bound is 2.5 %). Least squares alone got the ball's red 5-8 % low here (saturated pixels that noise
    pulls below 1 fitted as unsaturated, unsaturated ones pushed to 1 dropped); the reported products
    minimise the L1 loss with the clip kept exact (see Kernel::refine)."""
    truth = ball_scene
    truth["image"] = {"width": 128, "height": 96}
    rng = np.random.default_rng(noise_seed)
    photo = np.clip(_photo(truth) + rng.normal(0, 0.05, (96, 128, 3)), 0, 1).astype(np.float32)
    result = rtloop.fit(_start(truth), photo, seed=5)
    _check(result)
    assert _light_err(result, truth) < 0.05
    assert _product_err(result, truth) < 0.025


@pytest.mark.parametrize("space", ["linear", "srgb"])
def test_jpeg_quality_50(ball_scene, tmp_path, space):
    """JPEG at quality 50 subsamples chroma and quantises the dark blue channel hardest: light to 3 cm,
    colours to the documented 2 % (see test_strong_noise; least squares alone was 7-8 % off), in both loss
    spaces. Measured (studies/loss_space.py, seeds 0-4): light 15-17 mm in either; products 1.1-1.2 %
    linear, 0.65-0.69 % sRGB, where JPEG's errors are uniform."""
    truth = ball_scene
    truth["image"] = {"width": 128, "height": 96}
    scene = rtloop.load_scene(_start(truth))
    loaded = _load_bytes(_through_file(_photo(truth), "JPEG", scene, quality=50), ".jpg", scene, tmp_path)
    result = rtloop.fit(scene, loaded, seed=6, space=space)
    _check(result)
    assert _light_err(result, truth) < 0.03
    assert _product_err(result, truth) < 0.02


def test_model_mismatch_interreflection_like_fill_light(ball_scene):
    """The photo has light the model cannot make (a fill term, as from interreflections): the fit stays
    finite and near the truth rather than running off to a bound."""
    truth = ball_scene
    photo = _photo(truth)
    ids = rtloop.object_ids(truth)
    fill = np.where((ids == 0)[..., None], 0.03 * np.array([0.6, 0.6, 0.6]), 0.0)  # floor light on the ball
    result = rtloop.fit(_start(truth), np.minimum(photo + fill, 1).astype(np.float32), seed=7)
    _check(result)
    assert _light_err(result, truth) < 0.25


@pytest.mark.parametrize("scale", [1e-3, 1e3])
def test_millimetre_and_kilometre_scenes(ball_scene, scale):
    truth = ball_scene
    s = scale
    for key in ("position", "look_at"):
        truth["camera"][key] = [v * s for v in truth["camera"][key]]
    truth["light"]["position"] = [v * s for v in truth["light"]["position"]]
    truth["light"]["intensity"] *= s * s  # same irradiance at s times the distance
    truth["objects"][0]["center"] = [v * s for v in truth["objects"][0]["center"]]
    truth["objects"][0]["radius"] *= s
    truth["fit"]["light.position"] = {"min": [-8 * s, 0.5 * s, -8 * s], "max": [8 * s, 8 * s, 8 * s]}
    truth["fit"]["light.intensity"] = {"min": 1 * s * s, "max": 400 * s * s}
    photo = _photo(truth)
    assert 0.2 < (photo.max(axis=2) > 0.02).mean() < 0.9, "the same picture at every scale"
    result = rtloop.fit(_start(truth), photo, seed=8)
    _check(result)
    assert _light_err(result, truth) < 0.001 * s
    assert _product_err(result, truth) < 0.002


def test_one_sphere_hiding_another(ball_scene):
    truth = ball_scene
    hidden = {"name": "hidden", "shape": "sphere", "center": [0.2, 0.5, 3.0], "radius": 0.5,
              "material": {"albedo": [0.2, 0.9, 0.3]}}
    truth["objects"].insert(1, hidden)
    truth["fit"]["objects.hidden.albedo"] = {"min": [0, 0, 0], "max": [1, 1, 1]}
    ids = rtloop.object_ids(truth)
    assert (ids == 1).sum() == 0, "the second sphere is entirely behind the first"
    result = rtloop.fit(_start(truth), _photo(truth), seed=9)
    _check(result)
    assert _light_err(result, truth) < 0.001
    # The hidden sphere's colour is not in the image: reported, and left at the scene's value.
    assert result.identifiability["undetermined"] == ["objects.hidden.albedo"]
    assert result.scene.to_dict()["objects"][1]["material"]["albedo"] == [0.5, 0.5, 0.5]
    assert _product_err(result, truth, skip=("hidden",)) < 0.002


def test_scene_json_roundtrip_of_a_fit_result_is_valid(ball_scene):
    result = rtloop.fit(_start(ball_scene), _photo(ball_scene), seed=10, generations=5, population=8)
    again = rtloop.load_scene(json.loads(result.scene.to_json()))
    assert again.to_dict() == result.scene.to_dict()


def test_directional_light_sun(ball_scene):
    """A far light (a sun) as a directional light: only its direction is searched, and recovered."""
    truth = ball_scene
    sun = np.array([0.6, 1.0, -0.4])
    start = sunlit(truth, list(sun))
    result = rtloop.fit(start, _photo(truth), seed=12)
    fitted_dir = np.array(result.scene.to_dict()["light"]["direction"])
    angle = np.degrees(np.arccos(np.clip(fitted_dir @ sun / np.linalg.norm(sun), -1, 1)))
    assert angle < 0.05, f"direction off by {angle:.4f} degrees"
    assert np.linalg.norm(fitted_dir) == pytest.approx(1.0)
    assert result.settings["method"] == "projected"
    assert _product_err(result, truth) < 0.002
    assert result.scene.to_dict()["light"]["type"] == "directional"
    u = result.uncertainty  # noise-free photo: sigma is float32 rounding, with the warning that says so
    assert not any("not available" in w for w in u["warnings"])
    assert set(u["sigma"]) == {"light.direction.u", "light.direction.v"} | {
        f"products.{o}.{c}" for o in ("ball", "floor") for c in "rgb"}
    assert all(s is not None and 0 <= s < 1e-6 for s in u["sigma"].values())
    # A directional light has no position to fit, and a point light no direction.
    with pytest.raises(rtloop.SceneError, match="light.direction"):
        rtloop.load_scene({**truth, "fit": {"light.position": {"min": -1, "max": 1}}})
    with pytest.raises(rtloop.SceneError, match="light.direction"):
        rtloop.load_scene({**truth, "light": {"type": "directional", "direction": [0, 0, 0], "intensity": 1}})
    with pytest.raises(rtloop.SceneError, match="light.type"):
        rtloop.load_scene({**truth, "light": {"type": "spot", "position": [0, 1, 0], "intensity": 1}})


def test_glossy_ball_with_free_specular_and_shininess(ball_scene):
    """A highlight the model knows about informs the fit instead of biasing it: intensity x specular joins
    the closed-form solve, the shininess is searched with the light, and the fit is as exact as a matte one:
    the documented figures, light within 0.05 mm, products and intensity x specular within 1e-4, shininess
    within 5e-4 (measured 0.008 mm, 2e-6, 3e-5 and 5e-5)."""
    truth = ball_scene
    truth["objects"][0]["material"].update(specular=0.3, shininess=30.0)
    truth["fit"]["objects.ball.specular"] = {"min": 0, "max": 1}
    truth["fit"]["objects.ball.shininess"] = {"min": 1, "max": 100}
    start = _start(truth)
    start["objects"][0]["material"].update(specular=0.1, shininess=10.0)
    result = rtloop.fit(start, _photo(truth), seed=1)
    _check(result)
    assert result.settings["method"] == "projected"
    assert _light_err(result, truth) < 5e-5
    assert _product_err(result, truth) < 1e-4
    fitted = result.scene.to_dict()
    ks = fitted["light"]["intensity"] * fitted["objects"][0]["material"]["specular"]
    assert ks == pytest.approx(truth["light"]["intensity"] * 0.3, rel=1e-4)
    assert fitted["objects"][0]["material"]["shininess"] == pytest.approx(30.0, rel=5e-4)
    assert "light.intensity*objects.ball.specular" in result.identifiability["determined"]


def test_highlight_of_known_strength(ball_scene):
    """A fixed, known specular under a fixed intensity: the closed form holds the lobe at its value and
    fits only the albedos; with the intensity free, the highlight measures it (Q = intensity x specular,
    solved in closed form): the intensity and the albedos themselves within 1e-4 from a start of 30 W/sr
    (the truth 70; measured 1e-6)."""
    truth = ball_scene
    truth["objects"][0]["material"].update(specular=0.4, shininess=20.0)
    photo = _photo(truth)
    fixed = copy.deepcopy(truth)
    del fixed["fit"]["light.intensity"]
    result = rtloop.fit(_start(fixed), photo, seed=2)
    _check(result)
    assert result.settings["method"] == "projected"
    assert _light_err(result, truth) < 0.001
    assert _product_err(result, truth) < 0.002
    assert result.scene.to_dict()["objects"][0]["material"]["specular"] == 0.4
    start = _start(truth)
    start["light"]["intensity"] = 30.0
    result = rtloop.fit(start, photo, seed=2)
    _check(result)
    assert result.settings["method"] == "projected"
    assert not result.identifiability["degenerate"]
    fitted = result.scene.to_dict()
    assert fitted["light"]["intensity"] == pytest.approx(70.0, rel=1e-4)
    for o, t in zip(fitted["objects"], truth["objects"]):
        assert np.allclose(o["material"]["albedo"], t["material"]["albedo"], rtol=0, atol=1e-4), o["name"]
    assert _light_err(result, truth) < 1e-4


def test_known_highlight_out_of_view_measures_nothing(ball_scene):
    """A known specular on a ball whose highlight the camera cannot see (the light behind the ball, the
    highlight on its far side) measures no intensity: the fit keeps the scene's own value (the products'
    convention) instead of reading one off an unseen lobe, and stays accurate in the products."""
    truth = ball_scene
    truth["light"]["position"] = [0.5, 3.0, 4.0]
    truth["objects"][0]["material"].update(specular=0.4, shininess=200.0)
    start = _start(truth)
    start["light"]["intensity"] = 30.0
    result = rtloop.fit(start, _photo(truth), seed=3)
    _check(result)
    assert result.settings["method"] == "projected"
    assert _product_err(result, truth) < 1e-3