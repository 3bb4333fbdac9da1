"""Errors of the other parameters when one (eps^2) is at its lower bound 0: the unconstrained
Cramer-Rao bound at the estimate, i.e. the inverse of the full observed information in
natural parameters with the bound parameter counted as free, checked against Hessians
computed here independently (numpy finite differences of the Whittle likelihood and of the
dense Toeplitz REML likelihood, both written below); the same errors from ``calibrate`` and
``calibrate_batch``; conditional errors with a clear note only where that information is not
positive definite."""

from __future__ import annotations

import math

import numpy as np
import pytest

import blurtrap as bt
from blurtrap.inference import _bound_errors as _fit

KB = 1.380649e-23
T = 295.0
GAMMA = 6 * math.pi * 0.00093 * 1.53e-6
DT = 1.0 / 1500.0
W = 0.1 * DT
K = 5e-5


def _frames(k, eps2, n, seed):
    """Exact stationary frames by circulant embedding (numpy only, not blurtrap's
    simulator), as in test_boundary.py."""
    c = _autocov((k, GAMMA, eps2), n + 1)
    lam = np.fft.fft(np.concatenate([c, c[-2:0:-1]])).real
    z = np.random.default_rng(seed).standard_normal((2, lam.size))
    return np.fft.fft(np.sqrt(np.maximum(lam, 0) / lam.size) * (z[0] + 1j * z[1])).real[:n]


def _autocov(p, n):
    """C(0..n-1) of blurred, sampled, noisy frames (DESIGN item 5), numpy; p = (k, gamma,
    eps2), eps2 may be negative (the likelihood extends analytically below the bound)."""
    k, gamma, eps2 = p
    s2, tau = KB * T / k, gamma / k
    a = W / tau
    s = 2 / a - 2 * (1 - math.exp(-a)) / a**2
    b = 2 * (math.cosh(a) - 1) / a**2
    c = s2 * b * math.exp(-DT / tau) ** np.arange(n)
    c[0] = s2 * s + eps2
    return c


def _whittle_ref(x):
    """Whittle negative log-likelihood of ``x`` relative to its value at ``p0`` (small terms:
    no rounding loss), with the exact expected periodogram of the record (Fejer kernel) as
    the model, ordinates j = 1..M/2, half weight at Nyquist: ``f(p, p0)``."""
    m = x.size
    power = np.abs(np.fft.rfft(x - x.mean())[1:]) ** 2 * DT / m
    w = np.ones(power.size)
    w[-1] = 0.5
    lag = np.arange(m)

    def expected(p):
        c = _autocov(p, m)
        a = (1 - lag / m) * c
        a[0] = 0.0
        return DT * (c[0] + 2 * np.fft.fft(a).real[1:m // 2 + 1])

    def f(p, p0):
        e, e0 = expected(p), expected(p0)
        return float(np.sum(w * (np.log(e / e0) + power / e0 * (e0 - e) / e)))

    return f


def _reml_ref(x):
    """Dense Toeplitz REML negative log-likelihood (unknown mean profiled out, plus
    1/2 log(1' S^-1 1)) of ``x``, relative to its value at ``p0``: ``f(p, p0)``."""
    from scipy.linalg import cho_factor, cho_solve, toeplitz

    y = x - x.mean()
    one = np.ones(y.size)

    def full(p):
        cf = cho_factor(toeplitz(_autocov(p, y.size)), lower=True)
        si_y, si_1 = cho_solve(cf, y), cho_solve(cf, one)
        q = y @ si_y - (one @ si_y) ** 2 / (one @ si_1)
        return 0.5 * (2 * np.sum(np.log(np.diag(cf[0]))) + q + math.log(one @ si_1))

    return lambda p, p0: full(p) - full(p0)


def _fd_hessian(f, p0, s, h):
    """Hessian of ``f(p0 + s u)`` in u at 0 by central differences, Richardson-extrapolated
    from steps h and h/2 (error O(h^4))."""
    n = p0.size

    def at(u):
        return f(p0 + s * u, p0)

    def once(h):
        e = np.eye(n) * h
        hess = np.empty((n, n))
        for i in range(n):
            hess[i, i] = (at(e[i]) - 2 * at(np.zeros(n)) + at(-e[i])) / h**2
            for j in range(i):
                hess[i, j] = hess[j, i] = (at(e[i] + e[j]) - at(e[i] - e[j])
                                           - at(e[j] - e[i]) + at(-e[i] - e[j])) / (4 * h * h)
        return hess

    return (4 * once(h / 2) - once(h)) / 3


def _reference_cov(f, fit, s_bound, h=2e-3):
    """Inverse of the independent full Hessian (relative step ``h``), natural units."""
    p0 = np.asarray(fit.values, float)
    s = np.array([p0[0], p0[1], s_bound])
    return np.linalg.inv(_fd_hessian(f, p0, s, h)) * np.outer(s, s)


def _first_at_bound(n, likelihood, seeds=range(40)):
    """The first seed whose record (no tracking noise, k = 0.05 pN/nm, W = 0.1 dt) has eps^2
    fitted at its bound: (frames, fit)."""
    for seed in seeds:
        x = _frames(K, 0.0, n, seed)
        fit = bt.calibrate(bt.Recording(x, frame_interval=DT, exposure=W, temperature=T),
                           method="likelihood", likelihood=likelihood)
        if fit.at_bounds:
            return x, fit
    pytest.fail("no seed put eps^2 at its bound")


@pytest.fixture(scope="module")
def whittle_at_bound():
    return _first_at_bound(2**14, "whittle")


def _assert_k_gamma_cov(fit, ref, rel):
    """The fit's variances of k and gamma and their covariance equal the reference's."""
    cov = np.asarray(fit.covariance)
    for i, j in ((0, 0), (1, 1), (0, 1)):
        assert cov[i, j] == pytest.approx(ref[i, j], rel=rel), (i, j, cov[i, j], ref[i, j])


def test_whittle_errors_are_the_full_information_inverse(whittle_at_bound):
    """k and gamma errors (and their covariance) equal the inverse of the full 3x3 natural
    Hessian of the Whittle likelihood written above to 1e-6; conditional on the bound they
    were 6x smaller."""
    x, fit = whittle_at_bound
    assert fit.at_bounds == ("tracking_var",)
    assert math.isnan(fit.tracking_var_err)
    ref = _reference_cov(_whittle_ref(x), fit, 1e-18)
    _assert_k_gamma_cov(fit, ref, rel=1e-6)
    # not the conditional errors (the free block of the same information inverted)
    cond = np.linalg.inv(np.linalg.inv(ref)[:2, :2])
    assert fit.k_err > 2 * math.sqrt(cond[0, 0])
    assert fit.gamma_err > 2 * math.sqrt(cond[1, 1])
    (note,) = [n for n in fit.notes if "lower bound 0" in n]
    assert "unconstrained Cramer-Rao bound" in note and "result.intervals" in note
    assert "CONDITIONAL" not in note


def test_batch_gives_calibrates_errors_on_the_same_record(whittle_at_bound):
    """calibrate_batch's at-bound item carries the same errors as calibrate (same objective
    and estimate; Hessian from other start values: equal to rounding)."""
    x, fit = whittle_at_bound
    other = _frames(1e-5, (6e-9) ** 2, x.size, 7)  # interior: eps^2 ~ 4 SE
    b = bt.calibrate_batch(np.stack([x, other]), frame_interval=DT, exposure=W,
                           temperature=T)
    assert list(b.status) == ["ok", "ok"]
    assert b.at_bound.tolist() == [True, False]
    assert b.bound_conditional.tolist() == [False, False]
    assert math.isnan(b.tracking_var_err[0]) and np.isfinite(b.tracking_var_err[1])
    assert b.k[0] == pytest.approx(fit.k, rel=1e-8)
    assert b.k_err[0] == pytest.approx(fit.k_err, rel=1e-6)
    assert b.gamma_err[0] == pytest.approx(fit.gamma_err, rel=1e-6)


def test_exact_errors_are_the_full_information_inverse():
    """The exact (time-domain) likelihood at a bound: errors from differences of its autodiff
    gradient (second-order one-sided at the bound) equal the inverse of the full Hessian of
    the dense Toeplitz REML likelihood written above (1024 frames, 1e-4). The reference's
    step is 2e-2: differences of the dense Cholesky log-likelihood carry rounding noise that
    the Hessian divides by h^2, and at h = 2e-3 the reference itself moved by 0.5 % between
    fits 1e-14 apart (measured: its k variance at h = 2e-3, 5e-3, 1e-2, 2e-2 converges as
    2.574, 2.566, 2.5619, 2.5615 e-10; Richardson truncation at 2e-2 is O(h^4) ~ 2e-7)."""
    x, fit = _first_at_bound(1024, "exact")
    assert fit.at_bounds == ("tracking_var",)
    ref = _reference_cov(_reml_ref(x), fit, 1e-18, h=2e-2)
    _assert_k_gamma_cov(fit, ref, rel=1e-4)
    cond = np.linalg.inv(np.linalg.inv(ref)[:2, :2])
    assert fit.k_err > 1.5 * math.sqrt(cond[0, 0])


def test_not_positive_definite_falls_back_to_conditional_with_a_note(whittle_at_bound,
                                                                     monkeypatch):
    """Where the full information is not positive definite (forced here by demanding an
    impossible eigenvalue), the errors stay conditional on the bound and the note says they
    are too small and points to result.intervals."""
    x, fit = whittle_at_bound
    monkeypatch.setattr(_fit, "_PD_RTOL", 2.0)  # eigenvalues of a unit-diagonal 3x3 < 2
    res = bt.calibrate(bt.Recording(x, frame_interval=DT, exposure=W, temperature=T),
                       method="likelihood", likelihood="whittle")
    assert res.at_bounds == ("tracking_var",)
    ref = _reference_cov(_whittle_ref(x), fit, 1e-18)
    cond = np.linalg.inv(np.linalg.inv(ref)[:2, :2])
    assert res.k_err == pytest.approx(math.sqrt(cond[0, 0]), rel=1e-5)
    assert res.gamma_err == pytest.approx(math.sqrt(cond[1, 1]), rel=1e-5)
    (note,) = [n for n in res.notes if "lower bound 0" in n]
    assert "CONDITIONAL" in note and "too small" in note and "result.intervals" in note


def test_cov_from_hessian_rules():
    """Unit rules: bound rows NaN variance / zero covariance, inverse elsewhere, batched;
    an indefinite or non-finite information is reported as not positive definite."""
    h = np.array([[4.0, 1.0, 0.5], [1.0, 3.0, 0.2], [0.5, 0.2, 2.0]])
    s = np.array([2.0, 3.0, 5.0])
    bound = np.array([False, False, True])
    cov, pd = _fit.cov_from_hessian(h, s, bound)
    inv = np.linalg.inv(h) * np.outer(s, s)
    assert pd
    np.testing.assert_allclose(cov[:2, :2], inv[:2, :2], rtol=1e-12)
    assert math.isnan(cov[2, 2]) and cov[0, 2] == 0 and cov[2, 1] == 0
    bad = h.copy()
    bad[0, 1] = bad[1, 0] = 5.0  # indefinite
    nan = h.copy()
    nan[2, 2] = np.nan
    covs, pds = _fit.cov_from_hessian(np.stack([h, bad, nan]), np.stack([s] * 3),
                                      np.stack([bound] * 3))
    assert pds.tolist() == [True, False, False]
    np.testing.assert_allclose(covs[0, :2, :2], inv[:2, :2], rtol=1e-12)
    assert np.isnan(covs[1]).all() and np.isnan(covs[2]).all()


def test_a_tiny_start_value_does_not_make_the_difference_step_rounding_noise():
    """``unconstrained_cov(fd=True)`` for a parameter at its bound whose start value is ~1e-28
    of its natural scale (eps^2 started from a Whittle fit that was itself at 0): the first
    difference step is then rounding noise, so its unit is widened until the curvature stands
    above rounding, and the covariance equals the inverse of the exact Hessian (analytic
    objective: a correlated quadratic, bound parameter at 1e-30). Without the widening the
    full information came out not positive definite and the errors stayed conditional (too
    small), measured on an irregular-time fit."""
    import jax.numpy as jnp

    a = np.array([[4.0, 1.0, 1.5], [1.0, 3.0, 1.2], [1.5, 1.2, 2.0]])
    m = np.array([1.0, 2.0, -0.5])  # the third parameter's optimum is below its bound 0

    def nll(p, args):
        d = p - jnp.asarray(m)
        return 0.5 * d @ jnp.asarray(a) @ d

    value = np.array([1.2, 1.9, 1e-30])
    at_bound = np.array([False, False, True])
    scale = np.array([1.0, 1.0, 1e-28])
    cov, pd = _fit.unconstrained_cov(nll, value, None, scale, at_bound, fd=True)
    want = np.linalg.inv(a)
    assert pd
    np.testing.assert_allclose(cov[:2, :2], want[:2, :2], rtol=1e-6)
    assert np.isnan(cov[2, 2])
