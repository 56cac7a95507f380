"""A term's gain measured against the part of the loss a model can explain (docs/methods.md, "How a photo
selects them").

A photo's loss at the true scene is not 0: its noise, a JPEG's blocks and the 8-bit rounding leave a floor
(:func:`.goodness.pixel_floor`). A term that explains all of a model's error lowers the loss by its
excess over that floor, not by the whole loss; on a noisy photo the floor is most of the loss (a sensor
noise of 1 % of white leaves 60-80 % of a room-light photo's L1 loss), and the same room light that
lowers a clean photo's loss by a quarter lowers a noisy one's by 1-2 %. So the environment and the bounce
(the terms also judged on held-out pixels, which keep a column that only fits noise out) are judged by the
fraction of the excess they remove. The floor is summed over the test's pixels in the fit's own loss: the
L1 norm, in linear units or on the sRGB encodings (where a pixel's floor is its linear floor over its code
step, in codes / 255); other norms keep the fraction of the whole loss (``None``).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from .goodness import _quarter_step, pixel_floor

__all__ = ["FLOOR_SHARE", "excess_gain", "noise_floor"]


def noise_floor(encoding: np.ndarray, sigma: np.ndarray, blocking: dict[str, Any], pixels: np.ndarray | None, *,
                norm: str, space: str) -> float | None:
    """The L1 loss an exact model would leave on ``pixels`` (indices into the photo, all when None) of a
    photo with sRGB ``encoding`` (H, W, 3), noise ``sigma`` per channel and JPEG ``blocking``, in ``space``
    ("linear" or "srgb"); None for a norm other than L1."""
    if norm != "l1" or space not in ("linear", "srgb"):
        return None
    e = np.asarray(encoding, np.float32).reshape(-1, 3)
    e = e if pixels is None else e[np.asarray(pixels, np.int64)]
    quant = _quarter_step(e)
    floor = pixel_floor(quant, sigma, blocking)
    if space == "srgb":  # a pixel's floor in codes (its linear floor over its code step, 4 quarter steps) / 255
        floor = floor / (np.float32(4.0 * 255.0) * quant)
    return float(floor.sum(dtype=np.float64))


#: The floor counts for at most this fraction of the loss: the noise it is measured from is known to about a
#: tenth (:func:`.goodness.noise_sigma` read 0.0088-0.0099 on rtloop's renders of the lamp photos under a
#: noise of 0.01), so an excess below a tenth of the loss is not told from none, and a gain is at most ten
#: times the fraction of the whole loss.
FLOOR_SHARE = 0.9


def excess_gain(l0: float, l1: float, floor: float | None) -> float:
    """The fraction of the loss ``l0`` beyond the photo's ``floor`` that a term taking it to ``l1`` removes:
    (l0 - l1) / (l0 - floor), the floor taken as at most FLOOR_SHARE of ``l0``; the fraction of the whole
    loss, (l0 - l1) / l0, without a floor."""
    if not l0 > 0:
        return 0.0
    below = 0.0 if floor is None else min(max(floor, 0.0), FLOOR_SHARE * l0)
    return (l0 - l1) / (l0 - below)
