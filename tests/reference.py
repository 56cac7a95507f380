"""An independent float64 NumPy reference renderer for the rtloop scene format.

This is test scaffolding, not part of the package. It implements the scene specification directly
(pinhole camera through pixel centres, spheres and two-sided infinite planes, one point light with
hard shadows, Lambert + normalised Blinn-Phong shading) and shares no code with rtloop, so that the
tests can compare rtloop's renderer against it.

Specification (the public interface of the scene format):

* Camera: ``forward = normalize(look_at - position)``, ``right = normalize(cross(forward, up))``,
  ``true_up = cross(right, forward)``. Pixel ``(i, j)`` (``i`` the column from the left, ``j`` the row
  from the top) is sampled by the ray ``normalize(forward + x*right + y*true_up)`` with
  ``x = (2(i+0.5)/W - 1) * tan(vfov/2) * W/H`` and ``y = (1 - 2(j+0.5)/H) * tan(vfov/2)``.
* Radiance at the first hit: ``L = rho*ambient + V*I*color*max(0, n.l)/d^2 *
  [rho/pi + specular*(s+8)/(8pi)*max(0, n.h)^s]``; planes use the normal facing the viewer, sphere
  normals point outwards; a miss gives ``background``; the pixel value is ``exposure * L``.
"""

from __future__ import annotations

import copy
import json
import math
import os
from dataclasses import dataclass

import numpy as np

#: Offset of a shadow ray's origin along the (viewer-facing) surface normal, in metres.
SHADOW_OFFSET = 1e-6
#: Smallest accepted ray parameter for a primary-ray hit (unit directions, so metres).
PRIMARY_TMIN = 1e-9


# --------------------------------------------------------------------------------------------------
# Scene handling


def _v3(v) -> np.ndarray:
    a = np.asarray(v, dtype=np.float64).reshape(-1)
    if a.size == 1:
        a = np.repeat(a, 3)
    assert a.shape == (3,), f"expected 3 numbers, got {v!r}"
    return a


def with_defaults(scene) -> dict:
    """Return a deep copy of ``scene`` (a dict or a JSON file path) with the optional fields filled in."""
    if isinstance(scene, (str, os.PathLike)):
        with open(scene, encoding="utf-8") as fh:
            scene = json.load(fh)
    s = copy.deepcopy(scene)
    s.setdefault("ambient", [0.0, 0.0, 0.0])
    s.setdefault("background", [0.0, 0.0, 0.0])
    s.setdefault("exposure", 1.0)
    s.setdefault("fit", {})
    s["light"].setdefault("color", [1.0, 1.0, 1.0])
    for obj in s["objects"]:
        mat = obj.setdefault("material", {})
        mat.setdefault("specular", 0.0)
        mat.setdefault("shininess", 0.0)
    return s


@dataclass
class Camera:
    position: np.ndarray
    forward: np.ndarray
    right: np.ndarray
    true_up: np.ndarray
    tan_half: float


def camera(scene) -> Camera:
    """The camera basis of ``scene`` as the specification defines it."""
    cam = scene["camera"]
    pos = _v3(cam["position"])
    look = _v3(cam["look_at"])
    up = _v3(cam["up"])
    f = look - pos
    f = f / np.linalg.norm(f)
    r = np.cross(f, up)
    r = r / np.linalg.norm(r)
    u = np.cross(r, f)
    return Camera(pos, f, r, u, math.tan(math.radians(float(cam["vfov_deg"])) / 2.0))


def _size(scene, width, height) -> tuple[int, int]:
    w = int(scene["image"]["width"]) if width is None else int(width)
    h = int(scene["image"]["height"]) if height is None else int(height)
    return w, h


def primary_directions(scene, width=None, height=None, offsets=None) -> np.ndarray:
    """Unit ray directions, shape (H, W, 3), through the pixel centres.

    ``offsets`` (optional, shape (H, W, 2), values in [0, 1]) moves each ray to position ``(i + ox, j + oy)``
    inside its pixel instead of the centre ``(i + 0.5, j + 0.5)``.
    """
    w, h = _size(scene, width, height)
    cam = camera(scene)
    if offsets is None:
        offsets = np.full((h, w, 2), 0.5)
    offsets = np.asarray(offsets, dtype=np.float64)
    assert offsets.shape == (h, w, 2)
    i = np.arange(w, dtype=np.float64)[None, :] + offsets[..., 0]  # (H, W)
    j = np.arange(h, dtype=np.float64)[:, None] + offsets[..., 1]  # (H, W)
    x = (2.0 * i / w - 1.0) * cam.tan_half * w / h
    y = (1.0 - 2.0 * j / h) * cam.tan_half
    d = cam.forward + x[..., None] * cam.right + y[..., None] * cam.true_up
    return d / np.linalg.norm(d, axis=-1, keepdims=True)


def project(scene, point, width=None, height=None) -> tuple[float, float]:
    """Continuous pixel coordinates ``(i, j)`` of a world point (inverse of the ray formula).

    Integer values are pixel centres: the pixel containing the point is ``(round(i), round(j))``.
    """
    w, h = _size(scene, width, height)
    cam = camera(scene)
    p = _v3(point) - cam.position
    z = float(p @ cam.forward)
    assert z > 0, "point is behind the camera"
    x = float(p @ cam.right) / z
    y = float(p @ cam.true_up) / z
    i = (x / (cam.tan_half * w / h) + 1.0) * w / 2.0 - 0.5
    j = (1.0 - y / cam.tan_half) * h / 2.0 - 0.5
    return i, j


# --------------------------------------------------------------------------------------------------
# Intersection


def _ray_object_t(obj, o: np.ndarray, d: np.ndarray, tmin: float) -> np.ndarray:
    """Smallest ray parameter ``t > tmin`` where ``o + t d`` meets ``obj`` (inf for a miss).

    ``o`` is (N, 3) or (3,), ``d`` is (N, 3) and need not be unit length.
    """
    shape = obj["shape"]
    if shape == "sphere":
        c = _v3(obj["center"])
        r = float(obj["radius"])
        oc = o - c
        a = np.einsum("ij,ij->i", d, d)
        b = np.einsum("ij,ij->i", np.broadcast_to(oc, d.shape), d)
        cc = np.einsum("ij,ij->i", np.broadcast_to(oc, d.shape), np.broadcast_to(oc, d.shape)) - r * r
        disc = b * b - a * cc
        sq = np.sqrt(np.maximum(disc, 0.0))
        t0 = (-b - sq) / a
        t1 = (-b + sq) / a
        t = np.where(t0 > tmin, t0, np.where(t1 > tmin, t1, np.inf))
        return np.where(disc >= 0.0, t, np.inf)
    if shape == "plane":
        p = _v3(obj["point"])
        n = _v3(obj["normal"])
        n = n / np.linalg.norm(n)
        denom = d @ n
        num = np.broadcast_to((p - o) @ n, denom.shape)
        with np.errstate(divide="ignore", invalid="ignore"):
            t = num / denom
        ok = (denom != 0.0) & np.isfinite(t) & (t > tmin)
        return np.where(ok, t, np.inf)
    raise ValueError(f"unknown shape {shape!r}")


def nearest_hit(objects, o, d, tmin=PRIMARY_TMIN) -> tuple[np.ndarray, np.ndarray]:
    """Nearest hit over all objects: ``(t, ids)`` with ``ids = -1`` and ``t = inf`` for a miss."""
    ts = np.stack([_ray_object_t(obj, o, d, tmin) for obj in objects], axis=0)  # (K, N)
    ids = np.argmin(ts, axis=0)
    t = ts[ids, np.arange(ts.shape[1])]
    ids = np.where(np.isfinite(t), ids, -1)
    return t, ids


def occluded(objects, o, d, tmax: float) -> np.ndarray:
    """Whether any object meets the segment ``o + t d`` for ``0 < t < tmax``."""
    hit = np.zeros(d.shape[0], dtype=bool)
    for obj in objects:
        t = _ray_object_t(obj, o, d, 0.0)
        hit |= t < tmax
    return hit


# --------------------------------------------------------------------------------------------------
# Rendering


@dataclass
class Render:
    image: np.ndarray  # (H, W, 3) float64, exposure applied
    ids: np.ndarray  # (H, W) int, -1 = background
    visible: np.ndarray  # (H, W) bool, light visible from the hit point (False for background)
    n_dot_l: np.ndarray  # (H, W) float64, cosine at the hit point with the viewer-facing normal
    t: np.ndarray  # (H, W) float64, distance along the primary ray (inf for background)


def render_full(scene, width=None, height=None, offsets=None) -> Render:
    """Render ``scene`` (dict or path) at its size or at ``width`` x ``height``, one ray per pixel.

    The ray goes through the pixel centre, or through the positions ``offsets`` (see
    :func:`primary_directions`) inside the pixels.
    """
    s = with_defaults(scene)
    w, h = _size(s, width, height)
    objects = s["objects"]
    cam = camera(s)
    d = primary_directions(s, w, h, offsets).reshape(-1, 3)
    n_px = d.shape[0]
    t, ids = nearest_hit(objects, cam.position, d)
    hit = ids >= 0

    exposure = float(s["exposure"])
    img = np.broadcast_to(_v3(s["background"]), (n_px, 3)).copy()
    vis_out = np.zeros(n_px, dtype=bool)
    ndl_out = np.zeros(n_px)

    if np.any(hit):
        dh = d[hit]
        th = t[hit]
        idh = ids[hit]
        x = cam.position + th[:, None] * dh
        n = np.empty_like(x)
        rho = np.empty_like(x)
        ks = np.empty(x.shape[0])
        sh = np.empty(x.shape[0])
        for k, obj in enumerate(objects):
            m = idh == k
            if not np.any(m):
                continue
            if obj["shape"] == "sphere":
                nk = (x[m] - _v3(obj["center"])) / float(obj["radius"])
                nk = nk / np.linalg.norm(nk, axis=1, keepdims=True)
            else:
                nn = _v3(obj["normal"])
                nn = nn / np.linalg.norm(nn)
                nk = np.broadcast_to(nn, (int(m.sum()), 3)).copy()
                flip = np.einsum("ij,ij->i", nk, dh[m]) > 0.0
                nk[flip] = -nk[flip]
            n[m] = nk
            mat = obj["material"]
            rho[m] = _v3(mat["albedo"])
            ks[m] = float(mat["specular"])
            sh[m] = float(mat["shininess"])

        light = s["light"]
        intensity = float(light["intensity"])
        color = _v3(light["color"])
        if light.get("type") == "directional":
            # A light at infinity in direction d: no fall-off, shadow rays reach far beyond the scene.
            dvec = _v3(light["direction"]) / np.linalg.norm(light["direction"])
            lvec = np.broadcast_to(dvec, x.shape).copy()
            dist = np.ones(len(x))
            far = 1e6 * (1.0 + np.max(np.abs(x)))
            lp = x + far * lvec
        else:
            lp = _v3(light["position"])
            to_light = lp - x
            dist = np.linalg.norm(to_light, axis=1)
            lvec = to_light / dist[:, None]
        v = -dh
        hv = lvec + v
        hv = hv / np.maximum(np.linalg.norm(hv, axis=1, keepdims=True), 1e-300)
        ndl = np.einsum("ij,ij->i", n, lvec)
        ndh = np.maximum(np.einsum("ij,ij->i", n, hv), 0.0)

        # Shadow ray: from slightly above the surface to the light; parameter in (0, 1) spans the segment.
        so = x + SHADOW_OFFSET * n
        sd = lp - so
        vis = ~occluded(objects, so, sd, 1.0)

        brdf = rho / math.pi + (ks * (sh + 8.0) / (8.0 * math.pi) * ndh**sh)[:, None]
        direct = (vis * intensity * np.maximum(ndl, 0.0) / dist**2)[:, None] * color[None, :] * brdf
        img[hit] = rho * _v3(s["ambient"])[None, :] + direct
        vis_out[hit] = vis
        ndl_out[hit] = ndl

    return Render(
        image=(exposure * img).reshape(h, w, 3),
        ids=ids.reshape(h, w).astype(np.int64),
        visible=vis_out.reshape(h, w),
        n_dot_l=ndl_out.reshape(h, w),
        t=t.reshape(h, w),
    )


def render(scene, width=None, height=None) -> tuple[np.ndarray, np.ndarray]:
    """``(image float64 (H, W, 3), ids int (H, W))`` for ``scene``; see :func:`render_full`."""
    r = render_full(scene, width, height)
    return r.image, r.ids
