"""The light's position as a photo determines it: a direction from the subject, to a fraction of a degree,
and a distance that a far light's shading barely depends on. Its covariance in x, y and z is split into the
distance's sigma (along the line from the subject) and the direction's (across it); a distance whose sigma
exceeds DISTANCE_DETERMINED of itself is reported as not determined, with the reason, rather than as a sigma
of metres on x, y and z."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

__all__ = ["DISTANCE_DETERMINED", "light_distance"]

#: A light's distance from the subject is determined when its sigma is at most this fraction of it.
DISTANCE_DETERMINED = 0.25

_AXES = ("light.position.x", "light.position.y", "light.position.z")


def subject_centre(scene: dict[str, Any]) -> np.ndarray | None:
    """The centre the light's distance and direction are measured from: the mean of the spheres' centres
    (None without a sphere)."""
    centres = [o["center"] for o in scene.get("objects", []) if o.get("shape") == "sphere"]
    return np.mean(np.asarray(centres, float), axis=0) if centres else None


def light_distance(names: list[str], cov: np.ndarray | None, idx: np.ndarray, determined: np.ndarray,
                   scene: dict[str, Any]) -> dict[str, Any] | None:
    """The light's distance and direction from the subject with their sigmas, from the position's covariance
    (``cov`` over the parameters ``idx`` of ``names``; ``determined`` per name). None where the position is
    not a fitted parameter or the scene has no sphere."""
    if not all(a in names for a in _AXES) or "position" not in scene.get("light", {}):
        return None
    centre = subject_centre(scene)
    if centre is None:
        return None
    offset = np.asarray(scene["light"]["position"], float) - centre
    distance = float(np.linalg.norm(offset))
    out: dict[str, Any] = {"from": centre.tolist(), "distance_m": distance, "distance_sigma_m": None,
                           "direction_sigma_deg": None, "distance_determined": False}
    k = [names.index(a) for a in _AXES]
    if cov is None or not all(determined[i] for i in k) or not distance > 0:
        out["why"] = "the light's position is not determined by the pixels used"
        return out
    at = [int(np.flatnonzero(idx == i)[0]) for i in k]
    c = np.asarray(cov, float)[np.ix_(at, at)]
    u = offset / distance
    radial = float(max(u @ c @ u, 0.0))
    across = c - np.outer(c @ u, u) - np.outer(u, u @ c) + radial * np.outer(u, u)  # P C P, P = I - u u^T
    out["distance_sigma_m"] = math.sqrt(radial)
    out["direction_sigma_deg"] = math.degrees(math.sqrt(max(float(np.linalg.eigvalsh(across)[-1]), 0.0)) / distance)
    out["distance_determined"] = bool(out["distance_sigma_m"] <= DISTANCE_DETERMINED * distance)
    if not out["distance_determined"]:
        out["why"] = (f"the distance's sigma ({out['distance_sigma_m']:.3g} m) exceeds {DISTANCE_DETERMINED:.0%} of "
                      f"the distance ({distance:.3g} m): the shading fixes the light's direction, not how far it "
                      "is (a light far from the subject); the x, y, z sigmas are that distance's")
    return out
