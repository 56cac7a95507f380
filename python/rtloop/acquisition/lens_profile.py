"""A lens's own profile from the photo's EXIF: its distortion and vignetting removed before the scene is built.

A photo's EXIF names the camera (Make, Model) and usually the lens (LensModel), with the focal length and
the f-number it was taken at. Lensfun's database (through ``lensfunpy``) holds measured profiles of
about 1,300 lenses: the radial distortion at each focal length and the vignetting at each focal length,
aperture and distance. Where the photo's camera and lens are found, :class:`LensRemap` resamples the photo
into the pinhole camera the scene format describes (distortion removed, the image's scale at its centre
kept) and divides out the lens's falloff in linear light, so the photo shows the scene's radiance; masks and
pixel positions given on the photo as taken move with it (the interface of
:class:`~rtloop.acquisition.calibration.PinholeRemap`).

The focal length EXIF gives is the lens's paraxial one: it is the scale at the image's centre, where the
distortion models of Lensfun scale the image by their centre derivative, so the pinhole camera's focal
length is EXIF's divided by that derivative. A calibration (``--camera``) or a given field of view
(``--vfov``, a photo already free of distortion) take precedence. docs/acquisition.md, "Lens profiles".
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass
from typing import Any

import cv2
import numpy as np
from PIL import Image, UnidentifiedImageError

from .._files import MAX_IMAGE_BYTES, open_regular
from ..errors import RtloopError
from ._common import AcquisitionError
from .camera import centred_camera_matrix

__all__ = ["LensExif", "LensProfile", "LensRemap", "find_lens_profile", "read_lens_exif"]

_EXIF_IFD = 0x8769
_MAKE, _MODEL = 0x010F, 0x0110
_LENS_MAKE, _LENS_MODEL = 0xA433, 0xA434
_FOCAL_LENGTH, _F_NUMBER, _SUBJECT_DISTANCE = 0x920A, 0x829D, 0x9206
#: Longest camera or lens name believed (EXIF strings are at most a few dozen characters).
MAX_NAME = 128
#: The focus distance assumed when EXIF gives none (metres; Lensfun's vignetting is then read at infinity).
DEFAULT_DISTANCE_M = 1000.0


@dataclass(frozen=True)
class LensExif:
    """What the photo's EXIF says about its camera and lens (None where absent or unusable)."""

    make: str | None
    model: str | None
    lens_make: str | None
    lens_model: str | None
    focal_mm: float | None
    f_number: float | None
    distance_m: float | None


def _text(value: Any) -> str | None:
    """An EXIF string as text: bytes decoded, NULs and padding stripped; None when empty or too long."""
    if isinstance(value, bytes):
        value = value.decode("latin-1")
    if not isinstance(value, str):
        return None
    value = " ".join(value.replace("\x00", " ").split())
    return value if 0 < len(value) <= MAX_NAME and value.isprintable() else None


def _number(value: Any, low: float, high: float) -> float | None:
    try:
        v = float(value)
    except (TypeError, ValueError, ZeroDivisionError, OverflowError):
        return None
    return v if math.isfinite(v) and low <= v <= high else None


def read_lens_exif(path: str | os.PathLike[str]) -> LensExif | None:
    """The camera and lens the file's EXIF names; None when it names no camera (or is not a format Pillow
    reads)."""
    try:
        with open_regular(path, limit=MAX_IMAGE_BYTES, what="image") as fh, Image.open(fh) as im:
            top = im.getexif()
            ifd = top.get_ifd(_EXIF_IFD)
    except (OSError, RtloopError, UnidentifiedImageError, ValueError):
        return None
    found = LensExif(_text(top.get(_MAKE)), _text(top.get(_MODEL)), _text(ifd.get(_LENS_MAKE)),
                     _text(ifd.get(_LENS_MODEL)), _number(ifd.get(_FOCAL_LENGTH), 1.0, 5000.0),
                     _number(ifd.get(_F_NUMBER), 0.5, 128.0), _number(ifd.get(_SUBJECT_DISTANCE), 0.01, 1e6))
    return found if found.make or found.model else None


@dataclass(frozen=True)
class LensProfile:
    """A lens found in Lensfun's database for a photo, at the focal length and aperture it was taken at."""

    camera: Any  # lensfunpy.Camera
    lens: Any  # lensfunpy.Lens
    focal_mm: float
    f_number: float | None
    distance_m: float

    @property
    def name(self) -> str:
        return f"{self.lens.maker} {self.lens.model}".strip() if self.lens.maker not in self.lens.model \
            else str(self.lens.model)

    def remap(self, width: int, height: int, focal_px: float) -> LensRemap:
        """The resampling of a ``width`` x ``height`` photo whose EXIF focal length is ``focal_px``."""
        return LensRemap(self, width, height, focal_px)


def _lensfun() -> Any:
    try:
        import lensfunpy
    except ImportError:  # pragma: no cover - a dependency of the package
        return None
    return lensfunpy


def _pick_lens(db: Any, camera: Any, exif: LensExif) -> tuple[Any, str]:
    """The lens EXIF names for ``camera``: an exact match, else the best of a loose search when it scores
    above the next; a camera with a single lens in the database (a fixed-lens compact) needs no name."""
    if exif.lens_model is None:
        lenses = db.find_lenses(camera)
        if len(lenses) == 1:
            return lenses[0], ""
        return None, "the EXIF names no lens (LensModel)"
    lenses = db.find_lenses(camera, exif.lens_make, exif.lens_model)
    if not lenses:
        lenses = db.find_lenses(camera, None, exif.lens_model, loose_search=True)
        if len(lenses) > 1 and lenses[0].score <= lenses[1].score:
            return None, f"the lens {exif.lens_model!r} matches several in Lensfun's database"
    if not lenses:
        return None, f"the lens {exif.lens_model!r} is not in Lensfun's database"
    return lenses[0], ""


def find_lens_profile(exif: LensExif | None) -> tuple[LensProfile | None, str]:
    """The profile of the lens ``exif`` names, or None and why not (a line for the user)."""
    lensfun = _lensfun()
    if lensfun is None:
        return None, "lensfunpy is not installed"
    if exif is None:
        return None, "the EXIF names no camera"
    if exif.focal_mm is None:
        return None, "the EXIF gives no focal length"
    db = lensfun.Database()
    cameras = db.find_cameras(exif.make, exif.model) or db.find_cameras(exif.make, exif.model, loose_search=True)
    if not cameras:
        return None, f"the camera {exif.make or ''} {exif.model or ''} is not in Lensfun's database".replace("  ", " ")
    lens, why = _pick_lens(db, cameras[0], exif)
    if lens is None:
        return None, why
    if lens.type != lensfun.LensType.RECTILINEAR:
        return None, f"{lens.model} is not a rectilinear lens (a fisheye's geometry is not converted)"
    if not lens.calib_distortion and not lens.calib_vignetting:
        return None, f"Lensfun has no distortion or vignetting measurement of {lens.model}"
    if not (lens.min_focal * 0.99 <= exif.focal_mm <= max(lens.min_focal, lens.max_focal) * 1.01):
        return None, (f"the EXIF focal length {exif.focal_mm:g} mm is outside {lens.model}'s range "
                      f"({lens.min_focal:g}-{lens.max_focal:g} mm)")
    return LensProfile(cameras[0], lens, exif.focal_mm, exif.f_number, exif.distance_m or DEFAULT_DISTANCE_M), ""


class LensRemap:
    """The resampling from a photo taken through ``profile``'s lens to the scene's pinhole camera (same size),
    for photos (:meth:`correct`: the falloff divided out, then the geometry), masks and pixel positions."""

    def __init__(self, profile: LensProfile, width: int, height: int, exif_focal_px: float):
        lensfun = _lensfun()
        self.profile, self.width, self.height = profile, width, height
        flags = lensfun.ModifyFlags
        aperture = profile.f_number or (profile.lens.min_aperture or 8.0)

        def modifier(which: int, reverse: bool = False) -> Any:
            m = lensfun.Modifier(profile.lens, profile.camera.crop_factor, width, height)
            m.initialize(profile.focal_mm, aperture, profile.distance_m, scale=1.0, pixel_format=np.float32,
                         flags=which, reverse=reverse)
            return m

        self.distortion = bool(profile.lens.calib_distortion)
        self.vignetting = bool(profile.lens.calib_vignetting) and profile.f_number is not None
        # Lensfun's maps: for each pinhole pixel where it lies in the photo, and (reverse) the other way.
        self._maps = modifier(flags.DISTORTION).apply_geometry_distortion() if self.distortion else None
        self._back = modifier(flags.DISTORTION, True).apply_geometry_distortion() if self.distortion else None
        if not all(m is not None and m.dtype.kind == "f" and np.isfinite(m).all() for m in (self._maps, self._back)):  # Lensfun gives no map where its model cannot be inverted there
            self._maps = self._back = None
            self.distortion = False
        self._gain = None
        if self.vignetting:
            gain = np.ones((height, width, 3), np.float32)
            modifier(flags.VIGNETTING).apply_color_modification(gain)
            self._gain = gain if np.isfinite(gain).all() and (gain > 0).all() else None
            self.vignetting = self._gain is not None
        self.centre_scale = self._centre_scale()
        self.focal_px = exif_focal_px / self.centre_scale
        self.source_matrix = centred_camera_matrix(exif_focal_px, width, height)
        self.camera_matrix = centred_camera_matrix(self.focal_px, width, height)

    def _centre_scale(self) -> float:
        """Photo pixels per pinhole pixel at the image's centre (1 without a distortion profile)."""
        if self._maps is None:
            return 1.0
        y, x = self.height // 2, self.width // 2
        step = self._maps[y, x + 1] - self._maps[y, x - 1]
        scale = float(np.hypot(*step)) / 2.0
        if not (math.isfinite(scale) and 0.5 < scale < 2.0):
            raise AcquisitionError(f"lens profile of {self.profile.name}: its distortion scales the image's "
                                   f"centre by {scale:g}; give --lens-profile off, or a calibration (--camera)")
        return scale

    def image(self, image: np.ndarray, interpolation: int = cv2.INTER_CUBIC) -> np.ndarray:
        """The geometry alone (masks, an image already free of falloff)."""
        if self._maps is None:
            return np.ascontiguousarray(image)
        out = cv2.remap(image, self._maps, None, interpolation, borderMode=cv2.BORDER_REPLICATE)
        if out.dtype == np.float32:
            out = np.maximum(out, 0.0)
        return np.ascontiguousarray(out)

    def correct(self, photo: np.ndarray) -> np.ndarray:
        """A linear photo as the pinhole camera would show the scene: the falloff divided out on the sensor,
        then the geometry."""
        photo = np.asarray(photo, np.float32)
        if self._gain is not None:
            photo = photo * self._gain[..., : photo.shape[2]]
        return self.image(photo).astype(np.float32)

    def mask(self, mask: np.ndarray) -> np.ndarray:
        m = (np.asarray(mask) > 0).astype(np.uint8)
        return self.image(m, cv2.INTER_NEAREST) > 0

    def points(self, points: np.ndarray) -> np.ndarray:
        """Where photo pixels (N, 2) land in the pinhole image."""
        pts = np.asarray(points, np.float32).reshape(-1, 1, 2)
        if self._back is None:
            return pts.reshape(-1, 2).astype(float)
        # Pixel centres are at integer coordinates in both Lensfun's maps and OpenCV's remap.
        xs = cv2.remap(self._back[..., 0], pts, None, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
        ys = cv2.remap(self._back[..., 1], pts, None, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
        return np.column_stack([xs.ravel(), ys.ravel()]).astype(float)

    def report(self) -> dict[str, Any]:
        """The record in the scene's ``meta.acquisition.lens_profile``."""
        p = self.profile
        return {"source": f"Lensfun (lensfunpy {_lensfun().__version__})", "camera": f"{p.camera.maker} {p.camera.model}",
                "lens": p.name, "focal_mm": p.focal_mm, "f_number": p.f_number, "distance_m": p.distance_m,
                "distortion": self.distortion, "vignetting": self.vignetting,
                "centre_scale": self.centre_scale, "focal_px": self.focal_px,
                **({"corner_gain": float(self._gain[0, 0].mean())} if self._gain is not None else {})}
