"""Camera intrinsics from several photos of a board, and undistortion to the scene's pinhole camera.

The scene format's camera is an ideal pinhole: square pixels, principal point at the image centre,
no lens distortion. A real camera has none of these exactly. :func:`calibrate_camera` measures it
from photos of a ChArUco board or a chessboard (``cv2.calibrateCamera``: focal lengths, principal
point, radial k1 k2 [k3] and tangential p1 p2 distortion), and :func:`undistort_to_pinhole` resamples
a photo into the ideal camera the scene can describe: distortion removed, pixels made square and the
principal point moved to the centre. The new focal length is chosen so that every output pixel sees
something (a slight zoom when the principal point was off-centre or the distortion was barrel-shaped).

Take the calibration photos with the same camera, lens, zoom, focus and resolution as the scene
photo: 10 to 20 photos from different angles (tilted up to about 45 degrees), the board filling a
good part of the frame and reaching into the corners across the set.
"""

from __future__ import annotations

import math
import os
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from typing import Any

import cv2
import numpy as np

from ._common import AcquisitionError, check_image, read_json, to_detection_grey, undistort_points, write_json
from .boards import BoardSpec, detect_board, parse_board
from .camera import centred_camera_matrix

__all__ = ["MIN_VIEWS", "CameraIntrinsics", "PinholeRemap", "calibrate_camera", "undistort_to_pinhole"]

#: Fewest board photos calibrate_camera accepts.
MIN_VIEWS = 3


@dataclass
class CameraIntrinsics:
    """A calibrated camera (OpenCV's model) for photos of ``image_size`` = (width, height)."""

    camera_matrix: np.ndarray
    dist_coeffs: np.ndarray
    image_size: tuple[int, int]
    rms_px: float = float("nan")
    per_view_rms_px: list[float] = field(default_factory=list)
    views: list[str] = field(default_factory=list)
    board: dict[str, Any] | None = None

    @property
    def focal_px(self) -> tuple[float, float]:
        return float(self.camera_matrix[0, 0]), float(self.camera_matrix[1, 1])

    @property
    def principal_point(self) -> tuple[float, float]:
        return float(self.camera_matrix[0, 2]), float(self.camera_matrix[1, 2])

    def to_dict(self) -> dict[str, Any]:
        fx, fy = self.focal_px
        w, h = self.image_size
        return {
            "kind": "rtloop camera intrinsics (OpenCV model, pixel centres at integer coordinates)",
            "image_size": [int(w), int(h)],
            "camera_matrix": self.camera_matrix.tolist(),
            "dist_coeffs": np.asarray(self.dist_coeffs, dtype=float).ravel().tolist(),
            "rms_px": self.rms_px,
            "per_view_rms_px": list(self.per_view_rms_px),
            "views": list(self.views),
            "board": self.board,
            "vfov_deg": math.degrees(2 * math.atan(h / 2 / fy)),
            "hfov_deg": math.degrees(2 * math.atan(w / 2 / fx)),
        }

    @classmethod
    def from_dict(cls, d: dict[str, Any], where: str = "intrinsics") -> CameraIntrinsics:
        try:
            k = np.asarray(d["camera_matrix"], dtype=float)
            dist = np.asarray(d.get("dist_coeffs", []), dtype=float).ravel()
            w, h = (int(v) for v in d["image_size"])
            if k.shape != (3, 3) or not np.isfinite(k).all() or k[0, 0] <= 0 or k[1, 1] <= 0:
                raise ValueError("camera_matrix must be a 3x3 matrix with positive focal lengths")
            if dist.size not in (0, 4, 5, 8, 12, 14) or not np.isfinite(dist).all():
                raise ValueError("dist_coeffs must have 4, 5, 8, 12 or 14 numbers")
            if w <= 0 or h <= 0:
                raise ValueError("image_size must be positive")
        except (KeyError, TypeError, ValueError) as exc:
            raise AcquisitionError(
                f"{where}: not a camera calibration ({exc}); make one with 'rtloop-acquire calibrate'"
            ) from None
        return cls(
            k,
            dist if dist.size else np.zeros(5),
            (w, h),
            float(d.get("rms_px", float("nan")) or "nan"),
            list(d.get("per_view_rms_px", [])),
            list(d.get("views", [])),
            d.get("board"),
        )

    def save(self, path: str | os.PathLike[str]) -> None:
        write_json(path, self.to_dict())

    @classmethod
    def load(cls, path: str | os.PathLike[str]) -> CameraIntrinsics:
        name = os.fspath(path)
        data = read_json(name, "a camera calibration written by 'rtloop-acquire calibrate'")
        if not isinstance(data, dict):
            raise AcquisitionError(f"{name}: not a camera calibration")
        return cls.from_dict(data, where=name)

    def for_size(self, width: int, height: int, where: str = "photo") -> CameraIntrinsics:
        """The calibration for photos of another size with the same aspect ratio (a scaled image
        from the same sensor); a different aspect ratio (cropped or rotated photo) is an error."""
        w0, h0 = self.image_size
        if (width, height) == (w0, h0):
            return self
        s = width / w0
        if abs(height / h0 - s) > 0.01 * s:
            raise AcquisitionError(
                f"{where}: photo is {width}x{height} but the camera was calibrated on {w0}x{h0} photos "
                "(another aspect ratio: cropped or rotated?); use uncropped photos in the calibration's "
                "orientation, or calibrate again with photos of this size"
            )
        k = self.camera_matrix.copy()
        sx, sy = width / w0, height / h0
        k[0, 0] *= sx
        k[1, 1] *= sy
        k[0, 1] *= sx
        k[0, 2] = (k[0, 2] + 0.5) * sx - 0.5
        k[1, 2] = (k[1, 2] + 0.5) * sy - 0.5
        return CameraIntrinsics(
            k,
            self.dist_coeffs.copy(),
            (width, height),
            self.rms_px,
            self.per_view_rms_px,
            self.views,
            self.board,
        )


def calibrate_camera(
    images: Iterable[np.ndarray],
    board: BoardSpec | str | dict,
    *,
    names: Sequence[str] | None = None,
    fix_k3: bool = True,
    zero_tangent: bool = False,
    on_skip: Any = None,
) -> CameraIntrinsics:
    """Calibrate a camera from several linear RGB photos of a ChArUco board or a chessboard.

    Photos in which the board is not found (or too little of it) are skipped (``on_skip(name, message)``
    is called for each), but at least :data:`MIN_VIEWS` must remain. All photos must have one size.

    Args:
        fix_k3: keep the third radial coefficient at zero (recommended unless the lens is a wide angle
            and you have many photos).
        zero_tangent: keep p1, p2 at zero.

    Raises:
        AcquisitionError: photos of different sizes, or too few usable views.
    """
    spec = parse_board(board)
    obj_pts, img_pts, used, skipped = [], [], [], []
    size = None
    for i, image in enumerate(images):
        name = names[i] if names is not None and i < len(names) else f"photo {i + 1}"
        image = check_image(image, name)
        h, w = image.shape[:2]
        if size is None:
            size = (w, h)
        elif size != (w, h):
            raise AcquisitionError(
                f"{name}: photo is {w}x{h} but the first calibration photo is {size[0]}x{size[1]}; every "
                "calibration photo must come from the same camera at the same resolution and orientation"
            )
        try:
            det = detect_board(to_detection_grey(image), spec, where=name)
        except AcquisitionError as exc:
            skipped.append(str(exc))
            if on_skip is not None:
                on_skip(name, str(exc))
            continue
        obj_pts.append(det.object_points.astype(np.float32))
        img_pts.append(det.image_points.astype(np.float32))
        used.append(name)
    if size is None:
        raise AcquisitionError("calibration: no photos given")
    if len(used) < MIN_VIEWS:
        detail = f" ({skipped[0]})" if skipped else ""
        raise AcquisitionError(
            f"calibration: the board was found in only {len(used)} photo(s), need at least {MIN_VIEWS} "
            f"(10 to 20 is better), taken from different angles{detail}"
        )
    flags = 0
    if fix_k3:
        flags |= cv2.CALIB_FIX_K3
    if zero_tangent:
        flags |= cv2.CALIB_ZERO_TANGENT_DIST
    criteria = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 100, 1e-10)
    try:
        rms, k, dist, rvecs, tvecs = cv2.calibrateCamera(
            obj_pts, img_pts, size, None, None, flags=flags, criteria=criteria
        )
    except cv2.error as exc:
        raise AcquisitionError(f"calibration failed in OpenCV: {str(exc).strip().splitlines()[-1]}") from None
    per_view = []
    for o, p, rv, tv in zip(obj_pts, img_pts, rvecs, tvecs):
        proj, _ = cv2.projectPoints(o, rv, tv, k, dist)
        per_view.append(
            float(np.sqrt(np.mean(np.sum((proj.reshape(-1, 2) - p.reshape(-1, 2)) ** 2, axis=1))))
        )
    return CameraIntrinsics(k, dist.ravel(), size, float(rms), per_view, used, spec.to_dict())


class PinholeRemap:
    """The resampling from a calibrated photo to the scene's pinhole camera (same size), for images,
    masks and pixel positions."""

    def __init__(self, intrinsics: CameraIntrinsics, width: int, height: int, where: str = "photo"):
        intr = intrinsics.for_size(width, height, where)
        self.source_matrix = intr.camera_matrix
        self.dist_coeffs = np.asarray(intr.dist_coeffs, dtype=float)
        self.width, self.height = width, height
        self.focal_px = _valid_focal(self.source_matrix, self.dist_coeffs, width, height)
        self.camera_matrix = centred_camera_matrix(self.focal_px, width, height)
        self._maps = cv2.initUndistortRectifyMap(
            self.source_matrix, self.dist_coeffs, None, self.camera_matrix, (width, height), cv2.CV_32FC1
        )

    def image(self, image: np.ndarray, interpolation: int = cv2.INTER_CUBIC) -> np.ndarray:
        out = cv2.remap(image, self._maps[0], self._maps[1], interpolation, borderMode=cv2.BORDER_REPLICATE)
        if out.dtype == np.float32:
            out = np.maximum(out, 0.0)
        return np.ascontiguousarray(out)

    def mask(self, mask: np.ndarray) -> np.ndarray:
        m = (np.asarray(mask) > 0).astype(np.uint8)
        return self.image(m, cv2.INTER_NEAREST) > 0

    def points(self, points: np.ndarray) -> np.ndarray:
        """Where photo pixels (N, 2) land in the pinhole image."""
        return undistort_points(points, self.source_matrix, self.dist_coeffs, self.camera_matrix)


def undistort_to_pinhole(
    image: np.ndarray,
    intrinsics: CameraIntrinsics,
    *,
    where: str = "photo",
    interpolation: int = cv2.INTER_CUBIC,
) -> tuple[np.ndarray, float]:
    """Resample a photo into the scene format's camera: no distortion, square pixels, centred principal point.

    Returns:
        ``(image, focal_px)``: the new image (same size, float32 linear RGB) and its focal length in
        pixels; its vertical field of view is ``2 atan(H / (2 focal_px))``.
    """
    image = check_image(image, where)
    h, w = image.shape[:2]
    remap = PinholeRemap(intrinsics, w, h, where)
    return remap.image(image, interpolation).astype(np.float32), remap.focal_px


def _valid_focal(k: np.ndarray, dist: np.ndarray, w: int, h: int) -> float:
    """The smallest focal length (widest view) of the centred output camera whose every pixel maps
    inside the photo."""
    n = 200
    top = np.column_stack([np.linspace(0, w - 1, n), np.zeros(n)])
    bottom = np.column_stack([np.linspace(0, w - 1, n), np.full(n, h - 1.0)])
    left = np.column_stack([np.zeros(n), np.linspace(0, h - 1, n)])
    right = np.column_stack([np.full(n, w - 1.0), np.linspace(0, h - 1, n)])

    def norm(pts: np.ndarray) -> np.ndarray:
        return undistort_points(pts, k, dist)

    x_left = float(np.max(norm(left)[:, 0]))  # negative; innermost point of the left edge
    x_right = float(np.min(norm(right)[:, 0]))
    y_top = float(np.max(norm(top)[:, 1]))
    y_bottom = float(np.min(norm(bottom)[:, 1]))
    half_x = min(-x_left, x_right)
    half_y = min(-y_top, y_bottom)
    if half_x <= 0 or half_y <= 0:
        raise AcquisitionError(
            "calibration: the principal point lies outside the photo; the calibration is wrong, calibrate "
            "again"
        )
    return max((w - 1) / 2.0 / half_x, (h - 1) / 2.0 / half_y)
