"""The light's error bars against the truth of the Mitsuba test photos: the block sandwich covers the true
light on photos the model does not describe exactly (environment, bounce, gloss, lamp, noise, JPEG)."""

from __future__ import annotations

import importlib.util
import warnings
from pathlib import Path

import numpy as np
import pytest

BENCH = Path(__file__).resolve().parents[1] / "benches" / "coverage.py"


@pytest.fixture(scope="module")
def rows():
    spec = importlib.util.spec_from_file_location("coverage_bench", BENCH)
    bench = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(bench)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the noisy variants' negative-value warning
        return [bench.run_case(*c) for c in bench.cases()]


def _within(rows, cls, key, k):
    z = np.array([v for r in rows if r["class"] == cls for v in r[f"z_{key}"]], float)
    assert np.isfinite(z).all(), "every light coordinate has a sigma"
    return float(np.mean(z <= k))


def test_mismatch_photos_are_covered_within_three_sigma(rows):
    """16 mismatch photos (10 Mitsuba renders with terms or lights the model lacks, 6 direct photos with
    2 % noise or JPEG 40), 48 light coordinates: the true value within 3 sandwich sigma for >= 85 % of
    them, and within 1 sigma for 40-90 % (about 68 % for a calibrated normal: not hugely inflated).
    Gauss-Newton, which treats pixels as independent, covers far fewer: the test can fail.
    Measured: sandwich 98 % within 3 sigma, 56 % within 1; Gauss-Newton 33 % and 17 %."""
    assert sum(r["class"] == "mismatch" for r in rows) == 16
    assert _within(rows, "mismatch", "robust", 3) >= 0.85
    assert 0.40 <= _within(rows, "mismatch", "robust", 1) <= 0.90
    assert _within(rows, "mismatch", "gn", 3) < 0.6
