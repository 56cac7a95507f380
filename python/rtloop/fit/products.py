"""The products the image determines, and their one owner: P = exposure x intensity x colour x albedo
per object and channel, Q = intensity x specular, E = exposure x environment x albedo (with the
environment term); their bounds and their split back into scene values."""

from __future__ import annotations

import json
import math
from typing import Any

import numpy as np

from .. import _native
from ..scene import Scene, scene_to_dict

__all__ = ["albedo_derivative", "constant_term", "fix_gauge", "product_bounds", "product_range", "products", "products_of", "specular_product", "specular_range",
           "split_products", "unit_environment", "unit_environment_scene", "unit_light", "unit_light_scene", "unit_lobes",
           "unit_lobes_scene"]


def products_of(d: dict[str, Any]) -> dict[str, np.ndarray]:
    """Per object of the scene dict ``d``: exposure x light intensity x light colour x albedo (float64)."""
    light = np.asarray(d["light"]["color"], float) * float(d["light"]["intensity"]) * float(d["exposure"])
    return {o["name"]: light * np.asarray(o["material"]["albedo"], float) for o in d["objects"]}


def products(scene: Scene) -> dict[str, list[float]]:
    """:func:`products_of` the scene, as lists of floats (FitResult.products)."""
    return {name: [float(v) for v in p] for name, p in products_of(scene_to_dict(scene)).items()}


def product_range(ilo: float, ihi: float, scale_lo: Any, scale_hi: Any, albedo_lo: Any, albedo_hi: Any
                  ) -> tuple[Any, Any]:
    """Bounds of P from those of the intensity, of the channel scale (exposure x colour) and the albedo."""
    return ilo * scale_lo * albedo_lo, ihi * scale_hi * albedo_hi


def specular_product(intensity: float, specular: float) -> float:
    """Q = intensity x specular."""
    return intensity * specular


def specular_range(ilo: float, ihi: float, klo: float, khi: float) -> tuple[float, float]:
    """Bounds of Q = intensity x specular."""
    return ilo * klo, ihi * khi


def _unit_render(d: dict[str, Any], intensity: float, environment: float) -> np.ndarray:
    """The red channel of scene dict ``d`` rendered with a white light of ``intensity``, a grey
    environment of radiance ``environment``, every albedo 1, no specular, no ambient light, no
    interreflection, exposure 1, a black background."""
    return _native.render(_unit_scene(d, intensity, environment))[..., 0]


def _coated(o: dict[str, Any], material: dict[str, Any]) -> dict[str, Any]:
    """``material`` with object ``o``'s coat where it has one (a coated base's unit render goes through
    the coat)."""
    coat = o.get("material", {}).get("coat")
    return {**material, "coat": coat} if coat is not None else material


def unit_light_scene(d: dict[str, Any]) -> Scene:
    """The scene :func:`unit_light` renders (its red channel), for a caller that renders it with others."""
    return _unit_scene(d, 1.0, 0.0)


def _unit_scene(d: dict[str, Any], intensity: float, environment: float) -> Scene:
    """Scene dict ``d`` with a white light of ``intensity``, a grey environment of radiance
    ``environment``, every albedo 1, no specular, no ambient light, no interreflection, exposure 1, a
    black background."""
    unit = {
        **d,
        "light": {**d["light"], "intensity": intensity, "color": [1.0, 1.0, 1.0]},
        "ambient": [0.0, 0.0, 0.0],
        "environment": [environment] * 3,
        "interreflection": False,
        "exposure": 1.0,
        "background": [0.0, 0.0, 0.0],
        "objects": [{**o, "material": _coated(o, {"albedo": [1.0, 1.0, 1.0], "specular": 0.0})}
                    for o in d["objects"]],
        "fit": {},
    }
    return Scene(json.dumps(unit, allow_nan=False))


def unit_light(d: dict[str, Any]) -> np.ndarray:
    """The render of scene dict ``d`` per unit product (red channel): the direct light alone, of unit
    intensity, albedo 1, no ambient or environment light, no interreflection, no specular, exposure 1,
    black background. > 0 exactly where the light reaches the surface a pixel shows."""
    return _unit_render(d, 1.0, 0.0)


def unit_environment(d: dict[str, Any]) -> np.ndarray:
    """The scene's environment term per unit radiance (red channel): a grey environment of radiance 1
    seen by surfaces of albedo 1 (occluded by the scene's own spheres and planes), no light, no
    interreflection, exposure 1."""
    return _unit_render(d, 0.0, 1.0)


def unit_environment_scene(d: dict[str, Any]) -> Scene:
    """The scene :func:`unit_environment` renders (its red channel)."""
    return _unit_scene(d, 0.0, 1.0)


def albedo_derivative(d: dict[str, Any], c: int, unit: np.ndarray, unit_env: np.ndarray | None = None
                      ) -> np.ndarray:
    """d render / d albedo in channel ``c`` of scene dict ``d`` without interreflection (which makes the
    render depend on the other objects' albedos too): exposure x (ambient + intensity x colour x the
    unit-light render ``unit`` + environment x ``unit_env``, the unit-environment render, where the scene
    has an environment)."""
    light_rgb = np.array(d["light"]["color"], float) * d["light"]["intensity"]
    out = d["ambient"][c] + light_rgb[c] * unit
    env = d.get("environment", [0.0, 0.0, 0.0])[c]
    if env:
        if unit_env is None:
            raise ValueError("albedo_derivative: the scene has an environment: pass unit_env")
        out = out + env * unit_env
    return d["exposure"] * out


def unit_lobes(d: dict[str, Any], objects: set[int]) -> np.ndarray:
    """The scene ``d`` with only the specular lobes of ``objects`` (specular 1, their shininess; every
    albedo, the ambient light and the background 0): exactly the derivative of the render with respect
    to those objects' specular, on their pixels."""
    return _native.render(unit_lobes_scene(d, objects))


def unit_lobes_scene(d: dict[str, Any], objects: set[int]) -> Scene:
    """The scene :func:`unit_lobes` renders."""
    lobes = {
        **d,
        "ambient": [0.0, 0.0, 0.0],
        "background": [0.0, 0.0, 0.0],
        "interreflection": False,  # every albedo 0: the bounce adds exactly 0 (and would cost its gathers)
        "objects": [{**o, "material": _coated(o, {"albedo": [0.0, 0.0, 0.0],
                                                  "specular": 1.0 if k in objects else 0.0,
                                                  "shininess": o["material"]["shininess"]})}
                    for k, o in enumerate(d["objects"])],
        "fit": {},
    }
    return Scene(json.dumps(lobes, allow_nan=False))


#: The environment radiance's range when the fit adds the term itself (not in the fit section): up to the
#: radiance that alone renders an unoccluded white surface at the top of the photo's range, 1 / exposure.
AUTO_ENVIRONMENT_MAX = 1.0


def constant_term(scene: Scene) -> str:
    """The scene key of the constant radiance the closed form's second column models: "environment"
    (occluded), or "ambient" (unoccluded) when the scene gives or frees ambient light and no environment."""
    return _native.constant_term(scene)


def environment_range(scene: Scene) -> tuple[np.ndarray, np.ndarray]:
    """Per channel (min, max) of the constant radiance (:func:`constant_term`: the environment, or the
    ambient light) a fit may choose: its fit bounds when free, its value when the scene gives one, else
    [0, AUTO_ENVIRONMENT_MAX / exposure]."""
    d = scene_to_dict(scene)
    key = constant_term(scene)
    if key in scene.fit_paths:
        b = np.array(scene.bounds([key]), float)
        return b[:, 0], b[:, 1]
    env = np.asarray(d.get(key, [0.0, 0.0, 0.0]), float)
    if env.any():
        return env, env
    return np.zeros(3), np.full(3, AUTO_ENVIRONMENT_MAX / d["exposure"])


def product_bounds(scene: Scene, environment: bool = False) -> np.ndarray:
    """(objects, 4, 2) bounds of the closed-form unknowns from the fit section: rows 0-2 exposure x
    intensity x colour x albedo per channel, row 3 intensity x specular ((0, 0) for a matte object, which
    then costs no specular work); with ``environment`` (objects, 7, 2), rows 4-6 exposure x environment x
    albedo per channel (:func:`environment_range`)."""
    d = scene_to_dict(scene)
    paths = scene.fit_paths
    scale = np.array(d["light"]["color"], float) * d["exposure"]
    if "light.intensity" in paths:
        ilo, ihi = scene.bounds(["light.intensity"])[0]
    else:
        ilo = ihi = d["light"]["intensity"]
    out = np.zeros((len(d["objects"]), 7 if environment else 4, 2))
    elo, ehi = environment_range(scene)
    for k, o in enumerate(d["objects"]):
        p = f"objects.{o['name']}.albedo"
        b = np.array(scene.bounds([p])) if p in paths else np.repeat(np.array(o["material"]["albedo"])[:, None], 2, 1)
        out[k, :3, 0], out[k, :3, 1] = product_range(ilo, ihi, scale, scale, b[:, 0], b[:, 1])
        if environment:
            out[k, 4:, 0], out[k, 4:, 1] = product_range(1.0, 1.0, d["exposure"] * elo, d["exposure"] * ehi,
                                                         b[:, 0], b[:, 1])
        sp = f"objects.{o['name']}.specular"
        klo, khi = scene.bounds([sp])[0] if sp in paths else (o["material"]["specular"],) * 2
        out[k, 3] = specular_range(ilo, ihi, klo, khi)
    return out


def split_products(fitted: Scene, rows: list[list[float]], original: Scene, gauge: float | None = None) -> Scene:
    """Write closed-form products back as albedos, speculars and an intensity.

    ``rows``: per object [P_r, P_g, P_b], [P_r, P_g, P_b, Q] or [P_r, P_g, P_b, Q, E_r, E_g, E_b].
    Intensity x albedo (and x specular) is all the image determines; rtloop keeps the intensity at the
    scene's own value (the user's estimate of the lamp) unless an albedo or a specular would then exceed
    its upper bound, in which case the light is made just bright enough (the dimmest light consistent with
    the photo and the bounds). With E, the environment radiance is the least-squares value over the
    objects given their albedos (E_o,c = exposure x environment_c x albedo_o,c), within its range. With
    ``gauge`` (interreflection: 1 / the intensity the bounce was solved with, which the bounce measures)
    the intensity is that one, within its bounds.
    """
    d = scene_to_dict(fitted)
    paths = original.fit_paths
    scale = np.array(d["light"]["color"], float) * d["exposure"]
    intensity = d["light"]["intensity"]
    arr = np.asarray(rows, float)
    P = arr[:, :3]
    Q = arr[:, 3] if arr.shape[1] > 3 else np.zeros(len(arr))
    # The free albedos' objects (index into the rows) and their bounds, all at once: (n, 3) each.
    free = [k for k, o in enumerate(d["objects"]) if f"objects.{o['name']}.albedo" in paths]
    row_of = {k: i for i, k in enumerate(free)}
    bounds = np.array(original.bounds([f"objects.{d['objects'][k]['name']}.albedo" for k in free]) if free else [],
                      float).reshape(-1, 2)
    lo_all, hi_all = bounds[:, 0].reshape(-1, 3), bounds[:, 1].reshape(-1, 3)
    if "light.intensity" in paths:
        ilo, ihi = original.bounds(["light.intensity"])[0]
        intensity = min(max(scene_to_dict(original)["light"]["intensity"], ilo), ihi)
        need = intensity
        with np.errstate(divide="ignore", invalid="ignore"):
            req = np.where((hi_all > 0) & (scale > 0), P[free] / (scale * np.maximum(hi_all, 1e-300)), 0.0)
        req_max = req.max(axis=1)
        for k, o in enumerate(d["objects"]):
            if k in row_of:
                need = max(need, float(req_max[row_of[k]]))
            sp = f"objects.{o['name']}.specular"
            if sp in paths and Q[k] > 0:
                khi = original.bounds([sp])[0][1]
                need = max(need, float(Q[k] / khi) if khi > 0 else need)
        intensity = min(max(need, ilo), ihi)
        measured = _intensity_from_known(d, original, arr)
        if measured is not None:
            intensity = min(max(measured, ilo), ihi)
        if gauge is not None and gauge > 0:
            intensity = min(max(1.0 / gauge, ilo), ihi)
        fitted = fitted.with_params([intensity], ["light.intensity"])
    with np.errstate(divide="ignore", invalid="ignore"):
        rho_all = np.where(scale > 0, P[free] / (intensity * scale), lo_all)
    albedos = np.clip(np.nan_to_num(rho_all), lo_all, hi_all)
    for k, o in enumerate(d["objects"]):
        p = f"objects.{o['name']}.albedo"
        if k in row_of:
            fitted = fitted.with_params([float(v) for v in albedos[row_of[k]]], [p])
        sp = f"objects.{o['name']}.specular"
        if sp in paths:
            klo, khi = original.bounds([sp])[0]
            ks = Q[k] / intensity if intensity > 0 else klo
            fitted = fitted.with_params([float(np.clip(np.nan_to_num(ks), klo, khi))], [sp])
    if arr.shape[1] >= 7:
        rho = np.array([o["material"]["albedo"] for o in scene_to_dict(fitted)["objects"]], float)
        E = arr[:, 4:7]
        elo, ehi = environment_range(original)
        den = d["exposure"] * np.sum(rho * rho, axis=0)
        with np.errstate(divide="ignore", invalid="ignore"):
            env = np.where(den > 0, np.sum(E * rho, axis=0) / den, elo)
        env = [float(v) for v in np.clip(np.nan_to_num(env), elo, ehi)]
        key = constant_term(original)
        if key in paths:
            fitted = fitted.with_params(env, [key])
        else:  # the term the fit added itself (or the scene's fixed value): written in, not in the fit section
            fitted = Scene(json.dumps({**scene_to_dict(fitted), key: env}, allow_nan=False))
    return fitted


#: The least peak radiance (half an 8-bit code) of a known lobe that measures the light's intensity.
HIGHLIGHT_SEEN = 0.5 / 255


def _intensity_from_known(d: dict[str, Any], original: Scene, arr: np.ndarray) -> float | None:
    """The intensity the photo measures against something of known strength, by least squares: a fixed,
    non-zero specular k (its product Q = intensity x k), else a fixed constant radiance a, ambient or
    occluded environment alike (per object and channel P / E = intensity x colour_c / a_c, P = exposure x
    intensity x colour x albedo, E = exposure x a x albedo). None when neither is in the scene (a zero
    radiance measures nothing)."""
    paths = original.fit_paths
    ks = np.array([o["material"].get("specular", 0.0) if f"objects.{o['name']}.specular" not in paths else 0.0
                   for o in scene_to_dict(original)["objects"]], float)
    if arr.shape[1] > 3 and (ks > 0).any():
        # Each Q weighted by how much highlight its object shows (sum of its unit lobe squared at the fitted
        # light); a lobe that shows less than half an 8-bit code, or whose Q sits at a bound of its range,
        # measures nothing.
        known = {k for k in range(len(ks)) if ks[k] > 0}
        lobes = unit_lobes(d, known).max(axis=2).ravel()
        ids = _native.object_ids(original).ravel()  # the geometry is not fitted here
        ilo, ihi = original.bounds(["light.intensity"])[0]
        peak_scale = d["exposure"] * max(d["light"]["color"])
        w = np.zeros(len(ks))
        for k in known:
            q, mine = arr[k, 3], lobes[ids == k]
            inside = ilo * ks[k] * (1 + 1e-9) < q < ihi * ks[k] * (1 - 1e-9)
            if mine.size and inside and q * peak_scale * float(mine.max()) >= HIGHLIGHT_SEEN:
                w[k] = float(np.sum(mine * mine))
        den = float(np.sum(w * ks * ks))
        if den > 0:
            return float(np.sum(w * ks * arr[:, 3]) / den)
    key = constant_term(original)
    if arr.shape[1] < 7 or key in paths:
        return None
    a = np.asarray(scene_to_dict(original).get(key, [0.0, 0.0, 0.0]), float)
    colour = np.asarray(d["light"]["color"], float)
    w = np.where(a > 0, colour / np.where(a > 0, a, 1.0), 0.0) * arr[:, 4:7]  # P ~ intensity x w
    den = float(np.sum(w * w))
    return float(np.sum(w * arr[:, :3]) / den) if den > 0 else None


def fix_gauge(fitted: Scene, albedo_paths: list[str], bounds_scene: Scene) -> Scene:
    """Scale the light up (and the albedos down) until every albedo is within its original bounds, as far as
    the intensity's upper bound and the albedos' lower bounds allow; what is still outside is clamped, so
    every value ends inside the bounds of ``bounds_scene``."""
    s, s_max = 1.0, math.inf
    intensity = fitted.get_params(["light.intensity"])[0]
    ihi = bounds_scene.bounds(["light.intensity"])[0][1]
    if intensity > 0:
        s_max = ihi / intensity
    for p in albedo_paths:
        for v, (lo, hi) in zip(fitted.get_params([p]), bounds_scene.bounds([p])):
            if hi > 0:
                s = max(s, v / hi)
            if lo > 0:
                s_max = min(s_max, v / lo)
    s = min(s, max(1.0, s_max))
    out = fitted
    if s > 1.0:
        out = out.with_params([intensity * s], ["light.intensity"])
    for p in albedo_paths:
        b = bounds_scene.bounds([p])
        out = out.with_params([min(max(v / s, lo), hi) for v, (lo, hi) in zip(fitted.get_params([p]), b)], [p])
    return out
