"""Edges of the ball's outline: sub-pixel colour steps along rays, the robust (RANSAC) fit of a model to
several edge candidates per ray, and the score of a predicted outline on the edge image."""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from ..._stats import median
from .._common import encode_srgb
from .cone import BallSilhouette, _gauss_newton, _rays_cam, silhouette_polyline

#: Least number of edge points.
MIN_EDGE_POINTS = 16


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
        tol = min(tol, max(0.75, 3.0 * 1.4826 * float(median(res))))
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


def _outward_normals(poly: np.ndarray) -> np.ndarray:
    t = np.roll(poly, -1, axis=0) - np.roll(poly, 1, axis=0)
    n = np.column_stack([t[:, 1], -t[:, 0]])
    n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-12)
    if np.sum(n * (poly - poly.mean(axis=0))) < 0:
        n = -n
    return n


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
