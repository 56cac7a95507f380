"""Several lights and sphere lights: the lights fit against Mitsuba photos (tests/fixtures/lights, made by
tools/make_light_photos.py) whose truth the fit never sees, the choice of how many lights from held-out
pixels, and the ``lights`` argument's and field's errors."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

import rtloop
from rtloop.errors import RtloopError, SceneError

FIXTURES = Path(__file__).resolve().parent / "fixtures" / "lights"


def photo(name: str) -> tuple[dict, np.ndarray, Path]:
    folder = FIXTURES / name
    truth = json.loads((folder / "scene.json").read_text())
    image = rtloop.load_image(folder / "objective.png", rtloop.load_scene(truth))
    return truth, image, folder / "scene_input.json"


def nearest(found: list[dict], position: list[float]) -> tuple[int, float]:
    d = [np.linalg.norm(np.asarray(light["position"]) - position) for light in found]
    return int(np.argmin(d)), float(min(d))


def test_key_and_fill_at_a_quarter_are_both_found_with_their_products():
    truth, image, scene_input = photo("key-fill-25")
    res = rtloop.fit(scene_input, image, lights=2, seed=0)
    assert [light["name"] for light in res.lights] == ["light0", "light1"]
    key, fill = truth["lights"]
    k, dk = nearest(res.lights, key["position"])
    f, df = nearest(res.lights, fill["position"])
    assert k == 0 and f == 1  # the strongest first
    assert dk < 0.05 and df < 0.30, (dk, df)
    # the staged search: each light alone, then all together (one search of all of them spent 5,040)
    assert res.evaluations <= 1400, res.evaluations
    for o in truth["objects"]:
        for j, light in ((k, key), (f, fill)):
            want = np.asarray(o["material"]["albedo"]) * light["intensity"] * np.asarray(light["color"])
            got = np.asarray(res.products[o["name"]][j])
            assert np.max(np.abs(got - want)) / want.max() < 0.05, (o["name"], light["name"], got, want)


def test_the_fitted_scene_renders_the_photo():
    truth, image, scene_input = photo("key-fill-25")
    res = rtloop.fit(scene_input, image, lights=2, seed=0)
    render = np.clip(rtloop.render(res.scene, None, None, 1), 0, 1)
    ids = np.asarray(rtloop._native.object_ids(res.scene))
    # the photo's own 8-bit steps and the pixel-centre render against Mitsuba's box-filtered pixels
    assert np.median(np.abs(render - image)[ids >= 0]) < 2 / 255


def test_a_sphere_light_is_placed_and_sized():
    truth, image, scene_input = photo("soft-30")
    res = rtloop.fit(scene_input, image, seed=0)
    lamp = truth["lights"][0]
    assert len(res.lights) == 1
    assert np.linalg.norm(np.asarray(res.lights[0]["position"]) - lamp["position"]) < 0.01
    assert abs(res.lights[0]["radius"] - lamp["radius"]) < 0.2 * lamp["radius"]


@pytest.mark.parametrize("name, count", [("key-fill-25", 2), ("three-lights", 3)])
def test_the_number_of_lights_is_read_from_held_out_pixels(name, count):
    truth, image, scene_input = photo(name)
    res = rtloop.fit(scene_input, image, lights="auto", seed=0)
    assert len(res.lights) == count == len(truth["lights"])
    assert [e["lights"] for e in res.evidence if e["kept"]] == [count]
    for light in truth["lights"]:
        assert nearest(res.lights, light["position"])[1] < 0.30


def test_one_light_photo_keeps_one_light_with_auto():
    truth, image, scene_input = photo("soft-10")
    res = rtloop.fit(scene_input, image, lights="auto", seed=0)
    assert len(res.lights) == 1


def test_the_same_seed_gives_the_same_lights_on_any_thread_count():
    _, image, scene_input = photo("key-fill-25")
    a = rtloop.fit(scene_input, image, lights=2, seed=3, threads=1, generations=20)
    b = rtloop.fit(scene_input, image, lights=2, seed=3, threads=2, generations=20)
    assert a.lights == b.lights and a.products == b.products


def test_camera_terms_off_are_what_the_lights_fit_does_anyway():
    """vignetting="off" and tone="off" ask for no camera term, as the lights fit has none: the same lights bit
    for bit; a camera term asked for is still refused in one line naming it."""
    _, image, scene_input = photo("key-fill-25")
    plain = rtloop.fit(scene_input, image, lights=2, seed=3, generations=20)
    off = rtloop.fit(scene_input, image, lights=2, seed=3, generations=20, vignetting="off", tone="off")
    assert off.lights == plain.lights and off.products == plain.products
    with pytest.raises(RtloopError, match=r"^vignetting: not taken by the lights fit") as e:
        rtloop.fit(scene_input, image, lights=2, vignetting="on")
    assert "\n" not in str(e.value)


@pytest.mark.parametrize("bad", [0, 9, -1, 1.5, "two", True, [2]])
def test_a_bad_lights_argument_is_one_line_naming_it(bad):
    _, image, scene_input = photo("key-fill-25")
    with pytest.raises(RtloopError, match=r"^lights: ") as e:
        rtloop.fit(scene_input, image, lights=bad)
    assert "\n" not in str(e.value)


def test_lamp_and_window_are_found_from_the_scene_s_own_list():
    truth, image, scene_input = photo("lamp-window")
    res = rtloop.fit(scene_input, image, seed=0)
    lamp, window = truth["lights"]
    assert [light["kind"] for light in res.lights] == ["point", "rectangle"]
    assert np.linalg.norm(np.asarray(res.lights[0]["position"]) - lamp["position"]) < 0.05
    assert np.linalg.norm(np.asarray(res.lights[1]["position"]) - window["position"]) < 0.30


def test_a_window_renders_as_mitsuba_renders_it():
    """The truth of the lamp + window photo through rtloop's renderer against Mitsuba's photo on the lit
    pixels of the objects (away from silhouettes and the steepest pixels: shadow edges, which Mitsuba's
    box-filtered pixels average and the pixel-centre render does not); the window alone too, rendered by
    both, so that the rectangle light's own term is compared, not only the lamp's."""
    truth, image, _ = photo("lamp-window")
    scene = rtloop.load_scene(truth)
    render = np.clip(rtloop.render(scene, None, None, 1), 0, 1)
    ids = np.asarray(rtloop._native.object_ids(scene))
    from rtloop._pixels import edges
    from rtloop.fit.lights import steep
    ok = (ids >= 0) & ~edges(ids) & ~steep(image, 0.1).reshape(ids.shape) & (image.max(axis=2) > 0.05)
    assert ok.sum() > 2000
    diff = np.abs(render - image)[ok]
    assert np.median(diff) < 2 / 255 and np.quantile(diff, 0.95) < 6 / 255, (np.median(diff), np.quantile(diff, 0.95))
    # Without the window the lit pixels darken well beyond that: the comparison sees the window's term.
    no_window = dict(truth, lights=truth["lights"][:1])
    dark = np.clip(rtloop.render(rtloop.load_scene(no_window), None, None, 1), 0, 1)
    assert np.median(np.abs(dark - image)[ok]) > 10 / 255


@pytest.mark.parametrize("light, field", [
    ({"type": "rectangle", "position": [0, 3, 0], "normal": [0, -1, 0], "intensity": 5}, r"lights\[1\]\.size"),
    ({"type": "rectangle", "position": [0, 3, 0], "size": [1, 0], "normal": [0, -1, 0], "intensity": 5},
     r"lights\[1\]\.size"),
    ({"type": "rectangle", "position": [0, 3, 0], "size": [1, 1], "intensity": 5}, r"lights\[1\]\.normal"),
    ({"type": "rectangle", "position": [0, 3, 0], "size": [1, 1], "normal": [0, -1, 0], "up": [0, 1, 0],
      "intensity": 5}, r"lights\[1\]\.up"),
    ({"position": [0, 3, 0], "normal": [0, -1, 0], "intensity": 5}, r"lights\[1\]\.normal"),
    ({"type": "sphere", "position": [0, 3, 0], "intensity": 5}, r"lights\[1\]\.radius"),
    ({"type": "sphere", "position": [0, 3, 0], "radius": -1, "intensity": 5}, r"lights\[1\]\.radius"),
    ({"position": [0, 3, 0], "radius": 0.2, "intensity": 5}, r"lights\[1\]\.radius"),
    ({"name": "key", "position": [0, 3, 0], "intensity": 5}, r"lights\[1\]\.name"),
    ({"type": "window", "position": [0, 3, 0], "intensity": 5}, r"lights\[1\]\.type"),
    ({"position": [0, 3, 0], "intensity": -5}, r"lights\[1\]\.intensity"),
])
def test_a_bad_light_in_the_list_names_its_field(light, field):
    truth, _, _ = photo("key-fill-25")
    truth["lights"][1] = light
    with pytest.raises(SceneError, match=field) as e:
        rtloop.load_scene(truth)
    assert "\n" not in str(e.value)


def test_an_inserted_ball_casts_a_shadow_from_each_light():
    """rtloop.insert under the key + fill truth: the light the added ball takes from the floor is the sum
    of what it takes under each light alone (the same renderer with one light), and each alone takes a
    visible shadow's worth, so both shadows are there, each where its own light puts it."""
    truth, image, _ = photo("key-fill-25")
    ball = [{"name": "added", "shape": "sphere", "center": [0.1, 0.3, -0.9], "radius": 0.3,
             "material": {"albedo": [0.8, 0.8, 0.8]}}]
    with_ball = rtloop.load_scene(dict(truth, objects=truth["objects"] + ball))
    floor = np.asarray(rtloop._native.object_ids(with_ball)) == 2  # floor still seen with the ball there

    def taken(scene: dict) -> np.ndarray:
        r = rtloop.insert(scene, image, ball, spp=1, adaptive=False)
        return (r.without - r.with_objects).sum(axis=2)[floor]

    both = taken(truth)
    key = taken(dict(truth, lights=truth["lights"][:1]))
    fill = taken(dict(truth, lights=truth["lights"][1:]))
    assert (key > 0.02).sum() > 20 and (fill > 0.02).sum() > 20
    assert ((key > 0.02) & (fill < 1e-6)).sum() > 10 and ((fill > 0.02) & (key < 1e-6)).sum() > 10
    assert np.max(np.abs(both - (key + fill))) < 1e-5 * max(float(np.max(both)), 1.0)


@pytest.mark.parametrize("name, count", [("key-fill-25", 2), ("lamp-window", None)])
def test_each_light_s_error_bar_covers_its_error(name, count):
    """The truth (unseen by the fit) lies within 4 error bars of each fitted light (3-D lengths): the
    independent-pixel curvature alone puts it 10-20 error bars away on these photos."""
    truth, image, scene_input = photo(name)
    res = rtloop.fit(scene_input, image, lights=count, seed=0)
    for light in res.lights:
        _, error = nearest(truth["lights"], light["position"])
        bar = float(np.linalg.norm(light["position_error"]))
        assert 0 < bar < 0.5 and error < 4 * bar, (light["name"], error, bar)
