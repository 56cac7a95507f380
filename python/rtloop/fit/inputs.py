"""A fit's inputs and arguments checked (the image against the scene, the mask, the norm and footprint
arguments) and the doubt about fitted values at their bounds."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from ..errors import RtloopError
from ..scene import Scene
from .norm import NORMS

__all__ = ["FOOTPRINT_MODES", "MOSTLY_ABOVE_ONE", "check_footprint", "check_norm", "objective"]

#: An image with at least this fraction of its pixels above 1 in some channel is doubted (0..255 or not linear).
MOSTLY_ABOVE_ONE = 0.9


def check_norm(norm: Any) -> tuple[str, str]:
    """(mode, norm): ``norm`` checked (:data:`rtloop.fit.norm.NORMS` or "huber:H" with H > 0), and the norm
    the first fit takes ("l1" for "auto")."""
    ok = isinstance(norm, str) and (norm in NORMS or norm.startswith("huber:"))
    if ok and norm.startswith("huber:"):
        try:
            h = float(norm.split(":", 1)[1])
        except ValueError:
            h = math.nan
        ok = math.isfinite(h) and h > 0
    if not ok:
        raise RtloopError(f"norm: must be 'auto', 'l1', 'l2', 'huber' or 'huber:H' with H > 0 (got {norm!r})")
    return norm, "l1" if norm == "auto" else norm


#: The ``footprint`` argument's values, with True and False for "on" and "off".
FOOTPRINT_MODES = ("auto", "silhouette", "on", "off")


def check_footprint(footprint: Any) -> str:
    """``footprint`` as one of :data:`FOOTPRINT_MODES`, else an RtloopError naming the argument."""
    if isinstance(footprint, (bool, np.bool_)):
        return "on" if footprint else "off"
    if isinstance(footprint, str) and footprint in FOOTPRINT_MODES:
        return footprint
    raise RtloopError(f"footprint: must be 'auto', 'silhouette', 'on' or 'off' (or True / False) (got {footprint!r})")


def objective(scene: Scene, image: Any, mask: Any, doubts: list[str]) -> tuple[np.ndarray, np.ndarray | None]:
    """The image as float32 checked against the scene, and the mask's pixel indices (None: all)."""
    kind = getattr(getattr(image, "dtype", None), "kind", None)
    if kind is None:
        image = np.asarray(image)
        kind = image.dtype.kind
    if kind in "uib":
        raise RtloopError(
            f"image: a {np.asarray(image).dtype} array is not linear radiance (a decoded file's code values?); "
            "load the file with rtloop.load_image(path, scene), convert it with rtloop.srgb_to_linear(array), "
            "or pass float linear radiance (0 = black, 1 = the brightest value a file could store)"
        )
    if kind != "f":
        raise RtloopError(f"image: must be a float array of linear radiance (got dtype {np.asarray(image).dtype})")
    target = np.ascontiguousarray(image, dtype=np.float32)
    if target.shape != (scene.height, scene.width, 3):
        raise RtloopError(
            f"image: shape {target.shape} does not match the scene's ({scene.height}, {scene.width}, 3); "
            "load it with rtloop.load_image(path, scene)"
        )
    if not np.isfinite(target).all():
        raise RtloopError("image: contains NaN or infinite values")
    if (target < 0).any():
        doubts.append(f"image: {np.mean(target < 0):.2%} of the values are negative (min {float(target.min()):.4g}): "
                      "linear radiance is >= 0 (zero-mean noise is fine, an offset or a wrong encoding is not)")
    if float(target.max()) > 1.0 and np.mean(target.max(axis=2) > 1.0) >= MOSTLY_ABOVE_ONE:
        doubts.append(f"image: {np.mean(target.max(axis=2) > 1.0):.0%} of the pixels are above 1: is it 0..255 "
                      "code values or not linear? (rtloop.load_image gives linear 0..1)")
    if mask is None:
        return target, None
    m = np.asarray(mask)
    if m.shape != (scene.height, scene.width):
        raise RtloopError(f"mask: shape {m.shape} does not match the scene's ({scene.height}, {scene.width})")
    if m.dtype.kind not in "biuf":
        raise RtloopError(f"mask: must be bool (True = use) or 0/1 numbers (got dtype {m.dtype})")
    if m.dtype.kind == "f" and not np.isfinite(m).all():
        raise RtloopError("mask: contains NaN or infinite values (use a bool array, True = use)")
    if m.dtype.kind != "b" and not np.isin(m, (0, 1)).all():
        raise RtloopError("mask: numbers other than 0 and 1 (use a bool array, True = use)")
    if not m.any():
        raise RtloopError("mask: selects no pixel")
    return target, np.flatnonzero(m.astype(bool).ravel()).astype(np.uint32)
