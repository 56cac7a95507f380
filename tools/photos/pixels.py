"""Pixel helpers of the test photos: rtloop's sRGB transfer (``rtloop._srgb``) in float64, lossless PNG
bytes, the pixels away from silhouettes, unit vectors."""

from __future__ import annotations

import functools
import io

import numpy as np
from PIL import Image

from rtloop import _srgb


#: IEC 61966-2-1 encoding of clamp(x, 0, 1), in [0, 1], computed in float64 whatever the input's dtype.
srgb_oetf = functools.partial(_srgb.encode, dtype=np.float64)
#: 8-bit sRGB codes (rounded) of a linear image, encoded in float64.
encode8 = functools.partial(_srgb.encode8, dtype=np.float64)


def png_bytes(codes: np.ndarray) -> bytes:
    """A losslessly compressed 8-bit RGB PNG of ``codes``."""
    buf = io.BytesIO()
    Image.fromarray(codes, "RGB").save(buf, "PNG", optimize=True)
    return buf.getvalue()


def interior(ids: np.ndarray) -> np.ndarray:
    """Pixels whose 3x3 neighbourhood shows one object (away from silhouettes)."""
    pad = np.pad(ids, 1, mode="edge")
    same = np.ones(ids.shape, bool)
    for dy in range(3):
        for dx in range(3):
            same &= pad[dy:dy + ids.shape[0], dx:dx + ids.shape[1]] == ids
    return same


def unit(v: np.ndarray) -> np.ndarray:
    """``v`` scaled to length 1 along its last axis."""
    return v / np.linalg.norm(v, axis=-1, keepdims=True)
