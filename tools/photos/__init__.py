"""The Mitsuba 3 test photos' code, shared by tools/make_photos.py and the other make_*_photos.py tools:
the cases (cases.py), the Mitsuba scenes and renders (mitsuba.py), sRGB and pixel helpers (pixels.py),
the truth, input scenes and measurements (truth.py) and one case's folder (make.py).

Object ids and the sRGB transfer are rtloop's own (``rtloop.object_ids``, ``rtloop._srgb``): the
repository's ``python/`` folder goes first on ``sys.path`` when it holds a built extension
(``maturin develop``), so the tools run from a checkout without an install."""

from __future__ import annotations

import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]

_PYTHON = REPO / "python"
if any((_PYTHON / "rtloop").glob("_native*")) and str(_PYTHON) not in sys.path:
    sys.path.insert(0, str(_PYTHON))
