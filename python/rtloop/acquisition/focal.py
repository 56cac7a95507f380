"""The field of view of a photo without EXIF, refined from the ball resting on the floor: where the board
alone fixes it loosely, each field of view within REACH_SIGMAS of the board's estimate poses the camera on
the board and places a ball of the known radius resting on that floor; the outline such a ball projects
fits the photo's edges best at the true field of view (a wrong one makes the resting ball's outline too
large or too small, too high or too low, for its place on the floor). The refined field of view is the
minimum of the outline's RMS residual over a grid, by a parabola through the best three. Where the ball is
not found at the board's estimate (a board seen nearly face-on fixes the field of view worst of all), the
fields of view of a wide geometric grid are tried first (:func:`scan_vfov_for_ball`) and the refinement is
centred on the one whose outline fits best. docs/acquisition.md, "No EXIF"."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from ._common import AcquisitionError
from .ball import locate_ball
from .camera import focal_from_vfov
from .pose import FloorPose, estimate_floor_pose

__all__ = ["REACH_SIGMAS", "FocalRefinement", "field_of_view_record", "refine_vfov_by_ball", "scan_vfov_for_ball"]

#: The grid reaches this many of the board's standard deviations either side of its estimate, at most
#: REACH_MAX_DEG, in steps of a third of a standard deviation (at least STEP_MIN_DEG).
REACH_SIGMAS = 3.0
REACH_MAX_DEG = 8.0
STEP_MIN_DEG = 0.2
#: Where the ball is not found at the board's estimate: the fields of view tried, a geometric grid from
#: SCAN_FROM_DEG to SCAN_TO_DEG in steps of SCAN_RATIO (12 of them: a lens from a long telephoto to a
#: wide phone camera).
SCAN_FROM_DEG = 8.0
SCAN_TO_DEG = 100.0
SCAN_RATIO = 1.25


@dataclass
class FocalRefinement:
    """The refined field of view and what gave it: ``grid`` (vfov deg, outline RMS px) per field of view
    tried where a ball was found."""

    vfov_deg: float
    board_vfov_deg: float
    board_std_deg: float
    grid: list[tuple[float, float]]

    def to_dict(self) -> dict[str, Any]:
        return {"vfov_deg": self.vfov_deg, "board_vfov_deg": self.board_vfov_deg, "board_std_deg": self.board_std_deg,
                "grid": [[round(v, 4), round(r, 4)] for v, r in self.grid]}


def refine_vfov_by_ball(photo: np.ndarray, spec: Any, radius: float, pose: FloorPose, hint: tuple[float, float, float],
                        *, locate: dict[str, Any], where: str, centre: float | None = None) -> FocalRefinement | None:
    """The vertical field of view at which a ball of ``radius`` resting on the floor the board gives best
    fits the photo's outline (``hint``: the ball's centre and radius in pixels found at the board's
    estimate, or at ``centre`` where given: the grid is then centred there; ``locate``:
    :func:`locate_ball`'s other keyword arguments). None where fewer than three fields of view found the
    ball."""
    h = photo.shape[0]
    board, std = pose.camera.vfov_deg, float(pose.vfov_std_deg or 0.0)
    v0 = board if centre is None else float(centre)
    reach = min(REACH_SIGMAS * std, REACH_MAX_DEG)
    step = max(std / 3.0, STEP_MIN_DEG)
    n = max(1, int(math.floor(reach / step)))
    grid: list[tuple[float, float]] = []
    for k in range(-n, n + 1):
        v = v0 + k * step
        if not 3.0 <= v <= 150.0:
            continue
        try:
            p = estimate_floor_pose(photo, spec, focal_px=focal_from_vfov(v, h), focal_source="board", where=where)
            silhouette, _ = locate_ball(photo, p.camera, radius, hint=hint, where=where, **locate)
        except AcquisitionError:
            continue
        if math.isfinite(silhouette.rms_px):
            grid.append((v, float(silhouette.rms_px)))
    if len(grid) < 3:
        return None
    vs, rs = np.array([g[0] for g in grid]), np.array([g[1] for g in grid])
    i = int(np.argmin(rs))
    best = float(vs[i])
    if 0 < i < len(vs) - 1:  # a parabola through the best and its neighbours
        a, b, _ = np.polyfit(vs[i - 1:i + 2], rs[i - 1:i + 2] ** 2, 2)
        if a > 0:
            best = float(np.clip(-b / (2 * a), vs[i - 1], vs[i + 1]))
    return FocalRefinement(best, board, std, grid)


def scan_vfov_for_ball(photo: np.ndarray, spec: Any, radius: float, *, locate: dict[str, Any],
                       where: str) -> tuple[float, tuple[float, float, float]] | None:
    """The field of view, of the geometric grid SCAN_FROM_DEG to SCAN_TO_DEG, at which a ball of ``radius``
    resting on the floor the board gives is found with the best-fitting outline, and that outline (centre
    and radius in pixels); None where it is found at none. For a photo whose ball is not found at the
    board's own estimate."""
    h = photo.shape[0]
    best: tuple[float, float, tuple[float, float, float]] | None = None
    v = SCAN_FROM_DEG
    while v <= SCAN_TO_DEG * (1 + 1e-9):
        try:
            pose = estimate_floor_pose(photo, spec, focal_px=focal_from_vfov(v, h), focal_source="board", where=where)
            silhouette, _ = locate_ball(photo, pose.camera, radius, where=where, **locate)
        except AcquisitionError:
            silhouette = None
        if silhouette is not None and math.isfinite(silhouette.rms_px) and (best is None or silhouette.rms_px < best[1]):
            found = (float(silhouette.centre_px[0]), float(silhouette.centre_px[1]), float(silhouette.radius_px))
            best = (v, float(silhouette.rms_px), found)
        v *= SCAN_RATIO
    return None if best is None else (best[0], best[2])


def field_of_view_record(photo: np.ndarray, spec: Any, radius: float, vfov_deg: float, std_deg: float,
                         hint: tuple[float, float, float], ball_name: str, *, locate: dict[str, Any],
                         where: str) -> dict[str, Any]:
    """``meta.acquisition.field_of_view`` of a scene whose field of view the board gave (no EXIF, no
    --vfov): the one used and the board's standard deviation, and the scene as rtloop-scene builds it at one
    standard deviation either side (``alternates``: the camera and the ball's centre, posed on the board and
    placed on the floor at that field of view), from which rtloop-fit carries the field of view's uncertainty
    into the light's error bars. Without alternates (``why``) where the ball is not found at either side."""
    record: dict[str, Any] = {"vfov_deg": float(vfov_deg), "std_deg": float(std_deg), "alternates": []}
    h = photo.shape[0]
    for v in (vfov_deg - std_deg, vfov_deg + std_deg):
        try:
            if not 3.0 <= v <= 150.0:
                raise AcquisitionError(f"a field of view of {v:.2f} deg is outside 3-150 deg")
            pose = estimate_floor_pose(photo, spec, focal_px=focal_from_vfov(v, h), focal_source="board", where=where)
            _, sphere = locate_ball(photo, pose.camera, radius, hint=hint, where=where, **locate)
        except AcquisitionError as e:
            record["alternates"] = []
            record["why"] = f"at {v:.2f} deg: {' '.join(str(e).split())}"
            return record
        record["alternates"].append({"vfov_deg": float(v), "camera": pose.camera.to_scene_camera(),
                                     "objects": {ball_name: {"center": [float(c) for c in sphere.centre]}}})
    return record
