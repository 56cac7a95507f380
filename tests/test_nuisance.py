"""Nuisance parameters profiled out of the error bars (python/rtloop/uncertainty/nuisance.py): the Gauss-Newton
covariance with the nuisance's columns projected out, and both block sandwiches (least squares, and the median
regression's with its kernel bread) given the nuisance's basis, equal the parameters' block of the joint
covariance over the parameters and the nuisance together (with the nuisance in any parametrisation)."""

from __future__ import annotations

import numpy as np
import pytest

from rtloop.uncertainty import _Covariance
from rtloop.uncertainty.nuisance import basis, profile
from rtloop.uncertainty.sandwich import block_sandwich


def _problem(seed: int = 0):
    w, h = 48, 36
    n = w * h
    rng = np.random.default_rng(seed)
    x = np.linspace(-1, 1, 3 * n)
    jt = np.stack([np.ones(3 * n), x, np.cos(3 * x) + 0.1 * rng.normal(size=3 * n)])  # parameters of interest
    # nuisance columns correlated with them (ramps of a curve, say)
    nu = np.stack([np.clip((x + 1) * 2 - k, 0, 1) for k in range(3)])
    r0 = 0.02 * rng.standard_t(3, size=3 * n) + 0.01 * np.repeat(rng.normal(size=n // 8), 24)  # correlated
    return w, n, jt, nu, r0


def _gn(jt: np.ndarray, r0: np.ndarray, dof: int) -> tuple[_Covariance, float]:
    s2 = float(r0 @ r0) / dof
    p = jt.shape[0]
    return _Covariance({}, [], None, p, s2 * np.linalg.inv(jt @ jt.T), np.ones(p, bool), np.arange(p)), s2


@pytest.mark.parametrize("norm", ["l2", "l1"])
def test_profiled_sandwich_is_the_joint_sandwichs_block(norm):
    w, n, jt, nu, r0 = _problem()
    joint = np.vstack([jt, nu])
    dof = r0.size - joint.shape[0]
    fit_joint, s2 = _gn(joint, r0, dof)
    names = ["a", "b", "c", "n0", "n1", "n2"]
    out_joint, rob_joint = block_sandwich(joint, r0, np.arange(n), w, fit_joint, s2, names, 8, norm=norm)

    q = basis(nu.T, None)
    assert q.shape[1] == 3
    jt_gn = profile(jt, q)
    fit, _ = _gn(jt_gn, r0, dof)
    np.testing.assert_allclose(fit.cov, fit_joint.cov[:3, :3], rtol=1e-9)  # Frisch-Waugh-Lovell
    out, rob = block_sandwich(jt, r0, np.arange(n), w, fit, s2, names[:3], 8, norm=norm, nuisance=q)
    assert out["norm"] == out_joint["norm"] == norm
    np.testing.assert_allclose(rob.cov, rob_joint.cov[:3, :3], rtol=1e-8)
    # and it is wider than the parameters' own with the nuisance held
    held, _ = block_sandwich(jt, r0, np.arange(n), w, _gn(jt, r0, dof)[0], s2, names[:3], 8, norm=norm)
    assert all(out["sigma"][k] > held["sigma"][k] for k in "bc")


def test_nuisance_columns_no_used_residual_moves_are_left_out():
    _, n, jt, nu, _ = _problem()
    cols = np.vstack([nu, np.zeros(3 * n), nu[0] * 2.0]).T  # a zero column and a repeated one
    dropped = np.zeros(3 * n, bool)
    dropped[: n] = True
    q = basis(cols, dropped)
    assert q.shape[1] == 3 and np.allclose(q.T @ q, np.eye(3)) and not q[dropped].any()
    assert np.array_equal(profile(jt, basis(np.zeros((3 * n, 2)), None)), jt)


def test_a_blocks_own_leverage_no_longer_hides_the_model_error_it_holds():
    """The bias-reduced sandwich (CR2, sandwich._bias_reduced). A lobe of another shape than the model's, a
    pixel off, in one 8 px block that holds most of what fixes a parameter c (a highlight that moves with the
    light): least squares puts the error into c, and the block's own fit absorbs the part K_b (its leverage)
    of what its residuals push, so the plain form (CR1) reads the push (1 - K_b) times too short: c's actual
    error is 6.0 of its sigmas. With each block's score scaled by (I - K_b)^(-1/2) it is 2.4. Where no block
    dominates (the lobe's motion a small part of c's column) the two agree (0.58 and 0.59)."""
    import rtloop.uncertainty.sandwich as S

    w, h = 48, 36
    n = w * h
    yy, xx = np.divmod(np.arange(n), w)
    ys = (yy - h / 2) / h
    bump = np.exp(-((xx - 11.5) ** 2 + (yy - 11.5) ** 2) / (2 * 2.0**2))
    dipole = -(xx - 11.5) / 4.0 * bump  # how the lobe moves with the light

    def z(k: float, bias_reduced: bool) -> float:
        jt = np.repeat(np.stack([np.ones(n), (xx - w / 2) / w, ys + k * dipole, bump]), 3, axis=1)
        other = np.exp(-((xx - 12.5) ** 2 + (yy - 11.0) ** 2) / (2 * 1.5**2))  # the photo's lobe
        e = np.repeat(0.02 * other, 3) + 0.002 * np.random.default_rng(0).normal(size=3 * n)
        a = np.linalg.inv(jt @ jt.T)
        theta = a @ jt @ e  # the fit's error (the truth is 0)
        r0 = e - jt.T @ theta
        s2 = float(r0 @ r0) / (r0.size - 4)
        fit = _Covariance({}, [], None, 4, s2 * a, np.ones(4, bool), np.arange(4))
        saved = S.BIAS_REDUCED
        S.BIAS_REDUCED = bias_reduced
        try:
            out, _ = block_sandwich(jt, r0, np.arange(n), w, fit, s2, list("abcd"), 8, norm="l2")
        finally:
            S.BIAS_REDUCED = saved
        return abs(theta[2]) / out["sigma"]["c"]

    assert z(30.0, False) > 5.0 and z(30.0, True) < 3.0
    assert z(3.0, True) == pytest.approx(z(3.0, False), rel=0.25)
