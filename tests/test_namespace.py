"""The package's public face: ``dir(rtloop)`` is its API, every name in ``__all__`` exists, every
``rtloop.NAME`` the README's examples use is in ``__all__``, and ``import rtloop`` stays light."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import rtloop

REPO = Path(__file__).resolve().parents[1]


def test_dir_is_the_public_api():
    assert dir(rtloop) == sorted(rtloop.__all__)
    for helper in ("np", "Any", "annotations", "whole", "interrupted_at_import"):
        assert not hasattr(rtloop, helper), helper


def test_every_name_in_all_exists():
    for name in rtloop.__all__:
        assert getattr(rtloop, name) is not None, name
    from rtloop import JobResult, fit_many  # loaded on first use

    assert fit_many.__module__.startswith("rtloop.batch") and JobResult.__name__ == "JobResult"


def test_the_readme_uses_only_public_names():
    modules = {"cli", "uncertainty", "acquisition", "batch"}  # `rtloop.cli.fit`, ... in prose
    used = set(re.findall(r"\brtloop\.([A-Za-z_]\w*)", (REPO / "README.md").read_text(encoding="utf-8")))
    assert "save_image" in used or not used
    assert sorted(used - set(rtloop.__all__) - modules) == []


def test_import_loads_neither_the_batch_nor_opencv_nor_scipy():
    code = ("import sys, rtloop; print(sorted(m for m in ('rtloop.batch', 'cv2', 'scipy', 'matplotlib', "
            "'numpy.ma') if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"


def test_a_fit_result_has_a_short_repr(ball_scene):
    """repr(FitResult) is a few lines (the outcome and the fitted values), not the whole history."""
    photo = rtloop.render(ball_scene)
    result = rtloop.fit(ball_scene, photo, seed=1, population=8, generations=4)
    text = repr(result)
    assert len(text) < 800, len(text)
    assert text.startswith("FitResult(success=True, protocol='rtloop', seed=1, ")
    assert f"'light.position.x': {result.x['light.position.x']:.6g}" in text
    assert f"evaluations={result.evaluations}" in text
    for stage in result.stages:
        assert "history" not in repr(stage) and len(repr(stage)) < 800
