"""Running a fit's stages through ``_native.optimize``: the closed-form (projected) stage, or the light
and colour stages of the two-stage method with its refine pass."""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

import numpy as np

from .. import _native
from .._pixels import edges
from ..scene import MAX_MAGNITUDE, Scene
from .bounds import narrowed, restore_bounds, with_bounds
from .identifiability import keep_undetermined
from .products import fix_gauge, product_bounds, split_products
from .protocol import Budget, searched_paths
from .result import GenerationInfo, StageResult
from .spec import fitness_spec

__all__ = ["Stages", "sample_object_pixels"]


def sample_object_pixels(
    scene: Scene, lit: np.ndarray, per_object: int, rng: np.random.Generator
) -> np.ndarray:
    """Pixel indices inside each object's visible area, away from silhouettes, preferring lit pixels."""
    ids = _native.object_ids(scene)
    interior = ids.copy()
    interior[edges(ids)] = -2
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


class Stages:
    """The stages of one fit of ``scene`` to ``target``: each run appends its StageResult to ``stages``
    and its evaluations to ``evaluations``; the stage methods return the scene with their values."""

    def __init__(self, scene: Scene, target: np.ndarray, use: np.ndarray | None, mask: np.ndarray | None,
                 budget: Budget, ident: dict[str, Any], *, clip: bool, norm: str, space: str,
                 threads: int | None, pixels_per_object: int, rng: np.random.Generator,
                 callback: Callable[[GenerationInfo], Any] | None, footprint: str = "off",
                 report_names: list[str] | None = None):
        self.scene, self.target, self.use, self.mask = scene, target, use, mask
        self.budget, self.ident = budget, ident
        self.clip, self.norm, self.space, self.threads = clip, norm, space, threads
        self.pixels_per_object, self.rng, self.callback = pixels_per_object, rng, callback
        #: "off", "polish" (the closed-form polish, its products and loss) or "on" (every search too).
        self.footprint = footprint
        self.all_paths = scene.fit_paths
        self.all_names = scene.param_names()
        #: The callback's ``params`` are the values of these names (None: every fit parameter of ``scene``):
        #: a refit whose scene frees a term's parameters (a lobe's specular and shininess) still reports
        #: those of the fit's own scene, as its first stage did.
        self.report_index = None if report_names is None else [self.all_names.index(n) for n in report_names]
        self.light_paths = [p for p in self.all_paths if p.startswith("light.")]
        self.other_paths = [p for p in self.all_paths if not p.startswith("light.")]
        self.stages: list[StageResult] = []
        self.evaluations = 0
        #: With interreflection: the searches' passes holding the bounce (``_native.FitnessSpec``'s
        #: ``frozen_bounce``; 0: none; the refit with the bounce sets ``selection.BOUNCE_PASSES``).
        self.frozen_bounce = 0
        #: Objective values from which a pixel may be clipped (``_native.FitnessSpec``'s ``saturated``; None:
        #: SATURATED; ``goodness.clip_level`` for a noisy or JPEG photo).
        self.saturated: float | None = None
        #: Pixels within this many (Chebyshev distance) of another object's do not inform the closed-form
        #: products (``_native.FitnessSpec``'s ``solve_margin``; 0: a pixel's 4-neighbours show its object;
        #: :data:`rtloop.fit.JPEG_CHROMA_MARGIN` for a JPEG, whose colour mixes across silhouettes).
        self.solve_margin = 0
        #: With the footprint, the outline pixels (``_native.optimize``'s ``silhouettes``): "auto" integrated
        #: where the outline gate finds the photo needs it (a search with the footprint in its polish),
        #: "on" in every evaluation with the footprint, "off" at pixel centres.
        self.silhouettes = "off"
        #: The callback's ``params`` hold the closed-form products of each generation's best, split into the
        #: scene's parameters (one solve per generation); False: the scene's own values stand for them.
        self.products_per_generation = True

    def add(self, more: Stages) -> None:
        """Count the stages and evaluations of ``more`` (a refit's) as this fit's."""
        self.stages += more.stages
        self.evaluations += more.evaluations

    def run(self, name: str, stage_scene: Scene, paths: list[str], loss: str, pixels: np.ndarray | None,
            generations: int, stage_seed: int, product_bounds: np.ndarray | None = None,
            method: str = "de", polish: int = 0, polish_tol: float | None = None,
            x0: list[float] | None = None) -> StageResult:
        """One search over ``paths`` of ``stage_scene``, the rest held; its history and callbacks. The
        history comes back from the core; the user's callback (if any) alone takes the GIL per generation.
        ``x0``: a point (of ``paths``) the search's initial population holds (L-SHADE only)."""
        base_full = np.array(stage_scene.get_params(self.all_paths))
        index = [self.all_names.index(n) for n in stage_scene.param_names(paths)]
        callback = self.callback

        def on_generation(gen: int, best: np.ndarray, objectives: list[float], evals: int,
                          products: list[list[float]] | None) -> bool:
            assert callback is not None
            full = base_full.copy()
            full[index] = best
            if products is not None:
                split = split_products(stage_scene, products, self.scene)
                full = np.array(split.get_params(self.all_paths))
                full[index] = best
            if self.report_index is not None:
                full = full[self.report_index]
            info = GenerationInfo(name, gen, float(sum(objectives)), list(objectives), full,
                                  self.evaluations + evals)
            return callback(info) is not False

        b = self.budget
        t = time.perf_counter()
        spec = fitness_spec(paths, pixels=pixels, loss=loss, clip=self.clip, product_bounds=product_bounds,
                            norm=self.norm, space=self.space, footprint=self.footprint == "on",
                            frozen_bounce=self.frozen_bounce, saturated=self.saturated,
                            solve_margin=self.solve_margin)
        out = _native.optimize(
            stage_scene, self.target, spec, population=b.population, generations=generations, f=b.f, cr=b.cr,
            seed=stage_seed, method=method, polish=polish, polish_tol=polish_tol,
            polish_footprint=self.footprint == "polish" and method == "lshade" and polish > 0,
            with_products=callback is not None and self.products_per_generation, x0=x0,
            callback=None if callback is None else on_generation, threads=self.threads,
            silhouettes=self.silhouettes if self.footprint != "off" else "off",
        )
        history = [(gen, float(sum(objectives)), list(objectives), np.array(best))
                   for gen, best, objectives, _ in out.history]
        generations_run = out.generations
        if out.polish is not None and not out.stopped:
            # The Nelder-Mead polish after the last generation is logged as one more generation, so the
            # history (and the CSV, the report) ends at the fitted values.
            generations_run += 1
            history.append((generations_run, float(sum(out.objectives)), list(out.objectives), np.array(out.x)))
            if callback is not None:
                on_generation(generations_run, out.x, list(out.objectives), out.evaluations, out.products)
        self.evaluations += out.evaluations
        stage = StageResult(
            name=name, paths=paths, param_names=stage_scene.param_names(paths), x=out.x,
            objectives=list(out.objectives), evaluations=out.evaluations, generations=generations_run,
            seconds=time.perf_counter() - t, loss=loss, pixels=out.active_pixels, history=history,
            products=out.products, lit_pixels=out.lit_pixels, gauge=out.gauge, outlines=out.outlines,
        )
        self.stages.append(stage)
        return stage

    def projected(self, seed: int, environment: bool = False, name: str = "light+colour",
                  from_scene: bool = False) -> Scene:
        """The closed-form method: the light (and any shininess) searched, the products solved and split;
        with ``environment`` each object's occluded-environment product too. ``from_scene``: the search's
        initial population holds the scene's own values (a refit near a light already found: the search
        then never ends worse than that light; L-SHADE only)."""
        b, where = self.budget, searched_paths(self.all_paths)
        x0 = list(self.scene.get_params(where)) if from_scene and b.optimizer == "lshade" else None
        s = self.run(name, self.scene, where, "l1_projected", self.use, b.generations[0], seed,
                     product_bounds=product_bounds(self.scene, environment), method=b.optimizer,
                     polish=b.polish, polish_tol=b.protocol.get("polish_tol"), x0=x0)
        current = split_products(self.scene.with_params(list(s.x), where), s.products, self.scene, s.gauge)
        return keep_undetermined(current, self.scene, self.all_paths, self.ident, s.lit_pixels)

    def two_stage(self, seeds: np.ndarray) -> Scene:
        """The paper's light stage then colour stage, and with ``refine`` both again around the result."""
        current = self.scene
        if self.light_paths:
            current = self.light("light", current, int(seeds[0]))
        if self.other_paths:
            current = self.colour("colour", current, int(seeds[1]))
        if self.budget.protocol.get("refine") and self.light_paths and self.other_paths:
            # Second pass: the light again, now against the fitted colours, in a narrowed box around it.
            current = self.light("light-refine", narrowed(current, self.light_paths), int(seeds[2]))
            current = restore_bounds(current, self.scene)
            current = self.colour("colour-refine", current, int(seeds[3]))
        current = restore_bounds(current, self.scene)
        return keep_undetermined(current, self.scene, self.all_paths, self.ident)

    def light(self, name: str, stage_scene: Scene, seed: int) -> Scene:
        """Stage 1: the light's paths against the whole-image L1 loss."""
        s = self.run(name, stage_scene, self.light_paths, "l1", self.use, self.budget.generations[0], seed)
        return stage_scene.with_params(list(s.x), self.light_paths)

    def colour(self, name: str, stage_scene: Scene, seed: int) -> Scene:
        """Stage 2: everything else, R, G, B as three objectives on pixels sampled per object."""
        lit = _native.render(stage_scene).max(axis=2) > 1e-4
        if self.mask is not None:
            lit &= np.asarray(self.mask, bool)
        pixels = sample_object_pixels(stage_scene, lit, self.pixels_per_object, self.rng)
        search_scene = stage_scene
        widen: dict[str, tuple[Any, Any]] = {}
        if self.ident["degenerate"] and "light.intensity" in self.all_paths:
            intensity = stage_scene.get_params(["light.intensity"])[0]
            imax = stage_scene.bounds(["light.intensity"])[0][1]
            factor = max(1.0, imax / max(intensity, 1e-12))
            for p in self.other_paths:
                if p.endswith(".albedo"):
                    b = stage_scene.bounds([p])
                    # at most the scene format's largest number (MAX_MAGNITUDE), which with_bounds checks
                    widen[p] = ([lo for lo, _ in b], [max(hi, min(hi * factor, MAX_MAGNITUDE)) for _, hi in b])
            search_scene = with_bounds(stage_scene, widen)
        s = self.run(name, search_scene, self.other_paths, "l1_rgb", pixels, self.budget.generations[1], seed)
        fitted = stage_scene.with_params(list(s.x), self.other_paths)
        if widen:
            fitted = fix_gauge(fitted, list(widen), stage_scene)
        return fitted
