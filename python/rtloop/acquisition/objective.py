"""Turn a photo on disk into the linear-RGB target image that rtloop fits its scene to.

rtloop recovers a scene's light and colours by rendering the scene, comparing the render with a
photo (the *objective* image) and adjusting the unknowns until the two agree. The renderer
computes radiance, which adds up linearly: two lamps give twice the light of one. Ordinary image
files do not store radiance. An 8-bit PNG or JPEG stores sRGB-*encoded* values, bent by a
transfer curve (roughly a 1/2.2 power) so that 256 levels look even to the eye; code value 128
is only about 22% of the light of 255, not 50%. Comparing a render with such a file directly
would make every fitted light and albedo wrong, so :func:`load_image` undoes the curve first.

What :func:`load_image` does, in order:

1. **Decode** the file (PNG, JPEG, BMP, TIFF, and whatever else OpenCV or Pillow can read) at its
   real bit depth. OpenCV does the decoding because Pillow silently cuts 16-bit colour PNGs to 8
   bits; Pillow reads the EXIF orientation and decodes what OpenCV cannot (TGA, PCX, ...).
   Grey images are replicated to three channels; an alpha channel is **dropped** (transparent
   pixels keep whatever colour they store; rtloop has no use for coverage).
2. **Orient** the pixels as a viewer would show them, following the EXIF orientation tag (all
   eight values). Cameras often store a portrait photo sideways and set this tag instead.
3. **Crop** (only with ``crop=True``) the centre of the image to the scene's aspect ratio.
4. **Linearise**: ``response="srgb"`` (the default, right for almost every camera JPEG and PNG)
   applies the exact inverse sRGB transfer function to values scaled to [0, 1] (by 255 or
   65535); ``response="linear"`` only scales, for raw 16-bit machine-vision images whose
   values are already proportional to light. Floating-point TIFFs (and Radiance ``.hdr``) are
   taken as already linear whichever response is asked for, and are used as stored.
5. **Resize** to the scene's ``width`` x ``height`` with area averaging (``cv2.INTER_AREA``).
   This happens *after* linearisation on purpose: a pixel of the small image should hold the
   mean light of the photo pixels it covers, and only linear values can be averaged. (A 0/255
   checkerboard averages to linear 0.5; averaging the encoded values instead would give 127.5,
   which decodes to about 0.21.) Enlarging a smaller photo is allowed but warns, since it
   invents no detail. The photo and the scene must have the same aspect ratio (within 1%);
   otherwise pass ``crop=True`` or crop the photo yourself.

A camera RAW file (.dng, .cr2, .nef, .arw, ...) is read by rawpy (LibRaw, extra ``raw``) instead of steps
1, 2 and 4: linear, camera white balance, oriented; then cropped and resized the same way.

Every failure raises :class:`~rtloop.errors.AcquisitionError` with a one-line message that
starts with the file name.
"""

from __future__ import annotations

import functools
import io
import os
import warnings
from typing import Protocol

import numpy as np
from PIL import Image

from .._files import MAX_IMAGE_BYTES, InputFileError, open_regular, read_regular
from .._opencv import imdecode
from .._srgb import code_values
from ..errors import AcquisitionError
from .raw import is_raw, load_raw

__all__ = ["RESPONSES", "load_image", "load_mask"]

#: The accepted values of ``load_image(..., response=...)``.
RESPONSES = ("srgb", "linear")

#: Largest relative difference between the photo's and the scene's aspect ratios (width/height)
#: that is resized away without ``crop=True``.
ASPECT_TOLERANCE = 0.01

_EXIF_ORIENTATION = 0x0112


class _HasSize(Protocol):
    width: int
    height: int


#: What ``load_image`` accepts as ``scene``: an object with ``width``/``height``, or ``(width, height)``.
SceneLike = _HasSize | tuple[int, int]


class _Fail(Exception):
    """Internal: a problem with the file, turned into an AcquisitionError that names it."""


#: The most pixels a file may decode to (a 100-megapixel camera's photo fits; a "decompression bomb", a
#: small file claiming a huge size, does not). docs/scene-format.md: "Input limits".
MAX_DECODED_PIXELS = 120_000_000


def load_image(
    path: str | os.PathLike[str],
    scene: SceneLike,
    *,
    response: str = "srgb",
    crop: bool = False,
) -> np.ndarray:
    """Load a photo as a linear-RGB float image of exactly the scene's size.

    Args:
        path: The image file. PNG, JPEG, BMP and TIFF are supported (8 or 16 bits per sample;
            grey, grey+alpha, RGB, RGBA or palette; 32-bit float TIFF), plus anything else
            OpenCV or Pillow decodes. Alpha is dropped. The EXIF orientation tag is applied.
        scene: What the image must match: any object with integer ``width`` and ``height``
            attributes (such as an rtloop ``Scene``) or a ``(width, height)`` tuple.
        response: How stored values relate to light. ``"srgb"`` (default) inverts the sRGB
            transfer curve, which is what cameras and image editors write. ``"linear"`` only
            scales integers to [0, 1] (by 255 or 65535), for sensors that store raw linear
            counts. Float images are always taken as linear, whatever this says.
        crop: If true, first cut the largest centred region with the scene's aspect ratio out
            of the photo. If false, an aspect ratio more than 1% off the scene's is an error.

    Returns:
        A C-contiguous ``float32`` array of shape ``(height, width, 3)`` in linear RGB, where
        0 is black and 1 is the largest value the file could store (float images keep their
        own scale). It contains no NaN or infinity.

    Raises:
        AcquisitionError: The file is missing, a directory, unreadable, corrupt or of an
            unsupported kind; the image is empty or contains NaN/infinity; its aspect ratio
            does not match the scene's; ``response`` or ``scene`` is invalid. The one-line
            message starts with the file name.

    Warns:
        UserWarning: The (cropped) photo is smaller than the scene in some dimension, so it
            is enlarged.
    """
    name = os.fspath(path)
    try:
        return _load(name, scene, response, crop)
    except _Fail as exc:
        message = " ".join(str(exc).split())  # one line, whatever a library put in it
        raise AcquisitionError(f"{name}: {message}") from exc.__cause__


def _load(name: str, scene: SceneLike, response: str, crop: bool) -> np.ndarray:
    if response not in RESPONSES:
        raise _Fail(f"unknown response {response!r}; expected one of {', '.join(map(repr, RESPONSES))}")
    width, height = _scene_size(scene)

    if is_raw(name):  # camera RAW: linear and oriented by LibRaw; the response does not apply
        _check_regular(name)
        try:
            linear, _ = load_raw(name)
        except AcquisitionError as exc:
            raise _Fail(str(exc).removeprefix(f"{name}: ")) from None
        linear = _fit_aspect(linear, width, height, crop)
    else:
        pixels, orientation = _decode(name)  # (h, w) grey or (h, w, 3) RGB, uint8/uint16/float
        if pixels.shape[0] == 0 or pixels.shape[1] == 0:
            raise _Fail(f"image has zero size ({pixels.shape[1]}x{pixels.shape[0]})")
        pixels = _orient(pixels, orientation)
        pixels = _fit_aspect(pixels, width, height, crop)
        linear = _linearise(pixels, response)

    h, w = linear.shape[:2]
    if (w, h) != (width, height):
        if w < width or h < height:
            warnings.warn(
                f"{name}: image ({w}x{h}) is smaller than the scene ({width}x{height}) and is enlarged",
                stacklevel=3,
            )
        import cv2  # here, not at import: `import rtloop` loads no OpenCV

        linear = cv2.resize(linear, (width, height), interpolation=cv2.INTER_AREA)
    if linear.ndim == 2:
        linear = np.repeat(linear[:, :, np.newaxis], 3, axis=2)
    result = np.ascontiguousarray(linear, dtype=np.float32)
    assert result.shape == (height, width, 3)
    return result


def _scene_size(scene: SceneLike) -> tuple[int, int]:
    if isinstance(scene, tuple | list):
        if len(scene) != 2:
            raise _Fail(f"scene size must be (width, height), got {scene!r}")
        width, height = scene
    else:
        try:
            width, height = scene.width, scene.height
        except AttributeError:
            raise _Fail(
                f"scene must have width and height or be a (width, height) tuple, got {type(scene).__name__}"
            ) from None
    for value in (width, height):
        if isinstance(value, bool) or not isinstance(value, int | np.integer) or value <= 0:
            raise _Fail(f"scene width and height must be positive integers, got {width!r}x{height!r}")
    return int(width), int(height)


# --- decoding -------------------------------------------------------------------------------


def _decode(name: str) -> tuple[np.ndarray, int]:
    """The file's pixels as stored ((h, w) grey or (h, w, 3) RGB, alpha dropped) and its
    EXIF orientation."""
    try:
        raw = read_regular(name, limit=MAX_IMAGE_BYTES, what="image")
    except InputFileError as exc:
        raise _Fail(exc.reason) from None
    if not raw:
        raise _Fail("file is empty")
    data = np.frombuffer(raw, dtype=np.uint8)

    _check_pixel_count(raw)
    orientation = _exif_orientation(raw)
    decoded, said = imdecode(data)  # keeps bit depth; no EXIF rotation
    if decoded is not None:
        return _from_opencv(decoded), orientation
    return _decode_with_pillow(raw, said), orientation


def _check_regular(name: str) -> None:
    """Refuse, before any library opens it, a path that is not a regular file of at most MAX_IMAGE_BYTES
    (a FIFO would hang the reader, a device such as /dev/zero never end)."""
    try:
        open_regular(name, limit=MAX_IMAGE_BYTES, what="image").close()
    except InputFileError as exc:
        raise _Fail(exc.reason) from None


def _check_pixel_count(name: bytes) -> None:
    """Refuse, from the header alone, a file that would decode to more than MAX_DECODED_PIXELS."""
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # decompression-bomb warnings: the size is checked here
            with Image.open(io.BytesIO(name)) as img:
                w, h = img.size
    except Image.DecompressionBombError:  # Pillow's own refusal (over twice its MAX_IMAGE_PIXELS)
        raise _Fail(f"image claims more than {2 * (Image.MAX_IMAGE_PIXELS or 0) / 1e6:.0f} megapixels, more than "
                    f"the {MAX_DECODED_PIXELS / 1e6:.0f} rtloop decodes; downscale it first") from None
    except Exception:  # noqa: BLE001 - not a format Pillow reads: OpenCV's own limit applies
        return
    if w * h > MAX_DECODED_PIXELS:
        raise _Fail(f"image claims {w}x{h} = {w * h / 1e6:.0f} megapixels, more than the "
                    f"{MAX_DECODED_PIXELS / 1e6:.0f} rtloop decodes; downscale it first")


def _from_opencv(image: np.ndarray) -> np.ndarray:
    """OpenCV's (h, w[, c]) BGR(A) or grey(+alpha) array -> (h, w) grey or (h, w, 3) RGB."""
    image = _check_sample_type(image)
    if image.ndim == 2:
        return image
    channels = image.shape[2]
    if channels in (1, 2):  # grey, grey + alpha
        return image[:, :, 0]
    if channels in (3, 4):  # BGR, BGRA
        return image[:, :, 2::-1]
    raise _Fail(f"unsupported image with {channels} channels")


def _decode_with_pillow(name: bytes, said: str = "") -> np.ndarray:
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", Image.DecompressionBombWarning)
            with Image.open(io.BytesIO(name)) as img:
                img.load()
                if img.mode == "F":
                    array = np.asarray(img, dtype=np.float32)
                elif img.mode.startswith("I;16"):
                    array = np.asarray(img).astype(np.uint16)
                elif img.mode == "I":
                    array = np.asarray(img)
                    if array.size and (array.min() < 0 or array.max() > 65535):
                        raise _Fail("unsupported 32-bit integer image")
                    array = array.astype(np.uint16)
                elif img.mode in ("L", "LA", "1"):
                    array = np.asarray(img.convert("L"))
                else:
                    array = np.asarray(img.convert("RGB"))
    except _Fail:
        raise
    except Exception as exc:  # Pillow raises many types for bad files
        why = f": {said}" if said else ""
        raise _Fail(f"not a readable image (corrupt, truncated or unsupported format{why})") from exc
    return np.array(array)


def _check_sample_type(image: np.ndarray) -> np.ndarray:
    if image.dtype in (np.uint8, np.uint16, np.float32, np.float64):
        return image
    raise _Fail(f"unsupported sample type {image.dtype} (need 8- or 16-bit unsigned, or float)")


# --- orientation ----------------------------------------------------------------------------


def _exif_orientation(name: bytes) -> int:
    """The file's EXIF orientation tag (1-8); 1 (as stored) if it is missing or unreadable.

    OpenCV's IMREAD_UNCHANGED ignores this tag (unlike IMREAD_COLOR), so it is applied here.
    """
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # decompression-bomb and EXIF-parsing warnings
            with Image.open(io.BytesIO(name)) as img:
                value = img.getexif().get(_EXIF_ORIENTATION)
    except Exception:  # noqa: BLE001 - Pillow raises many types; OpenCV may still decode the file
        return 1
    if isinstance(value, int | np.integer) and 1 <= value <= 8:
        return int(value)
    return 1


def _orient(image: np.ndarray, orientation: int) -> np.ndarray:
    """Transform stored pixels to their displayed orientation (EXIF tag values 1-8).

    The tag says which side of the displayed picture the stored first row and first column lie
    on: 2 mirrors left-right, 3 turns 180 degrees, 4 mirrors top-bottom, 5 transposes, 6 turns
    90 degrees clockwise, 7 transposes across the other diagonal and 8 turns 90 degrees
    anticlockwise. Works on grey (h, w) and colour (h, w, c) arrays alike.
    """
    if orientation == 2:
        return image[:, ::-1]
    if orientation == 3:
        return image[::-1, ::-1]
    if orientation == 4:
        return image[::-1, :]
    if orientation == 5:
        return image.swapaxes(0, 1)
    if orientation == 6:
        return image[::-1, :].swapaxes(0, 1)
    if orientation == 7:
        return image[::-1, ::-1].swapaxes(0, 1)
    if orientation == 8:
        return image[:, ::-1].swapaxes(0, 1)
    return image


# --- geometry and values --------------------------------------------------------------------


def _fit_aspect(image: np.ndarray, width: int, height: int, crop: bool) -> np.ndarray:
    """Centre-crop to the scene's aspect ratio (crop=True) or check that it already matches."""
    h, w = image.shape[:2]
    if crop:
        if w * height > width * h:  # too wide: keep the middle columns
            new_w = round(h * width / height)
            if new_w == 0:
                raise _Fail(f"image ({w}x{h}) is too small to crop to the scene's shape ({width}x{height})")
            x0 = (w - new_w) // 2
            return image[:, x0 : x0 + new_w]
        if w * height < width * h:  # too tall: keep the middle rows
            new_h = round(w * height / width)
            if new_h == 0:
                raise _Fail(f"image ({w}x{h}) is too small to crop to the scene's shape ({width}x{height})")
            y0 = (h - new_h) // 2
            return image[y0 : y0 + new_h]
        return image
    scene_aspect = width / height
    if abs(w / h - scene_aspect) / scene_aspect > ASPECT_TOLERANCE:
        raise _Fail(
            f"image is {w}x{h} but the scene is {width}x{height}: aspect ratios differ "
            f"({w / h:.4g} vs {scene_aspect:.4g}); crop the image or pass crop=True"
        )
    return image


@functools.cache
def _lookup_table(levels: int, response: str) -> np.ndarray:
    """Linear value (float32) of each integer code 0..levels-1 under the given response."""
    if response != "linear":  # inverse of the sRGB transfer function (IEC 61966-2-1)
        return code_values(levels)
    table = (np.arange(levels, dtype=np.float64) / (levels - 1)).astype(np.float32)
    table.flags.writeable = False
    return table


def _linearise(image: np.ndarray, response: str) -> np.ndarray:
    if image.dtype == np.uint8:
        return _lookup_table(256, response)[image]
    if image.dtype == np.uint16:
        return _lookup_table(65536, response)[image]
    # Float samples are radiance already (float TIFF, Radiance HDR): keep them, but no NaN/inf.
    bad = ~np.isfinite(image)
    if bad.any():
        raise _Fail(f"image contains {int(bad.sum())} non-finite (NaN or infinite) values")
    with np.errstate(over="ignore"):
        result = image.astype(np.float32)  # always a copy
    if not np.isfinite(result).all():
        raise _Fail("image contains values too large for 32-bit floats")
    return result


def load_mask(path: str | os.PathLike[str], scene: SceneLike, *, crop: bool = False) -> np.ndarray:
    """Load a mask image for :func:`rtloop.fit`: white where the scene models the photo, black where it
    does not (another object, a reflection, a shadow the scene has no caster for).

    Any format :func:`load_image` reads, at the photo's or the scene's size (same aspect-ratio rules and
    ``crop``). Returns bool (H, W) at the scene's size, True = use the pixel. A working pixel is kept only
    when the mask is white over all of it (coverage >= 99 % after area averaging), so pixels that straddle
    the mask's edge are left out too.
    """
    values = load_image(path, scene, response="linear", crop=crop)
    keep = values.mean(axis=2) >= 0.99
    if not keep.any():
        raise AcquisitionError(f"{os.fspath(path)}: the mask is black everywhere: no pixel would be fitted")
    return keep
