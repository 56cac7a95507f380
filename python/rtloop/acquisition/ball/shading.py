"""Is the inside of an outline a shaded sphere, or floor? The ball's own shadow on the floor is also a crisp,
ball-sized outline, and seen from above its edge (dark shadow against the lit floor) can be stronger than the
ball's own; the two differ inside. A Lambertian sphere of one colour under any distant lighting has a radiance
that is, to within a few per cent, a quadratic function of its surface normal (the nine spherical harmonics
of order <= 2, Ramamoorthi and Hanrahan 2001); the normals of a hypothesised sphere are known at every pixel
inside its outline, and change fastest near it. The floor's radiance (lit, or in shadow) changes slowly and
smoothly across the image. :func:`sphere_likeness` compares the two explanations of the pixels inside the
outline, each with nine functions per colour channel: the ball's inside follows the sphere's normals, an
outline put on the shadow holds flat floor (both explain it alike) or floor with the ball's outline across it
(neither does)."""

from __future__ import annotations

import numpy as np

from ..camera import PinholeCamera

#: Pixels kept off the outline (the edge's blur and the outline's own error).
INSET_PX = 1.5
#: Fewest pixels inside an outline for the comparison.
MIN_PIXELS = 30


def _sh9(n: np.ndarray) -> np.ndarray:
    """The nine real spherical harmonics of order <= 2 (up to constant factors) at unit normals (N, 3)."""
    x, y, z = n[:, 0], n[:, 1], n[:, 2]
    return np.column_stack([np.ones(len(n)), x, y, z, x * y, y * z, x * z, x * x - y * y, 3 * z * z - 1])


def _biquadratic(uv: np.ndarray) -> np.ndarray:
    """Nine smooth functions of the pixel position, (1, u, u^2) x (1, v, v^2), centred and scaled."""
    c = uv.mean(axis=0)
    s = max(float(np.abs(uv - c).max()), 1.0)
    u, v = (uv[:, 0] - c[0]) / s, (uv[:, 1] - c[1]) / s
    one = np.ones_like(u)
    return np.column_stack([a * b for a in (one, u, u * u) for b in (one, v, v * v)])


def sphere_pixels(
    camera: PinholeCamera, centre: np.ndarray, radius: float, inset_px: float = INSET_PX
) -> tuple[np.ndarray, np.ndarray] | None:
    """Pixel coordinates (N, 2, integer) inside the sphere's outline (at least ``inset_px`` in from it) and
    the sphere's unit normals there (N, 3, world frame); None when the camera is inside the sphere, its centre
    is not in front of the camera, or fewer than MIN_PIXELS pixels are inside."""
    c = np.asarray(centre, float)
    o = camera.position
    oc = c - o
    dist = float(np.linalg.norm(oc))
    if dist <= radius * 1.01:
        return None
    uv_c = camera.project(c[None, :])[0]
    if not np.all(np.isfinite(uv_c)):
        return None
    # a generous bounding box: twice the apparent radius around the centre's pixel
    r_px = 2.0 * camera.focal_px * radius / np.sqrt(dist * dist - radius * radius)
    x0, x1 = int(max(0, np.floor(uv_c[0] - r_px))), int(min(camera.width - 1, np.ceil(uv_c[0] + r_px)))
    y0, y1 = int(max(0, np.floor(uv_c[1] - r_px))), int(min(camera.height - 1, np.ceil(uv_c[1] + r_px)))
    if x1 <= x0 or y1 <= y0:
        return None
    xs, ys = np.meshgrid(np.arange(x0, x1 + 1), np.arange(y0, y1 + 1))
    uv = np.column_stack([xs.ravel(), ys.ravel()])
    d = camera.rays(uv.astype(float))
    b = d @ oc
    miss2 = np.maximum(dist * dist - b * b, 0.0)  # the ray's squared distance from the centre
    shrink = inset_px * dist / camera.focal_px  # inset_px in metres at the sphere's distance
    inside = (b > 0) & (miss2 < (radius - shrink) ** 2)
    if np.count_nonzero(inside) < MIN_PIXELS:
        return None
    d, b, miss2, uv = d[inside], b[inside], miss2[inside], uv[inside]
    t = b - np.sqrt(radius * radius - miss2)
    n = (o + t[:, None] * d - c) / radius
    return uv, n / np.linalg.norm(n, axis=1, keepdims=True)


def sphere_likeness(image: np.ndarray, camera: PinholeCamera, centre: np.ndarray, radius: float) -> float:
    """How much better the photo inside a hypothesised sphere's outline is explained as that sphere's
    shading than as floor: the RMS residual of the least-squares fit of each colour channel by nine smooth
    functions of the pixel position (a floor), over that by the nine spherical harmonics of the sphere's
    normals. About 1 or less where the inside is floor, lit or in shadow (or floor and part of the ball);
    well above 1 on a ball lit from one side. ``image`` is linear RGB (H, W, 3). 0 when the outline holds
    too few pixels."""
    got = sphere_pixels(camera, centre, radius)
    if got is None:
        return 0.0
    uv, n = got
    rgb = np.asarray(image, float)[uv[:, 1], uv[:, 0], :]
    rms = []
    for basis in (_sh9(n), _biquadratic(uv.astype(float))):
        coef, *_ = np.linalg.lstsq(basis, rgb, rcond=None)
        res = rgb - basis @ coef
        rms.append(float(np.sqrt(np.mean(res * res))))
    sphere, floor = rms
    if not sphere > 0:
        return float("inf") if floor > 0 else 1.0
    return floor / sphere
