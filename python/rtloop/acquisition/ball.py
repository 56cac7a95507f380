"""The ball: its silhouette in the photo and its place in 3-D.

A sphere's outline in a pinhole image is not a circle but an ellipse (stretched away from the image
centre). What is exact is the *cone* of rays that graze the sphere: every silhouette ray ``d`` makes
the same angle ``alpha`` with the direction ``u`` to the sphere's centre, ``sin(alpha) = r / D`` at
distance ``D``. So the silhouette has three degrees of freedom, like a circle, and this module fits
that cone rather than a circle.

* :func:`locate_ball` (what ``rtloop-scene`` uses) knows the posed camera, the floor and the radius.
  A ball resting on the floor has only two unknowns, its centre's ``x`` and ``z``, and its outline
  (size included) follows from them exactly. Hough circles (on brightness and on colour saturation),
  or the user's hint ``(x, y, r)``, or a user-drawn mask, only seed a search over the floor position
  that scores each predicted outline by how well it lies on colour edges running along it. This
  tells the ball from its own shadow (a crisp ellipse too, but not the outline of a resting ball of
  that radius), from shading just inside the ball, and from textured surroundings. The best outline
  then gets sub-pixel edge points across it (the strongest colour step on each ray from its centre)
  and the centre is fitted to them by least squares (``place_sphere``'s model). With
  ``resting=False`` a last fit frees the centre's height (distance then comes from the apparent size
  alone, less precisely), which also tells how far the ball is from resting on the floor.
* :func:`find_ball` needs no pose: it fits the free cone ``(u, alpha)`` (3 unknowns) by RANSAC to
  edge points along rays from each Hough candidate, keeping the best-supported one. It cannot tell
  a ball from its shadow by size, so prefer ``locate_ball`` when the camera is posed.
* :func:`place_sphere` turns an outline into the sphere's centre in the world (resting on the floor,
  or free), fitting the centre to the outline's edge rays by least squares.

Edge points near a dark side of the ball against its own shadow cannot be seen and are left out:
the visible part of the outline (at least about a third of it) is enough.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field
from typing import Any

import cv2
import numpy as np

from ._common import AcquisitionError, check_image, encode_srgb
from .camera import PinholeCamera

__all__ = [
    "BallSilhouette",
    "SpherePlacement",
    "find_ball",
    "locate_ball",
    "place_sphere",
    "silhouette_polyline",
]

#: Least fraction of the outline (by angle) that must show a consistent edge.
MIN_COVERAGE = 0.3
#: Least number of edge points.
MIN_EDGE_POINTS = 16
#: Least outline score (mean edge support along the predicted outline, 0..1) for a ball to be accepted.
MIN_OUTLINE_SCORE = 0.4

_NO_BALL_HELP = (
    "make sure the ball stands out from the floor (contrast in brightness or colour) and is wholly in "
    "view, or give its approximate centre and radius in pixels (--ball X,Y,R) or a mask image of the "
    "ball (--ball-mask MASK.png, white on black)"
)


@dataclass
class BallSilhouette:
    """The ball's outline in the photo.

    Attributes:
        axis: unit direction (OpenCV camera frame: x right, y down, z forward) to the sphere's centre.
        alpha: the cone's half angle (radians): the apparent angular radius.
        focal_px: the focal length the rays were made with (the image is a centred pinhole).
        width, height: the image size.
        edge_points: (N, 2) pixel coordinates of the outline points used in the fit.
        rms_px: RMS distance (pixels, approximately) of those points from the fitted outline.
        coverage: fraction of the outline's angles with a point used.
        source: where the first guess came from ("hough", "hint", "mask").
    """

    axis: np.ndarray
    alpha: float
    focal_px: float
    width: int
    height: int
    edge_points: np.ndarray
    rms_px: float
    coverage: float
    source: str
    extra: dict[str, Any] = field(default_factory=dict)

    @property
    def centre_px(self) -> np.ndarray:
        """Pixel where the ray to the sphere's centre meets the image (not the ellipse's centre)."""
        return _project_cam(self.axis[None, :], self.focal_px, self.width, self.height)[0]

    @property
    def radius_px(self) -> float:
        """The radius of the circle with the outline's area (for reporting and drawing)."""
        pts = silhouette_polyline(self, 360)
        return float(math.sqrt(abs(cv2.contourArea(pts.astype(np.float32))) / math.pi))

    def report(self) -> dict[str, Any]:
        c = self.centre_px
        return {
            "centre_px": [float(c[0]), float(c[1])],
            "radius_px": self.radius_px,
            "angular_radius_deg": math.degrees(self.alpha),
            "edge_points": len(self.edge_points),
            "coverage": self.coverage,
            "rms_px": self.rms_px,
            "source": self.source,
        }


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


# --- rays and cones in the camera frame ----------------------------------------------------------------


def _rays_cam(uv: np.ndarray, f: float, w: int, h: int) -> np.ndarray:
    d = np.column_stack([(uv[:, 0] - (w - 1) / 2.0) / f, (uv[:, 1] - (h - 1) / 2.0) / f, np.ones(len(uv))])
    return d / np.linalg.norm(d, axis=1, keepdims=True)


def _project_cam(d: np.ndarray, f: float, w: int, h: int) -> np.ndarray:
    return np.column_stack([f * d[:, 0] / d[:, 2] + (w - 1) / 2.0, f * d[:, 1] / d[:, 2] + (h - 1) / 2.0])


def _axis(a: float, b: float) -> np.ndarray:
    v = np.array([a, b, 1.0])
    return v / np.linalg.norm(v)


@functools.cache
def _circle(n: int) -> tuple[np.ndarray, np.ndarray]:
    phi = np.linspace(0, 2 * np.pi, n, endpoint=False)
    return np.cos(phi)[:, None], np.sin(phi)[:, None]


def _cone_points(axis: np.ndarray, alpha: float, n: int) -> np.ndarray:
    """n unit rays on the cone around ``axis`` with half angle ``alpha``."""
    ax, ay, az = (float(v) for v in axis)
    # e1: a unit vector perpendicular to the axis; e2 = axis x e1.
    e1 = np.array([ay, -ax, 0.0]) if abs(az) < 0.9 else np.array([0.0, az, -ay])
    e1 /= math.sqrt(float(e1 @ e1))
    e2 = np.array([ay * e1[2] - az * e1[1], az * e1[0] - ax * e1[2], ax * e1[1] - ay * e1[0]])
    cos_phi, sin_phi = _circle(n)
    return math.cos(alpha) * axis[None, :] + math.sin(alpha) * (cos_phi * e1[None, :] + sin_phi * e2[None, :])


def silhouette_polyline(sil: BallSilhouette, n: int = 360) -> np.ndarray:
    """(n, 2) pixel points on the fitted outline (an ellipse), for drawing."""
    rays = _cone_points(sil.axis, sil.alpha, n)
    rays = rays[rays[:, 2] > 1e-6]
    return _project_cam(rays, sil.focal_px, sil.width, sil.height)


def _cone_residuals(params: np.ndarray, rays: np.ndarray) -> np.ndarray:
    u = _axis(params[0], params[1])
    return np.arccos(np.clip(rays @ u, -1.0, 1.0)) - params[2]


def _gauss_newton(
    fun, x0: np.ndarray, weights: np.ndarray | None = None, iterations: int = 30, step: float = 1e-7
) -> np.ndarray:
    """Minimise sum(w * fun(x)^2) with numerical derivatives and Levenberg damping."""
    x = np.asarray(x0, dtype=float).copy()
    lam = 1e-3

    def cost(v: np.ndarray) -> float:
        r = fun(v)
        return float(np.sum(r * r if weights is None else weights * r * r))

    c = cost(x)
    for _ in range(iterations):
        r = fun(x)
        jac = np.empty((len(r), len(x)))
        for i in range(len(x)):
            dx = np.zeros_like(x)
            dx[i] = step * max(1.0, abs(x[i]))
            jac[:, i] = (fun(x + dx) - r) / dx[i]
        wj = jac if weights is None else jac * weights[:, None]
        a = wj.T @ jac
        g = wj.T @ r
        improved = False
        for _ in range(10):
            try:
                delta = -np.linalg.solve(a + lam * np.diag(np.diag(a) + 1e-12), g)
            except np.linalg.LinAlgError:
                lam *= 10
                continue
            c_new = cost(x + delta)
            if c_new < c:
                x, c = x + delta, c_new
                lam = max(lam / 3, 1e-9)
                improved = True
                break
            lam *= 10
        if not improved or np.max(np.abs(delta)) < 1e-12:
            break
    return x


# --- robust fitting: several edge candidates per ray, the model with the widest support wins ------------


@dataclass
class _Edges:
    """Edge candidates: up to a few per ray from the guess's centre."""

    points: np.ndarray  # (M, 2) pixels
    rays: np.ndarray  # (M, 3) unit rays, camera frame
    ray_id: np.ndarray  # (M,) which of the K profile rays
    strength: np.ndarray  # (M,)
    k: int  # number of profile rays


def _support(residual_px: np.ndarray, edges: _Edges, tol: float) -> tuple[float, np.ndarray]:
    """Fraction of profile rays with an edge within ``tol`` pixels of the model, and the chosen edge
    (the closest) of each such ray."""
    r = np.abs(residual_px)
    order = np.lexsort((r, edges.ray_id))
    ids = edges.ray_id[order]
    first = np.ones(len(ids), bool)
    first[1:] = ids[1:] != ids[:-1]
    best = order[first]
    chosen = best[r[best] < tol]
    return len(chosen) / edges.k, chosen


def _refine(model, x: np.ndarray, edges: _Edges, f: float, tol: float) -> tuple[np.ndarray, np.ndarray]:
    """Alternate choosing each ray's edge nearest the model (within tol) and least squares."""
    chosen = np.zeros(0, int)
    for _ in range(8):
        _, new = _support(model(x, edges.rays) * f, edges, tol)
        if len(new) < 4 or np.array_equal(new, chosen):
            break
        chosen = new
        sub = edges.rays[chosen]
        x = _gauss_newton(lambda p, sub=sub: model(p, sub), x)
        # Tighten the tolerance towards the fit's own scatter (keeps out near-miss shadow edges).
        res = np.abs(model(x, sub)) * f
        tol = min(tol, max(0.75, 3.0 * 1.4826 * float(np.median(res))))
    return x, chosen


def _ransac(
    model, starts: list[np.ndarray], minimal, edges: _Edges, f: float, n_min: int, iterations: int, tol: float
) -> tuple[np.ndarray, np.ndarray, float]:
    """Best-supported model among the starts and among fits to random minimal sets of edges."""
    rng = np.random.default_rng(0)
    hypotheses = list(starts)
    pool = np.flatnonzero(edges.strength >= np.percentile(edges.strength, 25))
    if len(np.unique(edges.ray_id[pool])) >= n_min:
        for _ in range(iterations):
            pick = rng.choice(pool, size=n_min, replace=False)
            if len(np.unique(edges.ray_id[pick])) < n_min:
                continue
            # The rays must be spread around the outline to pin the model down.
            angles = np.sort(2 * np.pi * edges.ray_id[pick] / edges.k)
            gaps = np.diff(np.concatenate([angles, angles[:1] + 2 * np.pi]))
            if gaps.max() > 2 * np.pi - 0.35:
                continue
            h = minimal(pick)
            if h is not None:
                hypotheses.append(h)
    best_x, best_score = None, -1.0
    for h in hypotheses:
        with np.errstate(invalid="ignore"):
            res = model(h, edges.rays) * f
        if not np.all(np.isfinite(res)):
            continue
        score, _ = _support(res, edges, tol)
        if score > best_score:
            best_x, best_score = h, score
    if best_x is None:
        return starts[0], np.zeros(0, int), 0.0
    x, chosen = _refine(model, best_x, edges, f, tol)
    return x, chosen, len(chosen) / edges.k


def _cone_model(p: np.ndarray, rays: np.ndarray) -> np.ndarray:
    return _cone_residuals(p, rays)


def _circle_through(pts: np.ndarray) -> tuple[np.ndarray, float] | None:
    a = np.column_stack([2 * pts[:, 0], 2 * pts[:, 1], np.ones(len(pts))])
    b = np.sum(pts * pts, axis=1)
    sol, *_ = np.linalg.lstsq(a, b, rcond=None)
    c = sol[:2]
    r2 = sol[2] + c @ c
    if not np.isfinite(r2) or r2 <= 1:
        return None
    return c, float(math.sqrt(r2))


# --- finding the outline -------------------------------------------------------------------------------


def _edge_image(image: np.ndarray) -> np.ndarray:
    """sRGB-encoded colour, brightness-normalised and slightly blurred: edges where the eye sees them."""
    lum = image @ np.array([0.2126, 0.7152, 0.0722], dtype=np.float32)
    top = float(np.percentile(lum, 99.5))
    scaled = image / top if top > 1e-6 else image
    enc = encode_srgb(scaled)
    return cv2.GaussianBlur(enc, (0, 0), 0.8)


def _profile_edges(
    feat: np.ndarray, centre: np.ndarray, radii: np.ndarray, band: float, f: float, per_ray: int = 3
) -> _Edges | None:
    """Edge candidates along rays from ``centre`` at angles 2 pi k / K, searched within
    ``radii[k] +- band``: the ``per_ray`` strongest local maxima of the colour gradient on each ray,
    to a fraction of a pixel."""
    h, w = feat.shape[:2]
    k = len(radii)
    theta = np.linspace(0, 2 * np.pi, k, endpoint=False)
    step = max(0.25, 2 * band / 400)
    offsets = np.arange(-band, band + step / 2, step)
    s = np.maximum(radii[:, None] + offsets[None, :], 0.5)
    xs = (centre[0] + s * np.cos(theta)[:, None]).astype(np.float32)
    ys = (centre[1] + s * np.sin(theta)[:, None]).astype(np.float32)
    prof = cv2.remap(feat, xs, ys, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
    deriv = np.gradient(prof, step, axis=1)
    mag = np.sqrt(np.sum(deriv * deriv, axis=2))
    peak = np.zeros_like(mag, bool)
    peak[:, 2:-2] = (mag[:, 2:-2] >= mag[:, 1:-3]) & (mag[:, 2:-2] > mag[:, 3:-1])
    row_max = np.where(peak, mag, 0).max(axis=1)
    if not np.any(row_max > 0):
        return None
    peak &= mag >= 0.15 * float(np.percentile(row_max[row_max > 0], 90))
    ranked = np.where(peak, mag, -1.0)
    top = np.argsort(-ranked, axis=1)[:, :per_ray]
    rows = np.repeat(np.arange(k), top.shape[1])
    i = top.ravel()
    keep = ranked[rows, i] > 0
    rows, i = rows[keep], i[keep]
    if len(rows) < MIN_EDGE_POINTS:
        return None
    m0, m1, m2 = mag[rows, i - 1], mag[rows, i], mag[rows, i + 1]
    denom = m0 - 2 * m1 + m2
    frac = np.where(np.abs(denom) > 1e-12, 0.5 * (m0 - m2) / np.where(denom == 0, 1, denom), 0.0)
    s_edge = s[rows, i] + np.clip(frac, -0.5, 0.5) * step
    pts = np.column_stack(
        [centre[0] + s_edge * np.cos(theta[rows]), centre[1] + s_edge * np.sin(theta[rows])]
    )
    inside = (pts[:, 0] > 1) & (pts[:, 0] < w - 2) & (pts[:, 1] > 1) & (pts[:, 1] < h - 2)
    pts, rows, strength = pts[inside], rows[inside], m1[inside]
    if len(pts) < MIN_EDGE_POINTS:
        return None
    return _Edges(pts, _rays_cam(pts, f, w, h), rows, strength, k)


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
    sil = _make_silhouette(x, edges, chosen, f, w, h, source)
    # Second pass: profiles from the fitted outline's centre, searched close to it.
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
    return _make_silhouette(x2, edges2, chosen2, f, w, h, source)


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
        {"strength": float(np.median(edges.strength[chosen])), "edges": edges},
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
    """Find the ball's outline in a linear RGB photo of a centred pinhole camera.

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
    feat = _edge_image(image)
    candidates: list[tuple[float, float, float, str]] = []
    if mask is not None:
        m = np.asarray(mask)
        if m.shape[:2] != (h, w):
            raise AcquisitionError(
                f"{where}: the ball mask is {m.shape[1]}x{m.shape[0]} but the photo is {w}x{h}; draw the "
                "mask "
                "on the photo itself (same size)"
            )
        m8 = (
            (m.reshape(h, w, -1).max(axis=2) > 0).astype(np.uint8)
            if m.ndim == 3
            else (m > 0).astype(np.uint8)
        )
        contours, _ = cv2.findContours(m8, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
        if not contours:
            raise AcquisitionError(f"{where}: the ball mask is empty; paint the ball white on black")
        big = max(contours, key=cv2.contourArea)
        (cx, cy), _r = cv2.minEnclosingCircle(big)
        r = math.sqrt(cv2.contourArea(big) / math.pi)
        candidates.append((cx, cy, r, "mask"))
    elif hint is not None:
        x, y, r = (float(v) for v in hint)
        if not (0 <= x < w and 0 <= y < h and r > 2):
            raise AcquisitionError(
                f"{where}: the ball hint ({x:g}, {y:g}, radius {r:g}) is outside the {w}x{h} photo or too "
                "small; "
                "give X,Y,R in pixels of the photo"
            )
        candidates.append((x, y, r, "hint"))
    else:
        lo, hi = radius_range_px or (max(4.0, min(h, w) / 60), min(h, w) / 2)
        candidates.extend((*c, "hough") for c in _hough_candidates(image, int(lo), math.ceil(hi)))
        if exclude is not None and len(exclude) >= 3:
            poly = np.asarray(exclude, np.float32).reshape(-1, 1, 2)
            candidates = [c for c in candidates if cv2.pointPolygonTest(poly, (c[0], c[1]), False) < 0]
        candidates = _dedupe(candidates)[:12]
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


def _dedupe(cands: list[tuple[float, float, float, str]]) -> list[tuple[float, float, float, str]]:
    out: list[tuple[float, float, float, str]] = []
    for c in cands:
        if all(
            math.hypot(c[0] - o[0], c[1] - o[1]) > 0.2 * o[2] or abs(c[2] - o[2]) > 0.2 * o[2] for o in out
        ):
            out.append(c)
    return out


# --- placing the sphere --------------------------------------------------------------------------------


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


class _OutlineScore:
    """How well a predicted outline lies on edges of the photo: the mean, over points of the outline,
    of the strongest colour step across it within +-tol pixels, less the change *along* it there (an
    outline is an edge that runs with it; edges that cross it, as on a textured floor or a board,
    do not count), relative to a strong edge and capped at 1."""

    def __init__(self, feat: np.ndarray):
        self.feat = feat
        h, w = feat.shape[:2]
        gx = cv2.Sobel(feat, cv2.CV_32F, 1, 0, ksize=3) / 8
        gy = cv2.Sobel(feat, cv2.CV_32F, 0, 1, ksize=3) / 8
        g = np.sqrt(np.sum(gx * gx + gy * gy, axis=2))
        self.ref = max(1e-4, 0.5 * float(np.percentile(g, 99.5)))
        self.w, self.h = w, h

    def _sample(self, pts: np.ndarray) -> np.ndarray:
        pts = pts.astype(np.float32)
        return cv2.remap(
            self.feat, pts[..., 0], pts[..., 1], cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE
        )

    def __call__(self, poly: np.ndarray, tol: float, cap: float = 1.0) -> float:
        n = _outward_normals(poly)
        ok = (poly[:, 0] > 2) & (poly[:, 0] < self.w - 3) & (poly[:, 1] > 2) & (poly[:, 1] < self.h - 3)
        if ok.mean() < 0.5:
            return 0.0
        poly, n = poly[ok], n[ok]
        t = np.column_stack([-n[:, 1], n[:, 0]])
        m = int(np.clip(round(2 * tol / 0.5) + 1, 3, 15))
        offs = np.linspace(-tol, tol, m)
        base = poly[:, None, :] + offs[None, :, None] * n[:, None, :]
        dn, dt = 0.5 * n[:, None, :], 0.75 * t[:, None, :]
        f = self._sample(np.concatenate([base + dn, base - dn, base + dt, base - dt], axis=1))
        k = base.shape[1]
        across = f[:, :k] - f[:, k : 2 * k]
        along = f[:, 2 * k : 3 * k] - f[:, 3 * k :]
        step = np.sqrt(np.sum(across**2, axis=2)) - np.sqrt(np.sum(along**2, axis=2))
        return float(np.clip(step.max(axis=1) / self.ref, 0.0, cap).mean() * ok.mean())


def _outward_normals(poly: np.ndarray) -> np.ndarray:
    t = np.roll(poly, -1, axis=0) - np.roll(poly, 1, axis=0)
    n = np.column_stack([t[:, 1], -t[:, 0]])
    n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-12)
    if np.sum(n * (poly - poly.mean(axis=0))) < 0:
        n = -n
    return n


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
    from the distance) and scored by how well it lies on colour edges of the photo. This tells the ball
    from its own shadow (also a crisp ellipse, but not the outline of a resting ball of this radius) and
    from shading inside the ball. The best position is then refined by least squares on the edge
    points along the outline. With ``resting=False`` a last fit frees the centre's height.

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
    f = camera.focal_px
    feat = _edge_image(image)
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
    # Coarse screening with a wide tolerance, then a pattern search on the best few.
    ranked = []
    for p0, r_px, src in starts:
        poly = outline(p0)
        if poly is None:
            continue
        pred_r = math.sqrt(abs(cv2.contourArea(poly.astype(np.float32))) / math.pi)
        ranked.append((value(p0, max(2.0, 0.25 * pred_r)), p0, pred_r, src))
    ranked.sort(key=lambda item: -item[0])
    best = None
    for _, p0, pred_r, src in ranked[:4]:
        metres_per_px = float(np.linalg.norm(centre_of(p0) - camera.position)) / f
        p = p0
        for tol_px, step_px in ((0.25 * pred_r, 0.25 * pred_r), (0.08 * pred_r, 0.06 * pred_r), (1.0, 0.5)):
            tol_px = max(tol_px, 1.0)
            p, v = _pattern_search(
                lambda q, t=tol_px: value(q, t), p, max(step_px, 0.25) * metres_per_px, 0.1 * metres_per_px
            )
        # Last, uncapped: among outlines on edges everywhere, the one on the strongest (the true outline
        # rather than shading just inside it).
        p, _ = _pattern_search(lambda q: value(q, 1.0, 100.0), p, 0.5 * metres_per_px, 0.05 * metres_per_px)
        if best is None or v > best[0]:
            best = (v, p, src)
    if best is None or best[0] < MIN_OUTLINE_SCORE:
        raise AcquisitionError(
            f"{where}: no ball of radius {radius:g} m resting on the floor found (best outline matched "
            f"{0 if best is None else best[0]:.0%} of edges); check --ball-radius (metres) and "
            f"{_NO_BALL_HELP}"
        )
    _, p, source = best
    # Edge points across the found outline, then least squares on those near it (the exact fit).
    centre = centre_of(p)
    axis, alpha = _cone_of_centre(camera, centre, radius)
    provisional = BallSilhouette(axis, alpha, f, w, h, np.zeros((0, 2)), 0.0, 0.0, source)
    edges = _edges_across(feat, provisional, f)
    chosen = np.zeros(0, int)
    if edges is not None:
        p, chosen = _refine(model, p, edges, f, 1.5)
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
        axis, alpha, f, w, h, points, rms, len(chosen) / edges.k, source, {"outline_score": best[0]}
    )
    placement = SpherePlacement(centre, float(radius), resting, rms, float(centre[1] - floor_height))
    return final, placement


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


def _edges_across(feat: np.ndarray, sil: BallSilhouette, f: float) -> _Edges | None:
    """Sub-pixel edge candidates along rays across a predicted outline (from its centre)."""
    poly = silhouette_polyline(sil, 720)
    centre = sil.centre_px
    rel = poly - centre
    ang = np.mod(np.arctan2(rel[:, 1], rel[:, 0]), 2 * np.pi)
    order = np.argsort(ang)
    mean_r = float(np.mean(np.hypot(rel[:, 0], rel[:, 1])))
    k = int(np.clip(2 * np.pi * mean_r, 64, 720))
    theta = np.linspace(0, 2 * np.pi, k, endpoint=False)
    radii = np.interp(theta, ang[order], np.hypot(rel[:, 0], rel[:, 1])[order], period=2 * np.pi)
    return _profile_edges(feat, centre, radii, max(3.0, 0.06 * mean_r), f)


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
        m = np.asarray(mask)
        if m.shape[:2] != (h, w):
            raise AcquisitionError(
                f"{where}: the ball mask is {m.shape[1]}x{m.shape[0]} but the photo is {w}x{h}; draw the "
                "mask "
                "on the photo itself (same size)"
            )
        m8 = (m.reshape(h, w, -1).max(axis=2) > 0).astype(np.uint8)
        contours, _ = cv2.findContours(m8, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
        if not contours:
            raise AcquisitionError(f"{where}: the ball mask is empty; paint the ball white on black")
        big = max(contours, key=cv2.contourArea)
        mo = cv2.moments(big)
        if mo["m00"] <= 0:
            raise AcquisitionError(f"{where}: the ball mask is empty; paint the ball white on black")
        return [(mo["m10"] / mo["m00"], mo["m01"] / mo["m00"], math.sqrt(mo["m00"] / math.pi), "mask")]
    if hint is not None:
        x, y, r = (float(v) for v in hint)
        if not (0 <= x < w and 0 <= y < h and r > 2):
            raise AcquisitionError(
                f"{where}: the ball hint ({x:g}, {y:g}, radius {r:g}) is outside the {w}x{h} photo or too "
                "small; "
                "give X,Y,R in pixels of the photo"
            )
        return [(x, y, r, "hint")]
    lo, hi = max(4.0, min(h, w) / 60), min(h, w) / 2
    cands = [(*c, "hough") for c in _hough_candidates(image, int(lo), math.ceil(hi))]
    if exclude is not None and len(exclude) >= 3:
        poly = np.asarray(exclude, np.float32).reshape(-1, 1, 2)
        cands = [c for c in cands if cv2.pointPolygonTest(poly, (c[0], c[1]), False) < 0]
    return _dedupe(cands)[:12]
