"""The fit: rtloop's closed-form method or the paper's two stages, with all the arithmetic in Rust.

``fit()`` checks its inputs, picks the budget and method (:mod:`.protocol`), runs the stages
(:mod:`.stages`), splits the solved products back into scene values (:mod:`.products`) and names what
the photo does not determine (:mod:`.identifiability`). README: "Methods".
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

import numpy as np

from ..errors import RtloopError
from ..scene import Scene, load_scene
from .identifiability import identifiability as _identifiability
from .identifiability import lit_pixel_counts
from .products import product_bounds as _product_bounds
from .products import products as _products
from .protocol import LOSS_SPACES, PIXELS_PER_OBJECT, PROTOCOLS, budget, choose_method
from .result import FitResult, GenerationInfo, StageResult
from .stages import Stages, sample_object_pixels

__all__ = ["LOSS_SPACES", "PROTOCOLS", "FitResult", "GenerationInfo", "StageResult", "fit"]

# Kept importable from here, as from the single module this package replaces (tests and benches use them).
_REEXPORTED = (_product_bounds, lit_pixel_counts, sample_object_pixels)


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
    b = budget(protocol, space, population, generations, f, cr)
    target, use = _objective(scene, image, mask)
    all_paths = scene.fit_paths
    if not all_paths:
        raise RtloopError("fit: the scene's fit section names no free parameters")
    ident = _identifiability(scene, all_paths)
    choose_method(b, scene, all_paths, population=population, generations=generations, optimizer=optimizer,
                  polish=polish)
    settings = {**b.settings(), "clip": clip,
                "masked_pixels": None if use is None else int(scene.width * scene.height - use.size),
                "norm": norm, "space": space, "pixels_per_object": pixels_per_object, "threads": threads,
                "method": b.method, "optimizer": b.optimizer, "polish": b.polish}
    if b.projection_unavailable is not None:
        settings["projection_unavailable"] = b.projection_unavailable
    stages = Stages(scene, target, use, mask, b, ident, clip=clip, norm=norm, space=space, threads=threads,
                    pixels_per_object=pixels_per_object, rng=np.random.default_rng(seed), callback=callback)
    seeds = np.random.SeedSequence(seed).generate_state(4, dtype=np.uint64)
    current = stages.projected(int(seeds[0])) if b.method == "projected" else stages.two_stage(seeds)
    values = current.get_params(all_paths)
    result = FitResult(
        scene=current,
        x={n: float(v) for n, v in zip(scene.param_names(), values)},
        stages=stages.stages,
        evaluations=stages.evaluations,
        seconds=time.perf_counter() - t0,
        protocol=protocol,
        seed=seed,
        products=_products(current),
        identifiability=ident,
        settings=settings,
    )
    if uncertainty:
        from ..uncertainty import estimate_uncertainty

        try:
            result.uncertainty = estimate_uncertainty(result, target, clip=clip, mask=mask)
        except RtloopError as e:
            result.uncertainty = {"method": "gauss-newton", "sigma": {}, "warnings": [str(e)]}
    result.seconds = time.perf_counter() - t0
    return result


def _objective(scene: Scene, image: np.ndarray, mask: np.ndarray | None) -> tuple[np.ndarray, np.ndarray | None]:
    """The image as float32 checked against the scene, and the mask's pixel indices (None: all)."""
    target = np.ascontiguousarray(image, dtype=np.float32)
    if target.shape != (scene.height, scene.width, 3):
        raise RtloopError(
            f"image: shape {target.shape} does not match the scene's ({scene.height}, {scene.width}, 3); "
            "load it with rtloop.load_image(path, scene)"
        )
    if not np.isfinite(target).all():
        raise RtloopError("image: contains NaN or infinite values")
    if mask is None:
        return target, None
    m = np.asarray(mask)
    if m.shape != (scene.height, scene.width):
        raise RtloopError(f"mask: shape {m.shape} does not match the scene's ({scene.height}, {scene.width})")
    if not m.any():
        raise RtloopError("mask: selects no pixel")
    return target, np.flatnonzero(m.astype(bool).ravel()).astype(np.uint32)
