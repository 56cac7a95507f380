"""The coated material (``material.coat``: a Lambertian base under a rough GGX clear coat, Mitsuba 3's
``roughplastic``) against Mitsuba's own renders in tests/fixtures/coat (tools/make_coat_photos.py; linear
float renders, so the comparison is not limited by 8-bit codes). The tests need no Mitsuba."""

from __future__ import annotations

import copy
import json
from pathlib import Path

import numpy as np
import pytest

import rtloop
from conftest import matte_start
from rtloop.errors import RtloopError

COAT = Path(__file__).parent / "fixtures" / "coat"
CASES = sorted(p.name for p in COAT.iterdir() if (p / "linear.npz").exists())


def _truth(name: str) -> dict:
    return json.loads((COAT / name / "scene.json").read_text())


def _lit_interior(ids: np.ndarray, ref: np.ndarray, obj: int) -> np.ndarray:
    """Pixels of object ``obj`` whose 4 neighbours show it too (no silhouette) and that the light reaches
    (radiance above 2 % of the object's brightest), away from shadow edges."""
    m = ids == obj
    inner = m.copy()
    inner[1:, :] &= m[:-1, :]
    inner[:-1, :] &= m[1:, :]
    inner[:, 1:] &= m[:, :-1]
    inner[:, :-1] &= m[:, 1:]
    bright = ref.max(axis=-1)
    # and no shadow edge: each 4-neighbour within 20 % of the pixel
    b = np.pad(bright, 1, mode="edge")
    smooth = np.ones_like(m)
    for nb in (b[:-2, 1:-1], b[2:, 1:-1], b[1:-1, :-2], b[1:-1, 2:]):
        smooth &= np.abs(nb - bright) <= 0.2 * bright
    return inner & smooth & (bright > 0.02 * bright[m].max())


@pytest.mark.parametrize("name", CASES)
def test_coat_renders_like_mitsuba_roughplastic(name):
    """Every lit interior pixel of the coated ball within 1 % of Mitsuba's roughplastic, per channel (its
    highlight included); on the floor (the ball's shadow edge left to the footprint's own tests) 99 %."""
    scene = rtloop.load_scene(_truth(name))
    ref = np.load(COAT / name / "linear.npz")["image"].astype(np.float64)
    img = np.asarray(rtloop.render(scene, spp=16), dtype=np.float64)
    ids = np.asarray(rtloop.object_ids(scene))
    for obj in (0, 1):
        m = _lit_interior(ids, ref, obj)
        assert m.sum() > 200
        rel = np.abs(img[m] / ref[m] - 1.0).max(axis=-1)
        worst = float(rel.max() if obj == 0 else np.percentile(rel, 99))
        assert worst < 0.01, f"{name}, object {obj}: {100 * worst:.2f} % off"


@pytest.mark.parametrize("name", CASES)
def test_without_the_coat_the_render_is_off(name):
    """The same ball as Lambert plus Blinn-Phong at the same albedo is far from the photo: the agreement
    above is the coat's (the fixtures can tell the models apart)."""
    d = _truth(name)
    m = d["objects"][0]["material"]
    d["objects"][0]["material"] = {"albedo": m["albedo"], "specular": m["specular"], "shininess": 100.0}
    scene = rtloop.load_scene(d)
    ref = np.load(COAT / name / "linear.npz")["image"].astype(np.float64)
    img = np.asarray(rtloop.render(scene, spp=4), dtype=np.float64)
    ids = np.asarray(rtloop.object_ids(scene))
    mask = _lit_interior(ids, ref, 0)
    assert float(np.median(np.abs(img[mask] / ref[mask] - 1.0))) > 0.05


def test_coat_defaults_and_round_trip():
    d = _truth(CASES[0])
    d["objects"][0]["material"] = {"albedo": [0.5, 0.5, 0.5], "coat": {}}
    out = rtloop.load_scene(d).to_dict()["objects"][0]["material"]
    assert out["coat"] == {"roughness": 0.1, "ior": 1.49}
    assert out["specular"] == 1.0  # a physical coat reflects: Mitsuba's specular_reflectance 1
    assert "coat" not in rtloop.load_scene(_truth(CASES[0]) | {"objects": [
        {"shape": "sphere", "center": [0, 1, 0], "radius": 1}]}).to_dict()["objects"][0]["material"]
    again = rtloop.load_scene(rtloop.load_scene(_truth(CASES[0])).to_dict()).to_dict()
    assert again["objects"][0]["material"]["coat"] == _truth(CASES[0])["objects"][0]["material"]["coat"]


@pytest.mark.parametrize("coat, field", [
    ({"roughness": 0.0}, "objects[0].material.coat.roughness"),
    ({"roughness": 2.0}, "objects[0].material.coat.roughness"),
    ({"ior": 1.0}, "objects[0].material.coat.ior"),
    ({"ior": float("nan")}, "objects[0].material.coat.ior"),
    ({"alpha": 0.1}, "objects[0]"),
    ("rough", "objects[0]"),
])
def test_bad_coats_are_refused_in_one_line(coat, field):
    d = _truth(CASES[0])
    d["objects"][0]["material"]["coat"] = coat
    with pytest.raises(RtloopError) as e:
        rtloop.load_scene(d)
    msg = str(e.value)
    assert "\n" not in msg and field in msg, msg


def test_roughness_is_fittable_only_on_a_coat():
    d = _truth(CASES[0])
    d["fit"] = {"objects.floor.roughness": {"min": 0.05, "max": 0.5}}
    with pytest.raises(RtloopError, match=r'fit\["objects.floor.roughness"\].*no coat'):
        rtloop.load_scene(d)
    d["fit"] = {"objects.ball.roughness": {"min": 0.05, "max": 0.5}}
    assert rtloop.load_scene(d).fit_paths == ["objects.ball.roughness"]


def _matte_input(name: str) -> tuple[rtloop.Scene, dict]:
    """What a user writes: the fixture's camera and geometry, a matte ball, a neutral light, the light and
    every albedo free (tools/make_photos.py's fit section)."""
    truth = rtloop.load_scene(_truth(name)).to_dict()
    return rtloop.load_scene(matte_start(_truth(name))), truth


@pytest.mark.parametrize("name", [c for c in CASES if abs(_truth(c)["objects"][0]["material"]["coat"]["ior"] - 1.49) < 1e-9])
def test_the_default_fit_coats_a_plastic_ball_and_finds_its_roughness(name):
    """From a matte ball in the user's scene, the default fit sees the highlight, prefers the coat to
    Blinn-Phong by the evidence, and recovers the roughness within 10 %, the colour products (exposure x
    intensity x colour x diffuse reflectance) within 3 % and the light within 5 mm."""
    from rtloop.fit.products import products_of

    scene, truth = _matte_input(name)
    r = rtloop.fit(scene, rtloop.load_image(COAT / name / "objective.png", scene), uncertainty=False)
    ev = r.model["evidence"]["specular"]
    assert ev["lobe"] == "coat" and ev["coat"]["loss_with"] < ev["blinn_phong"]["loss_with"], ev
    f = r.scene.to_dict()
    true_alpha = truth["objects"][0]["material"]["coat"]["roughness"]
    alpha = f["objects"][0]["material"]["coat"]["roughness"]
    assert abs(alpha / true_alpha - 1) < 0.1, (alpha, true_alpha)
    pf, pt = products_of(f), products_of(truth)
    worst = max(float(np.max(np.abs(pf[k] - pt[k])) / np.max(pt[k])) for k in pt)
    assert worst < 0.03, f"{name}: products {100 * worst:.2f} % off"
    err = float(np.linalg.norm(np.subtract(f["light"]["position"], truth["light"]["position"])))
    assert err < 0.005, f"{name}: light {1000 * err:.1f} mm off"


def test_a_blinn_phong_ball_keeps_the_blinn_phong_lobe():
    """rtloop's own render of a Lambert + Blinn-Phong ball: the lobe is selected and the coat tried, but the
    evidence keeps Blinn-Phong (the coat is chosen only where it explains the photo better)."""
    scene, _ = _matte_input(CASES[0])
    truth = scene.to_dict()
    truth["light"] = {"position": [1.5, 3.5, -2.5], "intensity": 30.0, "color": [1, 1, 1]}
    truth["objects"][0]["material"] = {"albedo": [0.6, 0.2, 0.1], "specular": 0.5, "shininess": 60.0}
    photo = rtloop.render(rtloop.load_scene(truth))
    r = rtloop.fit(scene, photo, uncertainty=False)
    ev = r.model["evidence"]["specular"]
    assert ev["selected"] and ev["lobe"] == "blinn-phong", ev
    assert "coat" not in r.scene.to_dict()["objects"][0]["material"]


def test_the_lights_fit_refuses_a_coat_in_one_line():
    scene = rtloop.load_scene(_truth(CASES[0]) | {"fit": {
        "light.position": {"min": [-8, 0.5, -8], "max": [8, 8, 8]},
        "objects.ball.albedo": {"min": [0, 0, 0], "max": [1, 1, 1]}}})
    photo = np.load(COAT / CASES[0] / "linear.npz")["image"]
    with pytest.raises(RtloopError, match=r"^lights: objects.ball.material.coat: [^\n]*$"):
        rtloop.fit(scene, photo, lights=2, uncertainty=False)


def test_the_two_stage_method_fits_a_declared_coat():
    """A scene that declares the coat, with the floor's albedo known and the intensity free (the two-stage
    method, whose kernel shades the coat per pixel), on rtloop's own render of it: the light, intensity and
    base albedo come back."""
    d = _truth("coat-a010-red")
    d["image"] = {"width": 64, "height": 48}
    truth = copy.deepcopy(d)
    d["light"]["position"] = [0.0, 3.0, -1.0]
    d["objects"][0]["material"]["albedo"] = [0.5, 0.5, 0.5]
    d["fit"] = {"light.position": {"min": [-5, 0.5, -5], "max": [5, 6, 5]}, "light.intensity": {"min": 1, "max": 100},
                "objects.ball.albedo": {"min": [0, 0, 0], "max": [1, 1, 1]}}
    r = rtloop.fit(rtloop.load_scene(d), rtloop.render(rtloop.load_scene(truth)), uncertainty=False)
    assert r.settings["method"] == "two-stage"
    f = r.scene.to_dict()
    assert float(np.linalg.norm(np.subtract(f["light"]["position"], truth["light"]["position"]))) < 0.005
    assert abs(f["light"]["intensity"] / truth["light"]["intensity"] - 1) < 0.01
    np.testing.assert_allclose(f["objects"][0]["material"]["albedo"], truth["objects"][0]["material"]["albedo"],
                               rtol=0.01)
