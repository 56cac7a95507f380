"""Photos from disk with a camera response of your choice: sRGB, linear, a gamma, or a measured table.

:func:`rtloop.load_image` knows two responses: the sRGB curve (cameras' JPEGs and PNGs) and linear
(raw machine-vision counts). :func:`load_photo` reads the same files (PNG, JPEG, BMP, TIFF; 8 or 16
bits; EXIF orientation honoured; decoding is load_image's own) and adds:

* **RAW-like 16-bit TIFF**: linear sensor data such as ``dcraw -4 -T`` or ``rawpy`` writes, with an
  optional ``black_level`` and ``white_level`` in the file's integer code values (a 12-bit sensor in a
  16-bit file has white level 4095; black level is often 64..1024), so that
  ``value = (code - black) / (white - black)`` before the response is applied;
* **a user-supplied camera response** instead of the sRGB curve: ``gamma:2.2`` (linear = code^2.2),
  or a table file mapping code values to linear light (see :class:`CameraResponse`), e.g. measured
  from bracketed exposures with ``cv2.createCalibrateDebevec``.

As in load_image the curve is applied at full resolution and only then is the photo resized (area
averaging) to a requested size, since only linear values can be averaged.
"""

from __future__ import annotations

import csv
import io
import json
import math
import os
import warnings
from dataclasses import dataclass
from typing import Any

import cv2
import numpy as np
from PIL import Image

from .._files import MAX_IMAGE_BYTES, InputFileError, open_regular, read_regular
from .._opencv import imdecode
from .._srgb import decode
from ._common import AcquisitionError
from .objective import load_image
from .raw import is_raw, load_raw

__all__ = ["CameraResponse", "load_photo", "parse_response", "photo_info"]

_RESPONSE_HELP = (
    "use 'srgb', 'linear', 'gamma:G' (e.g. gamma:2.2) or a table file (.csv/.txt with columns "
    'CODE,LINEAR or CODE,R,G,B or one LINEAR per line; or .json {"codes": [...], "linear": [...]})'
)


@dataclass(frozen=True)
class CameraResponse:
    """How the values stored in a photo relate to light.

    kinds:
        ``srgb``: the inverse sRGB transfer curve. ``linear``: values are proportional to light.
        ``gamma``: linear = code ** gamma, code in [0, 1]. ``table``: piecewise-linear
        interpolation of ``linear`` (one column, or one per channel R, G, B) at ``codes`` in [0, 1],
        normalised so the largest code gives 1 in the brightest channel (keeps the channels'
        relative gains: a response table is not a white balance).
    """

    kind: str
    gamma: float = 1.0
    codes: tuple[float, ...] = ()
    linear: tuple[tuple[float, ...], ...] = ()  # (n, 1) or (n, 3)
    source: str = ""

    def to_linear(self, encoded: np.ndarray) -> np.ndarray:
        """Linear light of code values in [0, 1] ((H, W) or (H, W, 3)), float32."""
        x = np.clip(np.asarray(encoded, dtype=np.float32), 0.0, 1.0)
        if self.kind == "linear":
            return x
        if self.kind == "srgb":
            return decode(x).astype(np.float32)
        if self.kind == "gamma":
            return np.power(x, np.float32(self.gamma)).astype(np.float32)
        codes = np.asarray(self.codes, dtype=np.float64)
        table = np.asarray(self.linear, dtype=np.float64)
        # Apply through a fine lookup table: cheap for large photos.
        grid = np.linspace(0.0, 1.0, 65536)
        idx = np.round(x * 65535).astype(np.int32)
        if table.shape[1] == 1 or x.ndim == 2:
            lut = np.interp(grid, codes, table.mean(axis=1) if x.ndim == 2 else table[:, 0]).astype(
                np.float32
            )
            return lut[idx]
        out = np.empty(x.shape, np.float32)
        for c in range(3):
            lut = np.interp(grid, codes, table[:, c]).astype(np.float32)
            out[..., c] = lut[idx[..., c]]
        return out

    def describe(self) -> str:
        if self.kind == "gamma":
            return f"gamma {self.gamma:g}"
        if self.kind == "table":
            cols = "per channel" if len(self.linear[0]) == 3 else "one curve"
            return f"table of {len(self.codes)} points ({cols}) from {self.source}"
        return self.kind

    def to_dict(self) -> dict[str, Any]:
        d: dict[str, Any] = {"kind": self.kind}
        if self.kind == "gamma":
            d["gamma"] = self.gamma
        if self.kind == "table":
            d.update(source=self.source, points=len(self.codes))
        return d


def parse_response(spec: str | os.PathLike[str] | float | CameraResponse | dict) -> CameraResponse:
    """A :class:`CameraResponse` from ``"srgb"``, ``"linear"``, ``"gamma:2.2"`` (or a number), a table
    file (.csv, .txt, .json), a dict ``{"codes": [...], "linear": [...]}`` or a response."""
    if isinstance(spec, CameraResponse):
        return spec
    if isinstance(spec, (int, float)) and not isinstance(spec, bool):
        return _gamma(float(spec), str(spec))
    if isinstance(spec, dict):
        return _table_from_dict(spec, "dict")
    text = os.fspath(spec).strip()
    low = text.lower()
    if low in ("srgb", "linear"):
        return CameraResponse(low)
    if low.startswith(("gamma:", "gamma=")):
        return _gamma(_number(text[6:], text), text)
    try:
        return _gamma(float(text), text)
    except ValueError:
        pass
    if not os.path.exists(text):
        raise AcquisitionError(f"response {text!r}: not a known response and no such file; {_RESPONSE_HELP}")
    return _table_from_file(text)


def _number(s: str, text: str) -> float:
    try:
        return float(s)
    except ValueError:
        raise AcquisitionError(f"response {text!r}: {s!r} is not a number; {_RESPONSE_HELP}") from None


def _gamma(g: float, text: str) -> CameraResponse:
    if not (math.isfinite(g) and 0.2 <= g <= 5.0):
        raise AcquisitionError(
            f"response {text!r}: gamma must be between 0.2 and 5 (2.2 is typical), got {g:g}"
        )
    return CameraResponse("gamma", gamma=g)


def _table_from_file(path: str) -> CameraResponse:
    if path.lower().endswith(".json"):
        try:
            with open(path, encoding="utf-8") as fh:
                data = json.load(fh)
        except (OSError, ValueError) as exc:
            raise AcquisitionError(
                f"{path}: cannot read the response table ({exc}); {_RESPONSE_HELP}"
            ) from None
        if isinstance(data, list):
            data = {"linear": data}
        if not isinstance(data, dict):
            raise AcquisitionError(f"{path}: a JSON response table must be an object; {_RESPONSE_HELP}")
        return _table_from_dict(data, path)
    rows: list[list[float]] = []
    try:
        with open(path, encoding="utf-8", newline="") as fh:
            sample = fh.read(4096)
            fh.seek(0)
            delim = "," if "," in sample else ("\t" if "\t" in sample else " ")
            for n, row in enumerate(csv.reader(fh, delimiter=delim), start=1):
                cells = [c for c in (x.strip() for x in row) if c]
                if not cells or cells[0].startswith("#"):
                    continue
                try:
                    rows.append([float(c) for c in cells])
                except ValueError:
                    if rows:  # a header is allowed only on top
                        raise AcquisitionError(
                            f"{path}: line {n}: not a number: {row!r}; {_RESPONSE_HELP}"
                        ) from None
    except OSError as exc:
        raise AcquisitionError(f"{path}: cannot read the response table: {exc.strerror or exc}") from None
    if not rows:
        raise AcquisitionError(f"{path}: the response table is empty; {_RESPONSE_HELP}")
    widths = {len(r) for r in rows}
    if len(widths) != 1 or widths.pop() not in (1, 2, 3, 4):
        raise AcquisitionError(
            f"{path}: every line must have the same 1, 2, 3 or 4 numbers; {_RESPONSE_HELP}"
        )
    arr = np.asarray(rows, dtype=np.float64)
    if arr.shape[1] == 1:
        return _make_table(None, arr, path)
    if arr.shape[1] == 3:  # R,G,B per line, evenly spaced codes (e.g. a Debevec curve saved as text)
        return _make_table(None, arr, path)
    return _make_table(arr[:, 0], arr[:, 1:], path)


def _table_from_dict(data: dict, where: str) -> CameraResponse:
    try:
        linear = np.asarray(data["linear"], dtype=np.float64)
        codes = np.asarray(data["codes"], dtype=np.float64) if "codes" in data else None
    except (KeyError, TypeError, ValueError) as exc:
        raise AcquisitionError(f"{where}: bad response table ({exc}); {_RESPONSE_HELP}") from None
    if linear.ndim == 3 and linear.shape[1] == 1:  # cv2.createCalibrateDebevec's (256, 1, 3)
        linear = linear[:, 0, :]
    if linear.ndim == 1:
        linear = linear[:, None]
    return _make_table(codes, linear, where)


def _make_table(codes: np.ndarray | None, linear: np.ndarray, where: str) -> CameraResponse:
    n = len(linear)
    if linear.ndim != 2 or linear.shape[1] not in (1, 3) or n < 2:
        raise AcquisitionError(
            f"{where}: a response table needs at least 2 rows of 1 or 3 values; {_RESPONSE_HELP}"
        )
    if codes is None:
        codes = np.linspace(0.0, 1.0, n)
    else:
        codes = np.asarray(codes, dtype=np.float64)
        top = float(codes.max())
        if top > 1.0:  # integer codes: 8-bit if they fit, else 16-bit
            codes = codes / (255.0 if top <= 255 else 65535.0)
    if not (np.isfinite(codes).all() and np.isfinite(linear).all()):
        raise AcquisitionError(f"{where}: the response table has non-finite values")
    if np.any(np.diff(codes) <= 0):
        raise AcquisitionError(f"{where}: the response table's codes must increase strictly")
    if np.any(np.diff(linear, axis=0) < 0):
        raise AcquisitionError(
            f"{where}: the response table's linear values must not decrease (a camera's response is "
            "monotonic)"
        )
    if codes[0] > 0 or codes[-1] < 1:
        raise AcquisitionError(
            f"{where}: the response table must span the codes from 0 to the largest value (0..1, 0..255 or "
            "0..65535)"
        )
    peak = float(linear[-1].max())
    if peak <= 0:
        raise AcquisitionError(f"{where}: the response table's largest linear value must be > 0")
    linear = np.maximum(linear / peak, 0.0)
    return CameraResponse(
        "table",
        codes=tuple(codes.tolist()),
        linear=tuple(tuple(r) for r in linear.tolist()),
        source=os.fspath(where),
    )


# --- loading -------------------------------------------------------------------------------------------


def photo_info(path: str | os.PathLike[str]) -> dict[str, Any]:
    """Size (as displayed, EXIF orientation applied), sample type and channels of an image file,
    without converting it. Raises AcquisitionError for files that cannot be read."""
    name = os.fspath(path)
    try:
        raw = read_regular(name, limit=MAX_IMAGE_BYTES, what="image")
    except InputFileError as exc:
        raise AcquisitionError(str(exc)) from None
    data = np.frombuffer(raw, dtype=np.uint8)
    decoded = imdecode(data)[0] if data.size else None  # load_image below says why a bad file is bad
    if decoded is not None:
        h, w = decoded.shape[:2]
        dtype = decoded.dtype
        channels = 1 if decoded.ndim == 2 else decoded.shape[2]
    else:
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                with Image.open(io.BytesIO(raw)) as img:
                    w, h = img.size
                    mode = img.mode
        except Exception:  # noqa: BLE001 - Pillow raises many types; load_image gives the real error
            load_image(name, (1, 1), crop=True)  # raises a proper AcquisitionError
            raise AcquisitionError(f"{name}: not a readable image") from None
        dtype = (
            np.dtype(np.uint16)
            if mode.startswith("I;16") or mode == "I"
            else (np.dtype(np.float32) if mode == "F" else np.dtype(np.uint8))
        )
        channels = {"L": 1, "LA": 2, "RGB": 3, "RGBA": 4}.get(mode, 3)
    orientation = 1
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            with Image.open(io.BytesIO(raw)) as img:
                value = img.getexif().get(0x0112)
                if isinstance(value, int) and 1 <= value <= 8:
                    orientation = value
    except Exception:  # noqa: BLE001 - no EXIF: the stored orientation
        orientation = 1
    if orientation in (5, 6, 7, 8):
        w, h = h, w
    return {
        "width": int(w),
        "height": int(h),
        "dtype": str(np.dtype(dtype)),
        "channels": int(channels),
        "orientation": orientation,
    }


def load_photo(
    path: str | os.PathLike[str],
    size: Any = None,
    *,
    response: str | float | CameraResponse | dict = "srgb",
    black_level: float = 0.0,
    white_level: float | None = None,
    crop: bool = False,
) -> np.ndarray:
    """Load a photo as linear RGB float32, through any camera response.

    Args:
        path: PNG, JPEG, BMP, TIFF (8 or 16 bit, or float), or whatever rtloop.load_image reads; a camera
            RAW file (.dng, .cr2, .nef, .arw, ...) is read linear through rawpy (extra ``raw``).
        size: ``None`` keeps the photo's own size; else what rtloop.load_image accepts (a scene or
            ``(width, height)``): the photo is linearised at full size and then area-resized to it.
        response: see :func:`parse_response`. Float images are linear whatever this says (as in
            load_image).
        black_level, white_level: for raw-like data: code values (in the file's integer scale, e.g.
            0..65535) of black and of saturation; applied before the response.
        crop: centre-crop to the aspect ratio of ``size`` instead of failing when it differs.

    Raises:
        AcquisitionError: unreadable file, bad response, bad levels, wrong aspect ratio.
    """
    name = os.fspath(path)
    resp = parse_response(response)
    if is_raw(name):  # linear from LibRaw: the response and levels do not apply
        try:
            open_regular(name, limit=MAX_IMAGE_BYTES, what="image").close()
        except InputFileError as exc:
            raise AcquisitionError(str(exc)) from None
        linear, _ = load_raw(name)
        return linear if size is None else _resize_like_load_image(linear, size, crop, name)
    info = photo_info(name)
    levels = black_level != 0.0 or white_level is not None
    native = (info["width"], info["height"])
    if resp.kind in ("srgb", "linear") and not levels:
        return load_image(name, native if size is None else size, response=resp.kind, crop=crop)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        raw = load_image(name, native, response="linear")  # full size, codes / max code
    is_float = info["dtype"].startswith("float")
    if is_float:
        linear = raw
    else:
        if levels:
            full = 65535.0 if info["dtype"] == "uint16" else 255.0
            white = full if white_level is None else float(white_level)
            black = float(black_level)
            if not (0 <= black < white <= full):
                raise AcquisitionError(
                    f"{name}: black level {black:g} and white level {white:g} must satisfy 0 <= black < "
                    "white <= "
                    f"{full:g} (the file's code range)"
                )
            raw = np.clip((raw * full - black) / (white - black), 0.0, 1.0).astype(np.float32)
        linear = resp.to_linear(raw)
    if size is None:
        return np.ascontiguousarray(linear, dtype=np.float32)
    return _resize_like_load_image(linear, size, crop, name)


def _resize_like_load_image(linear: np.ndarray, size: Any, crop: bool, name: str) -> np.ndarray:
    if isinstance(size, (tuple, list)):
        width, height = (int(v) for v in size)
    else:
        width, height = int(size.width), int(size.height)
    h, w = linear.shape[:2]
    if crop:
        if w * height > width * h:
            nw = max(1, round(h * width / height))
            x0 = (w - nw) // 2
            linear = linear[:, x0 : x0 + nw]
        elif w * height < width * h:
            nh = max(1, round(w * height / width))
            y0 = (h - nh) // 2
            linear = linear[y0 : y0 + nh]
    elif abs(w / h - width / height) / (width / height) > 0.01:
        raise AcquisitionError(
            f"{name}: image is {w}x{h} but the target is {width}x{height}: aspect ratios differ "
            f"({w / h:.4g} vs {width / height:.4g}); crop the image or pass crop=True"
        )
    out = cv2.resize(linear, (width, height), interpolation=cv2.INTER_AREA)
    return np.ascontiguousarray(out, dtype=np.float32)
