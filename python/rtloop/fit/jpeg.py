"""A JPEG photo: how the fit tells one (its blocking, :func:`.goodness.jpeg_blocking`), and the pixels whose
colour its chroma mixes across an outline."""

from __future__ import annotations

from typing import Any

import numpy as np

__all__ = ["JPEG_CHROMA_MARGIN", "JPEG_SRGB_CODES", "is_jpeg", "jpeg_codes"]

#: A JPEG (its blocking detected and of at least JPEG_SRGB_CODES, :func:`is_jpeg`) stores colour
#: (chroma) at half the resolution in each direction (4:2:0, the default of libjpeg, Pillow and cameras),
#: and its decoder interpolates each pixel's colour from the neighbouring samples ("fancy upsampling":
#: weights 3/4 and 1/4 of the 2 x 2 samples around it), so a pixel's colour mixes those of the pixels up
#: to 2 away. Within that Chebyshev distance of another object a pixel's colour is part the other's (a
#: red ball's rim takes the grey floor's), which biased each object's colour products toward its
#: neighbours': those pixels still count in the loss, but not in the products' solve
#: (``settings["solve_margin"]``).
JPEG_CHROMA_MARGIN = 2

#: A photo whose JPEG blocks err by at least this many 8-bit codes (RMS, channel mean;
#: :func:`.goodness.jpeg_blocking`) has errors of constant size in code values, several times the 8-bit
#: quantisation's own (0.29 codes RMS): the default loss space compares it there.
JPEG_SRGB_CODES = 1.0

def is_jpeg(blocking: dict[str, Any]) -> bool:
    """Whether the photo is a JPEG by its blocking (:func:`.goodness.jpeg_blocking`): detected, and of at
    least JPEG_SRGB_CODES RMS (a PNG can show a significant but smaller grid: direct-back-left's 0.57
    codes)."""
    codes = float(np.mean(blocking.get("error_codes", [0.0, 0.0, 0.0])))
    return bool(blocking.get("detected")) and codes >= JPEG_SRGB_CODES


def jpeg_codes(blocking: dict[str, Any], space: str) -> float | None:
    """The JPEG's RMS error in codes (channel mean) where ``space="auto"`` would compare it in sRGB (a
    JPEG blocking of at least JPEG_SRGB_CODES), else None."""
    codes = float(np.mean(blocking.get("error_codes", [0.0, 0.0, 0.0])))
    return codes if space == "auto" and is_jpeg(blocking) else None
