"""Camera calibration from several synthetic board photos, and undistortion to the scene's pinhole
camera (rtloop.acquisition.calibration).

The views are made with a known camera: ideal pinhole views of the board (cv2.aruco's image, warped),
shifted to an off-centre principal point, then pushed through a known lens distortion.
"""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest

from rtloop.acquisition import (
    AcquisitionError,
    CameraIntrinsics,
    PinholeCamera,
    calibrate_camera,
    estimate_floor_pose,
    parse_board,
    undistort_to_pinhole,
)
from rtloop.acquisition.synthetic import board_view, distort

W, H = 800, 600
F = 700.0
K_TRUE = np.array([[F, 0, 410.0], [0, F, 290.0], [0, 0, 1]])
DIST_TRUE = np.array([-0.12, 0.05, 0.001, -0.0005, 0.0])
SPEC = parse_board("9x6,50mm,37mm")


def shoot(cam: PinholeCamera, dist: np.ndarray = DIST_TRUE) -> np.ndarray:
    """What the real (off-centre, distorting) camera sees from ``cam``'s pose."""
    ideal = board_view(SPEC, cam, supersample=2)
    shift = np.float32([[1, 0, K_TRUE[0, 2] - (W - 1) / 2], [0, 1, K_TRUE[1, 2] - (H - 1) / 2]])
    shifted = cv2.warpAffine(ideal, shift, (W, H), flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
    return distort(shifted, K_TRUE, dist) if np.any(dist) else shifted


def pose_around(i: int, n: int, rng: np.random.Generator) -> PinholeCamera:
    az = 2 * math.pi * i / n + rng.uniform(-0.3, 0.3)
    el = math.radians(rng.uniform(40, 65))
    d = rng.uniform(0.5, 0.65)
    pos = [d * math.cos(el) * math.sin(az), d * math.sin(el), d * math.cos(el) * math.cos(az)]
    look = rng.uniform(-0.08, 0.08, 3)
    look[1] = 0
    vfov = 2 * math.degrees(math.atan(H / 2 / F))
    return PinholeCamera.from_scene_camera(
        {"position": pos, "look_at": look.tolist(), "up": [rng.uniform(-0.3, 0.3), 1, 0], "vfov_deg": vfov},
        W,
        H,
    )


@pytest.fixture(scope="module")
def views() -> tuple[list[PinholeCamera], list[np.ndarray]]:
    rng = np.random.default_rng(2)
    cams = [pose_around(i, 6, rng) for i in range(6)]
    return cams, [shoot(c) for c in cams]


@pytest.fixture(scope="module")
def intrinsics(views) -> CameraIntrinsics:
    return calibrate_camera(views[1], SPEC)


def test_calibration_recovers_the_focal_length_within_1_percent(intrinsics) -> None:
    fx, fy = intrinsics.focal_px
    assert fx == pytest.approx(F, rel=0.01)
    assert fy == pytest.approx(F, rel=0.01)
    cx, cy = intrinsics.principal_point
    assert abs(cx - K_TRUE[0, 2]) < 8 and abs(cy - K_TRUE[1, 2]) < 8
    assert intrinsics.dist_coeffs[0] == pytest.approx(DIST_TRUE[0], abs=0.02)
    assert intrinsics.rms_px < 0.3
    assert len(intrinsics.views) == 6 and intrinsics.image_size == (W, H)


def test_undistorted_photo_is_the_scene_pinhole_and_gives_the_pose(views, intrinsics) -> None:
    cams, photos = views
    undistorted, focal = undistort_to_pinhole(photos[0], intrinsics)
    assert undistorted.shape == photos[0].shape
    assert focal == pytest.approx(F, rel=0.08)  # a slight zoom keeps every pixel inside the photo
    pose = estimate_floor_pose(undistorted, SPEC, focal_px=focal)
    truth = cams[0]
    distance = float(np.linalg.norm(truth.position))
    assert np.linalg.norm(pose.camera.position - truth.position) <= 0.01 * distance
    cos = float(np.dot(pose.camera.forward, truth.forward))
    assert math.degrees(math.acos(min(1.0, cos))) < 0.5
    assert pose.reprojection_rms_px < 0.5  # straight lines are straight again


def test_intrinsics_save_load_and_scale(tmp_path, intrinsics) -> None:
    path = tmp_path / "camera.json"
    intrinsics.save(path)
    again = CameraIntrinsics.load(path)
    np.testing.assert_allclose(again.camera_matrix, intrinsics.camera_matrix)
    np.testing.assert_allclose(again.dist_coeffs, intrinsics.dist_coeffs)
    half = again.for_size(W // 2, H // 2)
    assert half.focal_px[0] == pytest.approx(intrinsics.focal_px[0] / 2)
    assert half.principal_point[0] == pytest.approx((intrinsics.principal_point[0] + 0.5) / 2 - 0.5)
    with pytest.raises(AcquisitionError, match="calibrated on 800x600 photos"):
        again.for_size(600, 600)
    (tmp_path / "bad.json").write_text('{"camera_matrix": [[1, 0], [0, 1]], "image_size": [8, 8]}')
    with pytest.raises(AcquisitionError, match="not a camera calibration.*rtloop-acquire calibrate"):
        CameraIntrinsics.load(tmp_path / "bad.json")


def test_calibration_needs_enough_views_and_one_size(views) -> None:
    _, photos = views
    blank = np.full((H, W, 3), 0.3, np.float32)
    skipped = []
    with pytest.raises(AcquisitionError, match="found in only 2 photo.*at least 3"):
        calibrate_camera([photos[0], blank, photos[1]], SPEC, on_skip=lambda n, m: skipped.append(n))
    assert skipped == ["photo 2"]
    with pytest.raises(AcquisitionError, match="photo is 400x300 but the first calibration photo is 800x600"):
        calibrate_camera([photos[0], photos[1][::2, ::2].copy()], SPEC)


def test_chessboard_calibration() -> None:
    spec = parse_board("chess:10x7,30mm")
    rng = np.random.default_rng(5)
    images = []
    for i in range(4):
        cam = pose_around(i, 4, rng)
        ideal = board_view(spec, cam, supersample=2)
        images.append(ideal)
    intr = calibrate_camera(images, spec, zero_tangent=True)
    assert intr.focal_px[0] == pytest.approx(F, rel=0.02)
