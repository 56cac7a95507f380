"""Which pixels the Gauss-Newton model uses: not a silhouette or a shadow edge (discontinuous in the
parameters), not saturated in every channel, not masked out; saturated channels of the others are left
out one by one."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from .. import _native
from .._pixels import SATURATED, edges
from ..fit.products import unit_light_scene
from ..scene import Scene

__all__ = ["UsedPixels", "used_pixels"]


@dataclass
class UsedPixels:
    ids: np.ndarray  # (H, W) object index per pixel, -1 for background
    unit: np.ndarray  # (H, W) the unit-light render (> 0 where the light reaches the surface)
    idx: np.ndarray  # flat indices of the used pixels
    sat_u: np.ndarray  # (used, 3) saturated channels of the used pixels
    saturated: np.ndarray  # (H, W) saturated in every channel
    silhouette: np.ndarray  # (H, W)
    shadow_edge: np.ndarray  # (H, W)
    rendered: list[np.ndarray]  # (used, 3) float32 each: the renders of ``also`` at the used pixels
    images: list[np.ndarray]  # (H, W, 3) float32 each: the renders of ``also``


def used_pixels(work: Scene, wd: dict[str, Any], target: np.ndarray, mask: np.ndarray | None,
                also: Sequence[Scene] = ()) -> UsedPixels:
    """The pixels of ``target`` that the model of ``work`` (``wd`` as a dict) represents smoothly; with
    ``also`` (scenes of the same size, e.g. the fitted one, the unit environment) their renders at those
    pixels, from the same pass over the first hits as the unit-light render and the object index."""
    images, ids = _native.render_many([unit_light_scene(wd), *also])  # ids: work's first hits are these
    unit = images[0][..., 0]
    lit = unit > 0
    sat = target.reshape(-1, 3) >= SATURATED  # per channel: the others of the pixel still count
    saturated = sat.all(axis=1).reshape(ids.shape)
    silhouette = edges(ids)
    shadow_edge = edges(np.where(ids >= 0, lit.astype(np.int32), -1)) & ~silhouette
    use = ~(saturated | silhouette | shadow_edge)
    if mask is not None:  # pixels the fit left out (bool (H, W), True = used)
        use &= np.asarray(mask, bool)
    idx = np.flatnonzero(use)
    rendered = [np.take(img.reshape(-1, 3), idx, axis=0) for img in images[1:]]
    return UsedPixels(ids, unit, idx, np.take(sat, idx, axis=0), saturated, silhouette, shadow_edge, rendered,
                      list(images[1:]))
