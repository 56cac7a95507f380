"""What a photo's EXIF says about its camera: the focal length in pixels (from the focal length and the
focal-plane resolution, or the 35 mm-equivalent focal length) and the exposure (time, f-number, ISO), read
with Pillow."""

from __future__ import annotations

import math
import os
import warnings
from dataclasses import dataclass

from PIL import Image, UnidentifiedImageError

from .._files import MAX_IMAGE_BYTES, open_regular
from ..errors import RtloopError, RtloopWarning

__all__ = ["ExifFocal", "exif_exposure", "exif_focal"]

_EXIF_IFD = 0x8769
_FOCAL_LENGTH = 0x920A
_FOCAL_35MM = 0xA405
_FOCAL_PLANE_X_RES = 0xA20E
_FOCAL_PLANE_UNIT = 0xA210
_ORIENTATION = 0x0112
_EXPOSURE_TIME = 0x829A
_F_NUMBER = 0x829D
_ISO = 0x8827
_UNIT_MM = {2: 25.4, 3: 10.0, 4: 1.0, 5: 0.001}  # inch, cm, mm, micrometre
#: The diagonal of a 36 x 24 mm frame: "35 mm-equivalent" matches the diagonal field of view.
FULL_FRAME_DIAGONAL_MM = math.hypot(36.0, 24.0)
#: The EXIF values believed (README: "Input limits"): a lens's focal length from a phone's 1 mm to a 5 m
#: telescope, its 35 mm equivalent likewise, and a sensor's resolution from 10 to 5000 pixels per mm (a
#: 100 um to a 0.2 um pixel). A value outside is warned about and ignored, as if absent.
PLAUSIBLE = {
    _FOCAL_LENGTH: ("FocalLength", 1.0, 5000.0, "mm"),
    _FOCAL_35MM: ("FocalLengthIn35mmFilm", 1.0, 5000.0, "mm"),
    _FOCAL_PLANE_X_RES: ("FocalPlaneXResolution", 10.0, 5000.0, "pixels per mm"),
}


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


def _unit_mm(value: object) -> float | None:
    """FocalPlaneResolutionUnit in mm (2, the default, is the inch); None for a value that is no unit."""
    try:
        return _UNIT_MM.get(int(value or 2))  # type: ignore[call-overload]
    except (TypeError, ValueError, OverflowError, ZeroDivisionError):
        return None


def _plausible(ifd: dict, tag: int, where: str, per_mm: float = 1.0) -> float | None:
    """The tag's positive value (times ``per_mm``, its unit's conversion to mm) when plausible; None when
    absent, and None with an RtloopWarning naming the tag when outside :data:`PLAUSIBLE`."""
    value = _positive(ifd.get(tag))
    if value is None:
        return None
    name, low, high, unit = PLAUSIBLE[tag]
    if not low <= value * per_mm <= high:
        warnings.warn(f"{where}: EXIF {name} {value:g} is implausible (believed: {low:g} to {high:g} {unit}); "
                      "ignored", RtloopWarning, stacklevel=3)
        return None
    return value


def _read_exif(path: str | os.PathLike[str]) -> tuple[dict, tuple[int, int], int] | None:
    """The EXIF sub-IFD, the stored size and the orientation tag of a regular image file; None when it is
    not a format Pillow reads."""
    try:
        with open_regular(path, limit=MAX_IMAGE_BYTES, what="image") as fh, Image.open(fh) as im:
            exif = im.getexif()
            orientation = exif.get(_ORIENTATION)
            return exif.get_ifd(_EXIF_IFD), im.size, orientation if isinstance(orientation, int) else 1
    except (OSError, RtloopError, UnidentifiedImageError, ValueError):
        return None


def exif_focal(path: str | os.PathLike[str], width: int, height: int) -> ExifFocal | None:
    """The focal length in pixels at ``width`` x ``height`` (the photo's size as displayed, its EXIF
    orientation applied), or None when the file carries no usable EXIF focal length (or is not a format
    Pillow reads). An implausible value (see :data:`PLAUSIBLE`) warns (RtloopWarning) and counts as absent.

    FocalLength with FocalPlaneXResolution gives it exactly; FocalLengthIn35mmFilm gives it through the
    full frame's diagonal (exact for an undistorted photo of the camera's full sensor).
    """
    found = _read_exif(path)
    if found is None:
        return None
    ifd, stored, orientation = found
    where = os.fspath(path)
    # EXIF describes the stored image: its x axis (FocalPlaneXResolution's) is the displayed height when
    # the orientation turns the image a quarter (5-8, a phone held upright).
    across = height if orientation in (5, 6, 7, 8) else width
    scale = across / stored[0] if stored[0] else 1.0
    focal_mm = _plausible(ifd, _FOCAL_LENGTH, where)
    unit = _unit_mm(ifd.get(_FOCAL_PLANE_UNIT, 2))
    res = None if unit is None else _plausible(ifd, _FOCAL_PLANE_X_RES, where, 1.0 / unit)
    if focal_mm is not None and res is not None and unit is not None:
        return ExifFocal(focal_mm * res / unit * scale, f"EXIF focal length {focal_mm:g} mm and focal-plane resolution")
    f35 = _plausible(ifd, _FOCAL_35MM, where)
    if f35 is not None:
        focal_px = f35 * math.hypot(width, height) / FULL_FRAME_DIAGONAL_MM
        return ExifFocal(focal_px, f"EXIF 35 mm-equivalent focal length {f35:g} mm")
    return None


def exif_exposure(path: str | os.PathLike[str]) -> dict[str, float] | None:
    """The exposure the photo's EXIF records: ``exposure_time_s``, ``f_number``, ``iso`` (those present) and,
    with all three, ``ev100`` = log2(N² / t) - log2(ISO / 100), the exposure value at ISO 100 (one stop per
    unit; two photos' linear values compare after scaling by 2^(ev100_a - ev100_b)). None when the file
    carries none of them (or is not a format Pillow reads)."""
    found = _read_exif(path)
    if found is None:
        return None
    ifd = found[0]
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
