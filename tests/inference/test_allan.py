"""Allan variance: exact expectation and covariance against brute force, the estimator against
an independent exact-law generator, and the Allan-variance calibration."""

import math

import jax
import numpy as np
import pytest

import blurtrap as bt
from blurtrap.inference._allan import (
    _block_sum_variance_np,
    allan_covariance,
    allan_variance,
    octave_cluster_sizes,
)
from blurtrap.physics._allan import (
    allan_variance_model,
    block_sum_variance,
    frame_moments,
)

KB = 1.380649e-23


def autocov(n_lags, k, gamma, w, dt, temp, eps2):
    """C(0..n_lags-1) written out from the paper's formulas (numpy, not blurtrap):
    C(0) = sigma2 S(a) + eps2, C(n) = sigma2 B(a) rho^n, B = 2 (cosh a - 1)/a^2."""
    sigma2 = KB * temp / k
    tau = gamma / k
    a = w / tau
    s = 2 / a - 2 * (1 - math.exp(-a)) / a**2
    b = 2 * (math.cosh(a) - 1) / a**2
    c = sigma2 * b * np.exp(-np.arange(n_lags) * dt / tau)
    c[0] = sigma2 * s + eps2
    return c


def exact_frames(c, n_traces, rng):
    """Exact Gaussian frames with autocovariance c(0..N-1) by circulant embedding (Davies &
    Harte): the 2N-2 circulant extension is non-negative definite for these exponentially
    decaying covariances (checked)."""
    n = c.size
    row = np.concatenate([c, c[-2:0:-1]])
    lam = np.fft.fft(row).real
    assert lam.min() > -1e-12 * lam.max()
    lam = np.clip(lam, 0, None)
    z = rng.standard_normal((n_traces, row.size)) + 1j * rng.standard_normal((n_traces, row.size))
    y = np.fft.fft(np.sqrt(lam / row.size) * z, axis=1)
    return y.real[:, :n]


CASES = [  # k, gamma, W, dt, eps2 (camera, short exposure, photodiode-like dt << tau)
    (5e-5, 2.7e-8, 6.67e-4, 6.67e-4, 4e-18),
    (2e-5, 2.7e-8, 1e-4, 6.67e-4, 0.0),
    (1e-4, 2.7e-8, 1.28e-5, 1.28e-5, 1e-18),
]


@pytest.mark.parametrize("k, gamma, w, dt, eps2", CASES)
def test_expectation_equals_brute_force_sum(k, gamma, w, dt, eps2):
    m = np.array([1, 2, 3, 7, 16, 64, 200])
    c = autocov(2 * m.max() + 1, k, gamma, w, dt, 295.0, eps2)

    def v(n):
        lags = np.arange(1, n)
        return n * c[0] + 2 * np.sum((n - lags) * c[lags])

    brute = np.array([(4 * v(mm) - v(2 * mm)) / (2 * mm * mm) for mm in m])
    got = np.asarray(allan_variance_model(m, KB * 295.0 / k, gamma / k, w, dt, eps2))
    np.testing.assert_allclose(got, brute, rtol=1e-10)


def test_block_sum_variance_numpy_twin_matches_jax():
    """Same formula, two libraries: agreement to rounding, which the geometric sum amplifies
    by ~1/(r n) at small r n (2e-13 at r = 1e-3, n = 2)."""
    n = np.array([0.0, 1, 2, 5, 100, 12345])
    for c0, c1, r in [(1.0, 0.5, 0.7), (2.0, 1.9, 1e-3), (1.0, 1e-4, 30.0)]:
        np.testing.assert_allclose(_block_sum_variance_np(n, c0, c1, r),
                                   np.asarray(block_sum_variance(n, c0, c1, r)), rtol=1e-11)


def test_covariance_equals_dense_quadratic_form_formula():
    """Cov(x'Q1x, x'Q2x) = 2 tr(Q1 S Q2 S) for Gaussian x with covariance S (Toeplitz)."""
    k, gamma, w, dt, eps2 = CASES[0]
    n = 96
    c = autocov(n, k, gamma, w, dt, 295.0, eps2)
    s = c[np.abs(np.subtract.outer(np.arange(n), np.arange(n)))]
    m = np.array([1, 2, 4, 8, 16])
    qs = []
    for mm in m:
        rows = n - 2 * mm + 1
        d = np.zeros((rows, n))
        for kk in range(rows):  # d_k = sum(x[k+m:k+2m]) - sum(x[k:k+m])
            d[kk, kk + mm:kk + 2 * mm] = 1.0
            d[kk, kk:kk + mm] = -1.0
        qs.append(d.T @ d / (2.0 * mm * mm * rows))
    dense = np.array([[2 * np.trace(q1 @ s @ q2 @ s) for q2 in qs] for q1 in qs])
    sigma2, tau = KB * 295.0 / k, gamma / k
    c0, c1, r = (float(v) for v in frame_moments(sigma2, tau, w, dt, eps2))
    ours = allan_covariance(m, n - 2 * m + 1, n, c0, c1, r)
    np.testing.assert_allclose(ours, dense, rtol=1e-9)
    # mean of the quadratic forms: tr(Q S) is the exact expectation
    np.testing.assert_allclose([np.trace(q @ s) for q in qs],
                               np.asarray(allan_variance_model(m, sigma2, tau, w, dt, eps2)),
                               rtol=1e-10)


def test_estimator_mean_and_scatter_against_exact_law():
    """400 exact traces of 2048 frames: the mean estimate is within 4 SE of the expectation at
    every cluster size and the scatter matches the exact covariance's SD within 15 %
    (the SD of a sample SD of 400 draws is ~3.5 %, more for skewed large-m estimates)."""
    k, gamma, w, dt, eps2 = CASES[0]
    n, reps = 2048, 400
    frames = exact_frames(autocov(n, k, gamma, w, dt, 295.0, eps2), reps,
                          np.random.default_rng(5))
    ests = np.array([allan_variance(y, dt).avar for y in frames])
    m = octave_cluster_sizes(n)
    sigma2, tau = KB * 295.0 / k, gamma / k
    expect = np.asarray(allan_variance_model(m, sigma2, tau, w, dt, eps2))
    c0, c1, r = (float(v) for v in frame_moments(sigma2, tau, w, dt, eps2))
    sd = np.sqrt(np.diag(allan_covariance(m, n - 2 * m + 1, n, c0, c1, r)))
    z = (ests.mean(axis=0) - expect) / (sd / math.sqrt(reps))
    assert np.all(np.abs(z) < 4), z
    np.testing.assert_allclose(ests.std(axis=0, ddof=1), sd, rtol=0.15)


def test_estimator_is_offset_invariant_and_validates():
    rng = np.random.default_rng(1)
    y = rng.standard_normal(1000) * 1e-8
    a = allan_variance(y, 1e-3)
    b = allan_variance(y + 0.37, 1e-3)
    np.testing.assert_allclose(b.avar, a.avar, rtol=1e-6)
    assert a.tau[0] == pytest.approx(1e-3)
    with pytest.raises(ValueError, match="frame_interval"):
        allan_variance(y)
    with pytest.raises(ValueError, match="m must be"):
        allan_variance(y, 1e-3, m=[0, 4])
    with pytest.raises(ValueError, match="at least 16 frames"):
        allan_variance(y[:10], 1e-3)


def test_calibrate_allan_recovers_truth_and_quotes_errors():
    gamma = 6 * math.pi * 0.00095 * 1.53e-6
    k, dt = 5e-5, 1 / 1500
    x = bt.simulate(k, gamma, dt / 2, dt, 32768, key=jax.random.key(7),
                    method="exact_frames", tracking_std=2e-9)
    rec = bt.Recording(np.asarray(x).ravel(), frame_interval=dt, exposure=dt / 2)
    res = bt.calibrate(rec, method="allan")
    assert res.method == "allan"
    assert abs(res.k - k) < 3 * res.k_err
    assert abs(res.gamma - gamma) < 3 * res.gamma_err
    assert 0 < res.gof["p_value"] <= 1
    like = bt.calibrate(rec)
    # the Allan variance is a lossy summary: its errors cannot beat the likelihood's
    assert res.k_err > 0.9 * like.k_err and res.gamma_err > 0.9 * like.gamma_err


def test_allan_flags_eps2_driven_to_its_bound():
    """Frames without tracking noise (circulant embedding, not blurtrap's simulator): the
    log-space GLS drives eps^2 to ~1e-26 m^2. That is the bound 0, flagged as by the other
    fits (NaN error, a note), with the interval (0, 1.96 x the unconstrained SE): a finite
    'error' at 1e-26 had been reported as if eps^2 were estimated there."""
    from _circulant import circulant_frames

    dt = 1 / 1500
    y = circulant_frames(2e-5, 1e-8, dt, dt, 0.0, 32768, 1, temperature=295.0)
    res = bt.calibrate(bt.Recording(y, frame_interval=dt, exposure=dt, temperature=295.0),
                       method="allan")
    assert res.tracking_var < 1e-22  # the case: driven to 0 (3e-18 is one SE here)
    assert res.at_bounds == ("tracking_var",)
    assert math.isnan(res.tracking_var_err)
    assert any("lower bound 0" in n and "no profile" in n for n in res.notes)
    low, high = res.intervals["tracking_var"]
    assert low == 0.0 and 1e-18 < high < 2e-17
    assert res.interval_kinds["tracking_var"] == "wald (at the bound 0)"
    assert math.isfinite(res.k_err) and math.isfinite(res.gamma_err)
