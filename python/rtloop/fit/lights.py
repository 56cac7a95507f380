"""The lights fit: any number of point, directional, sphere and rectangle lights, their geometry searched by L-SHADE
one light at a time and then together (:mod:`.lights_search`) and, per object and channel, each light's
product (intensity x colour x albedo) and a constant solved in closed form (non-negative least squares;
``rust/fitness/lights.rs``). docs/methods.md, "Several lights".

``fit(scene, image, lights=N)`` lands here for N > 1, or for a scene that already has several lights, a
sphere light or a rectangle light; with ``lights="auto"`` the number is chosen from held-out pixels (:func:`choose_count`).
"""

from __future__ import annotations

import copy
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .. import _native
from .._pixels import edges
from ..errors import RtloopError
from ..scene import Scene, load_scene, scene_to_dict
from .lights_errors import light_errors
from .lights_search import Stages, staged, path_width

#: Pixels compared per fit at most (a seeded sample of the objects' interiors).
MAX_PIXELS = 6000
#: A pixel this bright in any channel is taken as clipped and left out.
CLIPPED = 0.99
#: The most lights ``lights="auto"`` tries.
AUTO_LIMIT = 3
#: The share of the steepest pixels left out of the held-out error (:func:`steep`).
EDGE_SHARE = 0.1
#: A further light is kept when it lowers the held-out squared error by this fraction at least.
AUTO_GAIN = 0.25
#: The most lights with a glossy object (``rust/fitness/lights.rs``'s MAX_GLOSSY_LIGHTS): two columns per
#: light and the constant stay within the exhaustive non-negative least squares' reach.
MAX_GLOSSY_LIGHTS = 4


@dataclass
class LightsFit:
    """What the lights fit found."""

    scene: Scene
    #: Per light: name, kind, position or direction, radius (size and normal), intensity, colour, its share
    #: of the light, and the error bars (``position_error`` per axis in metres, ``direction_error``,
    #: ``radius_error``, ``size_error`` (width, height; None for a side the photo does not fix, with
    #: ``size_note`` saying so), ``intensity_error``; None for the first light's intensity, which is held).
    lights: list[dict[str, Any]]
    #: Per object: per light the RGB product intensity x colour x albedo, then the constant (ambient) term,
    #: then, where any object is glossy, per light the lobe's product intensity x colour x specular.
    products: dict[str, list[list[float]]]
    loss: float
    evaluations: int
    seconds: float
    #: With ``lights="auto"``: per count tried, its held-out error and whether it was kept.
    evidence: list[dict[str, Any]] = field(default_factory=list)
    #: From the default fit (``lights`` not given): the one-light fit's test that tried a further light
    #: (:func:`.more_lights.gate`); None otherwise.
    gate: dict[str, Any] | None = None


def _light_list(d: dict[str, Any]) -> list[dict[str, Any]]:
    if "lights" in d:
        return [dict(light) for light in d["lights"]]
    return [{"name": "light0", **d["light"]}]


def _geometric_path(d: dict[str, Any], light: dict[str, Any], index: int) -> list[str]:
    """The fit paths of one light's geometry that the scene frees."""
    name = light["name"]
    names = ["light.position", "light.direction"] if index == 0 else [f"lights.{name}.position",
                                                                      f"lights.{name}.direction"]
    return [p for p in [*names, f"lights.{name}.radius", f"lights.{name}.size"] if p in d["fit"]]


def _locate(path: str, lights: list[dict[str, Any]]) -> tuple[dict[str, Any], str]:
    """The light a geometric path names and the key it sets."""
    parts = path.split(".")
    if len(parts) == 2:
        return lights[0], parts[1]
    return next(light for light in lights if light["name"] == parts[1]), parts[2]


def with_lights(scene: Scene, count: int) -> tuple[dict[str, Any], list[str]]:
    """The scene as a dict with ``count`` lights: its own, then copies of its first light named ``light1``,
    ... with the first light's position bounds; and the searched geometric paths."""
    d = scene_to_dict(scene)
    coated = [o["name"] for o in d["objects"] if "coat" in o["material"]]
    if coated:
        raise RtloopError(f"lights: objects.{coated[0]}.material.coat: the lights fit models Lambertian objects; "
                          "fit a coated object with one light")
    lights = _light_list(d)
    shininess = [p for p in d["fit"] if p.startswith("objects.") and p.endswith(".shininess")]
    if shininess:
        raise RtloopError(f"lights: fit[{shininess[0]!r}]: the lights fit holds a lobe's shininess as the scene gives "
                          "it; give it without a fit entry, or fit it with one light")
    glossy = [o["name"] for o in d["objects"] if o["material"].get("specular", 0.0) > 0]
    if glossy and max(count, len(lights)) > MAX_GLOSSY_LIGHTS:
        raise RtloopError(f"lights: objects.{glossy[0]}.specular: the lights fit takes a glossy object under at most "
                          f"{MAX_GLOSSY_LIGHTS} lights (asked for {max(count, len(lights))})")
    if count < len(lights):
        raise RtloopError(f"lights: the scene has {len(lights)} lights; cannot fit fewer ({count})")
    first = lights[0]
    fit = d["fit"]
    box = fit.get("light.position") or fit.get(f"lights.{first['name']}.position")
    for k in range(len(lights), count):
        if box is None or "position" not in first:
            raise RtloopError("lights: adding a light needs the first light's position free in the fit section "
                              "(its bounds are the new light's)")
        name = f"light{k}"
        while any(light["name"] == name for light in lights):
            name += "_"
        lo, hi = np.asarray(box["min"], float), np.asarray(box["max"], float)
        lights.append({"name": name, "position": list((lo + hi) / 2), "intensity": first["intensity"],
                       "color": first.get("color", [1.0, 1.0, 1.0])})
        fit[f"lights.{name}.position"] = copy.deepcopy(box)
    d.pop("light", None)
    d["lights"] = lights
    # The first light's own paths by their single-light names (as the scene reads them back).
    for key in ("position", "direction", "intensity", "color"):
        if f"lights.{first['name']}.{key}" in fit:
            fit[f"light.{key}"] = fit.pop(f"lights.{first['name']}.{key}")
    paths = [p for i, light in enumerate(lights) for p in _geometric_path(d, light, i)]
    if not paths:
        raise RtloopError("lights: no light's position, direction, radius or size is free in the fit section")
    return d, paths


def choose_pixels(scene: Scene, target: np.ndarray, seed: int, mask: np.ndarray | None = None) -> np.ndarray:
    """A seeded sample of at most ``MAX_PIXELS`` object pixels away from silhouettes and not clipped."""
    ids = np.asarray(_native.object_ids(scene))
    ok = (ids >= 0) & ~edges(ids) & (target.max(axis=2) < CLIPPED)
    idx = np.flatnonzero(ok.ravel())
    if mask is not None:
        idx = np.intersect1d(idx, mask)
    if idx.size == 0:
        raise RtloopError("image: no unclipped pixel inside an object to fit the lights to")
    if idx.size > MAX_PIXELS:
        idx = np.sort(np.random.default_rng(seed).choice(idx, MAX_PIXELS, replace=False))
    return idx.astype(np.uint32)


def _split(d: dict[str, Any], x: list[float], paths: list[str], products: list[list[list[float]]]) -> tuple[dict[str, Any], list[dict[str, Any]]]:
    """Write the geometry and the products back as scene values: the first light keeps its intensity and
    colour, each object's albedo is its product under the first light over that, and every other light's
    intensity and colour are the least-squares ratio of its products to the albedos."""
    out = copy.deepcopy(d)
    lights = out["lights"]
    k = 0
    for p in paths:
        light, key = _locate(p, lights)
        n = path_width(key)
        light[key] = x[k] if n == 1 else list(x[k:k + n])
        k += n
    every = np.asarray(products, float)  # objects x (lights + 1 (+ lights where any is glossy)) x 3
    prods = every[:, :len(lights) + 1]
    first = np.asarray(lights[0].get("color", [1, 1, 1]), float) * float(lights[0]["intensity"])
    albedo = prods[:, 0, :] / np.where(first > 0, first, 1.0)
    for o, a in zip(out["objects"], albedo):
        o.setdefault("material", {})["albedo"] = [float(v) for v in a]
    report = []
    total = float(prods[:, :-1, :].sum()) or 1.0
    for i, light in enumerate(lights):
        if i > 0:
            rgb = (prods[:, i, :] * albedo).sum(axis=0) / np.maximum((albedo ** 2).sum(axis=0), 1e-30)
            intensity = float(rgb.max())
            light["intensity"] = intensity
            light["color"] = [float(v / intensity) if intensity > 0 else 1.0 for v in rgb]
        report.append({"name": light["name"], "kind": light.get("type", "point"),
                       **{key: light[key] for key in ("position", "direction", "radius", "size", "normal")
                          if key in light},
                       "intensity": float(light["intensity"]), "color": light.get("color", [1.0, 1.0, 1.0]),
                       "share": float(prods[:, i, :].sum()) / total})
    for o, p in zip(out["objects"], prods):
        o["material"]["albedo"] = [float(v) for v in p[0] / np.where(first > 0, first, 1.0)]
    if every.shape[1] > prods.shape[1]:
        _write_specular(out, every[:, len(lights) + 1:])
    out["ambient"] = [0.0, 0.0, 0.0]
    return out, report


def _write_specular(out: dict[str, Any], lobes: np.ndarray) -> None:
    """Each glossy object's ``specular``: the least-squares ratio of its lobe products (``lobes``: objects x
    lights x RGB) to the lights' intensity x colour as written."""
    rgb = np.array([np.asarray(light.get("color", [1, 1, 1]), float) * float(light["intensity"])
                    for light in out["lights"]])
    for o, lobe in zip(out["objects"], lobes):
        if o["material"].get("specular", 0.0) > 0:
            o["material"]["specular"] = float((lobe * rgb).sum() / max(float((rgb ** 2).sum()), 1e-30))


def _strongest_first(d: dict[str, Any], paths: list[str], x: list[float],
                     products: list[list[list[float]]]) -> tuple[list[float], list[list[list[float]]]]:
    """The searched lights reordered by their share of the light, strongest first, where they are alike
    (the same kind and the same free keys: the search cannot tell them apart, so its order is chance)."""
    lights = d["lights"]
    blocks: list[tuple[int, list[str], list[float]]] = []
    k = 0
    for p in paths:
        light, key = _locate(p, lights)
        i = lights.index(light)
        n = path_width(key)
        if not blocks or blocks[-1][0] != i:
            blocks.append((i, [], []))
        blocks[-1][1].append(key)
        blocks[-1][2].extend(x[k:k + n])
        k += n
    alike = len(blocks) == len(lights) and all(b[1] == blocks[0][1] for b in blocks) and \
        len({light.get("type", "point") for light in lights}) == 1
    if not alike:
        return x, products
    prods = np.asarray(products, float)
    n = len(lights)
    share = prods[:, :n, :].sum(axis=(0, 2))
    order = sorted(range(n), key=lambda i: -share[i])
    x = [v for i in order for v in blocks[i][2]]
    lobes = [prods[:, [n + 1 + i for i in order], :]] if prods.shape[1] > n + 1 else []
    prods = np.concatenate([prods[:, order, :], prods[:, n:n + 1, :], *lobes], axis=1)
    return x, prods.tolist()


def fit_lights(scene: Any, target: np.ndarray, count: int | None, *, seed: int = 0, population: int | None = None,
               generations: int | None = None, threads: int | None = None, mask: np.ndarray | None = None,
               errors: bool = True) -> LightsFit:
    """Fit ``count`` lights (the scene's own number when None) to the linear float32 ``target`` by the staged
    search (:mod:`.lights_search`; ``population`` and ``generations`` set each light's own search); with
    ``errors``, each light's error bars (:mod:`.lights_errors`)."""
    scene = load_scene(scene)
    start = time.perf_counter()
    have = len(_light_list(scene_to_dict(scene)))
    d, paths = with_lights(scene, have if count is None else count)
    work = load_scene(d)
    pixels = choose_pixels(work, target, seed, mask)
    own = Stages().light
    stages = Stages(light=(population or own[0], generations or own[1], own[2]))
    x, loss, products, evaluations = staged(d, paths, target, pixels, seed, threads, stages)
    x, products = _strongest_first(d, paths, list(x), products)
    out, report = _split(d, x, paths, products)
    if errors:
        _attach_errors(report, d, paths, x, target, pixels, seed)
    fitted = load_scene(out)
    return LightsFit(
        scene=fitted, lights=report,
        products={name: [list(map(float, row)) for row in p] for name, p in zip(work.object_names, products)},
        loss=float(loss), evaluations=int(evaluations), seconds=time.perf_counter() - start,
    )


def _attach_errors(report: list[dict[str, Any]], d: dict[str, Any], paths: list[str], x: list[float],
                   target: np.ndarray, pixels: np.ndarray, seed: int) -> None:
    """Each light's error bars (:func:`.lights_errors.light_errors`) into its report entry."""
    bars = light_errors(d, paths, x, target, pixels, seed, lambda xk, pk: _split(d, xk, paths, pk)[1])
    for i, (light, bar) in enumerate(zip(report, bars)):
        light.update(bar)
        if i == 0:  # the first light's intensity is held: it sets the albedos' scale
            light["intensity_error"] = None


def choose_count(scene: Any, target: np.ndarray, *, seed: int = 0, limit: int = AUTO_LIMIT,
                 mask: np.ndarray | None = None, **kw: Any) -> LightsFit:
    """Fit one light, then one more while the pixels the fits did not see say the photo needs it
    (:func:`held_out_counts`), and the chosen count's error bars over all the chosen pixels."""
    scene = load_scene(scene)
    best, _, pixels = held_out_counts(scene, target, seed=seed, limit=limit, mask=mask, **kw)
    assert best is not None
    attach_errors(scene, best, target, pixels, seed)
    return best


def held_out_counts(scene: Scene, target: np.ndarray, *, seed: int = 0, limit: int = AUTO_LIMIT,
                    mask: np.ndarray | None = None,
                    first: Callable[[np.ndarray, np.ndarray], dict[str, float]] | None = None,
                    check: Callable[[LightsFit, int], dict[str, Any]] | None = None,
                    floor: Callable[[np.ndarray], float] | None = None,
                    **kw: Any) -> tuple[LightsFit | None, list[dict[str, Any]], np.ndarray]:
    """The count :func:`choose_count` keeps, without error bars, and the chosen pixels: each count is
    fitted on half the pixels (a seeded split) and scored on the other half; a further light is kept when
    it lowers that held-out error by ``AUTO_GAIN`` of it at least. The evidence is kept. ``first``: the
    held-out errors of the scene's own lights as some other fit has them (given the held-out and the
    training pixels; a dict of named errors): the scene's own count scores the least of those and its own
    fit, and where no further light is kept the answer is None. ``check(found, have)``:
    the caller's further rule for a fit with added lights, its evidence (``"passes"``: whether it holds).
    ``floor(held)``: the held-out error the photo's own rounding and noise leave (the expected squared
    error of a perfect model): a count whose error is within floor / (1 - AUTO_GAIN) ends the search, as
    no further light could cut it by AUTO_GAIN without fitting below that floor."""
    have = len(_light_list(scene_to_dict(scene)))
    pixels = choose_pixels(scene, target, seed, mask)
    half = np.random.default_rng(seed + 1).permutation(pixels.size) % 2 == 0
    train, held = np.sort(pixels[half]), np.sort(pixels[~half])
    held = held[~steep(target, EDGE_SHARE)[held]]
    best, evidence = None, []
    at_floor = None if floor is None else float(floor(held))
    for count in range(have, max(limit, have) + 1):
        found = fit_lights(scene, target, count, seed=seed, mask=train, errors=False, **kw)
        d, paths = with_lights(scene, count)
        x = _geometry(found, paths)
        err, _ = _native.lights_solve(load_scene(d), target, paths, held, x)
        err = float(err)
        more = check(found, have) if check is not None and count > have else {}
        if first is not None and count == have:  # the better of the two fits of the scene's own lights
            more = {"lights_fit": err, **{k: float(v) for k, v in first(held, train).items()}}
            err = min(more.values())
        keep = not evidence or err < (1.0 - AUTO_GAIN) * evidence[-1]["held_out"] and more.get("passes", True)
        evidence.append({"lights": count, "held_out": err, "pixels": int(held.size), "kept": bool(keep),
                         **more})
        if not keep:
            break
        best = found if first is None or count > have else None
        if count > have:
            evidence[-2]["kept"] = False
        if at_floor is not None and err <= at_floor / (1.0 - AUTO_GAIN):
            evidence[-1]["floor"] = at_floor  # at the photo's own floor: no further light is tried
            break
    if best is not None:
        best.evidence = evidence
    return best, evidence, pixels


def attach_errors(scene: Scene, found: LightsFit, target: np.ndarray, pixels: np.ndarray, seed: int) -> None:
    """``found``'s error bars over ``pixels`` (its lights' entries), as :func:`fit_lights` attaches them."""
    d, paths = with_lights(scene, len(found.lights))
    _attach_errors(found.lights, d, paths, _geometry(found, paths), target, pixels, seed)


def steep(target: np.ndarray, share: float) -> np.ndarray:
    """Flat indices' flags: the ``share`` of pixels where the photo changes fastest (its gradient over the
    two neighbours each way). There a pixel's area average (a shadow's edge, which the photo integrates
    over the pixel) and the fit's pixel centre differ by more than any light could explain."""
    g = np.zeros(target.shape[:2])
    g[1:-1, 1:-1] = (np.abs(target[2:, 1:-1] - target[:-2, 1:-1]).max(axis=2)
                     + np.abs(target[1:-1, 2:] - target[1:-1, :-2]).max(axis=2))
    return (g >= np.quantile(g, 1.0 - share)).ravel()


def _geometry(found: LightsFit, paths: list[str]) -> list[float]:
    """The searched values of ``found``'s lights, in the order of ``paths``."""
    x: list[float] = []
    for p in paths:
        light, key = _locate(p, found.lights)
        v = light[key]
        x += [float(v)] if path_width(key) == 1 else [float(c) for c in v]
    return x


def size_text(light: dict[str, Any]) -> str:
    """A rectangle light's size as the summary and the report write it (empty for another light): its
    width and height, and where they were searched, each side's error bar or "not determined"."""
    if "size" not in light:
        return ""
    w, h = light["size"]
    text = f"{w:.3g} x {h:.3g} m"
    bars = light.get("size_error")
    if bars is None:
        return text
    sides = [f"{side} {'not determined' if b is None else f'+- {b:.2g} m'}" for side, b in zip(("width", "height"), bars)]
    return f"{text} ({', '.join(sides)})"


def check_lights(lights: Any) -> int | str | None:
    """``fit(..., lights=)``: None, "auto" or a whole number of lights from 1 to 8."""
    if lights is None or lights == "auto":
        return lights
    if isinstance(lights, bool) or not isinstance(lights, (int, np.integer)) or not 1 <= int(lights) <= 8:
        raise RtloopError(f"lights: expected a whole number from 1 to 8 or \"auto\" (got {lights!r})")
    return int(lights)

