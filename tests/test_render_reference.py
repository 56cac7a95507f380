"""rtloop's renderer against the independent float64 NumPy reference in ``tests/reference.py``.

The reference implements the scene specification directly; these tests compare rtloop's float32
renderer with it pixel by pixel away from silhouettes and shadow boundaries (where a sub-pixel shift
legitimately flips a pixel), and check orientation, shadows, supersampling and resolution overrides.
"""

from __future__ import annotations

import importlib.util
import json
import math
import sys
from pathlib import Path

import numpy as np
import pytest

import rtloop


def _load_reference():
    """Import tests/reference.py by path (the tests directory is not a package)."""
    name = "rtloop_tests_reference"
    if name not in sys.modules:
        spec = importlib.util.spec_from_file_location(name, Path(__file__).with_name("reference.py"))
        module = importlib.util.module_from_spec(spec)
        sys.modules[name] = module
        spec.loader.exec_module(module)
    return sys.modules[name]


ref = _load_reference()

RTOL = 1e-3
ATOL = 1e-5


# --------------------------------------------------------------------------------------------------
# Helpers


def rt_render(scene: dict, **kw) -> np.ndarray:
    img = rtloop.render(rtloop.load_scene(scene), **kw)
    assert isinstance(img, np.ndarray)
    assert img.dtype == np.float32
    return np.asarray(img, dtype=np.float64)


def rt_ids(scene: dict, **kw) -> np.ndarray:
    ids = rtloop.object_ids(rtloop.load_scene(scene), **kw)
    assert isinstance(ids, np.ndarray)
    assert ids.dtype == np.int32
    return np.asarray(ids, dtype=np.int64)


def changes_near(a: np.ndarray) -> np.ndarray:
    """True where ``a`` differs from any of its 8 neighbours (image borders count as equal)."""
    h, w = a.shape
    p = np.pad(a, 1, mode="edge")
    out = np.zeros((h, w), dtype=bool)
    for dj in (-1, 0, 1):
        for di in (-1, 0, 1):
            out |= p[1 + dj : 1 + dj + h, 1 + di : 1 + di + w] != a
    return out


def blocks(a: np.ndarray, k: int) -> np.ndarray:
    """Split (kH, kW, ...) into (H, W, k*k, ...) blocks of k x k."""
    h, w = a.shape[0] // k, a.shape[1] // k
    b = a.reshape(h, k, w, k, *a.shape[2:]).swapaxes(1, 2)
    return b.reshape(h, w, k * k, *a.shape[2:])


def describe_mismatch(got, want, bad, ids, limit=8) -> str:
    js, is_ = np.nonzero(bad)
    err = np.abs(got - want).max(axis=-1)
    order = np.argsort(-err[js, is_])[:limit]
    lines = [f"{bad.sum()} of {bad.size} compared pixels out of tolerance; worst:"]
    for k in order:
        j, i = js[k], is_[k]
        lines.append(
            f"  (i={i}, j={j}) id={ids[j, i]} rtloop={got[j, i].tolist()} reference={want[j, i].tolist()}"
        )
    return "\n".join(lines)


def sphere(name, center, radius, albedo, specular=None, shininess=None):
    mat = {"albedo": list(map(float, albedo))}
    if specular is not None:
        mat["specular"] = float(specular)
    if shininess is not None:
        mat["shininess"] = float(shininess)
    return {
        "name": name,
        "shape": "sphere",
        "center": list(map(float, center)),
        "radius": float(radius),
        "material": mat,
    }


def plane(name, point, normal, albedo, specular=None, shininess=None):
    obj = sphere(name, [0, 0, 0], 1, albedo, specular, shininess)
    del obj["center"], obj["radius"]
    obj.update(shape="plane", point=list(map(float, point)), normal=list(map(float, normal)))
    return obj


def random_scene(seed: int) -> dict:
    """1-4 spheres on a floor, maybe a tilted back plane, a light above, a camera looking at the spheres."""
    rng = np.random.default_rng(seed)
    width = int(rng.integers(64, 129))
    height = int(rng.integers(48, 97))

    def maybe_specular():
        if rng.random() < 0.5:
            return float(rng.uniform(0.1, 1.0)), float(rng.uniform(1.0, 100.0))
        return None, None

    objects = []
    for k in range(int(rng.integers(1, 5))):
        r = rng.uniform(0.3, 1.1)
        lift = 0.0 if rng.random() < 0.3 else rng.uniform(0.05, 1.0)
        c = [rng.uniform(-2.2, 2.2), r + lift, rng.uniform(-2.0, 2.0)]
        ks, s = maybe_specular()
        objects.append(sphere(f"s{k}", c, r, rng.uniform(0.05, 0.95, 3), ks, s))
    ks, s = maybe_specular()
    objects.append(plane("floor", [0, 0, 0], [0, 1, 0], rng.uniform(0.1, 0.9, 3), ks, s))
    wall = None
    if rng.random() < 0.5:
        wall_p = np.array([0.0, 0.0, rng.uniform(3.5, 6.0)])
        wall_n = np.array([rng.uniform(-0.3, 0.3), rng.uniform(0.0, 0.5), -1.0])
        if rng.random() < 0.5:  # the stored orientation must not matter (two-sided)
            wall_n = -wall_n
        objects.append(plane("wall", wall_p, wall_n, rng.uniform(0.1, 0.9, 3)))
        wall = (wall_p, wall_n / np.linalg.norm(wall_n))
    spheres = [(np.array(o["center"]), o["radius"]) for o in objects if o["shape"] == "sphere"]

    def clear_of_everything(p, margin):
        if p[1] < margin:
            return False
        if any(np.linalg.norm(p - c) < r + margin for c, r in spheres):
            return False
        # on the camera's (-z) side of the wall
        return wall is None or (p - wall[0]) @ wall[1] * np.sign(-wall[1][2]) > margin

    while True:
        light = np.array([rng.uniform(-4, 4), rng.uniform(3, 7), rng.uniform(-4, 1.5)])
        if clear_of_everything(light, 0.3):
            break
    target = np.mean([c for c, _ in spheres], axis=0) + rng.uniform(-0.3, 0.3, 3)
    while True:
        dist = rng.uniform(4.5, 7.5)
        az = math.radians(rng.uniform(-45, 45))
        el = math.radians(rng.uniform(4, 30))
        pos = target + dist * np.array(
            [math.sin(az) * math.cos(el), math.sin(el), -math.cos(az) * math.cos(el)]
        )
        if clear_of_everything(pos, 0.3):
            break
    roll = rng.uniform(-0.2, 0.2)

    scene = {
        "image": {"width": width, "height": height},
        "camera": {
            "position": pos.tolist(),
            "look_at": target.tolist(),
            "up": [math.sin(roll), math.cos(roll), 0.0],
            "vfov_deg": float(rng.uniform(25, 50)),
        },
        "light": {"position": light.tolist(), "intensity": float(rng.uniform(20, 120))},
        "exposure": float(rng.uniform(0.5, 2.5)),
        "objects": objects,
    }
    if rng.random() < 0.6:
        scene["light"]["color"] = rng.uniform(0.4, 1.0, 3).tolist()
    if rng.random() < 0.5:
        scene["ambient"] = rng.uniform(0.0, 0.15, 3).tolist()
    if rng.random() < 0.5:
        scene["background"] = rng.uniform(0.0, 0.5, 3).tolist()
    return scene


def compare_with_reference(scene: dict, width=None, height=None):
    want = ref.render_full(scene, width, height)
    kw = {"width": width, "height": height}
    got = rt_render(scene, **kw)
    ids = rt_ids(scene, **kw)
    assert got.shape == want.image.shape
    assert ids.shape == want.ids.shape

    edges = changes_near(want.ids) | changes_near(want.visible)
    id_bad = ids != want.ids
    assert not np.any(id_bad & ~edges), (
        f"object ids differ away from silhouettes at {np.argwhere(id_bad & ~edges)[:10].tolist()} (j, i)"
    )
    assert id_bad.mean() < 0.01, f"object ids differ at {id_bad.sum()} pixels"

    assert np.all(np.isfinite(got))
    compare = ~edges & ~id_bad
    assert compare.mean() > 0.5  # the test must actually look at most of the image
    bad = compare[..., None] & ~(np.abs(got - want.image) <= RTOL * np.abs(want.image) + ATOL)
    bad = bad.any(axis=-1)
    assert not np.any(bad), describe_mismatch(got, want.image, bad, want.ids)
    return want, got, ids


# --------------------------------------------------------------------------------------------------
# The reference itself, against hand-computed values


HEAD_ON = {
    "image": {"width": 65, "height": 49},
    "camera": {"position": [0, 0, -5], "look_at": [0, 0, 0], "up": [0, 1, 0], "vfov_deg": 30},
    "light": {"position": [0, 0, -5], "intensity": 40.0},
    "objects": [sphere("ball", [0, 0, 0], 1.0, [0.8, 0.5, 0.2])],
}


def head_on_expected(specular=0.0, shininess=0.0, exposure=1.0):
    # centre pixel: hit at (0, 0, -1), n = l = v = h = -z, d = 4
    rho = np.array([0.8, 0.5, 0.2])
    return exposure * 40.0 / 16.0 * (rho / math.pi + specular * (shininess + 8) / (8 * math.pi))


def test_reference_head_on_sphere_matches_hand_computation():
    img, ids = ref.render(HEAD_ON)
    assert ids[24, 32] == 0 and ids[0, 0] == -1
    np.testing.assert_allclose(img[24, 32], head_on_expected(), rtol=1e-12)
    s = json.loads(json.dumps(HEAD_ON))
    s["objects"][0]["material"].update(specular=0.5, shininess=20.0)
    s["exposure"] = 1.7
    img, _ = ref.render(s)
    np.testing.assert_allclose(img[24, 32], head_on_expected(0.5, 20.0, 1.7), rtol=1e-12)


def test_reference_lit_and_shadowed_floor_match_hand_computation():
    s = shadow_scene()
    r = ref.render_full(s)
    i, j = (round(v) for v in ref.project(s, [0, 0, 0]))
    assert r.ids[j, i] == 1 and not r.visible[j, i]
    np.testing.assert_allclose(r.image[j, i], 2.0 * 0.5 * 0.1, rtol=1e-12)
    i, j = (round(v) for v in ref.project(s, [2.5, 0, 0]))
    x = ref.primary_directions(s)[j, i] * r.t[j, i] + np.array([0, 3.0, -7.0])
    d2 = float(np.sum((np.array([0, 6.0, 0]) - x) ** 2))
    want = 2.0 * (0.5 * 0.1 + 40.0 * (6.0 / math.sqrt(d2)) / d2 * 0.5 / math.pi)
    assert r.ids[j, i] == 1 and r.visible[j, i]
    np.testing.assert_allclose(r.image[j, i], want, rtol=1e-12)


# --------------------------------------------------------------------------------------------------
# rtloop against the reference


def test_head_on_sphere_centre_pixel():
    got = rt_render(HEAD_ON)
    assert got.shape == (49, 65, 3)
    np.testing.assert_allclose(got[24, 32], head_on_expected(), rtol=RTOL, atol=ATOL)
    np.testing.assert_array_equal(got[0, 0], 0.0)
    s = json.loads(json.dumps(HEAD_ON))
    s["objects"][0]["material"].update(specular=0.5, shininess=20.0)
    s["exposure"] = 1.7
    got = rt_render(s)
    np.testing.assert_allclose(got[24, 32], head_on_expected(0.5, 20.0, 1.7), rtol=RTOL, atol=ATOL)


@pytest.mark.parametrize("seed", list(range(12)))
def test_random_scene_matches_reference(seed):
    compare_with_reference(random_scene(seed))


@pytest.mark.parametrize("seed", list(range(4)))
def test_random_scene_under_a_directional_light_matches_reference(seed):
    scene = random_scene(100 + seed)
    rng = np.random.default_rng(seed)
    scene["light"] = {"type": "directional", "direction": [float(rng.uniform(-1, 1)), float(rng.uniform(0.3, 1)),
                                                            float(rng.uniform(-1, 1))],
                      "intensity": float(rng.uniform(1, 4)), "color": scene["light"].get("color", [1, 1, 1])}
    scene["fit"] = {}
    compare_with_reference(scene)


def test_scene_object_size_and_file_loading(tmp_path):
    s = random_scene(3)
    sc = rtloop.load_scene(s)
    assert (sc.width, sc.height) == (s["image"]["width"], s["image"]["height"])
    path = tmp_path / "scene.json"
    path.write_text(json.dumps(s))
    from_file = rtloop.render(rtloop.load_scene(str(path)))
    np.testing.assert_array_equal(from_file, rtloop.render(sc))


# --------------------------------------------------------------------------------------------------
# Orientation


ORIENT_CAMERA = {"position": [2.5, 2.0, -6.0], "look_at": [0.3, 0.9, 0.4], "up": [0, 1, 0], "vfov_deg": 40}


def orient_scene(center, light=None) -> dict:
    return {
        "image": {"width": 120, "height": 90},
        "camera": dict(ORIENT_CAMERA),
        "light": {
            "position": list(light if light is not None else ORIENT_CAMERA["position"]),
            "intensity": 60.0,
        },
        "objects": [sphere("ball", center, 0.5, [0.7, 0.7, 0.7])],
    }


def centroid(mask: np.ndarray) -> tuple[float, float]:
    js, is_ = np.nonzero(mask)
    assert len(js) > 20
    return float(is_.mean()), float(js.mean())


def test_moving_along_right_moves_right_and_along_up_moves_up():
    cam = ref.camera({"camera": ORIENT_CAMERA})
    c0 = np.array(ORIENT_CAMERA["look_at"], dtype=float)
    i0, j0 = centroid(rt_ids(orient_scene(c0)) == 0)
    assert abs(i0 - 59.5) < 1.0 and abs(j0 - 44.5) < 1.0  # look_at is at the image centre

    s_right = orient_scene(c0 + 1.0 * cam.right)
    i1, j1 = centroid(rt_ids(s_right) == 0)
    assert i1 > i0 + 5 and abs(j1 - j0) < 1.5
    pi_, pj = ref.project(s_right, c0 + 1.0 * cam.right)
    assert abs(i1 - pi_) < 1.0 and abs(j1 - pj) < 1.0

    s_up = orient_scene(c0 + 1.0 * cam.true_up)
    i2, j2 = centroid(rt_ids(s_up) == 0)
    assert j2 < j0 - 5 and abs(i2 - i0) < 1.5
    pi_, pj = ref.project(s_up, c0 + 1.0 * cam.true_up)
    assert abs(i2 - pi_) < 1.0 and abs(j2 - pj) < 1.0


def test_light_on_the_right_lights_the_right_side():
    cam = ref.camera({"camera": ORIENT_CAMERA})
    c0 = np.array(ORIENT_CAMERA["look_at"], dtype=float)
    s = orient_scene(c0, light=c0 + 4.0 * cam.right - 2.0 * cam.forward)
    ids = rt_ids(s)
    lum = rt_render(s).sum(axis=-1)
    mask = ids == 0
    ic, _ = centroid(mask)
    cols = np.arange(ids.shape[1])[None, :]
    right = lum[mask & (cols > ic + 2)].mean()
    left = lum[mask & (cols < ic - 2)].mean()
    assert right > 3.0 * left + 1e-6, (right, left)
    compare_with_reference(s)


# --------------------------------------------------------------------------------------------------
# Shadows


def shadow_scene() -> dict:
    return {
        "image": {"width": 80, "height": 60},
        "camera": {"position": [0, 3, -7], "look_at": [0, 0.5, 0], "up": [0, 1, 0], "vfov_deg": 40},
        "light": {"position": [0, 6, 0], "intensity": 40.0},
        "ambient": [0.1, 0.1, 0.1],
        "exposure": 2.0,
        "objects": [
            sphere("ball", [0, 1.5, 0], 0.7, [0.8, 0.5, 0.2]),
            plane("floor", [0, 0, 0], [0, 1, 0], [0.5, 0.5, 0.5]),
        ],
    }


def test_floor_beneath_sphere_is_in_shadow_and_outside_is_lit():
    s = shadow_scene()
    got = rt_render(s)
    ids = rt_ids(s)
    want = ref.render_full(s)
    ambient_only = 2.0 * 0.5 * 0.1

    i, j = (round(v) for v in ref.project(s, [0, 0, 0]))
    assert ids[j, i] == 1
    np.testing.assert_allclose(got[j, i], ambient_only, rtol=RTOL, atol=ATOL)

    for x in (2.5, -2.5):
        i, j = (round(v) for v in ref.project(s, [x, 0, 0]))
        assert ids[j, i] == 1
        assert np.all(got[j, i] > ambient_only + 0.1)
        np.testing.assert_allclose(got[j, i], want.image[j, i], rtol=RTOL, atol=ATOL)
    compare_with_reference(s)


# --------------------------------------------------------------------------------------------------
# Supersampling and resolution overrides


def test_spp_converges_to_box_filtered_high_resolution_render():
    s = random_scene(5)
    s["image"] = {"width": 48, "height": 36}
    s.setdefault("background", [0.2, 0.3, 0.4])
    k = 4
    sc = rtloop.load_scene(s)
    hi = np.asarray(rtloop.render(sc, width=48 * k, height=36 * k, spp=1), dtype=np.float64)
    hi_ref = ref.render_full(s, 48 * k, 36 * k)
    one = np.asarray(rtloop.render(sc, spp=1), dtype=np.float64)
    many = rtloop.render(sc, spp=16)
    assert many.dtype == np.float32
    many = np.asarray(many, dtype=np.float64)
    assert many.shape == one.shape == (36, 48, 3)
    assert np.all(np.isfinite(many)) and np.all(many >= 0)

    hb = blocks(hi, k)  # (36, 48, 16, 3)
    box = hb.mean(axis=2)
    flat = ~blocks(changes_near(hi_ref.ids) | changes_near(hi_ref.visible), k).any(axis=2)
    assert flat.mean() > 0.4

    # In smooth regions any set of samples inside the pixel lies within the radiance range over the pixel.
    rng_ = hb.max(axis=2) - hb.min(axis=2)
    tol = 1.5 * rng_ + RTOL * np.abs(box) + ATOL
    bad = flat[..., None] & (np.abs(many - box) > tol)
    assert not np.any(bad), describe_mismatch(many, box, bad.any(-1), blocks(hi_ref.ids, k)[..., 0])

    # Pure background is exactly the background whatever the sampling.
    bg = blocks(hi_ref.ids, k).max(axis=2) == -1
    bg &= blocks(hi_ref.ids, k).min(axis=2) == -1
    if np.any(bg):
        want_bg = s["exposure"] * np.array(s["background"])
        np.testing.assert_allclose(many[bg], np.broadcast_to(want_bg, many[bg].shape), rtol=1e-6, atol=1e-7)
        np.testing.assert_allclose(many[bg], one[bg], rtol=1e-6, atol=1e-7)

    # Across edges, 16 samples are a much better estimate of the pixel mean than the centre ray.
    edge = ~flat
    err_many = np.abs(many - box)[edge].mean()
    err_one = np.abs(one - box)[edge].mean()
    assert err_one > 0
    assert err_many < 0.6 * err_one, (err_many, err_one)


def test_resolution_override_keeps_field_of_view():
    s = random_scene(7)
    s["image"] = {"width": 80, "height": 60}
    sc = rtloop.load_scene(s)
    assert (sc.width, sc.height) == (80, 60)

    # Rendered at 2x, rtloop still agrees with the reference rendered at 2x ...
    compare_with_reference(s, width=160, height=120)
    assert rtloop.object_ids(sc, width=160, height=120).shape == (120, 160)

    # ... and averaging 2x2 blocks gives (to second order) the 1x centre samples away from edges.
    one = np.asarray(rtloop.render(sc), dtype=np.float64)
    hi = np.asarray(rtloop.render(sc, width=160, height=120), dtype=np.float64)
    assert one.shape == (60, 80, 3) and hi.shape == (120, 160, 3)
    hi_ref = ref.render_full(s, 160, 120)
    hb = blocks(hi, 2)
    box = hb.mean(axis=2)
    flat = ~blocks(changes_near(hi_ref.ids) | changes_near(hi_ref.visible), 2).any(axis=2)
    assert flat.mean() > 0.5
    tol = 0.5 * (hb.max(axis=2) - hb.min(axis=2)) + RTOL * np.abs(box) + ATOL
    bad = flat[..., None] & (np.abs(one - box) > tol)
    assert not np.any(bad), describe_mismatch(one, box, bad.any(-1), blocks(hi_ref.ids, 2)[..., 0])

    ids_one = np.asarray(rtloop.object_ids(sc))
    ids_hi = np.asarray(rtloop.object_ids(sc, width=160, height=120))
    np.testing.assert_array_equal(ids_one[flat], blocks(ids_hi, 2)[..., 0][flat])
