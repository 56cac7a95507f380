"""What a photo's EXIF says about its camera: the focal length in pixels (from the focal length and the
focal-plane resolution, or the 35 mm-equivalent focal length) and the exposure (time, f-number, ISO), read
with Pillow."""

from __future__ import annotations

import math
import os
from dataclasses import dataclass

from PIL import Image, UnidentifiedImageError

__all__ = ["ExifFocal", "exif_exposure", "exif_focal"]

_EXIF_IFD = 0x8769
_FOCAL_LENGTH = 0x920A
_FOCAL_35MM = 0xA405
_FOCAL_PLANE_X_RES = 0xA20E
_FOCAL_PLANE_UNIT = 0xA210
_EXPOSURE_TIME = 0x829A
_F_NUMBER = 0x829D
_ISO = 0x8827
_UNIT_MM = {2: 25.4, 3: 10.0, 4: 1.0, 5: 0.001}  # inch, cm, mm, micrometre
#: The diagonal of a 36 x 24 mm frame: "35 mm-equivalent" matches the diagonal field of view.
FULL_FRAME_DIAGONAL_MM = math.hypot(36.0, 24.0)


@dataclass(frozen=True)
class ExifFocal:
    """A focal length from EXIF: ``focal_px`` at the photo's stored size and where it came from."""

    focal_px: float
    source: str


def _positive(value: object) -> float | None:
    try:
        v = float(value)  # type: ignore[arg-type]  # IFDRational, int or float
    except (TypeError, ValueError, ZeroDivisionError):
        return None
    return v if math.isfinite(v) and v > 0 else None


def exif_focal(path: str | os.PathLike[str], width: int, height: int) -> ExifFocal | None:
    """The focal length in pixels at ``width`` x ``height`` (the photo's stored size), or None when the
    file carries no usable EXIF focal length (or is not a format Pillow reads).

    FocalLength with FocalPlaneXResolution gives it exactly; FocalLengthIn35mmFilm gives it through the
    full frame's diagonal (exact for an undistorted photo of the camera's full sensor).
    """
    try:
        with Image.open(path) as im:
            ifd = im.getexif().get_ifd(_EXIF_IFD)
            stored = im.size
    except (OSError, UnidentifiedImageError, ValueError):
        return None
    scale = width / stored[0] if stored[0] else 1.0  # EXIF describes the stored image
    focal_mm = _positive(ifd.get(_FOCAL_LENGTH))
    res = _positive(ifd.get(_FOCAL_PLANE_X_RES))
    unit = _UNIT_MM.get(int(ifd.get(_FOCAL_PLANE_UNIT, 2) or 2))
    if focal_mm is not None and res is not None and unit is not None:
        return ExifFocal(focal_mm * res / unit * scale, f"EXIF focal length {focal_mm:g} mm and focal-plane resolution")
    f35 = _positive(ifd.get(_FOCAL_35MM))
    if f35 is not None:
        focal_px = f35 * math.hypot(width, height) / FULL_FRAME_DIAGONAL_MM
        return ExifFocal(focal_px, f"EXIF 35 mm-equivalent focal length {f35:g} mm")
    return None


def exif_exposure(path: str | os.PathLike[str]) -> dict[str, float] | None:
    """The exposure the photo's EXIF records: ``exposure_time_s``, ``f_number``, ``iso`` (those present) and,
    with all three, ``ev100`` = log2(N² / t) - log2(ISO / 100), the exposure value at ISO 100 (one stop per
    unit; two photos' linear values compare after scaling by 2^(ev100_a - ev100_b)). None when the file
    carries none of them (or is not a format Pillow reads)."""
    try:
        with Image.open(path) as im:
            ifd = im.getexif().get_ifd(_EXIF_IFD)
    except (OSError, UnidentifiedImageError, ValueError):
        return None
    iso = ifd.get(_ISO)
    if isinstance(iso, (tuple, list)):
        iso = iso[0] if iso else None
    found = {k: v for k, v in (("exposure_time_s", _positive(ifd.get(_EXPOSURE_TIME))),
                               ("f_number", _positive(ifd.get(_F_NUMBER))), ("iso", _positive(iso)))
             if v is not None}
    if not found:
        return None
    if len(found) == 3:
        t, n, i = found["exposure_time_s"], found["f_number"], found["iso"]
        found["ev100"] = math.log2(n * n / t) - math.log2(i / 100.0)
    return found
