"""Small helpers shared by the acquisition modules: encoding for display and detection, PNG and JSON
files (written through rtloop._files), errors."""

from __future__ import annotations

import json
import os
from typing import Any

import cv2
import numpy as np

from .._files import jsonable, write_bytes, write_json
from .._srgb import encode
from ..errors import AcquisitionError

__all__ = [
    "AcquisitionError",
    "check_image",
    "encode_srgb",
    "jsonable",
    "read_json",
    "to_detection_grey",
    "to_display_bgr8",
    "write_json",
    "write_png16_srgb",
]


def check_image(image: Any, what: str = "image") -> np.ndarray:
    """A float32 (H, W, 3) copy-free view of a linear RGB image, or a clear AcquisitionError."""
    arr = np.asarray(image)
    if arr.ndim == 2:
        arr = np.repeat(arr[:, :, None], 3, axis=2)
    if arr.ndim != 3 or arr.shape[2] != 3 or arr.shape[0] < 8 or arr.shape[1] < 8:
        raise AcquisitionError(
            f"{what}: expected a linear RGB image of shape (H, W, 3) at least 8x8, got shape {arr.shape}"
        )
    if arr.dtype != np.float32:
        if arr.dtype == np.uint8:
            raise AcquisitionError(
                f"{what}: got 8-bit values; pass a linear float image (rtloop.load_image or "
                "rtloop.acquisition.load_photo make one)"
            )
        arr = arr.astype(np.float32)
    if not np.isfinite(arr).all():
        raise AcquisitionError(f"{what}: contains NaN or infinite values")
    return arr


def encode_srgb(linear: np.ndarray) -> np.ndarray:
    """Linear values -> sRGB-encoded values in [0, 1] (clipped), float32."""
    return encode(linear, np.float32).astype(np.float32)


def to_display_bgr8(linear: np.ndarray) -> np.ndarray:
    """A linear RGB image as 8-bit sRGB BGR (OpenCV's order), for drawing and detection."""
    enc = encode_srgb(linear)
    return np.ascontiguousarray((enc[:, :, ::-1] * 255.0 + 0.5).astype(np.uint8))


def to_detection_grey(linear: np.ndarray, stretch: bool = True) -> np.ndarray:
    """8-bit grey image for the marker and corner detectors.

    The detectors expect display-referred contrast, so the linear luminance is sRGB-encoded; with
    ``stretch`` a dim photo is first scaled so its 99.5th percentile maps to white (detection only
    cares about contrast, and an underexposed photo would otherwise give too little of it).
    """
    lum = 0.2126 * linear[:, :, 0] + 0.7152 * linear[:, :, 1] + 0.0722 * linear[:, :, 2]
    if stretch:
        top = float(np.percentile(lum, 99.5))
        if top > 1e-6:
            lum = lum / top
    return (encode_srgb(lum) * 255.0 + 0.5).astype(np.uint8)


def read_json(path: str | os.PathLike[str], what: str) -> Any:
    """Parse a JSON file or raise AcquisitionError naming it and saying what it should be."""
    from .._files import MAX_TEXT_BYTES, InputFileError, read_regular

    name = os.fspath(path)
    try:
        return json.loads(read_regular(name, limit=MAX_TEXT_BYTES, what=what).decode("utf-8"))
    except InputFileError as exc:
        raise AcquisitionError(str(exc)) from None
    except (OSError, UnicodeDecodeError) as exc:
        raise AcquisitionError(f"{name}: cannot read {what}: {exc}") from None
    except json.JSONDecodeError as exc:
        raise AcquisitionError(
            f"{name}: not valid JSON ({exc.msg} at line {exc.lineno}); expected {what}"
        ) from None


def encode_png(image_bgr_or_grey: np.ndarray) -> bytes:
    ok, buf = cv2.imencode(".png", image_bgr_or_grey)
    if not ok:
        raise AcquisitionError("could not encode PNG")
    return buf.tobytes()


def write_png16_srgb(path: str | os.PathLike[str], linear: np.ndarray) -> None:
    """Write a linear RGB image as a 16-bit sRGB-encoded PNG (what rtloop.load_image reads by default).

    Values above 1 are clipped (they were saturated in the photo anyway).
    """
    enc = encode_srgb(linear)
    data = (enc[:, :, ::-1] * 65535.0 + 0.5).astype(np.uint16)
    write_bytes(path, encode_png(np.ascontiguousarray(data)), parents=True)


def write_png8(path: str | os.PathLike[str], image_bgr: np.ndarray) -> None:
    write_bytes(path, encode_png(np.ascontiguousarray(image_bgr)), parents=True)


_UNDISTORT_CRITERIA = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 50, 1e-10)


def undistort_points(
    points: np.ndarray,
    camera_matrix: np.ndarray,
    dist_coeffs: np.ndarray,
    new_matrix: np.ndarray | None = None,
) -> np.ndarray:
    """Ideal (undistorted) coordinates of observed pixels (N, 2): normalised, or pixels of ``new_matrix``.

    Iterates to convergence (OpenCV's default of 5 iterations is not enough for strong distortion);
    works with OpenCV 4 (``undistortPointsIter``) and 5 (``undistortPoints`` with criteria).
    """
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 1, 2)
    k = np.asarray(camera_matrix, dtype=np.float64)
    d = np.asarray(dist_coeffs, dtype=np.float64)
    if hasattr(cv2, "undistortPointsIter"):
        out = cv2.undistortPointsIter(pts, k, d, None, new_matrix, _UNDISTORT_CRITERIA)
    else:
        out = cv2.undistortPoints(pts, k, d, R=None, P=new_matrix, criteria=_UNDISTORT_CRITERIA)
    return out.reshape(-1, 2)
