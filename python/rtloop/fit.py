"""The fit: the paper's two stages, or rtloop's closed-form method, with all the arithmetic in Rust.

Method ``projected`` (the default protocol ``rtloop`` uses it whenever the scene allows): for a scene
without ambient light, every pixel is linear in the products exposure x intensity x colour x albedo of its
object, and for a glossy object in intensity x specular. For each candidate light position (or direction)
and shininess those products are solved in closed form (least squares over the unsaturated pixels away
from silhouettes, clamped to their bounds) inside the fitness, so L-SHADE searches only the light's three
coordinates (and any free shininess) against the whole-image loss. This removes stage 1's bias from the
wrong starting colours and stage 2's separate search. The products reported are re-solved at the fitted
light to minimise the loss itself, saturated pixels one-sided (see the README, "Photos saturate").

Stage 1 ("light") frees the light (``light.*`` paths of the fit section) and minimises the sum of
absolute RGB differences over the whole image, every other parameter held at the scene's value.
Stage 2 ("colour") fixes that light and frees everything else (albedos, ...), with R, G and B as three
objectives (Pareto selection) on pixels sampled inside each object's visible, lit area.

Identifiability. With no ambient light and no specular term the image depends on the light's intensity
and an object's albedo only through their product. rtloop detects this from the scene and the fit
section and resolves it in one documented way: stage 2 may raise an albedo above its upper bound if the
image asks for it (the search range is widened by max intensity / stage-1 intensity), and the light is
then made just bright enough that every fitted albedo is back within its bounds (products unchanged).
Otherwise the intensity stays at the stage-1 value. The closed-form method splits its products the same
way around the scene's own intensity. The report names the determined products, and objects that no
visible pixel shows lit (their albedo is not in the photo: it keeps the scene's value).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from . import _native
from .errors import RtloopError
from .scene import Scene, load_scene, scene_to_dict

__all__ = ["LOSS_SPACES", "PROTOCOLS", "FitResult", "GenerationInfo", "StageResult", "fit"]

#: Where a loss compares pixel values: ``linear`` radiance (default) or ``srgb`` code values.
LOSS_SPACES = ("linear", "srgb")

#: Named settings. ``paper``: the paper's numbers. ``rtloop``: the default (see README, speed against error).
PROTOCOLS: dict[str, dict[str, Any]] = {
    "paper": {"population": 60, "generations": (200, 200), "f": 0.6, "cr": 0.8, "refine": False},
    # Default: the closed-form method searched by L-SHADE, 16 x 17 = 272 evaluations to find the basin, then
    # a Nelder-Mead polish of up to 200 evaluations that stops once its simplex spans less than 1e-6 of
    # every range (a short search hands the polish a wide simplex; 200 is where it stops improving). Chosen
    # on synthetic scenes (random lights and colours, clean, noisy and JPEG; not the reference scenes):
    # the smallest split with no wrong basin and every clean fit within 1 mm. Scenes it does not apply to
    # fall back to DE in two stages plus a refine pass, 30 x 100 per stage.
    # These are for a light position, 3 searched parameters ("per_dimensions"); D > 3 (a free shininess)
    # scales the population and generations by D / 3 and the polish by (D / 3)^2, as Nelder-Mead's cost
    # grows (a glossy ball: 21 x 22 + 356).
    "rtloop": {"population": 16, "generations": (16, 16), "f": 0.6, "cr": 0.8, "refine": True,
               "projected": True, "optimizer": "lshade", "polish": 200, "polish_tol": 1e-6, "per_dimensions": 3,
               "fallback_population": 30, "fallback_generations": (100, 100)},
}

#: Pixels sampled per object for stage 2.
PIXELS_PER_OBJECT = 64


@dataclass
class GenerationInfo:
    """What a fit's callback receives after every generation of every stage."""

    stage: str
    generation: int
    fitness: float
    objectives: list[float]
    #: Values of all of the scene's fit parameters (the stage's best individual, the rest held fixed).
    params: np.ndarray
    evaluations: int


@dataclass
class StageResult:
    name: str
    paths: list[str]
    param_names: list[str]
    x: np.ndarray
    objectives: list[float]
    evaluations: int
    generations: int
    seconds: float
    loss: str
    pixels: int
    #: (generation, fitness, objectives, x) of the best individual of every generation.
    history: list[tuple[int, float, list[float], np.ndarray]] = field(default_factory=list)
    #: For the projected loss: the closed-form products of the best individual, per object
    #: [P_r, P_g, P_b, Q] (Q = intensity x specular, 0 for a matte object).
    products: list[list[float]] | None = None
    #: For the projected loss: per object, its (unmasked) pixels that the fitted light reaches.
    lit_pixels: list[int] | None = None


@dataclass
class FitResult:
    """The outcome of :func:`fit`, in the spirit of scipy's OptimizeResult."""

    scene: Scene
    #: The fitted values of all fit parameters by scalar name (e.g. ``light.position.x``).
    x: dict[str, float]
    stages: list[StageResult]
    evaluations: int
    seconds: float
    protocol: str
    seed: int
    #: Per object: light intensity x light colour x albedo, the combination the image determines.
    products: dict[str, list[float]]
    identifiability: dict[str, Any]
    settings: dict[str, Any]
    success: bool = True
    message: str = ""
    #: Per-parameter 1-sigma uncertainty (see rtloop.uncertainty), or None when not estimated.
    uncertainty: dict[str, Any] | None = None

    @property
    def fitness(self) -> float:
        return float(sum(self.stages[-1].objectives)) if self.stages else float("nan")

    def report(self) -> dict[str, Any]:
        """A JSON-able summary (the ``fit_report`` of result.json)."""
        return {
            "protocol": self.protocol,
            "seed": self.seed,
            "settings": self.settings,
            "evaluations": self.evaluations,
            "seconds": round(self.seconds, 4),
            "stages": [
                {
                    "name": s.name,
                    "parameters": s.param_names,
                    "loss": s.loss,
                    "pixels": s.pixels,
                    "fitness": float(sum(s.objectives)),
                    "objectives": [float(v) for v in s.objectives],
                    "evaluations": s.evaluations,
                    "generations": s.generations,
                    "seconds": round(s.seconds, 4),
                }
                for s in self.stages
            ],
            "fitted": self.x,
            "products": self.products,
            "identifiability": self.identifiability,
            "uncertainty": self.uncertainty,
            "message": self.message,
        }


def _identifiability(scene: Scene, paths: list[str]) -> dict[str, Any]:
    d = scene_to_dict(scene)
    albedo_paths = [p for p in paths if p.endswith(".albedo")]
    light_scale = [p for p in paths if p in ("light.intensity", "light.color", "exposure")]
    specular_paths = [p for p in paths if p.endswith(".specular")]
    no_ambient = all(v == 0 for v in d["ambient"]) and "ambient" not in paths
    # A highlight of known strength (a fixed, non-zero specular) measures the light's intensity; a free
    # specular scales with the intensity like an albedo does.
    known_specular = any(
        o["material"]["specular"] != 0 and f"objects.{o['name']}.specular" not in paths for o in d["objects"]
    )
    degenerate = bool((albedo_paths or specular_paths) and light_scale and no_ambient and not known_specular)
    info: dict[str, Any] = {"degenerate": degenerate}
    if degenerate:
        info["determined"] = [f"{'*'.join(light_scale)}*{p}" for p in albedo_paths + specular_paths]
        info["note"] = (
            "no ambient light and no highlight of known strength: the image fixes only light intensity x "
            "albedo per object and channel (see 'products'), and intensity x specular; the intensity is "
            "kept at the scene's value (the paper protocol: stage 1's value) unless an albedo or a specular "
            "would exceed its bounds, in which case the light is made just bright enough"
        )
    elif len(light_scale) > 1:
        info["degenerate"] = True
        info["determined"] = ["*".join(light_scale)]
        info["note"] = f"{' and '.join(light_scale)} scale the image together; only their product is determined"
    return info


def _products(scene: Scene) -> dict[str, list[float]]:
    d = scene_to_dict(scene)
    light = np.array(d["light"]["color"]) * d["light"]["intensity"] * d["exposure"]
    return {o["name"]: [float(v) for v in light * np.array(o["material"]["albedo"])] for o in d["objects"]}


def sample_object_pixels(
    scene: Scene, lit: np.ndarray, per_object: int, rng: np.random.Generator
) -> np.ndarray:
    """Pixel indices inside each object's visible area, away from silhouettes, preferring lit pixels."""
    ids = _native.object_ids(scene)
    interior = ids.copy()
    same = np.ones_like(ids, dtype=bool)
    same[1:, :] &= ids[1:, :] == ids[:-1, :]
    same[:-1, :] &= ids[:-1, :] == ids[1:, :]
    same[:, 1:] &= ids[:, 1:] == ids[:, :-1]
    same[:, :-1] &= ids[:, :-1] == ids[:, 1:]
    interior[~same] = -2
    chosen = []
    for k in range(len(scene.object_names)):
        cand = np.flatnonzero((interior == k).ravel() & lit.ravel())
        if cand.size == 0:
            cand = np.flatnonzero((ids == k).ravel())
        if cand.size:
            chosen.append(rng.choice(cand, size=min(per_object, cand.size), replace=False))
    if not chosen:
        return np.zeros(0, np.uint32)
    return np.sort(np.concatenate(chosen)).astype(np.uint32)


def _with_bounds(scene: Scene, changes: dict[str, tuple[Any, Any]]) -> Scene:
    d = scene_to_dict(scene)
    for path, (lo, hi) in changes.items():
        d["fit"][path] = {"min": lo, "max": hi}
    return load_scene(d)


def fit(
    scene: Any,
    image: np.ndarray,
    *,
    protocol: str = "rtloop",
    seed: int = 0,
    population: int | None = None,
    generations: int | tuple[int, int] | None = None,
    f: float | None = None,
    cr: float | None = None,
    threads: int | None = None,
    clip: bool = True,
    pixels_per_object: int = PIXELS_PER_OBJECT,
    callback: Callable[[GenerationInfo], Any] | None = None,
    optimizer: str | None = None,
    polish: int | None = None,
    uncertainty: bool = True,
    mask: np.ndarray | None = None,
    norm: str = "l1",
    space: str = "linear",
) -> FitResult:
    """Fit the scene's free parameters (its ``fit`` section) to ``image``.

    ``image`` is the objective in linear RGB, float (H, W, 3) at the scene's size (see :func:`load_image`).
    ``protocol``: ``"rtloop"`` (default) or ``"paper"`` (population 60, 200 + 200 generations, F 0.6,
    CR 0.8); ``population``, ``generations`` (one number for both stages or a pair), ``f`` and ``cr``
    override it. ``seed`` makes the result reproducible on any number of ``threads``. ``clip`` compares
    min(render, 1) with the objective, as an 8/16-bit photo saturates. ``callback(GenerationInfo)`` runs
    after every generation; returning False stops the current stage. ``uncertainty`` adds per-parameter
    1-sigma estimates (Gauss-Newton at the optimum, scaled by the residual) to the result. ``optimizer``
    ("de" or "lshade") and ``polish`` (Nelder-Mead evaluations) override the protocol's search for the
    closed-form method. ``mask`` (bool (H, W), True = use) leaves out pixels the scene does not model
    (another object, a reflection, the photographer's shadow): they count in no loss and no solve.
    ``norm`` penalises each pixel's difference: "l1" (the paper's, default), "l2" (maximum likelihood for
    Gaussian noise), "huber" or "huber:H" (quadratic within H, default 0.02, linear beyond). ``space`` is
    where it is taken: "linear" (default, radiance) or "srgb" (the sRGB encodings of the clipped render
    and of the image, as an 8-bit file stores them: a shadow's error counts as the file resolves it); the
    closed-form products stay least squares in linear space, the reported ones minimise the sRGB loss.
    """
    t0 = time.perf_counter()
    scene = load_scene(scene)
    if protocol not in PROTOCOLS:
        raise RtloopError(f"protocol: unknown protocol {protocol!r} (known: {', '.join(PROTOCOLS)})")
    if space not in LOSS_SPACES:
        raise RtloopError(f"space: unknown loss space {space!r} (known: {', '.join(LOSS_SPACES)})")
    proto = PROTOCOLS[protocol]
    pop = int(population if population is not None else proto["population"])
    gens = generations if generations is not None else proto["generations"]
    gens = (int(gens), int(gens)) if isinstance(gens, (int, np.integer)) else (int(gens[0]), int(gens[1]))
    f_ = float(f if f is not None else proto["f"])
    cr_ = float(cr if cr is not None else proto["cr"])
    if pop < 4:
        raise RtloopError(f"population: must be at least 4 (got {pop})")
    if min(gens) < 0:
        raise RtloopError(f"generations: must be >= 0 (got {gens})")
    target = np.ascontiguousarray(image, dtype=np.float32)
    if target.shape != (scene.height, scene.width, 3):
        raise RtloopError(
            f"image: shape {target.shape} does not match the scene's ({scene.height}, {scene.width}, 3); "
            "load it with rtloop.load_image(path, scene)"
        )
    if not np.isfinite(target).all():
        raise RtloopError("image: contains NaN or infinite values")
    use: np.ndarray | None = None
    if mask is not None:
        m = np.asarray(mask)
        if m.shape != (scene.height, scene.width):
            raise RtloopError(f"mask: shape {m.shape} does not match the scene's ({scene.height}, {scene.width})")
        if not m.any():
            raise RtloopError("mask: selects no pixel")
        use = np.flatnonzero(m.astype(bool).ravel()).astype(np.uint32)
    all_paths = scene.fit_paths
    if not all_paths:
        raise RtloopError("fit: the scene's fit section names no free parameters")
    all_names = scene.param_names()
    light_paths = [p for p in all_paths if p.startswith("light.")]
    other_paths = [p for p in all_paths if not p.startswith("light.")]
    ident = _identifiability(scene, all_paths)
    settings = {"population": pop, "generations": list(gens), "f": f_, "cr": cr_, "clip": clip,
                "masked_pixels": None if use is None else int(scene.width * scene.height - use.size),
                "norm": norm, "space": space,
                "pixels_per_object": pixels_per_object, "threads": threads}
    stages: list[StageResult] = []
    evaluations = 0
    rng = np.random.default_rng(seed)
    current = scene

    def run(name: str, stage_scene: Scene, paths: list[str], loss: str, pixels: np.ndarray | None,
            generations: int, stage_seed: int, product_bounds: np.ndarray | None = None,
            method: str = "de", polish: int = 0, polish_tol: float | None = None) -> StageResult:
        nonlocal evaluations
        history: list[tuple[int, float, list[float], np.ndarray]] = []
        base_full = np.array(stage_scene.get_params(all_paths))
        index = [all_names.index(n) for n in stage_scene.param_names(paths)]

        def on_generation(gen: int, best: np.ndarray, objectives: list[float], evals: int,
                          products: list[list[float]] | None) -> bool:
            fitness = float(sum(objectives))
            history.append((gen, fitness, list(objectives), np.array(best)))
            if callback is not None:
                full = base_full.copy()
                full[index] = best
                if products is not None:
                    split = _split_products(stage_scene, products, scene)
                    full = np.array(split.get_params(all_paths))
                    full[index] = best
                info = GenerationInfo(name, gen, fitness, list(objectives), full, evaluations + evals)
                return callback(info) is not False
            return True

        t = time.perf_counter()
        out = _native.optimize(
            stage_scene, paths, target, pixels=pixels, loss=loss, clip=clip, population=pop,
            generations=generations, f=f_, cr=cr_, seed=stage_seed, threads=threads, callback=on_generation,
            product_bounds=product_bounds, method=method, polish=polish, norm=norm, space=space,
            with_products=callback is not None, polish_tol=polish_tol,
        )
        generations_run = out.generations
        if out.polish is not None and not out.stopped:
            # The Nelder-Mead polish after the last generation is logged as one more generation, so the
            # history (and the CSV, the report) ends at the fitted values.
            generations_run += 1
            on_generation(generations_run, np.asarray(out.x), list(out.objectives), out.evaluations,
                          out.products)
        evaluations += out.evaluations
        return StageResult(
            name=name, paths=paths, param_names=stage_scene.param_names(paths), x=np.asarray(out.x),
            objectives=list(out.objectives), evaluations=out.evaluations, generations=generations_run,
            seconds=time.perf_counter() - t, loss=loss, pixels=int(out.active_pixels), history=history,
            products=out.products, lit_pixels=out.lit_pixels,
        )

    def light_stage(name: str, stage_scene: Scene, stage_seed: int) -> Scene:
        s = run(name, stage_scene, light_paths, "l1", use, gens[0], stage_seed)
        stages.append(s)
        return stage_scene.with_params(list(s.x), light_paths)

    def colour_stage(name: str, stage_scene: Scene, stage_seed: int) -> Scene:
        lit = _native.render(stage_scene).max(axis=2) > 1e-4
        if mask is not None:
            lit &= np.asarray(mask, bool)
        pixels = sample_object_pixels(stage_scene, lit, pixels_per_object, rng)
        search_scene = stage_scene
        widen: dict[str, tuple[Any, Any]] = {}
        if ident["degenerate"] and "light.intensity" in all_paths:
            intensity = stage_scene.get_params(["light.intensity"])[0]
            imax = stage_scene.bounds(["light.intensity"])[0][1]
            factor = max(1.0, imax / max(intensity, 1e-12))
            for p in other_paths:
                if p.endswith(".albedo"):
                    b = stage_scene.bounds([p])
                    widen[p] = ([lo for lo, _ in b], [hi * factor for _, hi in b])
            search_scene = _with_bounds(stage_scene, widen)
        s = run(name, search_scene, other_paths, "l1_rgb", pixels, gens[1], stage_seed)
        stages.append(s)
        fitted = stage_scene.with_params(list(s.x), other_paths)
        if widen:
            fitted = _fix_gauge(fitted, list(widen), stage_scene)
        return fitted

    seeds = np.random.SeedSequence(seed).generate_state(4, dtype=np.uint64)
    why_not = _projection_blocker(scene, all_paths)
    method = "projected" if proto.get("projected") and why_not is None else "two-stage"
    settings["method"] = method
    if method == "two-stage" and generations is None and "fallback_generations" in proto:
        gens = proto["fallback_generations"]
        settings["generations"] = list(gens)
    if method == "two-stage" and population is None and "fallback_population" in proto:
        pop = settings["population"] = int(proto["fallback_population"])
    optimizer = optimizer if optimizer is not None else proto.get("optimizer", "de")
    polish_given = polish is not None
    polish = int(polish if polish is not None else proto.get("polish", 0))
    where = ["light.direction"] if "light.direction" in all_paths else ["light.position"]
    where += [p for p in all_paths if p.endswith(".shininess")]  # searched with the light
    if method == "projected" and proto.get("per_dimensions"):
        # The protocol's numbers are for its `per_dimensions` searched parameters (a light position); more
        # (a free shininess) get more of each (see PROTOCOLS), unless the caller set them.
        k = max(1.0, len(scene.param_names(where)) / proto["per_dimensions"])
        if population is None:
            pop = settings["population"] = round(pop * k)
        if generations is None:
            gens = (round(gens[0] * k), round(gens[1] * k))
            settings["generations"] = list(gens)
        if not polish_given:
            polish = round(polish * k * k)
    settings["optimizer"], settings["polish"] = optimizer, polish
    if method == "projected":
        s = run("light+colour", current, where, "l1_projected", use, gens[0], int(seeds[0]),
                product_bounds=_product_bounds(scene), method=optimizer, polish=polish,
                polish_tol=proto.get("polish_tol"))
        stages.append(s)
        current = _split_products(current.with_params(list(s.x), where), s.products, scene)
        current = _keep_undetermined(current, scene, all_paths, ident, s.lit_pixels)
    else:
        if proto.get("projected"):
            settings["projection_unavailable"] = why_not
        if light_paths:
            current = light_stage("light", current, int(seeds[0]))
        if other_paths:
            current = colour_stage("colour", current, int(seeds[1]))
        if proto.get("refine") and light_paths and other_paths:
            # Second pass: the light again, now against the fitted colours, in a narrowed box around it.
            current = light_stage("light-refine", _narrowed(current, light_paths), int(seeds[2]))
            current = _restore_bounds(current, scene)
            current = colour_stage("colour-refine", current, int(seeds[3]))
        current = _restore_bounds(current, scene)
        current = _keep_undetermined(current, scene, all_paths, ident)
    values = current.get_params(all_paths)
    result = FitResult(
        scene=current,
        x={n: float(v) for n, v in zip(all_names, values)},
        stages=stages,
        evaluations=evaluations,
        seconds=time.perf_counter() - t0,
        protocol=protocol,
        seed=seed,
        products=_products(current),
        identifiability=ident,
        settings=settings,
    )
    if uncertainty:
        from .uncertainty import estimate_uncertainty

        try:
            result.uncertainty = estimate_uncertainty(result, target, clip=clip, mask=mask)
        except RtloopError as e:
            result.uncertainty = {"method": "gauss-newton", "sigma": {}, "warnings": [str(e)]}
    result.seconds = time.perf_counter() - t0
    return result


def lit_pixel_counts(scene: Scene) -> list[int]:
    """Per object: how many of its visible pixels receive direct light from the scene's light."""
    d = scene_to_dict(scene)
    d["light"]["intensity"], d["light"]["color"], d["ambient"], d["exposure"] = 1.0, [1.0, 1.0, 1.0], [0, 0, 0], 1.0
    for o in d["objects"]:
        o["material"] = {"albedo": [1.0, 1.0, 1.0]}
    d["fit"] = {}
    unit = load_scene(d)
    lit = _native.render(unit)[..., 0] > 0
    ids = _native.object_ids(unit)
    return [int(((ids == k) & lit).sum()) for k in range(len(d["objects"]))]


def _keep_undetermined(fitted: Scene, original: Scene, paths: list[str], ident: dict[str, Any],
                       counts: list[int] | None = None) -> Scene:
    """An object the fitted light leaves unlit in every visible pixel says nothing about its albedo (a
    sphere lit only from behind, one hidden by another): report it and keep the scene's own value.
    ``counts``: lit pixels per object when the search already knows them (else rendered here)."""
    if "ambient" in paths or any(v != 0 for v in scene_to_dict(fitted)["ambient"]):
        return fitted  # ambient light still shows the albedo
    if counts is None:
        counts = lit_pixel_counts(fitted)
    undetermined = []
    for name, n in zip(fitted.object_names, counts):
        p = f"objects.{name}.albedo"
        if p in paths and n == 0:
            undetermined.append(p)
            fitted = fitted.with_params(original.get_params([p]), [p])
    if undetermined:
        ident["undetermined"] = undetermined
        ident["undetermined_note"] = (
            "no visible pixel of these objects receives direct light from the fitted light, so the photo "
            "does not determine their albedo; the scene's own values are kept"
        )
    return fitted


def _projection_blocker(scene: Scene, paths: list[str]) -> str | None:
    """None when the closed-form (projected) method applies to this scene and fit section, else why not."""
    d = scene_to_dict(scene)
    if "light.position" not in paths and "light.direction" not in paths:
        return "neither light.position nor light.direction is free"
    if any(v != 0 for v in d["ambient"]):
        return "the scene has ambient light"
    allowed = {"light.position", "light.direction", "light.intensity"}
    for o in d["objects"]:
        allowed |= {f"objects.{o['name']}.{m}" for m in ("albedo", "specular", "shininess")}
    extra = [p for p in paths if p not in allowed]
    if extra:
        return f"{', '.join(extra)} cannot be solved in closed form"
    if "light.intensity" in paths:
        known = [o["name"] for o in d["objects"]
                 if o["material"]["specular"] != 0 and f"objects.{o['name']}.specular" not in paths]
        if known:
            return (f"light.intensity is free and the specular of {', '.join(known)} is fixed (the highlight "
                    "then measures the intensity, which the closed form does not model)")
    if "light.intensity" in paths:
        fixed = [o["name"] for o in d["objects"] if f"objects.{o['name']}.albedo" not in paths]
        if fixed:
            return f"light.intensity is free but the albedo of {', '.join(fixed)} is fixed"
    return None


def _product_bounds(scene: Scene) -> np.ndarray:
    """(objects, 4, 2) bounds of the closed-form unknowns from the fit section: rows 0-2 exposure x
    intensity x colour x albedo per channel, row 3 intensity x specular ((0, 0) for a matte object, which
    then costs no specular work)."""
    d = scene_to_dict(scene)
    paths = scene.fit_paths
    scale = np.array(d["light"]["color"], float) * d["exposure"]
    if "light.intensity" in paths:
        ilo, ihi = scene.bounds(["light.intensity"])[0]
    else:
        ilo = ihi = d["light"]["intensity"]
    out = np.zeros((len(d["objects"]), 4, 2))
    for k, o in enumerate(d["objects"]):
        p = f"objects.{o['name']}.albedo"
        b = np.array(scene.bounds([p])) if p in paths else np.repeat(np.array(o["material"]["albedo"])[:, None], 2, 1)
        out[k, :3, 0] = ilo * scale * b[:, 0]
        out[k, :3, 1] = ihi * scale * b[:, 1]
        sp = f"objects.{o['name']}.specular"
        klo, khi = scene.bounds([sp])[0] if sp in paths else (o["material"]["specular"],) * 2
        out[k, 3] = (ilo * klo, ihi * khi)
    return out


def _split_products(fitted: Scene, products: list[list[float]], original: Scene) -> Scene:
    """Write closed-form products back as albedos, speculars and an intensity.

    ``products``: per object [P_r, P_g, P_b] or [P_r, P_g, P_b, Q], P = exposure x intensity x colour x
    albedo, Q = intensity x specular. Intensity x albedo (and x specular) is all the image determines;
    rtloop keeps the intensity at the scene's own value (the user's estimate of the lamp) unless an albedo
    or a specular would then exceed its upper bound, in which case the light is made just bright enough
    (the dimmest light consistent with the photo and the bounds).
    """
    d = scene_to_dict(fitted)
    paths = original.fit_paths
    scale = np.array(d["light"]["color"], float) * d["exposure"]
    intensity = d["light"]["intensity"]
    rows = np.asarray(products, float)
    P = rows[:, :3]
    Q = rows[:, 3] if rows.shape[1] > 3 else np.zeros(len(rows))
    if "light.intensity" in paths:
        ilo, ihi = original.bounds(["light.intensity"])[0]
        intensity = min(max(scene_to_dict(original)["light"]["intensity"], ilo), ihi)
        need = intensity
        for k, o in enumerate(d["objects"]):
            p = f"objects.{o['name']}.albedo"
            if p in paths:
                hi = np.array([b[1] for b in original.bounds([p])])
                with np.errstate(divide="ignore", invalid="ignore"):
                    req = np.where((hi > 0) & (scale > 0), P[k] / (scale * np.maximum(hi, 1e-300)), 0.0)
                need = max(need, float(np.max(req)))
            sp = f"objects.{o['name']}.specular"
            if sp in paths and Q[k] > 0:
                khi = original.bounds([sp])[0][1]
                need = max(need, float(Q[k] / khi) if khi > 0 else need)
        intensity = min(max(need, ilo), ihi)
        d["light"]["intensity"] = intensity
    for k, o in enumerate(d["objects"]):
        p = f"objects.{o['name']}.albedo"
        if p in paths:
            lo = np.array([b[0] for b in original.bounds([p])])
            hi = np.array([b[1] for b in original.bounds([p])])
            with np.errstate(divide="ignore", invalid="ignore"):
                rho = np.where(scale > 0, P[k] / (intensity * scale), lo)
            o["material"]["albedo"] = [float(v) for v in np.clip(np.nan_to_num(rho), lo, hi)]
        sp = f"objects.{o['name']}.specular"
        if sp in paths:
            klo, khi = original.bounds([sp])[0]
            ks = Q[k] / intensity if intensity > 0 else klo
            o["material"]["specular"] = float(np.clip(np.nan_to_num(ks), klo, khi))
    return load_scene(d)


def _fix_gauge(fitted: Scene, albedo_paths: list[str], bounds_scene: Scene) -> Scene:
    """Scale the light up (and the albedos down) until every albedo is within its original bounds."""
    s = 1.0
    for p in albedo_paths:
        vals = fitted.get_params([p])
        for v, (_, hi) in zip(vals, bounds_scene.bounds([p])):
            if hi > 0:
                s = max(s, v / hi)
    if s <= 1.0:
        return fitted
    intensity = fitted.get_params(["light.intensity"])[0] * s
    out = fitted.with_params([intensity], ["light.intensity"])
    for p in albedo_paths:
        out = out.with_params([v / s for v in fitted.get_params([p])], [p])
    return out


def _narrowed(scene: Scene, paths: list[str], fraction: float = 0.15) -> Scene:
    """The scene with the bounds of ``paths`` shrunk to +-fraction of their range around the current values."""
    changes = {}
    for p in paths:
        vals = scene.get_params([p])
        b = scene.bounds([p])
        lo = [max(l0, v - fraction * (h0 - l0)) for v, (l0, h0) in zip(vals, b)]
        hi = [min(h0, v + fraction * (h0 - l0)) for v, (l0, h0) in zip(vals, b)]
        changes[p] = (lo, hi)
    return _with_bounds(scene, changes)


def _restore_bounds(scene: Scene, original: Scene) -> Scene:
    d = scene_to_dict(scene)
    d["fit"] = scene_to_dict(original)["fit"]
    return load_scene(d)
