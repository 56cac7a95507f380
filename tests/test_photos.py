"""Photos as cameras take them, against an independent renderer: the Mitsuba 3
renders in tests/fixtures/photos (tools/make_photos.py; path tracing, a constant environment, rough
plastic, sphere lamps, noise and JPEG; pixels integrated over their area). The tests need no Mitsuba.

Two kinds of checks: rtloop's renderer with the true scene against the photo (its environment and bounce
terms model what Mitsuba renders), and the default fit, from the fit section a user writes today, against
the truth it never saw (the targets)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

import rtloop
from rtloop import _native
from rtloop._srgb import encode
from rtloop.fit.products import products_of

PHOTOS = Path(__file__).parent / "fixtures" / "photos"
CASES = sorted(p.name for p in PHOTOS.iterdir() if (p / "objective.png").exists())
DIRECT = [c for c in CASES if c.startswith("direct-")]
HARD = [c for c in CASES if not c.startswith(("direct-", "edge-"))]  # edge-*: tests/test_edges.py


def _truth(name: str) -> dict:
    return json.loads((PHOTOS / name / "scene.json").read_text())


def _photo(name: str, scene: rtloop.Scene) -> np.ndarray:
    return rtloop.load_image(PHOTOS / name / "objective.png", scene)


def _codes(render: np.ndarray, photo: np.ndarray, ids: np.ndarray, where: int | None = None) -> float:
    """Mean absolute difference in 8-bit sRGB codes over the objects' pixels (or object ``where``'s)."""
    a, b = (encode(np.clip(x, 0, 1)) for x in (render, photo))
    m = ids >= 0 if where is None else ids == where
    return float(np.abs(a - b)[m].mean() * 255)


@pytest.mark.parametrize("name", [c for c in CASES if c.startswith("env-") and "bounce" not in c])
def test_environment_renders_like_mitsuba(name):
    """Direct light plus a constant environment occluded by the scene (Mitsuba: path tracing, depth 2):
    the sky view factor reproduces it to a fraction of a code; without it the shadows are far too dark."""
    truth = _truth(name)
    scene = rtloop.Scene(json.dumps(truth))
    photo = _photo(name, scene)
    ids = _native.object_ids(scene)
    with_env = _codes(_native.render(scene, None, None, 16), photo, ids)
    without = _codes(_native.render(rtloop.Scene(json.dumps({**truth, "environment": [0, 0, 0]})), None, None, 16),
                     photo, ids)
    assert with_env < 0.5, with_env
    assert without > 3 * with_env


@pytest.mark.parametrize("name", [c for c in CASES if "bounce" in c])
def test_interreflection_renders_like_mitsuba(name):
    """Interreflection (Mitsuba: path tracing, depth 8): one bounce, with the spheres' own bounce as
    senders, brings the whole image within a code of the photo (from 3-6 codes) and the ball's error
    (18-33 codes without it: its underside lit by the floor) down by more than 6x."""
    truth = _truth(name)
    scene = rtloop.Scene(json.dumps(truth))
    photo = _photo(name, scene)
    ids = _native.object_ids(scene)
    bounced = _native.render(rtloop.Scene(json.dumps({**truth, "interreflection": True})), None, None, 16)
    plain = _native.render(scene, None, None, 16)
    assert _codes(bounced, photo, ids) < 1.0
    assert _codes(bounced, photo, ids) < 0.3 * _codes(plain, photo, ids)
    assert _codes(bounced, photo, ids, 0) < 0.15 * _codes(plain, photo, ids, 0)  # the first ball


def _fit(name: str) -> tuple[rtloop.FitResult, dict]:
    scene = rtloop.load_scene(PHOTOS / name / "scene_input.json")
    result = rtloop.fit(scene, _photo(name, scene), uncertainty=False)
    return result, _coated_truth(name, result.scene.to_dict())


def _coated_truth(name: str, fitted: dict) -> dict:
    """The truth as the fit's model means it: a ball the fit coated has Mitsuba's roughplastic
    diffuse_reflectance for its albedo (scene.json holds the Lambertian albedo that renders its base the
    same on average, meta.json the roughplastic's own parameters)."""
    truth = _truth(name)
    glossy = json.loads((PHOTOS / name / "meta.json").read_text()).get("extra_truth", {}).get("glossy_objects", {})
    coated = {o["name"] for o in fitted["objects"] if "coat" in o["material"]}
    for o in truth["objects"]:
        if o["name"] in glossy and o["name"] in coated:
            o["material"]["albedo"] = glossy[o["name"]]["bsdf"]["diffuse_reflectance"]
    return truth


def _errors(result: rtloop.FitResult, truth: dict) -> tuple[float, float]:
    """The light's position error (m) and the worst product error over objects and channels (relative to
    the object's largest true product; products are exposure x intensity x colour x albedo, what the
    photo determines: the truth's lights are coloured, the user's scene says white)."""
    fitted = result.scene.to_dict()
    err = float(np.linalg.norm(np.subtract(fitted["light"]["position"], truth["light"]["position"])))
    pf, pt = products_of(fitted), products_of(truth)
    worst = max(float(np.max(np.abs(pf[k] - pt[k])) / np.max(pt[k])) for k in pt)
    return err, worst


@pytest.fixture(scope="module")
def hard_fits() -> dict[str, tuple[float, float, list[str]]]:
    out = {}
    for name in HARD:
        r, truth = _fit(name)
        err, worst = _errors(r, truth)
        out[name] = (err, worst, r.model["terms"])
    return out


#: Photos whose colour products the model does not get within the target's 3 %, and why (strict xfail: the
#: test says so when that changes).
PRODUCT_GAPS: dict[str, str] = {}


@pytest.mark.parametrize("name", HARD)
def test_hard_photo_light_within_3cm(hard_fits, name):
    """The target per photo: environment, interreflection, gloss, a desk lamp, noise and JPEG,
    fitted with the fit section a user writes today and no extra flag: the light within 3 cm."""
    err, _, terms = hard_fits[name]
    assert err < 0.03, f"{name}: light {1000 * err:.1f} mm off (terms {terms})"


@pytest.mark.parametrize("name", [pytest.param(n, marks=pytest.mark.xfail(strict=True, reason=PRODUCT_GAPS[n]))
                                  if n in PRODUCT_GAPS else n for n in HARD])
def test_hard_photo_products_within_3_percent(hard_fits, name):
    """The target per photo: every colour product within 3 %."""
    _, worst, terms = hard_fits[name]
    assert worst < 0.03, f"{name}: product {100 * worst:.2f} % off (terms {terms})"


def test_hard_photos_median_within_15mm(hard_fits):
    errs = [v[0] for v in hard_fits.values()]
    assert np.median(errs) < 0.015, sorted(round(1000 * e, 1) for e in errs)


def test_terms_are_chosen_from_the_photo(hard_fits):
    """Each photo gets the terms its renderer put in: an environment where there is one, a bounce where
    the path tracer bounced, and nothing extra on photos without them."""
    for name, (_, _, terms) in hard_fits.items():
        if "bounce" in name:
            assert "interreflection" in terms, (name, terms)
        if name.startswith("env-") and "bounce" not in name:
            assert "environment" in terms and "interreflection" not in terms, (name, terms)
    for name in DIRECT:
        r, _ = _fit(name)
        assert r.model["terms"] == ["direct"], (name, r.model)


def test_direct_photos_median_within_3mm():
    """Photos with only what the base model has (Mitsuba's direct integrator; area-integrated pixels)."""
    errs = []
    for name in DIRECT:
        r, truth = _fit(name)
        err, worst = _errors(r, truth)
        errs.append(err)
        assert worst < 0.01, (name, worst)
    assert np.median(errs) < 0.003, errs


#: The first three clean direct photos, whose pixel-centre errors (3.3, 0.6 and 2.3 mm) the footprint was
#: measured against; the other eight count in the median.
FIRST_DIRECT = ("direct-overhead", "direct-side", "direct-two-balls")


def test_direct_photos_within_2mm_with_the_pixel_footprint():
    """``footprint=True`` (shadow edges and terminators integrated over each pixel, as Mitsuba's box filter
    does) takes the clean direct photos below the pixel-centre model's floor (3.3, 0.6 and 2.3 mm with
    pixel centres on the first three): each of those within 2 mm, the median over all eleven within 1.5 mm
    (measured: 0.2-3.5 mm, median 1.3 mm; the largest, 3.5 mm, direct-two-overhead, a light nearly
    overhead two small balls)."""
    errs = {}
    for name in DIRECT:
        scene = rtloop.load_scene(PHOTOS / name / "scene_input.json")
        r = rtloop.fit(scene, _photo(name, scene), uncertainty=False, footprint=True)
        errs[name] = _errors(r, _truth(name))[0]
    assert len(errs) >= 11
    assert max(errs[n] for n in FIRST_DIRECT) < 0.002, errs
    assert np.median(list(errs.values())) < 0.0015, errs


def test_a_term_rejected_first_is_tested_again_once_others_explain_their_part():
    """Forward selection (lamp-front: a dim bluish room, a bounce and a glossy ball): the room's light
    explains under 5 % of the loss while the bounce and the lobe are missing, so the first test rejects it;
    tested again on top of them it is selected, and the fit finds the light within the target's 3 cm (a fit
    without it put the light 9 cm too far and every product 6-7 % too high)."""
    r, truth = _fit("lamp-front")
    ev = r.model["evidence"]["environment"]
    assert ev["earlier_gain"] < 0.05 <= ev["gain"], ev
    assert ev["tested_with"] == ["interreflection", "specular"] and ev["selected"], ev
    assert r.model["terms"] == ["direct", "environment", "interreflection", "specular"]
    err, worst = _errors(r, truth)
    assert err < 0.03 and worst < 0.03, (err, worst)


@pytest.mark.parametrize("name, norm, term", [("env-overhead", "l2", "environment"),
                                              ("env-bounce-low", "l2", "interreflection"),
                                              ("gloss-a025", "huber", "specular")])
def test_the_terms_are_tested_in_every_norm(name, norm, term):
    """The fit's residual is weighed against the photo's quantisation floor in the fit's own norm: an L2
    or Huber loss (squares of residuals of a few codes) against the L1 floor looked explained (0.6-1.6x
    where the photo has a room's light, a bounce or a coat) and no term was tested: env-overhead with L2
    45 mm off, env-bounce-low 174 mm, gloss-a025 with Huber 12.6 mm. Measured against the floor in the same
    norm (the residual 6-22x the quantisation error's size) the term is found and the light comes 2.5-10x
    closer (7.0, 17.7 and 4.8 mm), within the target's 3 cm."""
    scene = rtloop.load_scene(PHOTOS / name / "scene_input.json")
    r = rtloop.fit(scene, _photo(name, scene), norm=norm, uncertainty=False)
    assert "skipped" not in r.model and r.model["residual"]["ratio"] > 3, r.model["residual"]
    assert term in r.model["terms"], r.model
    err, _ = _errors(r, _truth(name))
    assert err < 0.03, err


@pytest.mark.parametrize("name", ["gloss-a025", "gloss-back"])
def test_a_refit_starts_from_the_light_it_refines(name):
    """The refit with a selected term (here a sphere's lobe: light and shininess searched by a small
    population in a box around the light found) holds that light and the best trial shininess in its
    initial population, so it never ends worse than where it started. Before, the result hung on the
    seed: over seeds 0-3 gloss-a025's light was 0.65-10.1 mm off and gloss-back's 2.2-3.8 mm (its worst
    product 5.0-8.7 %), the refit's loss up to 17 % above the best seed's; now every seed finds the same
    light, 0.65 and 1.0 mm off."""
    scene = rtloop.load_scene(PHOTOS / name / "scene_input.json")
    photo, truth = _photo(name, scene), _truth(name)
    fits = [rtloop.fit(scene, photo, seed=seed, uncertainty=False) for seed in range(4)]
    lights = np.array([r.scene.to_dict()["light"]["position"] for r in fits])
    losses = [sum(r.stages[-1].objectives) for r in fits]
    assert all("specular" in r.model["terms"] for r in fits)
    assert np.ptp(lights, axis=0).max() < 5e-4, lights
    assert max(losses) < 1.001 * min(losses), losses
    for r in fits:
        assert _errors(r, truth)[0] < 0.002, r.scene.to_dict()["light"]["position"]
