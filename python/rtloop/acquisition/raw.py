"""Camera RAW files (DNG, CR2/CR3, NEF, ARW, ...) read with rawpy (LibRaw) into linear RGB: camera white
balance, no tone curve, no auto-brightening; the white balance used is recorded."""

from __future__ import annotations

import importlib
import os
from typing import Any

import numpy as np

from ..errors import AcquisitionError

__all__ = ["RAW_EXTENSIONS", "is_raw", "load_raw", "raw_settings"]

#: File extensions read as camera RAW (lower case, with the dot).
RAW_EXTENSIONS = frozenset(
    [".dng", ".cr2", ".cr3", ".crw", ".nef", ".nrw", ".arw", ".srf", ".sr2", ".raf", ".orf", ".rw2", ".pef", ".srw", ".raw", ".rwl", ".3fr", ".iiq", ".x3f", ".erf", ".mos", ".kdc"]
)


def is_raw(path: str | os.PathLike[str]) -> bool:
    return os.path.splitext(os.fspath(path))[1].lower() in RAW_EXTENSIONS


def load_raw(path: str | os.PathLike[str]) -> tuple[np.ndarray, dict[str, Any]]:
    """Linear RGB float32 (H, W, 3) in [0, 1] (sRGB primaries, camera white balance, orientation applied by
    LibRaw) and what was used: ``{"white_balance": [r, g, b, g2], "black_level": ..., "white_level": ...}``.

    Raises:
        AcquisitionError: rawpy is not installed, or LibRaw cannot read the file.
    """
    name = os.fspath(path)
    try:
        rawpy = importlib.import_module("rawpy")
    except ImportError:
        raise AcquisitionError(
            f"{name}: a camera RAW file, and reading RAW needs rawpy: pip install 'rtloop[raw]' (or convert it "
            "to a 16-bit linear TIFF and pass --response linear)"
        ) from None
    try:
        with rawpy.imread(name) as raw:
            rgb = raw.postprocess(
                gamma=(1, 1),  # linear: no tone curve
                no_auto_bright=True,
                use_camera_wb=True,
                output_bps=16,
                output_color=rawpy.ColorSpace.sRGB,
            )
            info = {
                "white_balance": [float(v) for v in raw.camera_whitebalance],
                "black_level": [float(v) for v in raw.black_level_per_channel],
                "white_level": float(raw.white_level),
            }
    except (rawpy.LibRawError, OSError) as exc:
        raise AcquisitionError(f"{name}: LibRaw cannot read it as a camera RAW file ({exc})") from None
    return (np.asarray(rgb, dtype=np.float32) / 65535.0), info


def raw_settings(path: str | os.PathLike[str]) -> dict[str, Any]:
    """What :func:`load_raw` applies to a RAW file (white balance, black and white levels), read without
    demosaicing; for the record of a fit's inputs."""
    name = os.fspath(path)
    try:
        rawpy = importlib.import_module("rawpy")
    except ImportError:
        raise AcquisitionError(f"{name}: reading RAW needs rawpy: pip install 'rtloop[raw]'") from None
    try:
        with rawpy.imread(name) as raw:
            return {
                "reader": f"rawpy {rawpy.__version__} (LibRaw): linear, camera white balance, sRGB primaries",
                "white_balance": [float(v) for v in raw.camera_whitebalance],
                "black_level": [float(v) for v in raw.black_level_per_channel],
                "white_level": float(raw.white_level),
            }
    except (rawpy.LibRawError, OSError) as exc:
        raise AcquisitionError(f"{name}: LibRaw cannot read it as a camera RAW file ({exc})") from None
