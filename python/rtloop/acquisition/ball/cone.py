"""The cone of rays that graze a sphere, and its outline in the image: a sphere's outline in a pinhole
image is an ellipse, but every grazing ray makes the same angle alpha with the direction to the centre
(sin alpha = r / D), so the outline has three degrees of freedom, fitted as a cone."""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field
from typing import Any

import cv2
import numpy as np


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
