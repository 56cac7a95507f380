"""Finding the ball without a pose (:func:`find_ball`: Hough candidates, then the free cone fitted by
RANSAC to edge points), and the seeds and pattern search that :func:`locate_ball` starts from."""

from __future__ import annotations

import math
from typing import Any

import cv2
import numpy as np

from ..._stats import median
from .._common import AcquisitionError, check_image, encode_srgb
from .cone import (
    BallSilhouette,
    _axis,
    _circle_through,
    _cone_model,
    _cone_residuals,
    _rays_cam,
    silhouette_polyline,
)
from .edges import MIN_EDGE_POINTS, _edge_image, _Edges, _profile_edges, _ransac, _refine
from .working import Working, working_size

#: Least fraction of the outline (by angle) that must show a consistent edge.
MIN_COVERAGE = 0.3


_NO_BALL_HELP = (
    "make sure the ball stands out from the floor (contrast in brightness or colour) and is wholly in "
    "view, or give its approximate centre and radius in pixels (--ball X,Y,R) or a mask image of the "
    "ball (--ball-mask MASK.png, white on black)"
)


def _fit_candidate(
    feat: np.ndarray,
    centre: np.ndarray,
    radius: float,
    f: float,
    source: str,
) -> BallSilhouette | None:
    h, w = feat.shape[:2]
    k = int(np.clip(2 * np.pi * radius, 64, 360))
    edges = _profile_edges(feat, centre, np.full(k, radius), max(5.0, 0.35 * radius), f)
    if edges is None:
        return None
    c_ray = _rays_cam(centre[None, :], f, w, h)[0]
    x0 = np.array([c_ray[0] / c_ray[2], c_ray[1] / c_ray[2], math.atan(radius / f)])

    def minimal(pick: np.ndarray) -> np.ndarray | None:
        circ = _circle_through(edges.points[pick])
        if circ is None or circ[1] > 3 * radius:
            return None
        cr = _rays_cam(circ[0][None, :], f, w, h)[0]
        return np.array([cr[0] / cr[2], cr[1] / cr[2], math.atan(circ[1] / f)])

    tol = max(1.0, 0.02 * radius)
    x, chosen, _ = _ransac(_cone_model, [x0], minimal, edges, f, 3, 200, tol)
    if len(chosen) < MIN_EDGE_POINTS or not (0 < x[2] < np.pi / 2):
        return None
    return _refit_near(feat, _make_silhouette(x, edges, chosen, f, w, h, source), x, k, tol)


def _refit_near(feat: np.ndarray, sil: BallSilhouette, x: np.ndarray, k: int, tol: float) -> BallSilhouette:
    """The cone ``x`` refitted to edges on ``k`` profiles from the outline's centre, searched close to the
    outline ``sil`` (``sil`` where too few are found)."""
    h, w = feat.shape[:2]
    f = sil.focal_px
    centre = sil.centre_px
    poly = silhouette_polyline(sil, 720)
    rel = poly - centre
    ang = np.mod(np.arctan2(rel[:, 1], rel[:, 0]), 2 * np.pi)
    order = np.argsort(ang)
    theta = np.linspace(0, 2 * np.pi, k, endpoint=False)
    radii = np.interp(theta, ang[order], np.hypot(rel[:, 0], rel[:, 1])[order], period=2 * np.pi)
    edges2 = _profile_edges(feat, centre, radii, max(3.0, 0.1 * float(np.mean(radii))), f)
    if edges2 is None:
        return sil
    x2, chosen2 = _refine(_cone_model, x, edges2, f, tol)
    if len(chosen2) < MIN_EDGE_POINTS or not (0 < x2[2] < np.pi / 2):
        return sil
    return _make_silhouette(x2, edges2, chosen2, f, w, h, sil.source)


def _make_silhouette(
    x: np.ndarray, edges: _Edges, chosen: np.ndarray, f: float, w: int, h: int, source: str
) -> BallSilhouette:
    res = _cone_residuals(x, edges.rays[chosen]) * f
    return BallSilhouette(
        _axis(x[0], x[1]),
        float(x[2]),
        f,
        w,
        h,
        edges.points[chosen],
        float(np.sqrt(np.mean(res**2))),
        float(len(chosen) / edges.k),
        source,
        {"strength": float(median(edges.strength[chosen])), "edges": edges},
    )


def _hough_candidates(image: np.ndarray, min_r: int, max_r: int) -> list[tuple[float, float, float]]:
    h, w = image.shape[:2]
    lum = image @ np.array([0.2126, 0.7152, 0.0722], dtype=np.float32)
    top = float(np.percentile(lum, 99.5)) or 1.0
    enc = encode_srgb(image / top)
    grey = (encode_srgb(lum / top) * 255 + 0.5).astype(np.uint8)
    hsv = cv2.cvtColor((enc * 255 + 0.5).astype(np.uint8), cv2.COLOR_RGB2HSV)
    sat = hsv[:, :, 1]
    out: list[tuple[float, float, float]] = []
    sigma = max(1.0, min(h, w) / 400)
    for channel in (grey, sat):
        blurred = cv2.GaussianBlur(channel, (0, 0), sigma)
        for method, p1, p2 in ((cv2.HOUGH_GRADIENT_ALT, 200, 0.6), (cv2.HOUGH_GRADIENT, 80, 25)):
            try:
                circles = cv2.HoughCircles(
                    blurred,
                    method,
                    1.5,
                    max(8, min(h, w) / 12),
                    param1=p1,
                    param2=p2,
                    minRadius=min_r,
                    maxRadius=max_r,
                )
            except cv2.error:
                circles = None
            if circles is not None:
                out.extend(
                    (float(c[0]), float(c[1]), float(c[2]))
                    for c in circles.reshape(-1, circles.shape[-1])[:6]
                )
    return out


def find_ball(
    image: np.ndarray,
    *,
    focal_px: float | None = None,
    hint: tuple[float, float, float] | None = None,
    mask: np.ndarray | None = None,
    radius_range_px: tuple[float, float] | None = None,
    exclude: np.ndarray | None = None,
    where: str = "photo",
) -> BallSilhouette:
    """Find the ball's outline in a linear RGB photo of a centred pinhole camera (a photo larger than
    :data:`.working.WORK_SIDE` pixels: in a copy of that size, the outline then refined on the photo).

    Args:
        image: float (H, W, 3) linear RGB.
        focal_px: the camera's focal length in pixels (makes the outline model exact); None assumes
            ``max(W, H)`` (the outline is then fitted a little less exactly away from the centre).
        hint: approximate ``(x, y, radius)`` in pixels: search only there.
        mask: a boolean (H, W) image true on the ball: its outline is used as the first guess.
        radius_range_px: the smallest and largest radius to look for (default: 1/60 to 1/2 of the
            image's smaller side).
        exclude: a polygon (N, 2) in pixels (e.g. the board) where the ball's centre cannot be.

    Raises:
        AcquisitionError: no outline consistent with a ball was found; says what to do.
    """
    image = check_image(image, where)
    h, w = image.shape[:2]
    f = float(focal_px) if focal_px else float(max(w, h))
    size = working_size(w, h)
    if size is not None:  # a large photo: searched in a smaller copy, refined on the photo
        work = Working((w, h), size)
        found = find_ball(
            work.image(image),
            focal_px=f / work.sy,
            hint=work.hint(None if hint is None else _checked_hint(hint, h, w, where)),
            mask=work.mask(mask, where),
            radius_range_px=None if radius_range_px is None else (
                radius_range_px[0] / work.sx, radius_range_px[1] / work.sx),
            exclude=work.polygon(exclude),
            where=where,
        )
        sil = work.silhouette(found, f)
        x = np.array([sil.axis[0] / sil.axis[2], sil.axis[1] / sil.axis[2], sil.alpha])
        r = sil.radius_px
        return _refit_near(_edge_image(image), sil, x, int(np.clip(2 * np.pi * r, 64, 720)), max(1.0, 0.02 * r))
    feat = _edge_image(image)
    candidates = _candidates(image, mask, hint, radius_range_px, exclude, where)
    best: BallSilhouette | None = None
    best_score = -1.0
    for cx, cy, r, source in candidates:
        sil = _fit_candidate(feat, np.array([cx, cy]), r, f, source)
        if sil is None or sil.coverage < MIN_COVERAGE:
            continue
        if radius_range_px and mask is None and hint is None:
            rr = sil.radius_px
            if not (0.8 * radius_range_px[0] <= rr <= 1.25 * radius_range_px[1]):
                continue
        score = sil.coverage / (0.25 + sil.rms_px)
        if score > best_score:
            best, best_score = sil, score
    if best is None:
        found = (
            f"{len(candidates)} candidate circles, none with a clear round outline"
            if candidates
            else "no circle"
        )
        raise AcquisitionError(f"{where}: no ball found ({found}); {_NO_BALL_HELP}")
    return best


def _candidates(
    image: np.ndarray,
    mask: np.ndarray | None,
    hint: tuple[float, float, float] | None,
    radius_range_px: tuple[float, float] | None,
    exclude: np.ndarray | None,
    where: str,
) -> list[tuple[float, float, float, str]]:
    """The circles ``(x, y, radius, source)`` to fit the outline from: the mask's, else the hint, else up to
    12 distinct Hough circles in the radius range whose centres are outside ``exclude``."""
    h, w = image.shape[:2]
    candidates: list[tuple[float, float, float, str]] = []
    if mask is not None:
        big = _mask_outline(mask, h, w, where)
        (cx, cy), _r = cv2.minEnclosingCircle(big)
        r = math.sqrt(cv2.contourArea(big) / math.pi)
        candidates.append((cx, cy, r, "mask"))
    elif hint is not None:
        candidates.append((*_checked_hint(hint, h, w, where), "hint"))
    else:
        lo, hi = radius_range_px or (max(4.0, min(h, w) / 60), min(h, w) / 2)
        candidates.extend((*c, "hough") for c in _hough_candidates(image, int(lo), math.ceil(hi)))
        if exclude is not None and len(exclude) >= 3:
            poly = np.asarray(exclude, np.float32).reshape(-1, 1, 2)
            candidates = [c for c in candidates if cv2.pointPolygonTest(poly, (c[0], c[1]), False) < 0]
        candidates = _dedupe(candidates)[:12]
    return candidates


def _dedupe(cands: list[tuple[float, float, float, str]]) -> list[tuple[float, float, float, str]]:
    out: list[tuple[float, float, float, str]] = []
    for c in cands:
        if all(
            math.hypot(c[0] - o[0], c[1] - o[1]) > 0.2 * o[2] or abs(c[2] - o[2]) > 0.2 * o[2] for o in out
        ):
            out.append(c)
    return out


def _seeds(
    image: np.ndarray,
    feat: np.ndarray,
    hint,
    mask,
    exclude,
    where: str,
) -> list[tuple[float, float, float, str]]:
    h, w = image.shape[:2]
    if mask is not None:
        mo = cv2.moments(_mask_outline(mask, h, w, where))
        if mo["m00"] <= 0:
            raise AcquisitionError(f"{where}: the ball mask is empty; paint the ball white on black")
        return [(mo["m10"] / mo["m00"], mo["m01"] / mo["m00"], math.sqrt(mo["m00"] / math.pi), "mask")]
    if hint is not None:
        return [(*_checked_hint(hint, h, w, where), "hint")]
    lo, hi = max(4.0, min(h, w) / 60), min(h, w) / 2
    cands = [(*c, "hough") for c in _hough_candidates(image, int(lo), math.ceil(hi))]
    if exclude is not None and len(exclude) >= 3:
        poly = np.asarray(exclude, np.float32).reshape(-1, 1, 2)
        cands = [c for c in cands if cv2.pointPolygonTest(poly, (c[0], c[1]), False) < 0]
    return _dedupe(cands)[:12]


def _mask_outline(mask: Any, h: int, w: int, where: str) -> np.ndarray:
    """The largest outer contour of a user-drawn ball mask (white on black, the photo's size)."""
    m = np.asarray(mask)
    if m.shape[:2] != (h, w):
        raise AcquisitionError(
            f"{where}: the ball mask is {m.shape[1]}x{m.shape[0]} but the photo is {w}x{h}; draw the "
            "mask on the photo itself (same size)"
        )
    m8 = (m.reshape(h, w, -1).max(axis=2) > 0).astype(np.uint8)
    contours, _ = cv2.findContours(m8, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
    if not contours:
        raise AcquisitionError(f"{where}: the ball mask is empty; paint the ball white on black")
    return max(contours, key=cv2.contourArea)


def _checked_hint(hint: Any, h: int, w: int, where: str) -> tuple[float, float, float]:
    """The user's ball hint (x, y, r) in pixels, checked against the photo."""
    x, y, r = (float(v) for v in hint)
    if not (0 <= x < w and 0 <= y < h and r > 2):
        raise AcquisitionError(
            f"{where}: the ball hint ({x:g}, {y:g}, radius {r:g}) is outside the {w}x{h} photo or too "
            "small; give X,Y,R in pixels of the photo"
        )
    return x, y, r


def _pattern_search(
    fun,
    x0: np.ndarray,
    step: float,
    min_step: float,
    max_evals: int = 120,
) -> tuple[np.ndarray, float]:
    """Maximise fun over 2-D by compass search with step halving."""
    x = np.asarray(x0, dtype=float)
    best = fun(x)
    evals = 1
    dirs = np.array([[1, 0], [-1, 0], [0, 1], [0, -1], [1, 1], [-1, -1], [1, -1], [-1, 1]], dtype=float)
    dirs[4:] /= math.sqrt(2)
    while step >= min_step and evals < max_evals:
        moved = False
        for d in dirs:
            cand = x + step * d
            v = fun(cand)
            evals += 1
            if v > best:
                x, best, moved = cand, v, True
                break
        if not moved:
            step /= 2
    return x, best
