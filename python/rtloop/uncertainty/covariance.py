"""What follows from a fit's covariance: its container, a directional light's cone of directions, and the
sigma of the diffuse products."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from .space import _Space


@dataclass
class _Covariance:
    """The covariance of the determined parameters and what follows from it."""

    sigma: dict[str, float | None]
    corr: list[list[float | None]]
    condition: float | None
    rank: int
    cov: np.ndarray | None  # over the parameters idx_p
    determined: np.ndarray
    idx_p: np.ndarray


def _product_sigma(space: _Space, wd: dict[str, Any], fit: _Covariance | None, use_products: bool
                   ) -> dict[str, float | None]:
    """The sigma of every diffuse product exposure x intensity x colour_c x albedo_c (``products.<object>.<c>``)
    from a covariance: the parameter's own where the products are the parameters, else propagated to first
    order (the gradient of the product over exposure, intensity, colour and albedo through the covariance,
    correlations with the light's position and between the factors included). None where a factor the product
    depends on is free but not determined."""
    names = space.names
    out: dict[str, float | None] = {}
    objects = [o["name"] for o in wd["objects"]]
    if fit is None or fit.cov is None:
        return {f"products.{o}.{c}": None for o in objects for c in "rgb"}
    where = {int(k): a for a, k in enumerate(fit.idx_p)}
    if use_products:
        for o in objects:
            for c in "rgb":
                n = f"products.{o}.{c}"
                k = names.index(n) if n in names else None
                out[n] = (float(np.sqrt(max(fit.cov[where[k], where[k]], 0.0)))
                          if k is not None and fit.determined[k] and k in where else None)
        return out
    light, e = wd["light"], float(wd["exposure"])
    for oi, o in enumerate(wd["objects"]):
        for ci, c in enumerate("rgb"):
            factors = {"exposure": e, "light.intensity": float(light["intensity"]),
                       f"light.color.{c}": float(light["color"][ci]),
                       f"objects.{o['name']}.albedo.{c}": float(o["material"]["albedo"][ci])}
            grad = np.zeros(fit.idx_p.size)
            ok = True
            for n in factors:
                if n not in names:
                    continue
                k = names.index(n)
                if not fit.determined[k] or k not in where:
                    ok = False
                    break
                grad[where[k]] = float(np.prod([w for m, w in factors.items() if m != n])) / space.factor[k]
            out[f"products.{o['name']}.{c}"] = float(np.sqrt(max(grad @ fit.cov @ grad, 0.0))) if ok else None
    return out


def _direction_cone(space: _Space, fit: _Covariance) -> dict[str, Any]:
    """A directional light's frame and its two angles' sigma as cone angles in degrees (None where an
    angle is not determined)."""
    k, dvec, u, v = space.direction
    block: dict[str, Any] = {"direction": dvec.tolist(), "u": u.tolist(), "v": v.tolist(),
                             "angle_deg": None, "rms_angle_deg": None}
    if fit.cov is not None and fit.determined[k] and fit.determined[k + 1]:
        at = [int(np.flatnonzero(fit.idx_p == k)[0]), int(np.flatnonzero(fit.idx_p == k + 1)[0])]
        c2 = fit.cov[np.ix_(at, at)]
        block["angle_deg"] = float(np.degrees(np.sqrt(max(np.linalg.eigvalsh(c2)[-1], 0.0))))
        block["rms_angle_deg"] = float(np.degrees(np.sqrt(max(np.trace(c2), 0.0))))
    return block
