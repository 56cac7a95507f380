"""The error bars against the truth of the Mitsuba test photos (studies/coverage.py): the block sandwich (of
the fit's L1 norm, the median regression's) covers the true light and the true colour products on photos the
model does not describe exactly (environment, bounce, gloss, lamp, noise, JPEG), and, with the default fit's
pixel footprint, the true light and the colour products on the clean direct photos without inflating the
bars."""

from __future__ import annotations

import importlib.util
import warnings
from pathlib import Path

import numpy as np
import pytest

BENCH = Path(__file__).resolve().parents[1] / "studies" / "coverage.py"


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
    """34 mismatch photos (12 Mitsuba renders with terms or lights the model lacks, 22 direct photos with
    2 % noise or JPEG 40), 102 light coordinates: the true value within 1 sandwich sigma for 40-90 % (about
    68 % for a calibrated normal: not hugely inflated). Gauss-Newton, which treats pixels as independent,
    covers far fewer within 3 than the sandwich: the test can fail. Measured with the footprint default,
    the noise-aware clip level and JPEG sRGB refit, the L1 sandwich and the shadow-edge / jump fix: see
    studies/results/coverage.md for the figures."""
    assert sum(r["class"] == "mismatch" for r in rows) == 34
    assert 0.40 <= _within(rows, "mismatch", "robust", 1) <= 0.90
    assert _within(rows, "mismatch", "gn", 3) < _within(rows, "mismatch", "robust", 3) - 0.15


def test_mismatch_photos_are_covered_within_three_sigma(rows):
    """The same 102 light coordinates within 3 sandwich sigma for >= 85 % of them (the target).
    Three changes made it, each measured alone on the same photos: the uncertainty finds the environment and
    bounce photos' shadow edges (their unit render lit every pixel) and leaves out the pixels a shadow edge
    crosses within a step (they entered the Jacobian with a jump / 2h: env-overhead z 6.0): 97 %; the
    sandwich follows the fit's L1 norm (median regression: model error leaves large residuals of one sign
    over regions, which an L1 fit weighs by their density at zero, not their size): 91 %; the noise-aware
    clip level and JPEG sRGB refit (without it the noisy and JPEG fits were 545 and 85 mm off): 85 %.
    Without all three: 83 % (studies/results/coverage.md)."""
    assert _within(rows, "mismatch", "robust", 3) >= 0.85


def test_mismatch_colour_products_are_covered_within_three_sigma(rows):
    """The colour products (exposure x intensity x colour x albedo per object and channel, ``result.products``
    against the truth's; 243 of them), with the sandwich's ``product_sigma`` (the light's uncertainty
    propagated: the products parameters' own where those are fitted, through the intensity and albedos'
    covariance where interreflection fixes the intensity): >= 85 % within 3 sigma, 40-90 % within 1.
    Gauss-Newton, blind to correlated residuals, covers far fewer (the control, as for the light: at least 15
    points below the sandwich). Measured without the pixel footprint's shift in the robust sigma: 97 % and
    65 %, Gauss-Newton 61 % within 3 (52 % without the noise-aware clip level and the JPEG sRGB refit); with
    the shift 98 % and 73 % (studies/results/coverage.md)."""
    assert _within(rows, "mismatch", "robust", 3, products=True) >= 0.85
    assert 0.40 <= _within(rows, "mismatch", "robust", 1, products=True) <= 0.90
    assert (_within(rows, "mismatch", "gn", 3, products=True)
            < _within(rows, "mismatch", "robust", 3, products=True) - 0.15)


def test_clean_photos_are_covered_and_not_inflated(bench, rows):
    """The 11 clean direct photos (33 light coordinates) with the default fit (its polish takes the pixel
    footprint): the true light within 3 sandwich sigma for >= 95 % of the coordinates, and the median sigma
    at most 3x the median actual error (not inflated; measured 97 % and 1.49, 64 % within 1 sigma, with the
    bias-reduced sandwich; 1.43 with the plain one, 1.20 and 52 % before the footprint's shift joined the
    robust sigma). Gauss-Newton's sigma covers far fewer here (45 %)."""
    clean = [r for r in rows if r["class"] == "clean"]
    assert len(clean) == 11
    assert _within(clean, "clean", "robust", 3) >= 0.95
    _, _, _, _, ratio = bench._stats(clean, "z_robust", "sigma_robust_mm")
    assert ratio <= 3.0
    assert _within(clean, "clean", "gn", 3) < 0.8


def test_clean_colour_products_are_covered_and_calibrated(bench, rows):
    """The clean photos' 84 colour products: within 3 sandwich sigma for >= 95 % (the light's target on clean
    photos), within 1 for 50-90 % (about 68 % for calibrated bars), the median sigma 0.7-3x the median
    error. Their errors (0.01-0.3 %) are mostly the pixel footprint over the balls' curved shading, which the
    albedos absorb and the residual cannot show; the robust sigma holds the shift it causes
    (``footprint_shift``). Measured 96 %, 68 % and 1.04; without the shift 87 %, 32 % and 0.65 (each
    robust assertion fails then). Gauss-Newton: 42 % within 3."""
    assert _within(rows, "clean", "robust", 3, products=True) >= 0.95
    assert 0.50 <= _within(rows, "clean", "robust", 1, products=True) <= 0.90
    _, _, _, _, ratio = bench._stats([r for r in rows if r["class"] == "clean"], "pz_robust", "psigma_robust_rel")
    assert 0.7 <= ratio <= 3.0
    assert _within(rows, "clean", "gn", 3, products=True) < 0.6


def test_the_bootstrap_covers_the_clean_photos(bench):
    """The thorough mode (``uncertainty="bootstrap"``) on the 11 clean direct photos fitted at pixel centres
    (``footprint="off"``, where the sandwich covers 94 % of the light coordinates): the true light within 3
    bootstrap sigma for >= 95 % of the 33 coordinates and more than the sandwich, the median sigma at most 3x
    the median error (not inflated), and the 84 products within 3 sigma for >= 95 %. Measured 97 %, 1.04 and
    96 %; the bootstrap's sigma holds the footprint's shift, which every replicate shares (without it 97 %,
    0.83 and 92 %: the products' assertion fails)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        rows = [bench.run_case(*c, footprint="off", bootstrap=True) for c in bench.cases() if c[1] == "clean"]
    assert _within(rows, "clean", "boot", 3) >= 0.95
    _, _, _, _, ratio = bench._stats(rows, "z_boot", "sigma_boot_mm")
    assert ratio <= 3.0
    assert _within(rows, "clean", "boot", 3, products=True) >= 0.95
    # the same fits' sandwich covers fewer: the bootstrap adds coverage
    assert _within(rows, "clean", "robust", 3) < _within(rows, "clean", "boot", 3)


def test_the_reported_bars_cover_the_photos_and_say_what_is_not_determined(rows, bench):
    """The bars the fit reports (u["bars"]): on at least 90 % of the photos every determined light coordinate
    lies within 3 sigma of the truth, no reported light sigma exceeds 0.5 m, and on the clean photos the median
    sigma is at most 3x the median error (not inflated)."""
    judged = [r for r in rows if np.isfinite(r["z_bars"]).any()]
    inside = [bool(np.nanmax(r["z_bars"]) <= 3) for r in judged]
    assert len(judged) >= 0.9 * len(rows) and np.mean(inside) >= 0.9
    assert np.nanmax([np.nanmax(r["sigma_bars_mm"]) for r in judged]) <= 500
    _, _, _, _, ratio = bench._stats([r for r in rows if r["class"] == "clean"], "z_bars", "sigma_bars_mm")
    assert 1.0 <= ratio <= 3.0
