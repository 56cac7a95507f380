"""OpenCV's image decoder without its native chatter: libpng's and OpenCV's own diagnostics, which C code
writes straight to the process's stderr, are caught and handed back, so a bad file gives one line."""

from __future__ import annotations

import os
import sys
import tempfile
import threading
from typing import Any

import numpy as np

__all__ = ["cv2", "imdecode", "leave_stderr_alone"]

_lock = threading.Lock()  # fd 2 is process-wide: one decode at a time holds it
_local = threading.local()


def leave_stderr_alone() -> None:
    """In this thread, decode without catching fd 2: a thread that decodes while another prints (a batch's
    workers beside its progress line) must not swallow that output. A ThreadPoolExecutor initializer."""
    _local.leave_stderr = True


def imdecode(data: np.ndarray) -> tuple[np.ndarray | None, str]:
    """``cv2.imdecode(data, IMREAD_UNCHANGED)`` (None when OpenCV cannot decode it) and what the native
    decoders wrote to stderr meanwhile (empty for a good file), stripped of OpenCV's log prefixes."""
    import cv2  # here, not at import: `import rtloop` loads no OpenCV

    if getattr(_local, "leave_stderr", False):
        try:
            return cv2.imdecode(data, cv2.IMREAD_UNCHANGED), ""
        except cv2.error:
            return None, ""
    with _lock, tempfile.TemporaryFile() as sink:
        sys.stderr.flush()
        saved = os.dup(2)
        try:
            os.dup2(sink.fileno(), 2)
            try:
                decoded: Any = cv2.imdecode(data, cv2.IMREAD_UNCHANGED)
            except cv2.error:
                decoded = None
        finally:
            os.dup2(saved, 2)
            os.close(saved)
        sink.seek(0)
        text = sink.read().decode("utf-8", "replace")
    lines = [_plain(line) for line in text.splitlines() if line.strip()]
    return decoded, "; ".join(lines)


def _plain(line: str) -> str:
    """``[ WARN:0@0.017] global grfmt_png.cpp:793 readFromStreamOrBuffer PNG input buffer is incomplete``
    -> ``PNG input buffer is incomplete``; ``libpng error: X`` stays as it is."""
    line = line.strip()
    if line.startswith("[") and "]" in line:
        rest = line.split("]", 1)[1].split()
        # "global FILE:LINE FUNCTION message...": drop the three location words.
        if len(rest) > 3 and rest[0] == "global":
            return " ".join(rest[3:])
        return " ".join(rest)
    return line


class _Lazy:
    """OpenCV's module, imported at its first use: ``from .._opencv import cv2`` at a module's top keeps
    ``import rtloop`` free of OpenCV."""

    def __getattr__(self, name: str) -> Any:
        import cv2 as module

        return getattr(module, name)


cv2 = _Lazy()
