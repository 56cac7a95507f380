"""The fitness a fit's native calls compare by (``_native.FitnessSpec``: the searched paths, the pixels, the
loss, its norm and space, the closed form's bounds), built here once per stage or test and passed to
``_native.optimize``, ``_native.evaluate`` and ``_native.held_out``."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from .. import _native
from ..scene import Scene
from . import products

__all__ = ["closed_form_spec", "fitness_spec"]


def fitness_spec(paths: Sequence[str], *, pixels: np.ndarray | None = None, loss: str = "l1",
                 clip: bool = True, product_bounds: np.ndarray | None = None, norm: str = "l1",
                 space: str = "linear", footprint: bool = False, frozen_bounce: int = 0,
                 saturated: float | None = None, solve_margin: int = 0) -> _native.FitnessSpec:
    """The spec of the fitness of ``paths`` (the arguments as ``_native.FitnessSpec`` takes them; ``pixels``
    as uint32 and ``product_bounds`` as float64, C-contiguous)."""
    if pixels is not None:
        pixels = np.ascontiguousarray(pixels, dtype=np.uint32)
    if product_bounds is not None:
        product_bounds = np.ascontiguousarray(product_bounds, dtype=np.float64)
    return _native.FitnessSpec(list(paths), pixels=pixels, loss=loss, clip=bool(clip),
                               product_bounds=product_bounds, norm=norm, space=space,
                               footprint=bool(footprint), frozen_bounce=int(frozen_bounce),
                               saturated=saturated, solve_margin=int(solve_margin))


def closed_form_spec(scene: Scene, paths: list[str], pixels: np.ndarray | None, *, environment: bool,
                     clip: bool, norm: str, space: str, saturated: float | None = None,
                     frozen_bounce: bool = False) -> _native.FitnessSpec:
    """The closed form's (``loss="l1_projected"``) spec of ``paths`` of ``scene`` on ``pixels``, with or
    without the environment column: the fitness every test of a term measures, in-sample and held out."""
    return fitness_spec(paths, pixels=pixels, loss="l1_projected", clip=clip,
                        product_bounds=products.product_bounds(scene, environment), norm=norm, space=space,
                        frozen_bounce=int(frozen_bounce), saturated=saturated)
