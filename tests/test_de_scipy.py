"""rtloop's L-SHADE against scipy.optimize.differential_evolution at equal evaluation budgets.

The optimiser runs in Rust through the test hook ``minimize_test_function`` of the test-only extension
``_rtloop_test_hooks`` (cargo feature ``test-hooks``, not in the wheel; ``.ci/build-test-hooks`` builds it
into target/test-hooks/, and CI sets RTLOOP_REQUIRE_TEST_HOOKS=1 so that it cannot be skipped there); the
test functions (minimum 0) are defined again here with NumPy and checked against the Rust ones.

Fair settings, for every function in 2, 5 and 10 dimensions on its usual box:

* budget B = 2000 D evaluations, rounded down to whole SciPy generations: SciPy's population is
  popsize * D = 15 D, so ``maxiter = B // (15 D) - 1`` and B = 15 D (maxiter + 1) exactly;
* SciPy: its defaults (best1bin, mutation (0.5, 1) dithered, recombination 0.7, Latin hypercube
  initialisation, immediate updating) with ``polish=False`` and ``tol=atol=0`` so that it spends the
  whole budget instead of stopping on its own population-energy criterion;
* rtloop: L-SHADE with the published defaults (N_init 18 D, H 6, p 0.11, archive 2.6, N_min 4, Latin
  hypercube) with ``max_evaluations=B``, no polish, and ``x_tol=0`` for the same reason;
* seeds 0..4 for both; the error is f(best) - 0.

Criterion: per function and dimension, rtloop's median error is no worse than SciPy's, where errors
below 1e-8 count as solved (both at or near floating-point noise: e.g. SciPy reaches 0 on the 2-D sphere
where L-SHADE stops at 1e-31). Measured medians are printed (``pytest -s``). The paper's DE/rand/1/bin
(``method="de"``) is printed beside them for information only.
"""

from __future__ import annotations

import importlib.util
import math
import os
import statistics
from pathlib import Path

import numpy as np
import pytest

optimize = pytest.importorskip("scipy.optimize")

HOOKS = Path(__file__).resolve().parents[1] / "target" / "test-hooks" / "_rtloop_test_hooks.abi3.so"


def _load_hooks():
    if not HOOKS.is_file():
        if os.environ.get("RTLOOP_REQUIRE_TEST_HOOKS"):
            raise RuntimeError(f"{HOOKS} is missing: run .ci/build-test-hooks")
        pytest.skip(f"the test hooks are not built ({HOOKS}): run .ci/build-test-hooks", allow_module_level=True)
    spec = importlib.util.spec_from_file_location("_rtloop_test_hooks", HOOKS)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


hooks = _load_hooks()


def sphere(x: np.ndarray) -> float:
    return float(np.sum(x * x))


def rosenbrock(x: np.ndarray) -> float:
    return float(np.sum(100.0 * (x[1:] - x[:-1] ** 2) ** 2 + (1.0 - x[:-1]) ** 2))


def rastrigin(x: np.ndarray) -> float:
    return float(10.0 * x.size + np.sum(x * x - 10.0 * np.cos(2.0 * np.pi * x)))


def ackley(x: np.ndarray) -> float:
    n = x.size
    return float(
        -20.0 * np.exp(-0.2 * np.sqrt(np.sum(x * x) / n))
        - np.exp(np.sum(np.cos(2.0 * np.pi * x)) / n)
        + 20.0
        + math.e
    )


def griewank(x: np.ndarray) -> float:
    i = np.arange(1, x.size + 1)
    return float(1.0 + np.sum(x * x) / 4000.0 - np.prod(np.cos(x / np.sqrt(i))))


# name -> (function, lower bound, upper bound) of the usual search box in every dimension.
FUNCTIONS = {
    "sphere": (sphere, -100.0, 100.0),
    "rosenbrock": (rosenbrock, -5.0, 10.0),
    "rastrigin": (rastrigin, -5.12, 5.12),
    "ackley": (ackley, -32.768, 32.768),
    "griewank": (griewank, -600.0, 600.0),
}
DIMS = (2, 5, 10)
SEEDS = range(5)
EVALS_PER_DIM = 2000
SCIPY_POPSIZE = 15
SOLVED = 1e-8  # errors below this count as equal
FACTOR = 1.0  # rtloop's median must be <= FACTOR * SciPy's (or both solved)


def budget(dim: int) -> tuple[int, int]:
    """(SciPy maxiter, evaluation budget) for about EVALS_PER_DIM * dim evaluations."""
    n = SCIPY_POPSIZE * dim
    maxiter = EVALS_PER_DIM * dim // n - 1
    return maxiter, n * (maxiter + 1)


def test_rust_test_functions_match_numpy():
    rng = np.random.default_rng(1)
    for name, (f, lo, hi) in FUNCTIONS.items():
        for dim in DIMS:
            assert (
                abs(hooks.test_function_value(name, [1.0 if name == "rosenbrock" else 0.0] * dim)) < 1e-15
            )
            for _ in range(20):
                x = rng.uniform(lo, hi, dim)
                a, b = f(x), hooks.test_function_value(name, x.tolist())
                assert abs(a - b) <= 1e-12 * (1.0 + abs(a)), (name, x, a, b)


@pytest.mark.parametrize("name", list(FUNCTIONS))
def test_lshade_no_worse_than_scipy_at_equal_budget(name):
    f, lo, hi = FUNCTIONS[name]
    failures = []
    for dim in DIMS:
        maxiter, evals = budget(dim)
        ours, de, theirs = [], [], []
        for seed in SEEDS:
            r = hooks.minimize_test_function(
                name, dim, lo, hi, method="lshade", max_evaluations=evals, seed=seed, x_tol=0.0
            )
            assert r["evaluations"] == evals and r["stop_reason"] == "max_evaluations"
            x = np.asarray(r["x"])
            assert np.all((lo <= x) & (x <= hi))
            assert abs(f(x) - r["f"]) <= 1e-12 * (1.0 + abs(r["f"]))
            ours.append(r["f"])
            d = hooks.minimize_test_function(
                name, dim, lo, hi, method="de", max_evaluations=evals, seed=seed, x_tol=0.0
            )
            de.append(d["f"])
            s = optimize.differential_evolution(
                f,
                [(lo, hi)] * dim,
                maxiter=maxiter,
                popsize=SCIPY_POPSIZE,
                tol=0.0,
                atol=0.0,
                polish=False,
                init="latinhypercube",
                seed=seed,
            )
            assert s.nfev <= evals
            theirs.append(float(s.fun))
        m_ours, m_theirs, m_de = (statistics.median(v) for v in (ours, theirs, de))
        print(
            f"\n{name:10s} D={dim:2d} budget {evals:6d}: median error rtloop L-SHADE {m_ours:.3e}, "
            f"SciPy {m_theirs:.3e}, rtloop DE/rand/1/bin {m_de:.3e}"
        )
        if not m_ours <= max(FACTOR * m_theirs, SOLVED):
            failures.append(f"{name}-{dim}: rtloop {ours} vs SciPy {theirs}")
    assert not failures, failures


def test_result_is_identical_on_any_thread_count():
    for method, polish in (("lshade", 200), ("jso", 0), ("de", 100)):
        runs = [
            hooks.minimize_test_function(
                "rastrigin",
                6,
                -5.12,
                5.12,
                method=method,
                max_evaluations=6000,
                seed=11,
                polish=polish,
                threads=t,
            )
            for t in (1, 2, 4, 8)
        ]
        for other in runs[1:]:
            assert other == runs[0], method
        assert runs[0]["history"][-1] >= runs[0]["f"]
    a = hooks.minimize_test_function("rastrigin", 6, -5.12, 5.12, seed=11, threads=2)
    b = hooks.minimize_test_function("rastrigin", 6, -5.12, 5.12, seed=12, threads=2)
    assert a["history"] != b["history"]


def test_hook_reports_stop_reason_and_polish():
    r = hooks.minimize_test_function("sphere", 4, -5.0, 5.0, max_evaluations=10**6, x_tol=1e-6)
    assert r["stop_reason"] == "converged" and r["evaluations"] < 10**5
    r = hooks.minimize_test_function("sphere", 4, -5.0, 5.0, max_evaluations=5000, x_tol=0.0)
    assert r["stop_reason"] == "max_evaluations" and r["evaluations"] == 5000 and r["population"] == 4
    # A short DE run on 3-D Rosenbrock (no local minima besides the global one) is far from converged;
    # Nelder-Mead finishes the job and says by how much it improved.
    plain = hooks.minimize_test_function("rosenbrock", 3, -5.0, 10.0, method="de", max_evaluations=600)
    r = hooks.minimize_test_function(
        "rosenbrock", 3, -5.0, 10.0, method="de", max_evaluations=600, polish=2000
    )
    assert 0 < r["polish_evaluations"] <= 2000 and r["evaluations"] == 600 + r["polish_evaluations"]
    assert r["f"] < 1e-8 and r["polish_improvement"] == pytest.approx(plain["f"] - r["f"], rel=1e-12)
    with pytest.raises(ValueError, match="unknown test function"):
        hooks.minimize_test_function("nope", 2, -1.0, 1.0)
    with pytest.raises(ValueError, match="method"):
        hooks.minimize_test_function("sphere", 2, -1.0, 1.0, method="cmaes")
    with pytest.raises(hooks.RtloopError, match="max_evaluations"):
        hooks.minimize_test_function("sphere", 2, -1.0, 1.0, max_evaluations=10)
