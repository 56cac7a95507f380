"""The sphere in the world: :func:`place_sphere` fits its centre to an outline's edge rays (resting on the
floor or free), :func:`locate_ball` searches the floor position whose predicted outline lies on edges."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import cv2
import numpy as np

from .._common import AcquisitionError, check_image
from ..camera import PinholeCamera
from .cone import BallSilhouette, _cone_points, _gauss_newton, _project_cam, _rays_cam
from .edges import MIN_EDGE_POINTS, _edge_image, _edges_across, _OutlineScore, _refine
from .search import _NO_BALL_HELP, _checked_hint, _pattern_search, _seeds
from .shading import sphere_likeness
from .working import Working, working_size

#: Least outline score (mean edge support along the predicted outline, 0..1) for a ball to be accepted.
MIN_OUTLINE_SCORE = 0.4


@dataclass
class SpherePlacement:
    """The sphere placed in the world."""

    centre: np.ndarray
    radius: float
    resting: bool
    rms_px: float
    height_above_floor: float  # of the centre, in metres (= radius when resting)

    def report(self) -> dict[str, Any]:
        return {
            "centre": [float(v) for v in self.centre],
            "radius": self.radius,
            "resting_on_floor": self.resting,
            "fit_rms_px": self.rms_px,
            "centre_height_m": self.height_above_floor,
        }


def _world_model(camera: PinholeCamera, radius: float, height: float | None):
    """Residual function (params, camera-frame rays) -> angle off the outline, for a sphere whose centre
    is (x, height, z) (``height`` given: resting) or (x, y, z)."""
    c = camera.position
    r_cw = camera.rotation.T

    def centre_of(p: np.ndarray) -> np.ndarray:
        return np.array([p[0], height, p[1]]) if height is not None else np.asarray(p, dtype=float)

    def model(p: np.ndarray, rays: np.ndarray) -> np.ndarray:
        v = r_cw @ (centre_of(p) - c)
        d = float(np.linalg.norm(v))
        if d <= radius * 1.0001:
            return np.full(len(rays), 10.0)
        return np.arccos(np.clip(rays @ (v / d), -1.0, 1.0)) - math.asin(radius / d)

    return model, centre_of


def _cone_of_centre(camera: PinholeCamera, centre: np.ndarray, radius: float) -> tuple[np.ndarray, float]:
    v = camera.rotation.T @ (centre - camera.position)
    d = float(np.linalg.norm(v))
    return v / d, math.asin(min(1.0, radius / d))


def place_sphere(
    silhouette: BallSilhouette,
    camera: PinholeCamera,
    radius: float,
    *,
    resting: bool = True,
    floor_height: float = 0.0,
    where: str = "photo",
) -> SpherePlacement:
    """The sphere's centre in the world from its outline, the camera, its radius and the floor.

    Args:
        silhouette: from :func:`find_ball` or :func:`locate_ball`, found in the image ``camera``
            describes (same size).
        camera: the posed camera (from ``estimate_floor_pose``).
        radius: the ball's radius in metres (measure it: circumference / 2 pi).
        resting: the ball lies on the floor plane ``y = floor_height`` (centre ``radius`` above it);
            False fits the centre freely in 3-D.

    Raises:
        AcquisitionError: bad radius, a photo of another size, or no solution in front of the camera.
    """
    _check_radius(radius)
    if (silhouette.width, silhouette.height) != (camera.width, camera.height):
        raise AcquisitionError(
            f"{where}: the ball was found in a {silhouette.width}x{silhouette.height} image but the camera "
            "is "
            f"{camera.width}x{camera.height}; use the same (undistorted) photo for both"
        )
    f = camera.focal_px
    rays = _rays_cam(silhouette.edge_points, f, camera.width, camera.height)
    c = camera.position
    u = camera.rotation @ silhouette.axis
    free_guess = c + radius / math.sin(silhouette.alpha) * u
    height = floor_height + radius
    if resting:
        guess = free_guess
        if abs(u[1]) > 1e-3:
            t = (height - c[1]) / u[1]
            if t > radius:
                guess = c + t * u
        model, centre_of = _world_model(camera, radius, height)
        p = _gauss_newton(lambda q: model(q, rays), np.array([guess[0], guess[2]]))
    else:
        model, centre_of = _world_model(camera, radius, None)
        p = _gauss_newton(lambda q: model(q, rays), free_guess)
    centre = centre_of(p)
    if np.dot(centre - c, camera.forward) <= radius:
        raise AcquisitionError(
            f"{where}: the ball's fitted centre is behind the camera; check --ball-radius and the board"
        )
    rms = float(np.sqrt(np.mean((model(p, rays) * f) ** 2)))
    return SpherePlacement(centre, float(radius), resting, rms, float(centre[1] - floor_height))


def _check_radius(radius: float) -> None:
    if not (isinstance(radius, (int, float)) and math.isfinite(radius) and radius > 0):
        raise AcquisitionError(f"ball radius must be > 0 metres (got {radius}); give it with --ball-radius")


def locate_ball(
    image: np.ndarray,
    camera: PinholeCamera,
    radius: float,
    *,
    hint: tuple[float, float, float] | None = None,
    mask: np.ndarray | None = None,
    resting: bool = True,
    floor_height: float = 0.0,
    exclude: np.ndarray | None = None,
    keep_off: tuple[float, float, float, float] | None = None,
    where: str = "photo",
) -> tuple[BallSilhouette, SpherePlacement]:
    """Find the ball of known radius resting on the floor, seen by a posed camera, and place it.

    Every candidate (Hough circles, or the hint, or the mask's outline) only seeds a search over the
    ball's position on the floor: for each position the outline is predicted exactly (its size follows
    from the distance) and scored by how well it lies on colour edges of the photo; each seed gives an
    outline from a coarse-to-fine search and one from a fine search alone. Of the outlines on enough edges
    (``MIN_OUTLINE_SCORE``), the ball is the one whose inside is best explained as a shaded sphere rather
    than floor (:func:`rtloop.acquisition.ball.shading.sphere_likeness`): its own shadow is a crisp,
    ball-sized outline too, seen from above on a stronger edge, but holds floor. The chosen position is then
    refined by least squares on the edge points along the outline. With ``resting=False`` a last fit frees
    the centre's height. A photo larger than :data:`.working.WORK_SIDE` pixels is searched in a copy of that
    size, and the outline refined on the photo itself.

    Args:
        hint, mask: as for :func:`find_ball` (seed the search there instead of Hough circles).
        exclude: a polygon (N, 2) in pixels where Hough candidates are ignored.
        keep_off: a floor rectangle ``(x_min, x_max, z_min, z_max)`` (world metres) the ball's contact
            point cannot be in: the board (whose pattern is full of edges).

    Returns:
        The outline (a :class:`BallSilhouette`) and the placed sphere (:class:`SpherePlacement`).

    Raises:
        AcquisitionError: no outline consistent with a resting ball of this radius was found.
    """
    image = check_image(image, where)
    _check_radius(radius)
    h, w = image.shape[:2]
    if (w, h) != (camera.width, camera.height):
        raise AcquisitionError(
            f"{where}: photo is {w}x{h} but the camera was posed on a {camera.width}x{camera.height} image; "
            "use the same (undistorted) photo for the board and the ball"
        )
    size = working_size(w, h)
    if size is None:
        feat = _edge_image(image)
        p, source, info = _search(image, feat, camera, radius, hint, mask, floor_height, exclude, keep_off, where)
        return _finish(feat, camera, radius, p, source, info, resting, floor_height, where)
    # A large photo: searched in a smaller copy, the outline then refined on the photo.
    work = Working((w, h), size)
    small = work.image(image)
    small_feat, small_camera = _edge_image(small), camera.resized(*size)
    p, source, info = _search(
        small, small_feat, small_camera, radius,
        work.hint(None if hint is None else _checked_hint(hint, h, w, where)), work.mask(mask, where),
        floor_height, work.polygon(exclude), keep_off, where,
    )
    # Refined on the copy's edges first (a pixel of the copy is several of the photo's: the photo's
    # edges are then taken within as many pixels of the outline, and the fit tightens from there).
    q, edges, chosen = _refined(small_feat, small_camera, radius, p, floor_height, 1.5)
    if edges is not None and len(chosen) >= MIN_EDGE_POINTS:
        p = q
    return _finish(_edge_image(image), camera, radius, p, source, info, resting, floor_height, where,
                   tol=1.5 * max(work.sx, work.sy))


def _search(
    image: np.ndarray,
    feat: np.ndarray,
    camera: PinholeCamera,
    radius: float,
    hint: tuple[float, float, float] | None,
    mask: np.ndarray | None,
    floor_height: float,
    exclude: np.ndarray | None,
    keep_off: tuple[float, float, float, float] | None,
    where: str,
) -> tuple[np.ndarray, str, dict[str, Any]]:
    """:func:`locate_ball`'s search: the ball's floor position (x, z), the source of its seed, and the
    scores that chose it."""
    h, w = image.shape[:2]
    f = camera.focal_px
    score = _OutlineScore(feat)
    height = floor_height + radius
    model, centre_of = _world_model(camera, radius, height)

    def outline(p: np.ndarray, n: int = 120) -> np.ndarray | None:
        centre = centre_of(p)
        if keep_off is not None and keep_off[0] <= p[0] <= keep_off[1] and keep_off[2] <= p[1] <= keep_off[3]:
            return None
        if np.dot(centre - camera.position, camera.forward) <= radius * 1.01:
            return None
        axis, alpha = _cone_of_centre(camera, centre, radius)
        rays = _cone_points(axis, alpha, n)
        if np.any(rays[:, 2] <= 1e-3):
            return None
        return _project_cam(rays, f, w, h)

    def value(p: np.ndarray, tol: float, cap: float = 1.0) -> float:
        poly = outline(p)
        return -1.0 if poly is None else score(poly, tol, cap)

    seeds = _seeds(image, feat, hint, mask, exclude, where)
    starts = _floor_starts(seeds, camera, radius, height, where)
    # Coarse screening with a wide tolerance, then a pattern search on the best few.
    ranked = []
    for p0, r_px, src in starts:
        poly = outline(p0)
        if poly is None:
            continue
        pred_r = math.sqrt(abs(cv2.contourArea(poly.astype(np.float32))) / math.pi)
        ranked.append((value(p0, max(2.0, 0.25 * pred_r)), p0, pred_r, src))
    ranked.sort(key=lambda item: -item[0])
    hypotheses = []  # (outline score, floor position, source)
    for _, p0, pred_r, src in ranked[:4]:
        metres_per_px = float(np.linalg.norm(centre_of(p0) - camera.position)) / f
        # (tolerance, step) in pixels
        coarse_to_fine = ((0.25 * pred_r, 0.25 * pred_r), (0.08 * pred_r, 0.06 * pred_r), (1.0, 0.5))
        # From each seed twice: coarse to fine (a seed off the ball), and fine only (a seed on the ball,
        # which the coarse stages can carry onto the stronger edge of its shadow beside it).
        for stages in (coarse_to_fine, coarse_to_fine[-1:]):
            p = p0
            for tol_px, step_px in stages:
                tol_px = max(tol_px, 1.0)
                p, v = _pattern_search(
                    lambda q, t=tol_px: value(q, t), p, max(step_px, 0.25) * metres_per_px, 0.1 * metres_per_px
                )
            # Last, uncapped: among outlines on edges everywhere, the one on the strongest (the true outline
            # rather than shading just inside it).
            p, _ = _pattern_search(lambda q: value(q, 1.0, 100.0), p, 0.5 * metres_per_px, 0.05 * metres_per_px)
            hypotheses.append((v, p, src))
    # Of the outlines that lie on edges, the ball is the one whose inside looks most like a shaded sphere
    # rather than floor: its own shadow is an outline on edges too (seen from above, on a stronger one), but
    # holds flat floor, or floor with the ball's outline across it.
    return _most_sphere_like(image, camera, radius, centre_of, hypotheses, where)


def _floor_starts(
    seeds: list[tuple[float, float, float, str]],
    camera: PinholeCamera,
    radius: float,
    height: float,
    where: str,
) -> list[tuple[np.ndarray, float, str]]:
    """Each seed circle's centre taken to the floor position (x, z) where a ball's centre at ``height``
    would be, in front of the camera: ``(position, radius in pixels (at least 3), source)``."""
    starts = []
    for cx, cy, r_px, _src in seeds:
        ray = camera.rays(np.array([[cx, cy]]))[0]
        if abs(ray[1]) < 1e-6:
            continue
        t = (height - camera.position[1]) / ray[1]
        if t <= radius:
            continue
        start = camera.position + t * ray
        starts.append((np.array([start[0], start[2]]), max(r_px, 3.0), _src))
    if not starts:
        raise AcquisitionError(
            f"{where}: no ball found (no candidate circle on the floor in front of the camera); "
            f"{_NO_BALL_HELP}"
        )
    return starts


def _most_sphere_like(
    image: np.ndarray,
    camera: PinholeCamera,
    radius: float,
    centre_of: Any,
    hypotheses: list[tuple[float, np.ndarray, str]],
    where: str,
) -> tuple[np.ndarray, str, dict[str, Any]]:
    """Of the distinct hypotheses ``(outline score, floor position, source)`` whose outlines lie on edges,
    the one whose inside looks most like a shaded sphere: its floor position, source and scores."""
    accepted = []
    for v, p, src in hypotheses:
        if v >= MIN_OUTLINE_SCORE and not any(np.linalg.norm(p - q) < 0.05 * radius for _, _, q, _ in accepted):
            accepted.append((sphere_likeness(image, camera, centre_of(p), radius), v, p, src))
    if not accepted:
        best_v = max((v for v, _, _ in hypotheses), default=0.0)
        raise AcquisitionError(
            f"{where}: no ball of radius {radius:g} m resting on the floor found (best outline matched "
            f"{best_v:.0%} of edges); check --ball-radius (metres) and "
            f"{_NO_BALL_HELP}"
        )
    likeness, outline_score, p, source = max(accepted, key=lambda item: item[0])
    return p, source, {"outline_score": outline_score, "sphere_likeness": likeness, "hypotheses": len(accepted)}


def _finish(
    feat: np.ndarray,
    camera: PinholeCamera,
    radius: float,
    p: np.ndarray,
    source: str,
    info: dict[str, Any],
    resting: bool,
    floor_height: float,
    where: str,
    tol: float = 1.5,
) -> tuple[BallSilhouette, SpherePlacement]:
    """The found floor position ``p`` refined by least squares on the edge points across its outline in
    ``feat`` (the edge image of the photo ``camera`` sees; first those within ``tol`` pixels of it), and
    the sphere placed."""
    h, w = feat.shape[:2]
    f = camera.focal_px
    model, centre_of = _world_model(camera, radius, floor_height + radius)
    p, edges, chosen = _refined(feat, camera, radius, p, floor_height, tol)
    if edges is None or len(chosen) < MIN_EDGE_POINTS:
        raise AcquisitionError(f"{where}: the ball's outline has too few sharp edge points; {_NO_BALL_HELP}")
    points = edges.points[chosen]
    if resting:
        centre = centre_of(p)
    else:
        free_model, free_centre = _world_model(camera, radius, None)
        centre = free_centre(_gauss_newton(lambda q: free_model(q, edges.rays[chosen]), centre_of(p)))
    axis, alpha = _cone_of_centre(camera, centre, radius)
    res = (np.arccos(np.clip(edges.rays[chosen] @ axis, -1, 1)) - alpha) * f
    rms = float(np.sqrt(np.mean(res**2)))
    final = BallSilhouette(
        axis, alpha, f, w, h, points, rms, len(chosen) / edges.k, source, info,
    )
    placement = SpherePlacement(centre, float(radius), resting, rms, float(centre[1] - floor_height))
    return final, placement


def _refined(
    feat: np.ndarray, camera: PinholeCamera, radius: float, p: np.ndarray, floor_height: float, tol: float
) -> tuple[np.ndarray, Any, np.ndarray]:
    """The resting ball's floor position ``p`` refined on the edge points across its outline within ``tol``
    pixels (:func:`.edges._refine`), the edge candidates (None: none) and the indices of those used."""
    h, w = feat.shape[:2]
    f = camera.focal_px
    model, centre_of = _world_model(camera, radius, floor_height + radius)
    axis, alpha = _cone_of_centre(camera, centre_of(p), radius)
    provisional = BallSilhouette(axis, alpha, f, w, h, np.zeros((0, 2)), 0.0, 0.0, "")
    edges = _edges_across(feat, provisional, f)
    if edges is None:
        return p, None, np.zeros(0, int)
    p, chosen = _refine(model, p, edges, f, tol)
    return p, edges, chosen
