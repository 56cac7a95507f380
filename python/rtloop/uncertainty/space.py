"""Which parameters sigma is reported for, and the scene that renders them: the scene's own fit
parameters, or the products where the image determines only those; a direction as two angles."""

from __future__ import annotations

import json
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..fit.products import product_range, products_of, specular_product, specular_range
from ..scene import MAX_MAGNITUDE, Scene

#: A linear parameter's (an albedo's, a product's, a specular's) scale is at most this times its value.
LINEAR_SCALE = 10.0
#: The scale of a direction angle (radians): the default step is STEP_FRACTION of it.
ANGLE_SCALE = 1.0

_LIGHT_SCALE = ("light.intensity", "light.color", "exposure")
_ANGLES = ("light.direction.u", "light.direction.v")


@dataclass
class _Space:
    """The parameters sigma is reported for, and how they map onto a scene that renders them."""

    work: Scene  # the scene whose fit parameters are varied (the products scene, or the fitted one)
    paths: list[str]  # work's fit paths, in the order of its parameter vector
    names: list[str]  # one per parameter
    theta0: np.ndarray
    lo: np.ndarray
    hi: np.ndarray
    scale: np.ndarray
    albedo: dict[int, tuple[int, int]]  # parameter index -> (object index, channel) of an albedo
    specular: dict[int, int]  # parameter index -> object index of a specular (the image is linear in it)
    factor: np.ndarray  # work's value / the parameter's (1 but for a product under a coloured work light)
    direction: tuple[int, np.ndarray, np.ndarray, np.ndarray] | None  # index of angle u, d, u, v

    def native(self, theta: np.ndarray) -> list[float]:
        """``work``'s parameter vector for ``theta`` (the two angles become a unit direction)."""
        theta = theta * self.factor
        if self.direction is None:
            return [float(v) for v in theta]
        k, d, u, v = self.direction
        return [float(x) for x in (*theta[:k], *_rotate(d, u, v, theta[k], theta[k + 1]), *theta[k + 2 :])]


def _products_blocker(scene: Scene, d: dict[str, Any]) -> str | None:
    """None when the image determines exactly the products of this scene and fit section, else why not."""
    paths = scene.fit_paths
    fixed = [o["name"] for o in d["objects"] if f"objects.{o['name']}.albedo" not in paths]
    if fixed:
        return f"the albedo of {', '.join(fixed)} is fixed"
    if not any(p in paths for p in _LIGHT_SCALE):
        return "no light scale (intensity, colour, exposure) is free"
    if any(v != 0 for v in d["ambient"]) or "ambient" in paths:
        return "the scene has ambient light"
    if d.get("interreflection"):
        return "the scene has interreflection (a bounce is as bright as the albedos themselves)"
    known = [o["name"] for o in d["objects"]
             if o["material"]["specular"] != 0 and f"objects.{o['name']}.specular" not in paths]
    if known:
        return f"the specular of {', '.join(known)} is fixed (a highlight of known strength measures the light)"
    if "light.color" in paths and any(p.endswith(".specular") for p in paths):
        return "the light colour is free and a specular term is fitted (a highlight shows the light's colour)"
    return None


def _scene_space(scene: Scene, d: dict[str, Any]) -> tuple[_Space, dict[str, Any]]:
    """The scene's own fit parameters (a direction as two angles)."""
    paths = list(scene.fit_paths)
    b = np.array(scene.bounds(paths), dtype=np.float64).reshape(-1, 2)
    return _space(scene, paths, d, b[:, 0], b[:, 1], {}), d


def _products_space(scene: Scene, d: dict[str, Any]) -> tuple[_Space, dict[str, Any]]:
    """A scene that renders the products, and its parameters; ``d`` (the scene as a dict) is changed into
    that scene's dict, and returned.

    The work scene's light has intensity 1 and colour w = exposure x colour (the fitted values; 1 in a
    channel where w is 0 and no specular is fitted), exposure 1: an albedo P_c / w_c there renders the
    diffuse product P_c (the parameter's ``factor`` is 1 / w_c), and a specular Q renders the lobe
    Q x w_c x lobe, as exposure x intensity x colour_c x specular x lobe does in the fitted scene.
    """
    paths = scene.fit_paths
    prods = products_of(d)
    glossy = [o for o in d["objects"] if f"objects.{o['name']}.specular" in paths]
    w = np.array(d["light"]["color"], float) * d["exposure"]
    w_work = np.where((w > 0) | bool(glossy), w, 1.0)  # a dark channel stays dark only under a lobe
    inv_w = np.divide(1.0, w_work, out=np.ones(3), where=w_work > 0)
    color_scale = w
    if "light.intensity" in paths:
        ilo, ihi = scene.bounds(["light.intensity"])[0]
    else:
        ilo = ihi = d["light"]["intensity"]
    if "light.color" in paths:
        cb = np.array(scene.bounds(["light.color"]))
        color_scale = d["exposure"] * np.array([cb[:, 0], cb[:, 1]])  # (2, 3): min and max
    else:
        color_scale = np.array([color_scale, color_scale])
    e_range = np.ones(2)  # the exposure's bounds / its fitted value
    if "exposure" in paths:
        e_range = np.array(scene.bounds(["exposure"])[0]) / d["exposure"]
        color_scale = color_scale * e_range[:, None]
    fit_old = d["fit"]
    fit_new: dict[str, Any] = {}
    bounds: dict[str, tuple[float, float]] = {}  # the products' own bounds, by work's parameter name
    factor: dict[str, float] = {}  # work's value / the product's, by work's parameter name
    rename: dict[str, str] = {}  # work's parameter name -> the product's
    for p in ("light.position", "light.direction"):
        if p in paths:
            fit_new[p] = fit_old[p]
    for o in d["objects"]:
        p = f"objects.{o['name']}.albedo"
        ab = np.array(scene.bounds([p]))
        prod = prods[o["name"]]
        plo, phi = product_range(ilo, ihi, color_scale[0], color_scale[1], ab[:, 0], ab[:, 1])
        o["material"]["albedo"] = [float(v) for v in prod * inv_w]
        top = float(max(np.max(phi), np.max(prod), 1.0) * np.max(inv_w))
        fit_new[p] = {"min": [0.0, 0.0, 0.0], "max": [_work_bound(top, np.max(prod * inv_w))] * 3}
        for c, lo_c, hi_c, f_c in zip("rgb", plo, phi, inv_w):
            bounds[f"{p}.{c}"] = (float(lo_c), float(hi_c))
            factor[f"{p}.{c}"] = float(f_c)
            rename[f"{p}.{c}"] = f"products.{o['name']}.{c}"
    for o in glossy:
        # Q = intensity x specular (at the fitted exposure, which the work light's colour carries).
        p = f"objects.{o['name']}.specular"
        klo, khi = scene.bounds([p])[0]
        q = specular_product(d["light"]["intensity"], o["material"]["specular"])
        o["material"]["specular"] = float(q)
        qlo, qhi = specular_range(ilo, ihi, klo, khi)
        bounds[p] = (float(qlo * e_range[0]), float(qhi * e_range[1]))
        fit_new[p] = {"min": 0.0, "max": _work_bound(max(bounds[p][1], q, 1.0), q)}
        rename[p] = f"products.{o['name']}.specular"
    for p in paths:
        if p not in _LIGHT_SCALE and p not in fit_new:
            fit_new[p] = fit_old[p]
    if any(v != 0 for v in d.get("environment", [0, 0, 0])):
        # The work albedo P_c / w_c is intensity x albedo_c: the environment term exposure x env x albedo
        # stays the same with env / intensity at exposure 1 (held at its fitted value, not varied).
        i = float(d["light"]["intensity"])
        d["environment"] = [float(d["exposure"] * v / i) if i > 0 else 0.0 for v in d["environment"]]
    d["light"]["intensity"], d["light"]["color"], d["exposure"] = 1.0, [float(v) for v in w_work], 1.0
    d["fit"] = fit_new
    work = Scene(json.dumps(d, allow_nan=False))  # made from a valid scene: load_scene's checks not needed
    new_paths = list(work.fit_paths)
    native_names = work.param_names(new_paths)
    b = np.array(work.bounds(new_paths), dtype=np.float64).reshape(-1, 2)
    for i, name in enumerate(native_names):
        if name in bounds:
            b[i] = bounds[name]
    return _space(work, new_paths, d, b[:, 0], b[:, 1], rename, factor), d


def _work_bound(top: float, value: float) -> float:
    """The work scene's upper bound for a product: ``top``, within the scene format's limit on bounds (a
    light of 3e7 W/sr and a specular of 4 make products beyond it; the products' own bounds, which the
    estimate uses, are kept apart) but never below the product's ``value``."""
    return float(max(min(top, MAX_MAGNITUDE), value))


def _space(
    work: Scene,
    paths: list[str],
    d: dict[str, Any],
    lo: np.ndarray,
    hi: np.ndarray,
    rename: dict[str, str],
    factor: dict[str, float] | None = None,
) -> _Space:
    """The parameters of ``work``'s ``paths``: scales from the bounds, albedos and speculars marked as
    linear, and a direction replaced by two angles about the fitted one (no bounds, scale ANGLE_SCALE).
    ``rename`` and ``factor`` (work's value / the parameter's, default 1) are by work's parameter name;
    ``lo``, ``hi`` are the parameters' own bounds."""
    native = work.param_names(paths)
    fac = np.array([(factor or {}).get(name, 1.0) for name in native])
    values = np.array(work.get_params(paths), dtype=np.float64) / fac
    rng = hi - lo
    scale = np.where(rng > 0, rng, np.maximum(np.abs(values), 1.0))
    _light_scale(scale, native, d)
    objects = {f"objects.{o['name']}.": i for i, o in enumerate(d["objects"])}
    albedo, specular = {}, {}
    for i, name in enumerate(native):
        head, _, tail = name.rpartition(".albedo.")
        if head + "." in objects and tail in ("r", "g", "b"):
            albedo[i] = (objects[head + "."], "rgb".index(tail))
        elif name.endswith(".specular") and name[: -len("specular")] in objects:
            specular[i] = objects[name[: -len("specular")]]
    # A linear parameter's column is exact (or rendered, with a bounce); its step says which pixels cross the
    # clip within it. Bounds far wider than the value (a light of 3e5 W/sr with its intensity free over
    # decades) would step the products by thousands of times themselves and put every pixel on the kink: at
    # most LINEAR_SCALE times the value (a step of a hundredth of it: a float32 render's rounding stays at
    # 1e-5 of a rendered column).
    for k in (*albedo, *specular):
        scale[k] = min(scale[k], max(LINEAR_SCALE * abs(values[k]), 1e-6 * scale[k]))
    names = [rename.get(name, name) for name in native]
    direction = None
    if "light.direction.x" in native:
        k = native.index("light.direction.x")
        dvec, u, v = _tangent_basis(np.array(values[k : k + 3]), np.array(d["camera"]["up"], float))
        names[k : k + 3] = list(_ANGLES)
        values = np.concatenate([values[:k], [0.0, 0.0], values[k + 3 :]])
        lo = np.concatenate([lo[:k], [-np.inf, -np.inf], lo[k + 3 :]])
        hi = np.concatenate([hi[:k], [np.inf, np.inf], hi[k + 3 :]])
        scale = np.concatenate([scale[:k], [ANGLE_SCALE, ANGLE_SCALE], scale[k + 3 :]])
        fac = np.concatenate([fac[:k], [1.0, 1.0], fac[k + 3 :]])
        albedo = {(i - 1 if i > k else i): oc for i, oc in albedo.items()}
        specular = {(i - 1 if i > k else i): o for i, o in specular.items()}
        direction = (k, dvec, u, v)
    return _Space(work, paths, names, values, lo, hi, scale, albedo, specular, fac, direction)


def _light_scale(scale: np.ndarray, native: list[str], d: dict[str, Any]) -> None:
    """A point light's position is scaled by its distance from the subject (the spheres' centre, else the
    camera) where that is shorter than its bounds' range: the finite-difference step is then a fixed small
    angle seen from the subject, however wide the box (a box of +-1000 m around a light 20 m away would
    step it by 2 m, 6 degrees, and the derivative would not be one)."""
    if "position" not in d.get("light", {}):
        return
    from .light import subject_centre

    centre = subject_centre(d)
    if centre is None:
        centre = np.asarray(d["camera"]["position"], float)
    distance = float(np.linalg.norm(np.asarray(d["light"]["position"], float) - centre))
    if not (np.isfinite(distance) and distance > 0):
        return
    for axis in "xyz":
        name = f"light.position.{axis}"
        if name in native:
            k = native.index(name)
            scale[k] = min(scale[k], distance)


def _tangent_basis(d: np.ndarray, up: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Unit ``d`` and two unit axes perpendicular to it: u = up x d (horizontal), v = d x u (towards up)."""
    d = d / np.linalg.norm(d)
    u = np.cross(up, d)
    if np.linalg.norm(u) < 1e-6 * np.linalg.norm(up):  # d along up: any horizontal axis will do
        u = np.cross(np.eye(3)[int(np.argmin(np.abs(d)))], d)
    u /= np.linalg.norm(u)
    return d, u, np.cross(d, u)


def _rotate(d: np.ndarray, u: np.ndarray, v: np.ndarray, a: float, b: float) -> np.ndarray:
    """``d`` turned by the angle |(a, b)| (radians) towards a u + b v: the exponential map at d."""
    w = a * u + b * v
    angle = float(np.hypot(a, b))
    if angle == 0.0:
        return d
    return np.cos(angle) * d + np.sin(angle) * (w / angle)
