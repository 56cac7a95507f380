"""The field of view of a photo without EXIF, refined from the ball resting on the floor: where the board
alone fixes it loosely, each field of view within REACH_SIGMAS of the board's estimate poses the camera on
the board and places a ball of the known radius resting on that floor; the outline such a ball projects
fits the photo's edges best at the true field of view (a wrong one makes the resting ball's outline too
large or too small, too high or too low, for its place on the floor). The refined field of view is the
minimum of the outline's RMS residual over a grid, by a parabola through the best three. Where the ball is
not found at the board's estimate (a board seen nearly face-on fixes the field of view worst of all), the
fields of view of a wide geometric grid are tried first (:func:`scan_vfov_for_ball`) and the refinement is
centred on the one whose outline fits best; so too where the grid at the board's estimate has no minimum
inside it (:func:`refine_or_rescan`). docs/acquisition.md, "The field of view"."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from ._common import AcquisitionError
from .ball import BallSilhouette, SpherePlacement, locate_ball
from .camera import focal_from_vfov
from .overlay import _board_outline_px
from .pose import VFOV_TARGET_DEG, FloorPose, estimate_floor_pose

__all__ = ["REACH_SIGMAS", "FocalRefinement", "field_of_view_record", "loose_view_warning",
           "refine_field_of_view", "refine_or_rescan", "refine_vfov_by_ball", "scan_vfov_for_ball"]

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

    @property
    def bracketed(self) -> bool:
        """Whether the best outline has a field of view tried on either side of it (else the minimum may
        lie beyond the grid)."""
        i = min(range(len(self.grid)), key=lambda k: self.grid[k][1])
        return 0 < i < len(self.grid) - 1

    @property
    def best_rms_px(self) -> float:
        return min(r for _, r in self.grid)

    def to_dict(self) -> dict[str, Any]:
        return {"vfov_deg": self.vfov_deg, "board_vfov_deg": self.board_vfov_deg, "board_std_deg": self.board_std_deg,
                "grid": [[round(v, 4), round(r, 4)] for v, r in self.grid]}


def loose_view_warning(where: str, vfov_deg: float, vfov_std_deg: float, focal_px: float, height: int) -> str:
    """One line for a field of view the board fixes more loosely than ``VFOV_TARGET_DEG``: its spread and
    the resulting spread of the focal length, which scales every distance the board's size gives (the
    camera's, and so the ball's and the light's)."""
    # d f / f = d vfov * (f^2 + h^2 / 4) / (f h)
    rel = math.radians(vfov_std_deg) * (focal_px**2 + height**2 / 4) / (focal_px * height)
    return (f"{where} has no EXIF focal length and the board fixes the vertical field of view only to "
            f"{vfov_deg:.2f} +- {vfov_std_deg:.2f} deg ({VFOV_TARGET_DEG:g} wanted): the focal length, and with it "
            f"the distances from the camera (the ball's, the light's), are uncertain by about +-{100 * rel:.1f} %; "
            "give --vfov or --camera, or pass --strict to refuse such a view")


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


def refine_or_rescan(photo: np.ndarray, spec: Any, radius: float, pose: FloorPose,
                     hint: tuple[float, float, float], scanned: tuple[float, Any] | None, *,
                     locate: dict[str, Any],
                     where: str) -> tuple[FocalRefinement | None, tuple[float, Any] | None]:
    """:func:`refine_vfov_by_ball` centred on the board's estimate (or on ``scanned``'s field of view where
    given: ``(vfov, outline)`` from :func:`scan_vfov_for_ball`). Where the board's estimate gives no
    minimum inside its grid (the best outline at the grid's end, or too few found: a board seen nearly
    face-on can be far off and still show a poorer outline there), the wide scan is tried too and its
    refinement kept where its best outline fits better. Returns the refinement and the scan used (or
    None)."""
    centre = None if scanned is None else scanned[0]
    refinement = refine_vfov_by_ball(photo, spec, radius, pose, hint, locate=locate, where=where,
                                     centre=centre)
    if scanned is not None or (refinement is not None and refinement.bracketed):
        return refinement, scanned
    rescanned = scan_vfov_for_ball(photo, spec, radius, locate=locate, where=where)
    if rescanned is None:
        return refinement, None
    again = refine_vfov_by_ball(photo, spec, radius, pose, rescanned[1], locate=locate, where=where,
                                centre=rescanned[0])
    if again is not None and (refinement is None or again.best_rms_px < refinement.best_rms_px):
        return again, rescanned
    return refinement, None


def refine_field_of_view(
    photo: np.ndarray,
    spec: Any,
    ball_radius: float,
    pose: FloorPose,
    silhouette: BallSilhouette | None,
    sphere: SpherePlacement | None,
    locate: dict[str, Any],
    focal_source: str,
    where: str,
    notes: list[str],
    h: int,
    scanned: tuple[float, Any] | None = None,
) -> tuple[FloorPose, BallSilhouette, SpherePlacement, Any]:
    """Step 4b, the field of view: when the board alone fixes it loosely (``focal_source`` "board", a spread
    over ``VFOV_TARGET_DEG``), refined from the ball resting on the floor (the grid centred where
    ``scanned`` found it, if given); the pose and the ball again at the refined focal length
    (``locate["exclude"]`` updated) and the field-of-view note replaced in ``notes``. Returns the pose, the
    ball and the refinement (None when not refined, and then the rest as given)."""
    if not (focal_source == "board" and (pose.vfov_std_deg or 0.0) > VFOV_TARGET_DEG):
        return pose, silhouette, sphere, None
    found = scanned[1] if scanned is not None else (
        float(silhouette.centre_px[0]), float(silhouette.centre_px[1]), float(silhouette.radius_px))
    refinement, scanned = refine_or_rescan(photo, spec, ball_radius, pose, found, scanned, locate=locate,
                                           where=where)
    found = scanned[1] if scanned is not None else found
    chosen = refinement.vfov_deg if refinement is not None else None if scanned is None else scanned[0]
    if chosen is not None:
        std, board_vfov = pose.vfov_std_deg, pose.camera.vfov_deg
        pose = estimate_floor_pose(photo, spec, focal_px=focal_from_vfov(chosen, h), focal_source="board",
                                   where=where)
        pose.vfov_std_deg = std
        locate["exclude"] = _board_outline_px(pose)
        silhouette, sphere = locate_ball(photo, pose.camera, ball_radius, hint=found, where=where, **locate)
        how = "refined from the ball resting on the floor to" if refinement is not None else (
            "the ball resting on the floor found best at")
        found_where = "" if scanned is None else (
            ", the ball not found, or found worse, near the board's estimate")
        notes[:] = [n for n in notes if "no EXIF focal length" not in n]
        notes.append(loose_view_warning(where, board_vfov, std, pose.camera.focal_px, h)
                     .replace("; give --vfov", f"; {how} {chosen:.2f} deg (where its outline fits best)"
                              f"{found_where}; give --vfov"))
    return pose, silhouette, sphere, refinement


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
