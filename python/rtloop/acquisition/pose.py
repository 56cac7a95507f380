"""The floor plane and the camera pose from one ChArUco board lying on the floor.

World frame (the scene's): metres, right-handed, +y up, the board's printed face in the plane y=0
with the origin at the board's centre, +x along the board's columns (to the right as printed) and
+z along its rows (down the printed page). In board coordinates (OpenCV's: x right, y down the
page, z into the paper) a point ``p`` is at ``WORLD_FROM_BOARD @ (p - board_centre)`` in the world;
the paper's normal towards the viewer (-z) becomes +y.

:func:`estimate_floor_pose` finds the board's corners, solves the perspective-n-point problem
(``cv2.solvePnP`` with the planar IPPE solver, then Levenberg-Marquardt refinement) and returns the
camera as the scene format writes it. The photo must already be a centred pinhole image, as
:func:`rtloop.acquisition.calibration.undistort_to_pinhole` makes one; without a calibration the
focal length is estimated from the board itself (less accurate: a calibration is better).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import cv2
import numpy as np

from ._common import AcquisitionError, check_image, to_detection_grey
from .boards import BoardDetection, BoardSpec, detect_board, parse_board
from .camera import PinholeCamera, centred_camera_matrix

__all__ = ["WORLD_FROM_BOARD", "FloorPose", "estimate_floor_pose", "estimate_focal_from_board"]

#: Rotation from board coordinates (x right, y down the page, z into the paper) to world (+y up).
WORLD_FROM_BOARD = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])


@dataclass
class FloorPose:
    """The camera and the floor found from a board on the floor.

    Attributes:
        camera: the scene's camera (world frame above) for the photo's full size.
        board: the board description used.
        detection: the corners found (pixel and board coordinates).
        rvec, tvec: OpenCV's board -> camera pose.
        reprojection_rms_px: RMS distance between the corners found and the board reprojected.
        focal_source: where the focal length came from ("calibration", "given", "board").
        vfov_std_deg: with ``focal_source`` "board", the vertical field of view's standard deviation (deg).
    """

    camera: PinholeCamera
    board: BoardSpec
    detection: BoardDetection
    rvec: np.ndarray
    tvec: np.ndarray
    reprojection_rms_px: float
    focal_source: str
    vfov_std_deg: float | None = None

    @property
    def floor_plane(self) -> dict[str, Any]:
        """The floor as the scene format's plane (the board's face is y = 0)."""
        return {"point": [0.0, 0.0, 0.0], "normal": [0.0, 1.0, 0.0]}

    def board_to_world(self, points: np.ndarray) -> np.ndarray:
        p = np.asarray(points, dtype=float).reshape(-1, 3)
        return (p - self.board.centre) @ WORLD_FROM_BOARD.T

    def report(self) -> dict[str, Any]:
        cam = self.camera
        return {
            "board": self.board.to_dict(),
            "corners": len(self.detection),
            "reprojection_rms_px": self.reprojection_rms_px,
            "focal_px": cam.focal_px,
            "focal_source": self.focal_source,
            **({"vfov_std_deg": self.vfov_std_deg} if self.vfov_std_deg is not None else {}),
            "camera_distance_m": float(np.linalg.norm(cam.position)),
            "camera_height_m": float(cam.position[1]),
        }


#: The field of view wanted without EXIF (deg): a board's own estimate looser than this is used with a
#: warning that gives its spread, or refused in one line (why, and what to give instead) when strict.
VFOV_TARGET_DEG = 0.3
#: Looser than this (deg) the board's estimate is refused even when not strict: only a spread it cannot
#: give (a singular covariance). Looser than VFOV_TARGET_DEG the scene builder refines the field of view from
#: the ball resting on the floor (:mod:`.focal`).
VFOV_LIMIT_DEG = math.inf


def _focal_std(
    detection: BoardDetection, k: np.ndarray, rvec: np.ndarray, tvec: np.ndarray, noise_px: float
) -> float:
    """The focal length's standard deviation (pixels) for corners located to ``noise_px`` (1 sigma per
    coordinate), from the Jacobian of the corners' projections in (rotation, translation, focal length)."""
    _, jac = cv2.projectPoints(detection.object_points, rvec, tvec, k, np.zeros(5))
    j = np.column_stack([jac[:, :6], jac[:, 6] + jac[:, 7]])  # one focal length (fixed aspect ratio)
    try:
        cov = np.linalg.inv(j.T @ j)
    except np.linalg.LinAlgError:
        return float("inf")
    return noise_px * math.sqrt(max(float(cov[6, 6]), 0.0))


def estimate_focal_from_board(detection: BoardDetection, width: int, height: int, *,
                              strict: bool = False) -> tuple[float, float]:
    """Focal length (pixels) of a centred, distortion-free camera from one view of a flat board, and the
    standard deviation of the vertical field of view it gives (deg).

    A single view of a plane fixes the focal length once the principal point is known (Zhang), if
    the board is seen at an angle; seen head-on it does not. The uncertainty is the calibration's own: the
    covariance of (pose, focal length) for corners located as well as the fit's reprojection residual says
    (its RMS over the 2N - 7 degrees of freedom). Refused, in one line naming the cause and the fixes, when
    that standard deviation exceeds :data:`VFOV_TARGET_DEG` with ``strict``, else :data:`VFOV_LIMIT_DEG`
    (the caller warns between the two).
    """
    k0 = centred_camera_matrix(float(max(width, height)), width, height)
    flags = (
        cv2.CALIB_USE_INTRINSIC_GUESS
        | cv2.CALIB_FIX_PRINCIPAL_POINT
        | cv2.CALIB_FIX_ASPECT_RATIO
        | cv2.CALIB_ZERO_TANGENT_DIST
        | cv2.CALIB_FIX_K1
        | cv2.CALIB_FIX_K2
        | cv2.CALIB_FIX_K3
        | cv2.CALIB_FIX_K4
        | cv2.CALIB_FIX_K5
        | cv2.CALIB_FIX_K6
    )
    n = len(detection.object_points)
    noise = float("nan")
    try:
        rms, k, _, rvecs, tvecs = cv2.calibrateCamera(
            [detection.object_points], [detection.image_points], (width, height), k0, np.zeros(5), flags=flags
        )
        f = float(k[0, 0])
        noise = float(rms) * math.sqrt(2 * n / max(2 * n - 7, 1))
        f_std = _focal_std(detection, k, rvecs[0], tvecs[0], noise)
    except cv2.error:
        f, f_std = float("nan"), float("inf")
    vfov = math.degrees(2 * math.atan(height / 2 / f)) if f > 0 else float("nan")
    if not (math.isfinite(f) and 3.0 <= vfov <= 150.0):
        raise AcquisitionError(
            "could not estimate the focal length from the board (it is probably seen nearly head-on); "
            "give --vfov or --camera ('rtloop-acquire calibrate'), or use a photo whose EXIF has the focal length"
        )
    # d vfov / d f = -h / (f^2 + h^2/4) radians per pixel
    vfov_std = math.degrees(f_std * height / (f * f + height * height / 4))
    gate = VFOV_TARGET_DEG if strict else VFOV_LIMIT_DEG
    if not (vfov_std <= gate and math.isfinite(vfov_std)):
        raise AcquisitionError(
            f"the board's view does not fix the focal length (vertical field of view {vfov:.1f} +- "
            f"{vfov_std:.2f} deg from its {n} corners, reprojected to {noise:.2f} px; "
            f"{f'{gate:g} deg needed with --strict' if strict else 'no spread it can be used with'}"
            "): seen too nearly head-on, or too small, far or "
            "few-cornered for its perspective to show; give --vfov or --camera, use a photo whose EXIF has the "
            "focal length, or photograph a larger board closer and at more of an angle"
        )
    return f, vfov_std


def estimate_floor_pose(
    image: np.ndarray,
    board: BoardSpec | str | dict,
    *,
    focal_px: float | None = None,
    focal_source: str | None = None,
    where: str = "photo",
    strict: bool = False,
) -> FloorPose:
    """Camera pose and floor plane from a ChArUco board lying on the floor.

    Args:
        image: linear RGB float image (H, W, 3) of a *centred pinhole camera*: undistorted and
            re-centred (see ``undistort_to_pinhole``), or from a camera whose distortion is negligible.
        board: the board (a :class:`BoardSpec`, an inline spec or a JSON file, see ``boards``).
        focal_px: the focal length in pixels at this image's size; None estimates it from the board.
        focal_source: how the focal length was obtained, for the report.
        where: the name used in error messages (the file name).
        strict: with the focal length estimated from the board, refuse one looser than
            :data:`VFOV_TARGET_DEG` (else only past :data:`VFOV_LIMIT_DEG`; :attr:`FloorPose.vfov_std_deg`
            says how loose it is).

    Raises:
        AcquisitionError: no board, too few corners, corners on a line, no focal length.
    """
    image = check_image(image, where)
    spec = parse_board(board)
    if spec.kind != "charuco":
        raise AcquisitionError(
            f"{where}: the floor pose needs a ChArUco board (a chessboard's corners can't be "
            "named when part of it is hidden, and its orientation is ambiguous)"
        )
    h, w = image.shape[:2]
    vfov_std = None
    detection = detect_board(to_detection_grey(image), spec, where=where)
    if focal_px is None:
        focal_px, vfov_std = estimate_focal_from_board(detection, w, h, strict=strict)
        focal_source = "board"
    elif not (math.isfinite(focal_px) and focal_px > 0):
        raise AcquisitionError(f"{where}: focal length must be > 0 pixels (got {focal_px})")
    k = centred_camera_matrix(float(focal_px), w, h)
    obj = detection.object_points.astype(np.float64)
    img = detection.image_points.astype(np.float64)
    dist = np.zeros(5)
    ok, rvec, tvec = cv2.solvePnP(obj, img, k, dist, flags=cv2.SOLVEPNP_IPPE)
    if not ok:
        ok, rvec, tvec = cv2.solvePnP(obj, img, k, dist, flags=cv2.SOLVEPNP_ITERATIVE)
    if not ok:
        raise AcquisitionError(f"{where}: could not solve the board's pose from {len(obj)} corners")
    rvec, tvec = cv2.solvePnPRefineLM(obj, img, k, dist, rvec, tvec)
    projected, _ = cv2.projectPoints(obj, rvec, tvec, k, dist)
    rms = float(np.sqrt(np.mean(np.sum((projected.reshape(-1, 2) - img) ** 2, axis=1))))
    camera = PinholeCamera.from_opencv(rvec, tvec, float(focal_px), w, h, WORLD_FROM_BOARD, spec.centre)
    if camera.position[1] <= 0:
        raise AcquisitionError(
            f"{where}: the board appears to be seen from below the floor; is --board right?"
        )
    return FloorPose(
        camera,
        spec,
        detection,
        np.asarray(rvec).reshape(3),
        np.asarray(tvec).reshape(3),
        rms,
        focal_source or "given",
        vfov_std,
    )
