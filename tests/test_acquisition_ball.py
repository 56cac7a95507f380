"""The ball's outline and its centre in 3-D (rtloop.acquisition.ball), on photos rendered by rtloop.

Each photo is rtloop.render of a scene (README format) with a known camera; the camera handed to the
ball finder is that scene camera, so the only error measured is the ball's.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
import pytest

import rtloop
from rtloop.acquisition import (
    AcquisitionError,
    PinholeCamera,
    find_ball,
    locate_ball,
    place_sphere,
)
from conftest import floor, sphere

W, H = 640, 480


class Case(NamedTuple):
    """A photo's scene: the camera, the ball resting on the floor at (x, z), one light, a grey ambient."""

    camera: list[float]
    look_at: list[float]
    vfov: float
    ball_xz: tuple[float, float]
    radius: float
    light: list[float]
    ambient: float
    albedo: list[float]
    floor: float


CASES = {
    "yellow-front-light": Case([0.3, 0.7, -1.2], [0, 0.05, 0], 50, (0.15, 0.1), 0.1,
                                light=[0.8, 1.5, -0.3], ambient=0.0, albedo=[0.8, 0.6, 0.1], floor=0.5),
    "back-light-dark-shadow": Case([0.3, 0.7, -1.2], [0, 0.05, 0], 50, (0.15, 0.1), 0.1,
                                    light=[-0.6, 1.2, 0.8], ambient=0.03, albedo=[0.8, 0.6, 0.1], floor=0.5),
    "paper-scene": Case([0, 1.6, -6], [0, 0.8, 0], 35, (0.0, 0.0), 1.0,
                         light=[2.5, 4.5, -1], ambient=0.0, albedo=[0.8, 0.7, 0.1], floor=0.6),
    "wide-angle-near-edge": Case([0.5, 0.45, -1.0], [0, 0.1, 0], 70, (-0.45, 0.05), 0.08,
                                  light=[0.3, 1.2, -0.5], ambient=0.02, albedo=[0.2, 0.3, 0.8], floor=0.5),
    "grey-ball-grey-floor": Case([-0.8, 1.1, -1.4], [0.1, 0, 0.1], 45, (0.2, 0.3), 0.12,
                                  light=[0.5, 1.6, -1.0], ambient=0.05, albedo=[0.6, 0.6, 0.6], floor=0.35),
}


def scene_for(case: Case) -> dict:
    (bx, bz), r = case.ball_xz, case.radius
    ball = np.array([bx, r, bz])
    intensity = 2.5 * float(np.sum((np.array(case.light) - ball) ** 2))
    return {
        "image": {"width": W, "height": H},
        "camera": {"position": case.camera, "look_at": case.look_at, "up": [0, 1, 0], "vfov_deg": case.vfov},
        "light": {"position": case.light, "intensity": intensity},
        "ambient": [case.ambient] * 3,
        "objects": [sphere("ball", ball.tolist(), r, case.albedo), floor([case.floor] * 3)],
    }


def rendered(names, width: int, height: int, spp: int) -> dict[str, tuple[dict, np.ndarray]]:
    """The scenes of the cases ``names`` at ``width`` x ``height`` and their renders."""
    out = {}
    for name in names:
        scene = scene_for(CASES[name])
        scene["image"] = {"width": width, "height": height}
        out[name] = (scene, rtloop.render(scene, spp=spp))
    return out


@pytest.fixture(scope="module")
def photos() -> dict[str, tuple[dict, np.ndarray]]:
    return rendered(CASES, W, H, 9)


def truth(scene: dict) -> tuple[PinholeCamera, np.ndarray, float]:
    """The camera of ``scene`` at its image size, and its ball's centre and radius."""
    cam = PinholeCamera.from_scene_camera(scene["camera"], scene["image"]["width"], scene["image"]["height"])
    ball = scene["objects"][0]
    return cam, np.array(ball["center"]), ball["radius"]


@pytest.mark.parametrize("name", list(CASES))
def test_resting_ball_centre_within_1_percent_of_camera_distance(photos, name: str) -> None:
    scene, image = photos[name]
    cam, centre, r = truth(scene)
    silhouette, sphere = locate_ball(image, cam, r)
    distance = float(np.linalg.norm(centre - cam.position))
    assert np.linalg.norm(sphere.centre - centre) <= 0.01 * distance
    assert sphere.centre[1] == pytest.approx(r)  # resting on the floor
    assert silhouette.rms_px < 1.0
    assert silhouette.coverage > 0.3
    # The outline's apparent radius matches the true angular radius.
    assert silhouette.alpha == pytest.approx(np.arcsin(r / distance), rel=0.01)


def test_free_centre_also_recovers_the_height(photos) -> None:
    scene, image = photos["grey-ball-grey-floor"]
    cam, centre, r = truth(scene)
    _, sphere = locate_ball(image, cam, r, resting=False)
    distance = float(np.linalg.norm(centre - cam.position))
    assert np.linalg.norm(sphere.centre - centre) <= 0.02 * distance
    assert sphere.height_above_floor == pytest.approx(r, rel=0.1)


@pytest.mark.parametrize("name", ["yellow-front-light", "back-light-dark-shadow", "paper-scene"])
def test_find_ball_then_place_sphere(photos, name: str) -> None:
    """The outline finder that knows nothing of the floor (exact sphere-outline model), then placement
    from its outline. (locate_ball, which searches for a resting ball, is the robust one.)"""
    scene, image = photos[name]
    cam, centre, r = truth(scene)
    silhouette = find_ball(image, focal_px=cam.focal_px)
    expected = cam.project(centre[None, :])[0]
    assert np.linalg.norm(silhouette.centre_px - expected) < 0.5
    sphere = place_sphere(silhouette, cam, r)
    assert np.linalg.norm(sphere.centre - centre) <= 0.01 * np.linalg.norm(centre - cam.position)


def test_hint_and_mask(photos) -> None:
    scene, image = photos["back-light-dark-shadow"]
    cam, centre, r = truth(scene)
    distance = float(np.linalg.norm(centre - cam.position))
    uv = cam.project(centre[None, :])[0]
    sil, sphere = locate_ball(image, cam, r, hint=(uv[0] + 8, uv[1] - 5, 30))
    assert sil.source == "hint"
    assert np.linalg.norm(sphere.centre - centre) <= 0.01 * distance
    mask = rtloop.object_ids(scene) == 0
    sil, sphere = locate_ball(image, cam, r, mask=mask)
    assert sil.source == "mask"
    assert np.linalg.norm(sphere.centre - centre) <= 0.01 * distance


# --- the ball's own shadow beside it, seen from above ---------------------------------------------------

#: Cameras nearly straight down on a ball resting on the floor, the lamp high on the far side of the ball: the
#: camera sees the ball's dark side and its crisp shadow beside it on a stronger edge than the ball's own.
TOP_DOWN = [
    {"position": [0.62, 1.6, -0.42], "look_at": [0.28, 0.0, -0.06], "up": [0, 0, 1], "vfov_deg": 46},
    {"position": [0.2, 1.6, -0.45], "look_at": [0.14, 0.0, -0.1], "up": [0, 0, 1], "vfov_deg": 46},
]
TOP_DOWN_BALL = [0.56, 0.1, 0.04]


def _top_down(camera: dict, light: list[float]) -> dict:
    return {
        "image": {"width": W, "height": H},
        "camera": camera,
        "light": {"position": light, "intensity": 6.0},
        "ambient": [0.02] * 3,
        "objects": [
            {"name": "ball", "shape": "sphere", "center": TOP_DOWN_BALL, "radius": 0.1,
             "material": {"albedo": [0.72, 0.28, 0.14]}},
            {"name": "floor", "shape": "plane", "point": [0, 0, 0], "normal": [0, 1, 0],
             "material": {"albedo": [0.46, 0.42, 0.36]}},
        ],
    }


@pytest.mark.parametrize("camera", TOP_DOWN)
@pytest.mark.parametrize("light", [[1.0, 2.0, 1.6], [1.2, 2.3, -1.6], [-0.6, 2.3, -1.2]])
def test_ball_not_its_shadow_from_above(camera, light) -> None:
    """Seen from above with its shadow beside it the ball is found, not the shadow (an outline of the same
    size on edges too; before the inside was compared, the first case was placed 138 mm off on it)."""
    scene = _top_down(camera, light)
    cam, centre, r = truth(scene)
    _, sphere = locate_ball(rtloop.render(scene, spp=9), cam, r)
    assert np.linalg.norm(sphere.centre - centre) <= 0.01 * float(np.linalg.norm(centre - cam.position))


def test_sphere_likeness_closed_form() -> None:
    """An image that is exactly a quadratic function of a sphere's normals inside its outline (a shaded ball)
    and a quadratic of the pixel position outside (the floor): inside the true outline the sphere explains it to rounding, so the
    likeness is far above 1; an outline moved half a radius, or on the floor alone, is no sphere (<= 1)."""
    from rtloop.acquisition.ball.shading import sphere_likeness, sphere_pixels

    cam = PinholeCamera.from_scene_camera(TOP_DOWN[0], W, H)
    centre, r = np.array(TOP_DOWN_BALL), 0.1
    v, u = np.mgrid[0:H, 0:W] / W
    image = np.repeat((0.05 + 0.02 * u + 0.01 * v * v)[:, :, None], 3, axis=2)  # floor: smooth in the image
    uv, n = sphere_pixels(cam, centre, r, inset_px=0.0)
    shade = 0.3 + 0.5 * n @ np.array([0.3, 0.8, -0.5]) + 0.1 * n[:, 0] * n[:, 2]
    image[uv[:, 1], uv[:, 0]] = shade[:, None] * np.array([0.7, 0.3, 0.15])
    assert sphere_likeness(image, cam, centre, r) > 1e3
    assert sphere_likeness(image, cam, centre + [0.05, 0, 0], r) < 1.0
    assert sphere_likeness(image, cam, centre + [0.6, 0, 0.3], r) < 1e-3  # floor alone: fitted exactly as floor
    assert sphere_likeness(image, cam, centre + [50, 0, 0], r) == 0.0  # out of the photo


# --- a 12 MP photo ----------------------------------------------------------------------------------------

#: A phone's 12 MP frame: larger than the size the ball is searched at (rtloop.acquisition.ball.working).
BIG_W, BIG_H = 4032, 3024
BIG_CASES = ["yellow-front-light", "back-light-dark-shadow", "paper-scene"]


@pytest.fixture(scope="module")
def big_photos() -> dict[str, tuple[dict, np.ndarray]]:
    return rendered(BIG_CASES, BIG_W, BIG_H, 4)


@pytest.mark.parametrize("name", BIG_CASES)
def test_ball_in_a_12_mp_photo(big_photos, name: str) -> None:
    """The scenes of the small photos rendered at 4032 x 3024 (the paper scene's ball 800 px across): found
    and placed as well as at 640 x 480, by both finders, with the outline on the photo's own pixels."""
    scene, image = big_photos[name]
    cam, centre, r = truth(scene)
    distance = float(np.linalg.norm(centre - cam.position))
    silhouette, sphere = locate_ball(image, cam, r)
    assert (silhouette.width, silhouette.height) == (BIG_W, BIG_H)
    assert np.linalg.norm(sphere.centre - centre) <= 0.01 * distance
    assert silhouette.rms_px < 1.0
    assert silhouette.coverage > 0.3
    assert silhouette.alpha == pytest.approx(np.arcsin(r / distance), rel=0.01)
    outline = find_ball(image, focal_px=cam.focal_px)
    assert np.linalg.norm(outline.centre_px - cam.project(centre[None, :])[0]) < 0.5
    assert np.linalg.norm(place_sphere(outline, cam, r).centre - centre) <= 0.01 * distance


def test_hint_mask_and_their_errors_in_a_12_mp_photo(big_photos) -> None:
    """A hint and a mask in the 12 MP photo's pixels seed the search there; a hint off the photo or a mask of
    another size is one line naming the photo's own size."""
    scene, image = big_photos["back-light-dark-shadow"]
    cam, centre, r = truth(scene)
    distance = float(np.linalg.norm(centre - cam.position))
    k = BIG_W / W
    uv = cam.project(centre[None, :])[0]
    sil, sphere = locate_ball(image, cam, r, hint=(uv[0] + 8 * k, uv[1] - 5 * k, 30 * k))
    assert sil.source == "hint"
    assert np.linalg.norm(sphere.centre - centre) <= 0.01 * distance
    sil, sphere = locate_ball(image, cam, r, mask=rtloop.object_ids(scene) == 0)
    assert sil.source == "mask"
    assert np.linalg.norm(sphere.centre - centre) <= 0.01 * distance
    with pytest.raises(AcquisitionError, match=rf"outside the {BIG_W}x{BIG_H} photo"):
        locate_ball(image, cam, r, hint=(BIG_W + 10, 100, 200))
    with pytest.raises(AcquisitionError, match=rf"mask is 640x480 but the photo is {BIG_W}x{BIG_H}"):
        find_ball(image, mask=np.ones((H, W), bool))


# --- failures -----------------------------------------------------------------------------------------


def test_no_ball_is_a_clear_error(photos) -> None:
    scene, _ = photos["paper-scene"]
    empty = dict(scene, objects=scene["objects"][1:])
    floor_only = rtloop.render(empty, spp=4)
    cam, _, r = truth(scene)
    with pytest.raises(AcquisitionError, match=r"no ball.*--ball X,Y,R"):
        locate_ball(floor_only, cam, r)
    with pytest.raises(AcquisitionError, match=r"no ball.*--ball X,Y,R"):
        find_ball(np.full((H, W, 3), 0.2, np.float32))


def test_photo_of_the_wrong_size_is_a_clear_error(photos) -> None:
    scene, image = photos["paper-scene"]
    cam, _, r = truth(scene)
    with pytest.raises(AcquisitionError, match=r"photo is 320x240 but the camera .* 640x480"):
        locate_ball(image[::2, ::2].copy(), cam, r)
    with pytest.raises(AcquisitionError, match="mask is 320x240 but the photo is 640x480"):
        locate_ball(image, cam, r, mask=np.ones((240, 320), bool))
    with pytest.raises(AcquisitionError, match="hint"):
        locate_ball(image, cam, r, hint=(900, 100, 20))
    with pytest.raises(AcquisitionError, match="radius must be > 0"):
        locate_ball(image, cam, -1.0)
