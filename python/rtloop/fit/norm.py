"""The loss's norm chosen from the photo (``norm="auto"``, the default): L2 where the photo is a linear camera
file and the first fit's residual is dense, else L1.

The L1 fit (the paper's norm) is robust: its residual can be large on a few pixels the model does not
represent (a pixel straddling an outline, a soft shadow's edge) and they do not move the answer. That is
the right estimator when the model explains the photo everywhere else to the photo's own noise. Where the
residual is larger than the noise at most pixels (a real material that is not exactly Lambertian, a
camera's noise on a 16-bit photo), there are no outliers to be robust to: the misfit is everywhere, and
the mean (L2) weighs the pixels that say most about the light, a highlight's position among them, where
the median (L1) lets the bulk of the diffuse shading decide. So the first fit's residual is measured per
pixel against the photo's own error (its quantisation step, the noise measured in it and a JPEG's error,
in quadrature), and when the median pixel's residual exceeds DENSE_MEDIAN_Z of them the fit is made again
in L2, on the pixels whose area shows one object only (a pixel straddling an outline is rendered at its
centre, its error is the model's, not the photo's).

The photo's noise model decides where this test is made: only on a linear camera file (:func:`linear_file`:
a linear 16-bit or 8-bit PNG or TIFF, a developed RAW), whose error is the sensor's shot and read noise, for
which L2 is the likelihood's own norm. A photo that has been through a camera's processing (an sRGB file,
8- or 16-bit, a JPEG: a tone curve, sharpening, compression) keeps L1.

Measured (studies/results/real_photos.md, docs/accuracy.md): on the real photos of the DiLiGenT ball (16-bit
linear, 96 lights) the L1 fit's median residual is 1.5-2.4 of the photo's errors and L2 lowers the mean
light-direction error from 1.27 to 0.38 deg; on 24 Mitsuba photos of the same kind (a coated and a matte
ball under 12 lights each, 16-bit linear with shot and read noise: studies/results/linear_photos.md) it
never costs more than the seed-to-seed spread and lowers the mean from 1.21 to 1.16 deg (matte 0.044 to 0.032).
On sRGB photos the test is not made: rtloop-scene's 16-bit one-photo objectives (tests/fixtures/onephoto:
Mitsuba, a floor, a board masked) have a dense residual too, and L2 is worse there on four of six views
(the low one 18 -> 174 mm); the 8-bit Mitsuba photos of tests/fixtures/photos keep L1 either way.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from .. import _native
from .._pixels import SATURATED, edges
from .._srgb import decode, encode, per_code
from .._stats import median

__all__ = ["DENSE_MEDIAN_Z", "NORMS", "dense_residual", "linear_file", "norm_verdict", "not_linear_verdict",
           "pixel_errors", "pixel_mask", "representable_pixels"]

#: The norms fit() takes: "auto" (chosen from the photo), "l1", "l2", "huber", "huber:H".
NORMS = ("auto", "l1", "l2", "huber")

#: The median of |residual| / error over the used pixels above which the residual is dense. For a residual
#: that is the photo's Gaussian noise alone the median is 0.67; it is 0.28-0.92 on the Mitsuba photos
#: (model-exact but for outlines and soft shadows: sparse) and 1.5-2.4 on the real ones.
DENSE_MEDIAN_Z = 1.2

#: The finest quantisation rtloop assumes of a photo that is not 8-bit codes: a 16-bit file's step.
FINEST_STEP = 1.0 / 65535.0


#: How far (in 16-bit steps) a value may lie from a whole step and still be one: float32's rounding of k / 65535.
_STEP_SLACK = 0.01


def linear_file(target: Any) -> bool:
    """True when every value of the photo is a whole step of a 16-bit linear file (k / 65535, within float32's
    rounding): what ``load_image(..., response="linear")`` reads from a linear 16-bit or 8-bit PNG or TIFF
    and what a RAW file develops to. An sRGB file (8- or 16-bit), a JPEG or a computed array is not."""
    v = np.asarray(target, np.float64).ravel() * 65535.0
    return bool(v.size) and bool(np.all(np.abs(v - np.rint(v)) <= _STEP_SLACK))


def not_linear_verdict() -> dict[str, Any]:
    """The record of ``norm="auto"`` on a photo that is not a linear camera file (:func:`linear_file`): L1."""
    return {"used": "l1", "linear_file": False, "median_z": None, "threshold": DENSE_MEDIAN_Z,
            "why": "the photo is not a linear camera file (its values are not whole steps of a 16-bit linear "
                   "file: an sRGB or JPEG photo, or a computed array): L1, robust to what a camera's processing "
                   "and the model's few unrepresented pixels leave"}


def _step8(encoded: np.ndarray) -> np.ndarray:
    """The 8-bit sRGB code step in linear units at the float32 sRGB encodings ``encoded``."""
    half = np.float32(0.5 / 255)
    top, bottom = np.minimum(encoded + half, np.float32(1)), np.maximum(encoded - half, np.float32(0))
    return decode(top) - decode(bottom)


def _step8_at(x: np.ndarray) -> np.ndarray:
    """:func:`_step8` at the float32 linear values ``x``."""
    return _step8(encode(x, np.float32))


def pixel_errors(target: np.ndarray, codes: np.ndarray | None, sigma: Any, jpeg_codes: Any) -> np.ndarray:
    """Per pixel and channel (H*W, 3) the photo's own error in linear units, as a standard deviation: its
    quantisation (the 8-bit code step there where it has 8-bit ``codes``, else a 16-bit step) over sqrt(12),
    the measured noise ``sigma`` (per channel) and a JPEG's RMS error ``jpeg_codes`` (per channel, in codes,
    times the code step there), in quadrature."""
    t = np.asarray(target, np.float32).reshape(-1, 3)
    jpeg = np.asarray(jpeg_codes, np.float32)[None, :]
    if codes is not None:
        step8 = per_code(_step8_at, np.asarray(codes).reshape(-1, 3))
    elif jpeg.any():
        step8 = _step8_at(t)
    else:
        step8 = None
    quant = step8 if codes is not None else np.full_like(t, FINEST_STEP)
    var = quant * quant / np.float32(12.0) + np.asarray(sigma, np.float32)[None, :] ** 2
    if step8 is not None and jpeg.any():
        var = var + (step8 * jpeg) ** 2
    return np.sqrt(var)


def dense_residual(render: np.ndarray, target: np.ndarray, use: np.ndarray | None, codes: np.ndarray | None,
                   sigma: Any, jpeg_codes: Any, *, clip: bool = True) -> dict[str, Any]:
    """The first fit's residual (``render`` of the fitted scene against ``target``, on the used unsaturated
    pixels) in units of the photo's own errors (:func:`pixel_errors`): its median ``median_z``, and whether
    that makes it dense (at least DENSE_MEDIAN_Z). An image with no error of its own (not 8-bit codes, no
    JPEG, its measured noise below a 16-bit step: a render) has nothing to measure the residual against
    (``noise_free``): not dense."""
    t = np.asarray(target, np.float32).reshape(-1, 3)
    m = np.asarray(render, np.float32).reshape(-1, 3)
    if clip:
        m = np.minimum(m, np.float32(1.0))
    keep = (t < SATURATED).all(axis=1)
    if use is not None:
        sel = np.zeros(t.shape[0], bool)
        sel[np.asarray(use, np.int64)] = True
        keep &= sel
    if not keep.any():
        return {"median_z": None, "dense": False, "pixels": 0}
    if codes is None and not np.any(jpeg_codes) and float(np.max(sigma)) < FINEST_STEP:
        return {"median_z": None, "dense": False, "pixels": int(keep.sum()), "noise_free": True}
    err = pixel_errors(target, codes, sigma, jpeg_codes)[keep]
    z = np.abs(m[keep] - t[keep]) / np.maximum(err, np.float32(1e-12))
    mid = float(median(z))
    return {"median_z": mid if math.isfinite(mid) else None,
            "dense": bool(math.isfinite(mid) and mid >= DENSE_MEDIAN_Z), "pixels": int(keep.sum()),
            "threshold": DENSE_MEDIAN_Z}


def representable_pixels(scene: Any, use: np.ndarray | None, ids: np.ndarray | None = None) -> np.ndarray:
    """The pixel indices of ``use`` (None: all) whose 4-neighbours show the same object (or background):
    the pixels the model renders as the camera integrates them. ``ids``: ``scene``'s object ids where the
    caller has them."""
    ids = np.asarray(_native.object_ids(scene)) if ids is None else ids
    inside = np.flatnonzero(~edges(ids).ravel())
    if use is not None:
        inside = np.intersect1d(inside, np.asarray(use, np.int64))
    return inside.astype(np.uint32)


def norm_verdict(density: dict[str, Any]) -> dict[str, Any]:
    """The record of the choice (``fit_report.model.norm``) from :func:`dense_residual`'s ``density``:
    ``used`` "l2" where the residual is dense, else "l1", with the statistic and why."""
    z = density["median_z"]
    out: dict[str, Any] = {"used": "l2" if density["dense"] else "l1", "linear_file": True, "median_z": z,
                           "threshold": DENSE_MEDIAN_Z}
    if density["dense"]:
        out["why"] = (f"the L1 fit's residual is dense: the median pixel's is {z:.2g} of the photo's own "
                      f"errors (at least {DENSE_MEDIAN_Z:g}), so the misfit is everywhere, not on a few "
                      "pixels: refitted in L2 on the pixels that show one object only")
    elif density.get("noise_free"):
        out["why"] = ("the image shows no noise or quantisation of its own (a render?) to measure the "
                      "residual against: L1")
    elif z is None:
        out["why"] = "no unsaturated pixel to measure the residual on: L1"
    else:
        out["why"] = (f"the L1 fit's residual is sparse: the median pixel's is {z:.2g} of the photo's own "
                      f"errors (below {DENSE_MEDIAN_Z:g}): L1, robust to the few pixels the model does not "
                      "represent")
    return out


def pixel_mask(pixels: np.ndarray, width: int, height: int) -> np.ndarray:
    """A bool (height, width) mask, True on the flat indices ``pixels``."""
    mask = np.zeros(width * height, bool)
    mask[np.asarray(pixels, np.int64)] = True
    return mask.reshape(height, width)
