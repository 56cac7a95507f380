"""Synthetic photos with known geometry: a ChArUco board seen by a known camera, lens distortion, and
a board composited onto the floor of an rtloop render. Used by the tests, and handy to check a setup
(``rtloop-scene`` on a synthetic photo must give back the camera it was made with)."""

from __future__ import annotations

from typing import Any

import cv2
import numpy as np

from ._common import undistort_points
from .boards import BoardSpec, board_image
from .camera import PinholeCamera
from .pose import WORLD_FROM_BOARD

__all__ = ["board_homography", "board_view", "distort", "paste_board_on_floor"]


def board_homography(
    spec: BoardSpec,
    camera: PinholeCamera,
    px_per_square: int,
    world_from_board: np.ndarray = WORLD_FROM_BOARD,
    board_origin: np.ndarray | None = None,
) -> np.ndarray:
    """Homography from the board image's pixels (``board_image(spec, px_per_square)``) to the camera's.

    The board's point p (board coordinates) is at ``world_from_board @ (p - board_origin)`` in the world
    (by default the board lies on the floor y=0, centred on the origin, as ``estimate_floor_pose`` assumes).
    """
    origin = spec.centre if board_origin is None else np.asarray(board_origin, dtype=float)
    r_cw = camera.rotation.T
    r = r_cw @ world_from_board
    t = -r_cw @ (world_from_board @ origin + camera.position)
    s = spec.square_m / px_per_square
    pixel_to_board = np.array([[s, 0, 0.5 * s], [0, s, 0.5 * s], [0, 0, 1.0]])
    h = camera.camera_matrix @ np.column_stack([r[:, 0], r[:, 1], t]) @ pixel_to_board
    return h / h[2, 2]


def board_view(
    spec: BoardSpec,
    camera: PinholeCamera,
    *,
    background: float = 0.35,
    white: float = 0.8,
    black: float = 0.03,
    supersample: int = 3,
    **placement: Any,
) -> np.ndarray:
    """A linear RGB float image of the board seen by ``camera`` (antialiased by supersampling)."""
    big = camera.resized(camera.width * supersample, camera.height * supersample)
    # Board pixels about as large as the supersampled photo's where the board is nearest.
    px_per_square = 160
    h = board_homography(spec, big, px_per_square, **placement)
    tex = board_image(spec, px_per_square).astype(np.float32) / 255.0
    tex = black + (white - black) * tex
    mask = np.ones_like(tex)
    size = (big.width, big.height)
    warped = cv2.warpPerspective(
        tex, h, size, flags=cv2.INTER_AREA, borderMode=cv2.BORDER_CONSTANT, borderValue=0
    )
    cover = cv2.warpPerspective(
        mask, h, size, flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=0
    )
    img = warped + (1.0 - cover) * background
    small = cv2.resize(img, (camera.width, camera.height), interpolation=cv2.INTER_AREA)
    return np.ascontiguousarray(np.repeat(small[:, :, None], 3, axis=2), dtype=np.float32)


def paste_board_on_floor(
    render: np.ndarray,
    floor_mask: np.ndarray,
    floor_albedo: float,
    spec: BoardSpec,
    camera: PinholeCamera,
    *,
    white: float = 0.85,
    black: float = 0.04,
    supersample: int = 3,
) -> np.ndarray:
    """Lay the board on the floor of an rtloop render: where ``floor_mask`` is true the floor's
    shading (render / floor_albedo) is multiplied by the board's albedo (white or black)."""
    cam = camera.resized(camera.width * supersample, camera.height * supersample)
    px_per_square = 160
    h = board_homography(spec, cam, px_per_square)
    tex = board_image(spec, px_per_square).astype(np.float32) / 255.0
    albedo_tex = black + (white - black) * tex
    size = (cam.width, cam.height)
    warped = cv2.warpPerspective(albedo_tex, h, size, flags=cv2.INTER_AREA, borderValue=0)
    cover = cv2.warpPerspective(np.ones_like(tex), h, size, flags=cv2.INTER_LINEAR, borderValue=0)
    albedo = warped + (1.0 - cover) * floor_albedo
    albedo = cv2.resize(albedo, (camera.width, camera.height), interpolation=cv2.INTER_AREA)
    out = np.array(render, dtype=np.float32, copy=True)
    factor = (albedo / floor_albedo)[:, :, None]
    out = np.where(floor_mask[:, :, None], out * factor, out)
    return out.astype(np.float32)


def distort(image: np.ndarray, camera_matrix: np.ndarray, dist_coeffs: np.ndarray) -> np.ndarray:
    """What a lens with ``dist_coeffs`` makes of the ideal pinhole image ``image`` (same K).

    The source position of every output pixel is computed on a grid 4 pixels apart and interpolated.
    """
    h, w = image.shape[:2]
    step = 4
    gh, gw = -(-h // step) + 1, -(-w // step) + 1
    ys, xs = np.mgrid[0:gh, 0:gw].astype(np.float64) * step + (step - 1) / 2.0
    ideal = undistort_points(
        np.stack([xs.ravel(), ys.ravel()], axis=1), camera_matrix, dist_coeffs, camera_matrix
    )
    ideal = ideal.reshape(gh, gw, 2).astype(np.float32)
    fine = cv2.resize(ideal, (gw * step, gh * step), interpolation=cv2.INTER_LINEAR)[:h, :w]
    return cv2.remap(
        image,
        np.ascontiguousarray(fine[:, :, 0]),
        np.ascontiguousarray(fine[:, :, 1]),
        cv2.INTER_LINEAR,
        borderMode=cv2.BORDER_REPLICATE,
    )
