"""The Mitsuba 3 side of the test photos: a case's scene dictionary (camera, lights, BSDFs, the
"infinite" floor) and its render (``scalar_rgb``, imported lazily so that --help works without Mitsuba)."""

from __future__ import annotations

import math
import sys
from typing import Any

import numpy as np

from photos.cases import HEIGHT, WIDTH, Case
from photos.pixels import unit

MITSUBA_VERSION = "3.9.1"
VARIANT = "scalar_rgb"
PLANE_HALF_SIZE = 1000.0  # metres: the "infinite" floor is a 2000 m x 2000 m two-sided rectangle


def _mi():
    """Mitsuba with the scalar_rgb variant set (imported lazily so that --help works without it)."""
    try:
        import mitsuba as mi
    except ImportError:
        sys.exit(f"make_photos.py: needs Mitsuba 3: pip install 'mitsuba=={MITSUBA_VERSION}' "
                 "(or pip install '.[photos]')")
    if mi.__version__ != MITSUBA_VERSION:
        print(f"make_photos.py: warning: Mitsuba {mi.__version__}, the fixtures were made with "
              f"{MITSUBA_VERSION}", file=sys.stderr)
    mi.set_variant(VARIANT)
    return mi


def _rgb(v: list[float] | np.ndarray) -> dict[str, Any]:
    return {"type": "rgb", "value": [float(c) for c in v]}


def lamp_radiance(intensity_rgb: np.ndarray, radius: float) -> np.ndarray:
    """Radiance of a uniformly emitting sphere whose radiant intensity is ``intensity_rgb`` (W/sr).

    A Lambertian sphere of radius r and radiance L shows the projected area pi r^2 in every direction,
    so its intensity is I = L pi r^2 in every direction, and the irradiance it gives a surface that sees
    the whole sphere above its horizon is exactly I cos(theta) / d^2 (d to the centre), the point light
    at its centre.  So L = I / (pi r^2).
    """
    return np.asarray(intensity_rgb, float) / (math.pi * radius * radius)


def bsdf_dict(bsdf: dict[str, Any], *, specular_off: bool = False, diffuse_only: bool = False) -> dict[str, Any]:
    """Mitsuba BSDF of a case's material (two-sided wrapping is added for planes by the caller).

    ``specular_off``: a roughplastic with specular_reflectance 0 (its diffuse base only, Fresnel
    transmission included); ``diffuse_only``: a Lambertian BSDF with the roughplastic's diffuse colour.
    """
    if bsdf["type"] == "diffuse":
        return {"type": "diffuse", "reflectance": _rgb(bsdf["albedo"])}
    if diffuse_only:
        return {"type": "diffuse", "reflectance": _rgb(bsdf["diffuse"])}
    out = {
        "type": "roughplastic",
        "distribution": "ggx",
        "alpha": float(bsdf["alpha"]),
        "int_ior": 1.5,
        "nonlinear": False,
        "diffuse_reflectance": _rgb(bsdf["diffuse"]),
    }
    if specular_off:
        out["specular_reflectance"] = _rgb([0.0, 0.0, 0.0])
    return out


def mitsuba_dict(case: Case, *, spp: int, seed: int, integrator: str | None = None,
                 max_depth: int | None = None, environment: bool = True, point_lamp: bool = False,
                 material: str = "case") -> dict[str, Any]:
    """The Mitsuba scene dictionary of a case.

    Overrides (for calibration renders): ``integrator``/``max_depth``, ``environment=False``,
    ``point_lamp`` (a point light in place of the sphere lamp, same intensity), ``material`` "case",
    "specular_off" or "diffuse_only" (see :func:`bsdf_dict`).
    """
    mi = _mi()
    cam = case.camera
    integ = integrator or case.integrator
    depth = max_depth if integrator else case.max_depth
    scene: dict[str, Any] = {
        "type": "scene",
        "integrator": {"type": integ, **({"max_depth": depth} if depth is not None else {})},
        "sensor": {
            "type": "perspective",
            "fov": float(cam["vfov_deg"]),
            "fov_axis": "y",
            "near_clip": 0.01,
            "far_clip": 10000.0,
            "to_world": mi.ScalarTransform4f().look_at(
                origin=cam["position"], target=cam["look_at"], up=cam.get("up", [0.0, 1.0, 0.0])),
            "film": {"type": "hdrfilm", "width": WIDTH, "height": HEIGHT, "pixel_format": "rgb",
                     "rfilter": {"type": "box"}},
            "sampler": {"type": "stratified", "sample_count": spp, "seed": seed, "jitter": True},
        },
    }
    intensity_rgb = case.intensity * np.asarray(case.color, float)
    if case.lamp_radius > 0 and not point_lamp:
        scene["lamp"] = {
            "type": "sphere",
            "center": [float(c) for c in case.light_position],
            "radius": case.lamp_radius,
            "bsdf": {"type": "diffuse", "reflectance": _rgb([0.0, 0.0, 0.0])},
            "emitter": {"type": "area", "radiance": _rgb(lamp_radiance(intensity_rgb, case.lamp_radius))},
        }
    else:
        scene["light"] = {"type": "point", "position": [float(c) for c in case.light_position],
                          "intensity": _rgb(intensity_rgb)}
    if environment and case.environment is not None:
        scene["environment"] = {"type": "constant", "radiance": _rgb(case.environment)}
    for obj in case.objects:
        bsdf = bsdf_dict(obj["bsdf"], specular_off=material == "specular_off",
                         diffuse_only=material == "diffuse_only")
        if obj["shape"] == "sphere":
            scene[obj["name"]] = {"type": "sphere", "center": [float(c) for c in obj["center"]],
                                  "radius": float(obj["radius"]), "bsdf": bsdf}
        elif obj["shape"] == "mesh":  # an OBJ, flat-shaded, two-sided as rtloop's
            scene[obj["name"]] = {
                "type": "obj", "filename": str(obj["file"]), "face_normals": True,
                "to_world": mi.ScalarTransform4f().translate([float(c) for c in obj.get("position", [0, 0, 0])])
                @ mi.ScalarTransform4f().scale(float(obj.get("scale", 1.0))),
                "bsdf": {"type": "twosided", "bsdf": bsdf},
            }
        else:
            p = np.array(obj["point"], float)
            n = unit(np.array(obj["normal"], float))
            helper = np.array([1.0, 0.0, 0.0]) if abs(n[0]) < 0.9 else np.array([0.0, 0.0, 1.0])
            frame = mi.ScalarTransform4f().look_at(origin=p.tolist(), target=(p + n).tolist(),
                                                   up=np.cross(n, helper).tolist())
            scene[obj["name"]] = {
                "type": "rectangle",
                "to_world": frame @ mi.ScalarTransform4f().scale([PLANE_HALF_SIZE, PLANE_HALF_SIZE, 1.0]),
                "bsdf": {"type": "twosided", "bsdf": bsdf},
            }
    return scene


def render(scene_dict: dict[str, Any]) -> np.ndarray:
    """Linear radiance (HEIGHT, WIDTH, 3) float64 of a Mitsuba scene dictionary."""
    mi = _mi()
    return np.array(mi.render(mi.load_dict(scene_dict)), dtype=np.float64)
