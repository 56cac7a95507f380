"""White balance and colour correction, in linear light, before fitting.

rtloop fits albedos as linear RGB reflectances under a white light. A camera's white balance (or
a lamp that is not white) tints every pixel; a fit would then blame the objects' colours (or the
light's colour, if it is free). Two ways to undo that, both applied to the *linear* photo as a 3x3
matrix (``corrected = image @ matrix``):

* **Grey card** (:func:`grey_card_balance`): a neutral card in view, given as a pixel rectangle.
  Each channel is scaled so the card comes out neutral, keeping its luminance (the photo's overall
  brightness stays as shot, so the fitted light intensity keeps its meaning).
* **ColorChecker** (:func:`colorchecker_correction`): an X-Rite/Calibrite ColorChecker Classic
  (24 patches) in view, found by OpenCV contrib's ``cv2.mcc`` detector. A full 3x3 matrix maps the
  measured patches to their published sRGB values (least squares in linear light, saturated
  patches left out), scaled so the grey patches keep their luminance. When this OpenCV has no
  ``cv2.mcc`` module the function says so (and a grey card still works).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import cv2
import numpy as np

from .._srgb import decode
from ._common import AcquisitionError, check_image, to_display_bgr8

__all__ = [
    "COLORCHECKER_SRGB8",
    "ColourCorrection",
    "colorchecker_correction",
    "grey_card_balance",
    "mcc_available",
    "parse_rect",
]

_LUMA = np.array([0.2126, 0.7152, 0.0722])

#: The 24 patches of the ColorChecker Classic in sRGB (8-bit, D65; X-Rite's values for charts made
#: after November 2014), row by row from "dark skin" to "black".
COLORCHECKER_SRGB8 = np.array(
    [
        [115, 82, 68],
        [194, 150, 130],
        [98, 122, 157],
        [87, 108, 67],
        [133, 128, 177],
        [103, 189, 170],
        [214, 126, 44],
        [80, 91, 166],
        [193, 90, 99],
        [94, 60, 108],
        [157, 188, 64],
        [224, 163, 46],
        [56, 61, 150],
        [70, 148, 73],
        [175, 54, 60],
        [231, 199, 31],
        [187, 86, 149],
        [8, 133, 161],
        [243, 243, 242],
        [200, 200, 200],
        [160, 160, 160],
        [122, 122, 121],
        [85, 85, 85],
        [52, 52, 52],
    ],
    dtype=np.float64,
)


def _srgb8_to_linear(v: np.ndarray) -> np.ndarray:
    return decode(np.asarray(v, dtype=np.float64) / 255.0)


@dataclass
class ColourCorrection:
    """A linear-light colour correction: ``corrected = image @ matrix`` (pixels as row vectors)."""

    matrix: np.ndarray
    source: str
    details: dict[str, Any] = field(default_factory=dict)

    def apply(self, image: np.ndarray) -> np.ndarray:
        img = check_image(image, "image")
        out = img.reshape(-1, 3) @ self.matrix.astype(np.float32)
        return np.ascontiguousarray(np.maximum(out, 0.0).reshape(img.shape), dtype=np.float32)

    def report(self) -> dict[str, Any]:
        return {"source": self.source, "matrix": self.matrix.tolist(), **self.details}

    @classmethod
    def identity(cls) -> ColourCorrection:
        return cls(np.eye(3), "none")


def parse_rect(
    text: str | tuple | list, width: int | None = None, height: int | None = None, what: str = "grey card"
) -> tuple[int, int, int, int]:
    """``X,Y,W,H`` (pixels, top-left corner and size) checked against the image size."""
    try:
        if isinstance(text, str):
            vals = [float(v) for v in text.replace(" ", "").split(",")]
        else:
            vals = [float(v) for v in text]
        if len(vals) != 4:
            raise ValueError
    except ValueError:
        raise AcquisitionError(
            f"{what}: expected X,Y,W,H in pixels (top-left corner, width, height), got {text!r}"
        ) from None
    x, y, w, h = (round(v) for v in vals)
    if w < 2 or h < 2 or x < 0 or y < 0:
        raise AcquisitionError(
            f"{what}: the rectangle {x},{y},{w},{h} must have x, y >= 0 and be at least 2x2 pixels"
        )
    if width is not None and height is not None and (x + w > width or y + h > height):
        raise AcquisitionError(
            f"{what}: the rectangle {x},{y},{w},{h} reaches outside the {width}x{height} photo; give "
            "X,Y,W,H in "
            "pixels of the photo as it is on disk (before undistortion)"
        )
    return x, y, w, h


def grey_card_balance(
    image: np.ndarray,
    rect: str | tuple[int, int, int, int],
    *,
    where: str = "photo",
) -> ColourCorrection:
    """White balance from a neutral (grey or white) card inside ``rect`` = (x, y, w, h) pixels.

    Raises:
        AcquisitionError: the rectangle is outside the photo, the card is too dark, overexposed
            (clipped pixels cannot be balanced), or not uniform (probably not the card).
    """
    img = check_image(image, where)
    h_img, w_img = img.shape[:2]
    x, y, w, h = parse_rect(rect, w_img, h_img)
    patch = img[y : y + h, x : x + w].reshape(-1, 3).astype(np.float64)
    clipped = float(np.mean(np.any(patch >= 0.995, axis=1)))
    if clipped > 0.01:
        raise AcquisitionError(
            f"{where}: {clipped:.0%} of the grey card's pixels are clipped (overexposed); expose for the "
            "card "
            "(lower exposure) or choose a darker grey card"
        )
    mean = patch.mean(axis=0)
    lum = float(mean @ _LUMA)
    if lum < 0.003 or np.any(mean <= 1e-5):
        raise AcquisitionError(
            f"{where}: the grey card region {x},{y},{w},{h} is almost black (mean "
            f"{mean.round(4).tolist()}); is the "
            "rectangle on the card, and is the card lit?"
        )
    spread = float(np.std(patch @ _LUMA) / lum)
    if spread > 0.25:
        raise AcquisitionError(
            f"{where}: the grey card region {x},{y},{w},{h} is not uniform (brightness varies by "
            f"{spread:.0%}); "
            "give a rectangle that lies inside the card"
        )
    gains = lum / mean
    return ColourCorrection(
        np.diag(gains),
        "grey card",
        {
            "rect": [x, y, w, h],
            "card_mean_linear_rgb": mean.tolist(),
            "gains": gains.tolist(),
            "card_uniformity": spread,
        },
    )


def mcc_available() -> bool:
    """Whether this OpenCV has contrib's ColorChecker detector (``cv2.mcc``)."""
    return hasattr(cv2, "mcc") and hasattr(cv2.mcc, "CCheckerDetector_create")


def colorchecker_correction(image: np.ndarray, *, where: str = "photo") -> ColourCorrection:
    """Colour correction from a ColorChecker Classic (24 patches) found in the photo by ``cv2.mcc``.

    Raises:
        AcquisitionError: ``cv2.mcc`` is not available in this OpenCV, no chart was found, or too
            many patches are clipped.
    """
    img = check_image(image, where)
    if not mcc_available():
        raise AcquisitionError(
            "ColorChecker detection needs OpenCV's contrib module 'mcc' (cv2.mcc), which this OpenCV "
            f"({cv2.__version__}) does not have; install opencv-contrib-python-headless, or use a grey "
            "card (--grey-card X,Y,W,H) instead"
        )
    checker, corners = _detect_colorchecker(img, where)
    measured, clipped = _measure_patches(img, corners, where)
    target = _srgb8_to_linear(COLORCHECKER_SRGB8)
    use = ~clipped
    if use.sum() < 12:
        raise AcquisitionError(
            f"{where}: {int(clipped.sum())} of the ColorChecker's 24 patches are clipped (overexposed); "
            "lower the exposure"
        )
    matrix, *_ = np.linalg.lstsq(measured[use], target[use], rcond=None)
    # Keep the photo's brightness: the grey patches' luminance is unchanged.
    greys = np.arange(18, 24)[use[18:24]]
    if len(greys):
        scale = float((measured[greys] @ _LUMA).sum() / ((measured[greys] @ matrix) @ _LUMA).sum())
        matrix = matrix * scale
    else:
        scale = 1.0
    corrected = measured @ matrix

    # Compare chromaticities (exposure-independent) before and after.
    def chroma_err(a: np.ndarray) -> float:
        na = a / np.maximum(a.sum(axis=1, keepdims=True), 1e-9)
        nt = target / target.sum(axis=1, keepdims=True)
        return float(np.sqrt(np.mean(np.sum((na[use] - nt[use]) ** 2, axis=1))))

    return ColourCorrection(
        matrix,
        "ColorChecker",
        {
            "patches_used": int(use.sum()),
            "chart_corners_px": np.asarray(checker.getBox()).tolist(),
            "chromaticity_rms_before": chroma_err(measured),
            "chromaticity_rms_after": chroma_err(corrected),
            "brightness_scale": scale,
            "detector_cost": float(checker.getCost()),
            "patch_corners_px": corners.tolist(),
        },
    )


def _detect_colorchecker(img: np.ndarray, where: str) -> tuple[Any, np.ndarray]:
    """The ColorChecker ``cv2.mcc`` finds in the photo (shown to it scaled to its 99.5th percentile) and
    its 24 patches' corners, float32 (24, 4, 2)."""
    lum = img @ _LUMA.astype(np.float32)
    top = float(np.percentile(lum, 99.5)) or 1.0
    bgr = to_display_bgr8(img / max(top, 1e-6))
    detector = cv2.mcc.CCheckerDetector_create()
    detector.setColorChartType(cv2.mcc.MCC24)  # the default is not set in some OpenCV builds
    if not detector.process(bgr, 1):
        raise AcquisitionError(
            f"{where}: no ColorChecker (24-patch Classic) found; it must be flat, evenly lit, fill at least "
            "about 1/10 of the photo's width, and not be glared; or use --grey-card"
        )
    checker = detector.getBestColorChecker()
    corners = np.asarray(checker.getColorCharts(), dtype=np.float32).reshape(-1, 4, 2)
    if len(corners) != 24:
        raise AcquisitionError(
            f"{where}: the ColorChecker detector returned {len(corners)} patches, expected 24"
        )
    return checker, corners


def _measure_patches(img: np.ndarray, corners: np.ndarray, where: str) -> tuple[np.ndarray, np.ndarray]:
    """The mean linear RGB of the middle of each patch (24, 3), and whether each patch is clipped (more
    than 2 % of its pixels at white in any channel)."""
    measured = np.empty((24, 3))
    clipped = np.zeros(24, bool)
    h, w = img.shape[:2]
    for i, quad in enumerate(corners):
        centre = quad.mean(axis=0)
        inner = centre + 0.6 * (quad - centre)  # keep the middle of the patch
        mask = np.zeros((h, w), np.uint8)
        cv2.fillConvexPoly(mask, np.round(inner * 16).astype(np.int32), 1, lineType=cv2.LINE_8, shift=4)
        pix = img[mask.astype(bool)]
        if len(pix) < 4:
            raise AcquisitionError(
                f"{where}: ColorChecker patch {i + 1} is too small in the photo; move closer"
            )
        measured[i] = pix.mean(axis=0)
        clipped[i] = np.mean(np.any(pix >= 0.995, axis=1)) > 0.02
    return measured, clipped
