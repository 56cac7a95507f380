"""Capture a low-noise photo from a camera through OpenCV's VideoCapture.

:func:`capture_photo` reads a few warm-up frames (so automatic exposure and white balance settle), then
tries to *lock* exposure and white balance at the settled values (or at values you give) so they do
not drift while frames are averaged or between the photos of a session, then averages N frames (the
noise falls as 1/sqrt(N)) and returns a 16-bit image plus a record of the settings.

Locking is best effort: which controls exist, and what their values mean, depends on the camera and
on the OpenCV backend (V4L2 on Linux, Media Foundation or DirectShow on Windows, AVFoundation on
macOS). Every request is read back; the report says for each control whether it was *locked*
(the camera confirmed it), *requested* (accepted but not confirmed by the read-back), or
*unsupported*. The frames' mean brightness is also watched: if it drifts during the capture, the
exposure is evidently still moving, and you are told.

The saved PNG keeps the camera's own encoding (usually sRGB for webcams): the average of 8-bit
frames is stored as 16 bits (value x 257) so no precision is lost; load it with the camera's
response (``--response srgb``, the default of rtloop.load_image and rtloop-fit).

The source is anything with VideoCapture's methods ``isOpened``, ``read``, ``get``, ``set`` and
``release`` (see :class:`FrameSource`), so tests use a fake camera.
"""

from __future__ import annotations

import datetime as _dt
import math
import os
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, Protocol

import cv2
import numpy as np

from .._files import write_bytes
from ._common import AcquisitionError, encode_png, write_json

__all__ = ["BACKENDS", "CaptureResult", "FrameSource", "capture_photo", "open_camera", "save_capture"]

#: Backend names accepted by :func:`open_camera`.
BACKENDS = {
    "any": cv2.CAP_ANY,
    "v4l2": cv2.CAP_V4L2,
    "dshow": cv2.CAP_DSHOW,
    "msmf": cv2.CAP_MSMF,
    "avfoundation": cv2.CAP_AVFOUNDATION,
    "gstreamer": cv2.CAP_GSTREAMER,
    "ffmpeg": cv2.CAP_FFMPEG,
}

#: Values of CAP_PROP_AUTO_EXPOSURE that mean "manual" on the common backends, tried in order:
#: V4L2 (1 = manual, 3 = aperture priority), DirectShow (0.25 = manual, 0.75 = auto), MSMF (0).
_MANUAL_EXPOSURE_MODES = (1.0, 0.25, 0.0)

#: Properties recorded in the report (read back after locking).
_REPORTED = {
    "width": cv2.CAP_PROP_FRAME_WIDTH,
    "height": cv2.CAP_PROP_FRAME_HEIGHT,
    "fps": cv2.CAP_PROP_FPS,
    "auto_exposure": cv2.CAP_PROP_AUTO_EXPOSURE,
    "exposure": cv2.CAP_PROP_EXPOSURE,
    "gain": cv2.CAP_PROP_GAIN,
    "iso_speed": cv2.CAP_PROP_ISO_SPEED,
    "brightness": cv2.CAP_PROP_BRIGHTNESS,
    "contrast": cv2.CAP_PROP_CONTRAST,
    "saturation": cv2.CAP_PROP_SATURATION,
    "gamma": cv2.CAP_PROP_GAMMA,
    "auto_white_balance": cv2.CAP_PROP_AUTO_WB,
    "wb_temperature": cv2.CAP_PROP_WB_TEMPERATURE,
    "autofocus": cv2.CAP_PROP_AUTOFOCUS,
    "focus": cv2.CAP_PROP_FOCUS,
}

#: Mean-brightness change across the averaged frames above which the exposure is called unstable.
DRIFT_LIMIT = 0.02


class FrameSource(Protocol):
    """What :func:`capture_photo` needs of a camera: cv2.VideoCapture's interface."""

    def isOpened(self) -> bool: ...
    def read(self) -> tuple[bool, np.ndarray | None]: ...
    def get(self, prop: int) -> float: ...
    def set(self, prop: int, value: float) -> bool: ...
    def release(self) -> None: ...


@dataclass
class CaptureResult:
    """An averaged capture.

    Attributes:
        image: uint16 (H, W, 3) in OpenCV's BGR order (or (H, W) grey), the mean of the frames scaled
            to 16 bits, in the camera's own encoding (not linearised).
        settings: the report written beside the PNG (see :func:`capture_photo`).
        warnings: human-readable problems (controls that could not be locked, drift, clipping).
    """

    image: np.ndarray
    settings: dict[str, Any]
    warnings: list[str] = field(default_factory=list)


def open_camera(
    device: int | str = 0, backend: str = "any", width: int | None = None, height: int | None = None
) -> cv2.VideoCapture:
    """Open a camera (an index) or a video file/URL with OpenCV, asking for a resolution if given."""
    if backend not in BACKENDS:
        raise AcquisitionError(f"unknown backend {backend!r}; use one of {', '.join(BACKENDS)}")
    cap = cv2.VideoCapture(device, BACKENDS[backend])
    if not cap.isOpened():
        cap.release()
        raise AcquisitionError(
            f"camera {device!r}: cannot open it (backend {backend}); check the index (0 is the first camera; "
            "on Linux see 'ls /dev/video*'), that no other program uses it, and the permissions"
        )
    if width:
        cap.set(cv2.CAP_PROP_FRAME_WIDTH, float(width))
    if height:
        cap.set(cv2.CAP_PROP_FRAME_HEIGHT, float(height))
    return cap


def _read(source: FrameSource, what: str) -> np.ndarray:
    ok, frame = source.read()
    if not ok or frame is None or getattr(frame, "size", 0) == 0:
        raise AcquisitionError(
            f"camera: could not read a frame ({what}); the camera may have been unplugged or is busy"
        )
    frame = np.asarray(frame)
    if frame.dtype not in (np.uint8, np.uint16) or frame.ndim not in (2, 3):
        raise AcquisitionError(
            f"camera: unsupported frame {frame.dtype} {frame.shape} (need 8/16-bit grey or BGR)"
        )
    if frame.ndim == 3 and frame.shape[2] == 4:
        frame = frame[:, :, :3]
    return frame


def _close(a: float, b: float) -> bool:
    return math.isfinite(a) and math.isfinite(b) and abs(a - b) <= 1e-3 * max(1.0, abs(b))


def _try_set(source: FrameSource, prop: int, value: float) -> tuple[str, float]:
    """Set a property and read it back: ("locked" | "requested" | "unsupported", read-back)."""
    try:
        accepted = bool(source.set(prop, float(value)))
    except cv2.error:
        accepted = False
    try:
        back = float(source.get(prop))
    except cv2.error:
        back = float("nan")
    if accepted and _close(back, value):
        return "locked", back
    if accepted:
        return "requested", back
    return "unsupported", back


def _lock_exposure(source: FrameSource, exposure: float | None) -> dict[str, Any]:
    before = float(source.get(cv2.CAP_PROP_EXPOSURE))
    mode_state, mode_value = "unsupported", float("nan")
    for manual in _MANUAL_EXPOSURE_MODES:
        mode_state, mode_value = _try_set(source, cv2.CAP_PROP_AUTO_EXPOSURE, manual)
        if mode_state == "locked":
            break
    target = before if exposure is None else float(exposure)
    if not math.isfinite(target) or (exposure is None and target == 0 and mode_state == "unsupported"):
        value_state, back = "unsupported", float("nan")
    else:
        value_state, back = _try_set(source, cv2.CAP_PROP_EXPOSURE, target)
    if mode_state == "locked" and value_state == "locked":
        state = "locked"
    elif mode_state == "unsupported" and value_state == "unsupported":
        state = "unsupported"
    else:
        state = "requested"  # e.g. automatic exposure not confirmed off: the value may still move
    return {
        "state": state,
        "auto_exposure_off": mode_state,
        "auto_exposure_value": mode_value,
        "exposure_requested": target,
        "exposure_read_back": back,
    }


def _lock_white_balance(source: FrameSource, temperature: float | None) -> dict[str, Any]:
    auto_state, auto_back = _try_set(source, cv2.CAP_PROP_AUTO_WB, 0.0)
    settled = float(source.get(cv2.CAP_PROP_WB_TEMPERATURE))
    target = settled if temperature is None else float(temperature)
    if math.isfinite(target) and target > 0:
        temp_state, back = _try_set(source, cv2.CAP_PROP_WB_TEMPERATURE, target)
    else:
        temp_state, back = "unsupported", float("nan")
    if auto_state == "locked" and temp_state in ("locked", "unsupported") and temperature is None:
        state = "locked"  # auto WB off keeps the settled balance even when the temperature is not readable
    elif auto_state == "locked" and temp_state == "locked":
        state = "locked"
    elif auto_state == "unsupported" and temp_state == "unsupported":
        state = "unsupported"
    else:
        state = "requested"
    return {
        "state": state,
        "auto_white_balance_off": auto_state,
        "auto_white_balance_read_back": auto_back,
        "temperature_requested": target,
        "temperature_read_back": back,
    }


def capture_photo(
    source: FrameSource,
    *,
    frames: int = 16,
    warmup: int = 10,
    lock_exposure: bool = True,
    exposure: float | None = None,
    lock_white_balance: bool = True,
    wb_temperature: float | None = None,
    settle_frames: int = 3,
    log: Callable[[str], None] | None = None,
    device: Any = None,
) -> CaptureResult:
    """Average ``frames`` frames from ``source`` after ``warmup`` frames, locking what can be locked.

    Args:
        frames: frames averaged (>= 1). Noise falls as 1/sqrt(frames); the scene must stay still.
        warmup: frames read and dropped first so automatic exposure and white balance settle.
        lock_exposure / exposure: switch automatic exposure off and keep the settled exposure (or set
            ``exposure``, in the backend's units: V4L2 uses 100 us steps, DirectShow/MSMF log2 seconds).
        lock_white_balance / wb_temperature: switch automatic white balance off and keep the settled
            balance (or set a colour temperature in kelvin).
        settle_frames: frames dropped after locking, so a changed setting has taken effect.
        log: called with progress and warning lines (e.g. ``print`` to stderr).
        device: recorded in the report.

    Returns:
        :class:`CaptureResult`; ``settings`` holds the frame size and type, the frames averaged, the
        lock outcome per control, every readable camera property, the mean brightness drift, the
        clipped fraction and the estimated noise per frame and after averaging.

    Raises:
        AcquisitionError: the source is not open, a frame cannot be read, or frames change size.
    """
    say = log or (lambda _msg: None)
    if frames < 1 or warmup < 0 or settle_frames < 0:
        raise AcquisitionError(f"capture: frames must be >= 1 and warmup >= 0 (got {frames}, {warmup})")
    if not source.isOpened():
        raise AcquisitionError("camera: not open; check the device index or path")
    notes: list[str] = []
    backend = _backend_name(source)
    say(f"warming up: {warmup} frames")
    for i in range(warmup):
        _read(source, f"warm-up frame {i + 1}")
    locks = _lock_controls(source, lock_exposure, exposure, lock_white_balance, wb_temperature, backend, notes)
    for _ in range(settle_frames):
        _read(source, "settling frame")

    say(f"averaging {frames} frames")
    start = time.monotonic()
    acc, acc_sq, means, shape, dtype = _accumulate_frames(source, frames)
    seconds = time.monotonic() - start
    image, full, noise, drift, clipped = _frame_statistics(acc, acc_sq, means, frames, dtype, notes)
    properties = _readable_properties(source)
    for note in notes:
        say(f"warning: {note}")
    settings = {
        "created": _dt.datetime.now().astimezone().isoformat(timespec="seconds"),
        "device": device if isinstance(device, (int, str)) or device is None else str(device),
        "backend": backend,
        "frame": _frame_record(shape, dtype),
        "frames_averaged": frames,
        "warmup_frames": warmup,
        "capture_seconds": seconds,
        "encoding": (
            "the camera's own (usually sRGB for webcams): the mean of the frames scaled to 16 bits; "
            "load with the camera's response (rtloop's default 'srgb' for most webcams)"
        ),
        "locks": locks,
        "properties": properties,
        "brightness_drift": drift,
        "clipped_fraction": clipped,
        "noise_per_frame_16bit": noise * 65535.0 / full if math.isfinite(noise) else None,
        "noise_after_averaging_16bit": noise * 65535.0 / full / math.sqrt(frames)
        if math.isfinite(noise)
        else None,
        "warnings": notes,
    }
    return CaptureResult(image, settings, notes)


def _backend_name(source: FrameSource) -> str:
    """The capture backend's name (``getBackendName``), "" when the source has none or it fails."""
    backend = ""
    get_backend = getattr(source, "getBackendName", None)
    if callable(get_backend):
        try:
            backend = str(get_backend())
        except cv2.error:
            backend = ""
    return backend


def _lock_controls(
    source: FrameSource,
    lock_exposure: bool,
    exposure: float | None,
    lock_white_balance: bool,
    wb_temperature: float | None,
    backend: str,
    notes: list[str],
) -> dict[str, Any]:
    """Lock the exposure and the white balance as asked; a note appended to ``notes`` for each lock the
    camera refused or did not confirm. Returns the outcome per control."""
    locks: dict[str, Any] = {}
    if lock_exposure or exposure is not None:
        locks["exposure"] = _lock_exposure(source, exposure)
    else:
        locks["exposure"] = {"state": "automatic (not locked on request)"}
    if lock_white_balance or wb_temperature is not None:
        locks["white_balance"] = _lock_white_balance(source, wb_temperature)
    else:
        locks["white_balance"] = {"state": "automatic (not locked on request)"}
    for control, result in locks.items():
        state = result["state"]
        name = control.replace("_", " ")
        if state == "unsupported":
            notes.append(
                f"{name}: this camera/backend ({backend or 'unknown'}) does not let OpenCV lock it; "
                "it may change between photos: fix it in the camera's own software if you can"
            )
        elif state == "requested":
            notes.append(
                f"{name}: the lock was accepted but the camera did not confirm it (read back "
                f"{result.get('exposure_read_back', result.get('temperature_read_back'))}); "
                "check that the photos agree in brightness and colour"
            )
    return locks


def _accumulate_frames(source: FrameSource, frames: int) -> tuple[np.ndarray, np.ndarray, list[float], Any, Any]:
    """Read ``frames`` frames (all of one size and type). Returns their sum and sum of squares (float64),
    the mean of each frame, the frames' shape and dtype."""
    acc = None
    acc_sq = None
    means = []
    shape = dtype = None
    for i in range(frames):
        frame = _read(source, f"frame {i + 1} of {frames}")
        if shape is None:
            shape, dtype = frame.shape, frame.dtype
            acc = np.zeros(shape, np.float64)
            acc_sq = np.zeros(shape, np.float64)
        elif frame.shape != shape or frame.dtype != dtype:
            raise AcquisitionError(
                f"camera: frame {i + 1} is {frame.dtype} {frame.shape} but the first was {dtype} {shape}; "
                "the "
                "camera changed its mode during the capture; try again"
            )
        f64 = frame.astype(np.float64)
        acc += f64
        acc_sq += f64 * f64
        means.append(float(f64.mean()))
    assert acc is not None and acc_sq is not None and shape is not None and dtype is not None
    return acc, acc_sq, means, shape, dtype


def _frame_statistics(
    acc: np.ndarray, acc_sq: np.ndarray, means: list[float], frames: int, dtype: Any, notes: list[str]
) -> tuple[np.ndarray, float, float, float, float]:
    """The averaged frame as 16 bits, the frames' full scale, the mean noise per frame (nan from one
    frame), the brightness drift and the clipped fraction; notes on drift and clipping appended to
    ``notes``."""
    full = 255.0 if dtype == np.uint8 else 65535.0
    mean = acc / frames
    image = np.clip(np.round(mean * (65535.0 / full)), 0, 65535).astype(np.uint16)
    noise = (
        float(np.sqrt(np.maximum(acc_sq / frames - mean * mean, 0.0)).mean()) if frames > 1 else float("nan")
    )
    drift = (max(means) - min(means)) / max(np.mean(means), 1e-9) if frames > 1 else 0.0
    if drift > DRIFT_LIMIT:
        notes.append(
            f"brightness changed by {drift:.1%} during the capture: the exposure (or the light) was still "
            "moving; "
            "lock the exposure, keep the light steady, and capture again"
        )
    clipped = float(np.mean(mean >= full - 0.5))
    if clipped > 0.001:
        notes.append(f"{clipped:.2%} of the samples are clipped at white: lower the exposure")
    return image, full, noise, drift, clipped


def _readable_properties(source: FrameSource) -> dict[str, float]:
    """Every reported camera property the source can read (finite, not -1)."""
    properties = {}
    for key, prop in _REPORTED.items():
        try:
            v = float(source.get(prop))
        except cv2.error:
            continue
        if math.isfinite(v) and v != -1:
            properties[key] = v
    return properties


def _frame_record(shape: Any, dtype: Any) -> dict[str, Any]:
    """The frame's size, channels, bits and channel order, for the report."""
    return {
        "width": int(shape[1]),
        "height": int(shape[0]),
        "channels": 1 if len(shape) == 2 else int(shape[2]),
        "bits": 8 if dtype == np.uint8 else 16,
        "order": "grey" if len(shape) == 2 else "BGR",
    }


def save_capture(result: CaptureResult, path: str | os.PathLike[str]) -> tuple[str, str]:
    """Write the 16-bit PNG and, beside it, the JSON report (same name, ``.json``). Returns both paths."""
    png = os.fspath(path)
    if not png.lower().endswith(".png"):
        raise AcquisitionError(f"{png}: the capture is saved as PNG; give a file name ending in .png")
    write_bytes(png, encode_png(np.ascontiguousarray(result.image)), parents=True)
    report = os.path.splitext(png)[0] + ".json"
    write_json(report, {**result.settings, "image": os.path.basename(png)})
    return png, report
