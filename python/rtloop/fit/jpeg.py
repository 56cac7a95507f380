"""A JPEG photo: how the fit tells one (its blocking, :func:`.goodness.jpeg_blocking`), and the pixels whose
colour its chroma mixes across an outline."""

from __future__ import annotations

from typing import Any

import numpy as np

from .._stats import median

__all__ = ["DARK_CODES", "BRIGHT_CODES", "CODES_ALIKE", "JPEG_CHROMA_MARGIN", "JPEG_SRGB_CODES", "codes_alike",
           "is_jpeg", "jpeg_codes"]

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


#: The dark and the bright pixels whose residuals :func:`codes_alike` compares: the model's 8-bit sRGB code
#: below DARK_CODES (linear 0.0144, where a sensor's read noise and its clipping at 0 are many codes) and
#: at least BRIGHT_CODES (linear 0.117).
DARK_CODES = 32
BRIGHT_CODES = 96
#: A JPEG's errors are alike in code values where the dark pixels' residual spreads at most this many
#: times the bright pixels' (a JPEG's own quantisation: 0.4-0.8 on the direct photos at quality 40; a
#: noisy sensor's demosaiced JPEG: 2.3-2.5, its darks' read noise amplified by the encoding's slope).
CODES_ALIKE = 1.5
#: Fewer residuals than this in either group: no evidence either way.
MIN_VALUES = 300


def codes_alike(render: np.ndarray, target: np.ndarray, use: np.ndarray | None,
                saturated: float | None) -> dict[str, Any]:
    """Whether a first fit's residual is alike in 8-bit sRGB code values in the dark and the bright pixels
    (``render``: the fit's render, ``target``: the photo, both linear (H, W, 3); ``use``: the pixels fitted,
    flat indices, None for all; values at or above ``saturated`` (1 where None) left out): the robust
    spread (1.4826 x the median absolute deviation) of photo minus render in codes, per group of the
    render's code. ``alike`` is False where the dark group spreads more than CODES_ALIKE times the bright
    one; None where a group has fewer than MIN_VALUES values."""
    from .._srgb import encode

    model = np.minimum(np.asarray(render, np.float64).reshape(-1, 3), 1.0)
    photo = np.asarray(target, np.float64).reshape(-1, 3)
    if use is not None:
        model, photo = model[use], photo[use]
    keep = (photo < (1.0 if saturated is None else saturated)) & (model < 1.0) & (photo >= 0.0)
    code = 255.0 * encode(model[keep])
    residual = 255.0 * encode(photo[keep]) - code
    out: dict[str, Any] = {"dark_below_codes": DARK_CODES, "bright_from_codes": BRIGHT_CODES,
                           "alike_within": CODES_ALIKE}
    spreads = []
    for name, sel in (("dark", code < DARK_CODES), ("bright", code >= BRIGHT_CODES)):
        r = residual[sel]
        out[f"{name}_values"] = int(r.size)
        if r.size < MIN_VALUES:
            out["alike"] = None
            return out
        spreads.append(1.4826 * float(median(np.abs(r - median(r)))))
        out[f"{name}_spread_codes"] = round(spreads[-1], 3)
    out["alike"] = bool(spreads[0] <= CODES_ALIKE * max(spreads[1], 1e-9))
    return out
