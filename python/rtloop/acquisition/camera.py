"""The scene format's camera, placed in the world, and its link to OpenCV's camera model.

rtloop's scene camera is a pinhole with square pixels and the principal point at the image centre,
given by ``position``, ``look_at``, ``up`` and the full vertical field of view ``vfov_deg``
(docs/scene-format.md, "Camera"). OpenCV describes the same camera by an intrinsic matrix
``K = [[f, 0, cx], [0, f, cy], [0, 0, 1]]`` and a pose ``X_cam = R X_world + t`` in its camera frame
(x right, y *down*, z forward), with pixel centres at integer coordinates.

The two agree exactly when

* ``f = (H / 2) / tan(vfov / 2)`` and ``cx = (W - 1) / 2``, ``cy = (H - 1) / 2`` (rtloop's pixel
  ``(i, j)`` has its centre at ``i + 0.5`` on a continuous axis starting at the image's left edge;
  OpenCV puts the centre of pixel ``i`` at ``i``);
* OpenCV's camera axes, written in world coordinates, are ``right``, ``-true_up`` and ``forward``.

:class:`PinholeCamera` holds that camera (focal length in pixels, a rotation whose *columns* are
OpenCV's camera axes in world coordinates, and the position) and converts both ways.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import cv2
import numpy as np

from ._common import AcquisitionError

__all__ = ["PinholeCamera", "centred_camera_matrix", "focal_from_vfov", "vfov_from_focal"]


def focal_from_vfov(vfov_deg: float, height: int) -> float:
    """Focal length in pixels of a pinhole camera with the given full vertical field of view."""
    return (height / 2.0) / math.tan(math.radians(vfov_deg) / 2.0)


def vfov_from_focal(focal_px: float, height: int) -> float:
    """Full vertical field of view in degrees of a pinhole camera with focal length ``focal_px``."""
    return math.degrees(2.0 * math.atan((height / 2.0) / focal_px))


def centred_camera_matrix(focal_px: float, width: int, height: int) -> np.ndarray:
    """OpenCV's K for square pixels and the principal point at the image centre."""
    return np.array(
        [[focal_px, 0.0, (width - 1) / 2.0], [0.0, focal_px, (height - 1) / 2.0], [0.0, 0.0, 1.0]]
    )


def _unit(v: np.ndarray, what: str) -> np.ndarray:
    n = float(np.linalg.norm(v))
    if not math.isfinite(n) or n < 1e-12:
        raise AcquisitionError(f"camera: {what} has zero length")
    return v / n


@dataclass(frozen=True)
class PinholeCamera:
    """A centred, square-pixel pinhole camera placed in the world (the scene format's camera).

    Attributes:
        width, height: Image size in pixels.
        focal_px: Focal length in pixels (the same along x and y).
        rotation: 3x3; its columns are OpenCV's camera axes (x right, y down, z forward) in world
            coordinates, so a camera-frame direction ``d`` is ``rotation @ d`` in the world.
        position: The camera centre in world coordinates (metres).
    """

    width: int
    height: int
    focal_px: float
    rotation: np.ndarray
    position: np.ndarray

    # --- conversions ------------------------------------------------------------------------------------

    @classmethod
    def from_scene_camera(cls, camera: dict[str, Any], width: int, height: int) -> PinholeCamera:
        """Build from a scene's ``camera`` dict (position, look_at, up, vfov_deg) and image size."""
        position = np.asarray(camera["position"], dtype=float)
        look_at = np.asarray(camera["look_at"], dtype=float)
        up = np.asarray(camera.get("up", [0.0, 1.0, 0.0]), dtype=float)
        forward = _unit(look_at - position, "look_at - position")
        right = _unit(np.cross(forward, up), "forward x up")
        true_up = np.cross(right, forward)
        rotation = np.column_stack([right, -true_up, forward])
        focal = focal_from_vfov(float(camera["vfov_deg"]), height)
        return cls(int(width), int(height), focal, rotation, position)

    @classmethod
    def from_opencv(
        cls,
        rvec: np.ndarray,
        tvec: np.ndarray,
        focal_px: float,
        width: int,
        height: int,
        world_from_object: np.ndarray | None = None,
        object_origin: np.ndarray | None = None,
    ) -> PinholeCamera:
        """Build from an OpenCV pose (object -> camera) of a centred camera.

        With ``world_from_object`` (3x3 rotation M) and ``object_origin`` (a point o in object
        coordinates), world coordinates are ``M (p_object - o)``.
        """
        r_co, _ = cv2.Rodrigues(np.asarray(rvec, dtype=float).reshape(3))
        t = np.asarray(tvec, dtype=float).reshape(3)
        centre_obj = -r_co.T @ t
        axes_obj = r_co.T  # columns: camera axes in object coordinates
        m = np.eye(3) if world_from_object is None else np.asarray(world_from_object, dtype=float)
        o = np.zeros(3) if object_origin is None else np.asarray(object_origin, dtype=float)
        return cls(int(width), int(height), float(focal_px), m @ axes_obj, m @ (centre_obj - o))

    @property
    def forward(self) -> np.ndarray:
        return self.rotation[:, 2].copy()

    @property
    def right(self) -> np.ndarray:
        return self.rotation[:, 0].copy()

    @property
    def true_up(self) -> np.ndarray:
        return -self.rotation[:, 1]

    @property
    def vfov_deg(self) -> float:
        return vfov_from_focal(self.focal_px, self.height)

    @property
    def camera_matrix(self) -> np.ndarray:
        return centred_camera_matrix(self.focal_px, self.width, self.height)

    def rvec_tvec(self) -> tuple[np.ndarray, np.ndarray]:
        """OpenCV's world -> camera pose (for cv2.projectPoints, cv2.drawFrameAxes)."""
        r_cw = self.rotation.T
        rvec, _ = cv2.Rodrigues(r_cw)
        return rvec.reshape(3), -r_cw @ self.position

    def to_scene_camera(self, look_at: np.ndarray | None = None) -> dict[str, Any]:
        """The scene format's ``camera``: position, look_at, up (the exact image up, so roll is kept),
        vfov_deg. ``look_at`` defaults to where the optical axis meets the floor y=0 when it does
        (in front of the camera, within 100 focal distances), else one metre ahead."""
        f = self.forward
        if look_at is None:
            look_at = self.position + f
            if f[1] < -1e-6:
                s = -self.position[1] / f[1]
                if 0 < s < 1e6:
                    look_at = self.position + s * f
        else:
            look_at = np.asarray(look_at, dtype=float)
            along = float(np.dot(look_at - self.position, f))
            if along <= 0:
                raise AcquisitionError("camera: look_at is behind the camera")
            look_at = self.position + along * f  # keep the optical axis exact
        return {
            "position": [float(v) for v in self.position],
            "look_at": [float(v) for v in look_at],
            "up": [float(v) for v in self.true_up],
            "vfov_deg": float(self.vfov_deg),
        }

    def resized(self, width: int, height: int) -> PinholeCamera:
        """The same camera rendering ``width`` x ``height`` pixels (same field of view)."""
        return PinholeCamera(
            int(width), int(height), self.focal_px * height / self.height, self.rotation, self.position
        )

    # --- geometry ---------------------------------------------------------------------------------------

    def rays(self, uv: np.ndarray) -> np.ndarray:
        """Unit world directions through OpenCV pixel coordinates ``uv`` (N, 2)."""
        uv = np.asarray(uv, dtype=float).reshape(-1, 2)
        d = np.column_stack(
            [
                (uv[:, 0] - (self.width - 1) / 2.0) / self.focal_px,
                (uv[:, 1] - (self.height - 1) / 2.0) / self.focal_px,
                np.ones(len(uv)),
            ]
        )
        d = d @ self.rotation.T
        return d / np.linalg.norm(d, axis=1, keepdims=True)

    def project(self, points: np.ndarray) -> np.ndarray:
        """OpenCV pixel coordinates (N, 2) of world points (N, 3); NaN for points behind the camera."""
        p = (np.asarray(points, dtype=float).reshape(-1, 3) - self.position) @ self.rotation
        with np.errstate(divide="ignore", invalid="ignore"):
            z = np.where(p[:, 2] > 1e-12, p[:, 2], np.nan)
            u = self.focal_px * p[:, 0] / z + (self.width - 1) / 2.0
            v = self.focal_px * p[:, 1] / z + (self.height - 1) / 2.0
        return np.column_stack([u, v])
