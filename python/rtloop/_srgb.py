"""The sRGB transfer function (IEC 61966-2-1), both ways: the one copy in Python (the Rust core has its
own in the film). ``dtype`` keeps each caller's precision: float32 callers get float32 arithmetic.

An 8-bit photo as :func:`rtloop.load_image` decodes it holds at most 256 distinct values, those of
:func:`code_values`. :func:`codes8` finds its codes (or says it is no such photo), and a function of the
pixel values is then computed once per code and looked up (:func:`per_code`): the very numbers the
function gives on the whole image, each from the same value by the same arithmetic, not an
approximation."""

from __future__ import annotations

import functools
from collections.abc import Callable
from typing import Any

import numpy as np

__all__ = ["code_values", "codes8", "decode", "encode", "encode8", "per_code", "srgb_to_linear"]


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


@functools.cache
def code_values(levels: int = 256) -> np.ndarray:
    """The linear value (float32, read-only) of each sRGB code 0 .. ``levels`` - 1: what
    :func:`rtloop.load_image` makes of an 8-bit (256) or 16-bit (65536) file's codes."""
    table = decode(np.arange(levels, dtype=np.float64) / (levels - 1)).astype(np.float32)
    table.flags.writeable = False
    return table


#: :func:`codes8` sorts a float32 into buckets by its bits above this one (sign, exponent and the top 8 of
#: the 23 mantissa bits: a bucket spans at most 2^-8 of its values, the 8-bit codes' values lie at least
#: 0.9 % apart), so that each bucket holds at most one code's value.
_BUCKET_SHIFT = 15


@functools.cache
def _code_buckets() -> np.ndarray | None:
    """Per bucket of the floats from 0 to 1 (their bits above _BUCKET_SHIFT), the code whose value it
    holds, else the next code up (int16; each bucket holds at most one code's value, and a value between
    codes is told apart by the check against the code's own bits). None if two codes shared a bucket (the
    spacing above rules it out; then no array has codes)."""
    keys = (code_values().view(np.uint32) >> _BUCKET_SHIFT).astype(np.int64)
    if not (np.diff(keys) > 0).all():  # the codes' values rise: distinct keys rise too (np.unique loads numpy.ma)
        return None
    table = np.searchsorted(keys, np.arange(int(keys[-1]) + 1)).astype(np.int16)
    table.flags.writeable = False
    return table


def codes8(values: Any) -> np.ndarray | None:
    """The 8-bit sRGB codes (uint8, ``values``' shape) of a float32 array every value of which is bit for
    bit the linear value of a code (:func:`code_values`, as :func:`rtloop.load_image` decodes an 8-bit
    file); None for any other array (another dtype, a value between codes, a negative zero, a 16-bit or
    noisy photo). The core's loop: a few percent of the time of one sRGB transfer over the values."""
    from . import _native

    v = np.asarray(values)
    table = _code_buckets()
    if v.dtype != np.float32 or v.size == 0 or table is None:
        return None
    codes = _native.codes8(np.ascontiguousarray(v).reshape(-1), code_values(), table, _BUCKET_SHIFT)
    return None if codes is None else codes.reshape(v.shape)


def per_code(fn: Callable[[np.ndarray], np.ndarray], codes: np.ndarray) -> np.ndarray:
    """``fn`` of the linear values of ``codes`` (:func:`codes8`), computed once per code: ``fn`` must act
    on each value alone (elementwise, as the transfer functions do) and take the float32 values (as the
    photo holds them) in an array of any shape. Bit for bit ``fn(code_values()[codes])``. Each ``fn``'s
    table is kept: pass module-level functions, not a new closure per call."""
    return _per_code_table(fn)[codes]


@functools.cache
def _per_code_table(fn: Callable[[np.ndarray], np.ndarray]) -> np.ndarray:
    table = np.asarray(fn(code_values().copy()))
    table.flags.writeable = False
    return table
