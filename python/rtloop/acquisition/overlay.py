"""The overlay :func:`rtloop.acquisition.build.build_scene` draws for checking the alignment: the board's
corners, outline and world axes, the ball's edge points and fitted outline, and the ball as rtloop renders
the scene, over the photo."""

from __future__ import annotations

from typing import Any

import cv2
import numpy as np

import rtloop

from ._common import to_display_bgr8
from .ball import BallSilhouette, silhouette_polyline
from .pose import FloorPose

__all__ = ["OVERLAY_MAX_SIDE", "draw_overlay"]

#: Longest side of the overlay image (pixels); larger photos are drawn scaled down.
OVERLAY_MAX_SIDE = 1600


def _board_outline_px(pose: FloorPose) -> np.ndarray:
    bw, bh = pose.board.size_m
    corners = np.array([[0, 0, 0], [bw, 0, 0], [bw, bh, 0], [0, bh, 0]], dtype=float)
    return pose.camera.project(pose.board_to_world(corners))


def draw_overlay(
    photo: np.ndarray,
    scene: dict[str, Any],
    pose: FloorPose,
    silhouette: BallSilhouette,
) -> np.ndarray:
    """The photo with the board's corners, outline and world axes, the ball's edge points and fitted
    outline, and the ball's outline as rendered from ``scene`` (rtloop.object_ids)."""
    h, w = photo.shape[:2]
    scale = min(1.0, OVERLAY_MAX_SIDE / max(w, h))
    ow, oh = max(1, round(w * scale)), max(1, round(h * scale))
    out = _overlay_background(photo, scale, ow, oh)
    sx, sy = ow / w, oh / h
    lw = max(1, round(max(ow, oh) / 800))

    def px(points: np.ndarray) -> np.ndarray:
        p = np.asarray(points, dtype=float).reshape(-1, 2)
        q = np.column_stack([(p[:, 0] + 0.5) * sx - 0.5, (p[:, 1] + 0.5) * sy - 0.5])
        return np.round(q * 16).astype(np.int32)  # 4 fractional bits for cv2's shift=4

    # Rendered silhouette of the scene's ball (what rtloop will render); drawn last, below.
    ids = rtloop.object_ids(scene, ow, oh)
    ball_index = next(i for i, o in enumerate(scene["objects"]) if o["shape"] == "sphere")
    ball_region = (ids == ball_index).astype(np.uint8)
    contours, _ = cv2.findContours(ball_region, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)

    _draw_board(out, pose, px, lw)
    # Ball: the edge points used and the fitted outline.
    for p in px(silhouette.edge_points):
        cv2.circle(out, tuple(int(v) for v in p), 16 * lw, (0, 0, 255), -1, cv2.LINE_AA, shift=4)
    cv2.polylines(
        out, [px(silhouette_polyline(silhouette, 360))], True, (255, 255, 0), lw, cv2.LINE_AA, shift=4
    )
    _draw_rendered_outline(out, contours, lw)
    _draw_legend(out, lw)
    return out


def _overlay_background(photo: np.ndarray, scale: float, ow: int, oh: int) -> np.ndarray:
    """The photo scaled to (ow, oh) for drawing on, brightened when dark, as 8-bit BGR."""
    img = cv2.resize(photo, (ow, oh), interpolation=cv2.INTER_AREA) if scale < 1 else photo
    lum = img @ np.array([0.2126, 0.7152, 0.0722], dtype=np.float32)
    top = float(np.percentile(lum, 99.0))
    if 0 < top < 0.5:
        img = img * (0.8 / top)  # brighten a dark photo, for seeing only
    return to_display_bgr8(img)


def _draw_board(out: np.ndarray, pose: FloorPose, px: Any, lw: int) -> None:
    """Board: outline, corners found, world axes at the origin (x red, y = up green, z blue); ``px`` maps
    photo pixels to the overlay's fixed-point pixels."""
    cam = pose.camera
    outline = _board_outline_px(pose)
    cv2.polylines(out, [px(outline)], True, (0, 255, 255), lw, cv2.LINE_AA, shift=4)
    for p in px(pose.detection.image_points):
        cv2.circle(out, tuple(int(v) for v in p), 3 * 16 * lw // 2, (0, 200, 0), lw, cv2.LINE_AA, shift=4)
    length = 0.5 * min(pose.board.size_m)
    axes = cam.project(np.array([[0, 0, 0], [length, 0, 0], [0, length, 0], [0, 0, length]], dtype=float))
    if np.isfinite(axes).all():
        o = tuple(int(v) for v in px(axes[0])[0])
        for end, colour, label in (
            (axes[1], (0, 0, 255), "x"),
            (axes[2], (0, 255, 0), "y (up)"),
            (axes[3], (255, 0, 0), "z"),
        ):
            e = tuple(int(v) for v in px(end)[0])
            cv2.arrowedLine(out, o, e, colour, 2 * lw, cv2.LINE_AA, shift=4, tipLength=0.15)
            cv2.putText(
                out,
                label,
                (e[0] // 16 + 4, e[1] // 16 - 4),
                cv2.FONT_HERSHEY_SIMPLEX,
                0.5 * lw,
                colour,
                lw,
                cv2.LINE_AA,
            )


def _draw_rendered_outline(out: np.ndarray, contours: Any, lw: int) -> None:
    """The rendered outline, dashed and drawn last, so the fitted outline under it stays visible."""
    for contour in contours:
        pts = contour.reshape(-1, 2)
        dash = max(4, 6 * lw)
        for start in range(0, len(pts), 2 * dash):
            seg = pts[start : start + dash + 1]
            if len(seg) > 1:
                cv2.polylines(out, [seg.reshape(-1, 1, 2)], False, (255, 0, 255), lw + 1, cv2.LINE_AA)


def _draw_legend(out: np.ndarray, lw: int) -> None:
    """The legend in the top left corner, on a darkened box."""
    legend = [
        ("board corners found", (0, 200, 0)),
        ("board outline (from the pose)", (0, 255, 255)),
        ("ball edge points", (0, 0, 255)),
        ("ball outline fitted", (255, 255, 0)),
        ("ball as rtloop renders the scene (dashed)", (255, 0, 255)),
    ]
    font, size = cv2.FONT_HERSHEY_SIMPLEX, 0.5 * lw
    box_w = max(cv2.getTextSize(text, font, size, lw)[0][0] for text, _ in legend) + 12 * lw
    box = out[: 18 * lw * len(legend) + 8 * lw, :box_w]
    box[:] = (box * 0.35).astype(np.uint8)  # darken behind the legend
    y = 18 * lw
    for text, colour in legend:
        cv2.putText(out, text, (6 * lw, y), font, size, colour, lw, cv2.LINE_AA)
        y += 18 * lw
