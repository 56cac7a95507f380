"""rtloop's median (python/rtloop/_stats.py) is numpy's median value bit for bit, without the first-call
import of numpy.ma that ``np.median`` makes; the package calls it, not ``np.median``."""

from __future__ import annotations

import re
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from rtloop._stats import median

PACKAGE = Path(__file__).resolve().parents[1] / "python" / "rtloop"

_arrays = hnp.arrays(
    dtype=st.sampled_from([np.float32, np.float64, np.int64, np.uint8]),
    shape=hnp.array_shapes(min_dims=1, max_dims=3, min_side=0, max_side=6),
    elements={"allow_nan": True, "allow_infinity": True},
)


def _both(a: np.ndarray, axis: int | None) -> tuple[object, object]:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # an empty slice's mean, inf - inf
        return np.median(a, axis=axis), median(a, axis=axis)


@settings(max_examples=400, deadline=None)
@given(a=_arrays, data=st.data())
def test_the_median_is_numpys_bit_for_bit(a, data):
    axis = data.draw(st.sampled_from([None, *range(a.ndim)]))
    want, got = _both(a, axis)
    want, got = np.asarray(want), np.asarray(got)
    assert got.dtype == want.dtype and got.shape == want.shape
    assert np.array_equal(got, want, equal_nan=True)


def test_a_nan_anywhere_makes_the_median_nan_and_even_counts_average_the_middle_two():
    assert median(np.array([3.0, 1.0, 2.0, 10.0])) == 2.5
    assert np.isnan(median(np.array([1.0, np.nan, 2.0])))
    out = median(np.array([[1.0, np.nan], [3.0, 4.0], [5.0, 6.0]]), axis=0)
    assert out[0] == 3.0 and np.isnan(out[1])


def test_the_package_calls_its_median_not_numpys():
    calls = [f"{p.relative_to(PACKAGE)}:{i}" for p in PACKAGE.rglob("*.py") if p.name != "_stats.py"
             for i, line in enumerate(p.read_text().splitlines(), 1) if re.search(r"\bnp\.(nan)?median\(", line)]
    assert not calls, calls


def test_the_median_does_not_import_numpy_ma():
    code = "import sys, numpy as np; from rtloop._stats import median; median(np.arange(5.0)); print('numpy.ma' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "False"
