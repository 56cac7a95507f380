"""The sRGB transfer function (IEC 61966-2-1), both ways: the one copy in Python (the Rust core has its
own in the film). ``dtype`` keeps each caller's precision: float32 callers get float32 arithmetic."""

from __future__ import annotations

from typing import Any

import numpy as np

__all__ = ["decode", "encode", "encode8", "srgb_to_linear"]


def encode(linear: Any, dtype: Any = None) -> np.ndarray:
    """Linear values -> sRGB-encoded values in [0, 1] (clipped), computed in ``dtype`` (default: the
    input's)."""
    x = np.clip(np.asarray(linear, dtype=dtype), 0.0, 1.0)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055)


def encode8(linear: Any, dtype: Any = None) -> np.ndarray:
    """8-bit sRGB code values (rounded to nearest) of linear values, encoded in ``dtype``."""
    return np.round(encode(linear, dtype) * 255.0).astype(np.uint8)


def decode(encoded: Any) -> np.ndarray:
    """sRGB-encoded values in [0, 1] -> linear values, computed in the input's dtype (not clipped)."""
    x = np.asarray(encoded)
    return np.where(x <= 0.04045, x / 12.92, ((x + 0.055) / 1.055) ** 2.4)


def srgb_to_linear(image: Any) -> np.ndarray:
    """An sRGB-encoded image array -> float32 linear radiance, what :func:`rtloop.fit` takes: uint8 code
    values (0..255), uint16 (0..65535) or floats in [0, 1] (for example ``np.asarray(Image.open(path))``,
    or that divided by 255). A file is better read with :func:`rtloop.load_image`, which also knows 16-bit
    and float files, EXIF orientation and camera responses."""
    from .errors import RtloopError

    x = np.asarray(image)
    if x.dtype == np.uint8:
        v = x.astype(np.float64) / 255.0
    elif x.dtype == np.uint16:
        v = x.astype(np.float64) / 65535.0
    elif x.dtype.kind == "f":
        v = x.astype(np.float64)
        if not np.isfinite(v).all() or v.min(initial=0.0) < 0.0 or v.max(initial=0.0) > 1.0:
            raise RtloopError("srgb_to_linear: float sRGB values must be finite and within [0, 1]")
    else:
        raise RtloopError(f"srgb_to_linear: needs uint8, uint16 or float values (got dtype {x.dtype})")
    return decode(v).astype(np.float32)
