"""The error bars against the truth of the Mitsuba test photos (benches/coverage.py): the block sandwich
covers the true light and the true colour products on photos the model does not describe exactly
(environment, bounce, gloss, lamp, noise, JPEG), and, with the default fit's pixel footprint, the true light on
the clean direct photos without inflating the bars."""

from __future__ import annotations

import importlib.util
import warnings
from pathlib import Path

import numpy as np
import pytest

BENCH = Path(__file__).resolve().parents[1] / "benches" / "coverage.py"


@pytest.fixture(scope="module")
def bench():
    spec = importlib.util.spec_from_file_location("coverage_bench", BENCH)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.fixture(scope="module")
def rows(bench):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the noisy variants' negative-value warning
        return [bench.run_case(*c) for c in bench.cases()]


def _within(rows, cls, key, k, products=False):
    z = np.array([v for r in rows if r["class"] == cls for v in r[("pz_" if products else "z_") + key]], float)
    assert z.size and np.isfinite(z).all(), "every light coordinate and product has a sigma"
    return float(np.mean(z <= k))


def test_mismatch_photos_are_covered_within_one_sigma(rows):
    """32 mismatch photos (10 Mitsuba renders with terms or lights the model lacks, 22 direct photos with
    2 % noise or JPEG 40), 96 light coordinates: the true value within 1 sandwich sigma for 40-90 % (about
    68 % for a calibrated normal: not hugely inflated). Gauss-Newton, which treats pixels as independent,
    covers far fewer within 3 than the sandwich: the test can fail. Measured with the footprint default and
    the noise-aware clip level and JPEG sRGB refit (issue 15: the noisy and JPEG fits' errors shrank, so
    both cover more): sandwich 68 % within 1 sigma and 85 % within 3; Gauss-Newton 60 % within 3 (before
    issue 15: 64 %, 83 % and 49 %)."""
    assert sum(r["class"] == "mismatch" for r in rows) == 32
    assert 0.40 <= _within(rows, "mismatch", "robust", 1) <= 0.90
    assert _within(rows, "mismatch", "gn", 3) < _within(rows, "mismatch", "robust", 3) - 0.15


def test_mismatch_photos_are_covered_within_three_sigma(rows):
    """The same 96 light coordinates within 3 sandwich sigma for >= 85 % of them. Met again (85 %, 82 of 96)
    since issue 15's noise-aware clip level and JPEG sRGB refit: with the footprint default alone 83 %, as
    its residual no longer carries the pixel-centre model's error at terminator pixels, which inflated the
    sigma of the environment and bounce photos (env-overhead: z 6.0, 0.2 with the pixel-centre residual;
    benches/results/coverage.md). The remaining misses are those photos (env-*, bounce-*, lamp-*)."""
    assert _within(rows, "mismatch", "robust", 3) >= 0.85


def test_mismatch_colour_products_are_covered_within_three_sigma(rows):
    """The colour products (exposure x intensity x colour x albedo per object and channel, ``result.products``
    against the truth's; 231 of them), with the sandwich's ``product_sigma`` (the light's uncertainty
    propagated: the products parameters' own where those are fitted, through the intensity and albedos'
    covariance where interreflection fixes the intensity): >= 85 % within 3 sigma, 40-90 % within 1.
    Measured with the footprint default: 95 % and 56 %; Gauss-Newton 52 % and 29 %."""
    assert _within(rows, "mismatch", "robust", 3, products=True) >= 0.85
    assert 0.40 <= _within(rows, "mismatch", "robust", 1, products=True) <= 0.90
    assert _within(rows, "mismatch", "gn", 3, products=True) < 0.6


def test_clean_photos_are_covered_and_not_inflated(bench, rows):
    """The 11 clean direct photos (33 light coordinates) with the default fit (its polish takes the pixel
    footprint): the true light within 3 sandwich sigma for >= 95 % of the coordinates, and the median sigma
    at most 3x the median actual error (not inflated; measured 97 % and 0.96). Fitted at pixel centres
    (``footprint="off"``) the
    renderers' footprint difference is an error the residual of a noise-free photo hardly shows (82 %,
    median ratio 0.48; benches/results/coverage.md); Gauss-Newton's sigma covers far fewer here too."""
    clean = [r for r in rows if r["class"] == "clean"]
    assert len(clean) == 11
    assert _within(clean, "clean", "robust", 3) >= 0.95
    _, _, _, ratio = bench._stats(clean, "z_robust", "sigma_robust_mm")
    assert ratio <= 3.0
    assert _within(clean, "clean", "gn", 3) < 0.8


def test_the_bootstrap_covers_the_clean_photos(bench):
    """The thorough mode (``uncertainty="bootstrap"``) on the 11 clean direct photos fitted at pixel centres
    (``footprint="off"``, where the sandwich covers 82 % of the light coordinates and 60 % of the products): the
    true light within 3 bootstrap sigma for >= 95 % of the 33 coordinates, the median sigma at most 3x the
    median error (not inflated), and the 84 products within 3 sigma for >= 85 % (the issue's 95 % is not
    reached: measured 97 %, 0.84 and 92 %)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        rows = [bench.run_case(*c, footprint="off", bootstrap=True) for c in bench.cases() if c[1] == "clean"]
    assert _within(rows, "clean", "boot", 3) >= 0.95
    _, _, _, ratio = bench._stats(rows, "z_boot", "sigma_boot_mm")
    assert ratio <= 3.0
    assert _within(rows, "clean", "boot", 3, products=True) >= 0.85
    assert _within(rows, "clean", "robust", 3) < 0.9  # the same fits' sandwich: the bootstrap adds coverage
