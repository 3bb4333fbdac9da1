"""The design's prediction near the bound eps^2 >= 0: the projected-Gaussian covariance
against a Monte Carlo projection in numpy (precision-matrix form of the constrained optimum),
and against the scatter of calibrate_batch fits of frames drawn by circulant embedding of the
exact frame autocovariance (numpy, not blurtrap's simulator)."""

import math

import numpy as np
import pytest
from _circulant import circulant_frames

import blurtrap as bt
from blurtrap.design import bound_probability, bounded_covariance, whittle_information

T = 295.0
GAMMA = 6 * math.pi * 0.00095 * 1.53e-6
K = 5e-5
DT = 1 / 1500


def projected_scatter(cov, n_draws=400_000, seed=0):
    """Covariance of the constrained estimate by Monte Carlo: Z ~ N(0, cov) around a true
    eps^2 (relative units, so the bound sits at -1 on the third coordinate); where Z_e < -1
    the other coordinates move to argmin (t - Z)^T P (t - Z) with t_e = -1, i.e.
    t_o = Z_o - P_oo^-1 P_oe (t_e - Z_e) (P = inv(cov)); eps^2's own coordinate is clipped."""
    rng = np.random.default_rng(seed)
    z = rng.multivariate_normal(np.zeros(3), cov, size=n_draws)
    p = np.linalg.inv(cov)
    shift = -np.linalg.solve(p[:2, :2], p[:2, 2])  # d t_o / d t_e at fixed Z
    low = z[:, 2] < -1.0
    t = z.copy()
    t[low, :2] += np.outer(-1.0 - z[low, 2], shift)
    t[low, 2] = -1.0
    return np.cov(t.T), low.mean()


@pytest.mark.parametrize("eps", [1e-9, 2e-9])
def test_bounded_covariance_matches_a_monte_carlo_projection(eps):
    cov = np.linalg.inv(np.asarray(whittle_information(K, GAMMA, 0.1 * DT, DT, 16384, T,
                                                       eps**2)))
    mc, frac = projected_scatter(cov)
    pred = np.asarray(bounded_covariance(cov[None]))[0]
    # SD of the SD estimate from 4e5 draws: ~0.1 %; the bound changes the SDs by 20-35 %
    np.testing.assert_allclose(np.sqrt(np.diag(pred)), np.sqrt(np.diag(mc)), rtol=0.01)
    np.testing.assert_allclose(pred[0, 1], mc[0, 1], rtol=0.02)
    assert float(bound_probability(cov[None])[0]) == pytest.approx(frac, abs=0.003)
    assert np.sqrt(pred[0, 0] / cov[0, 0]) < 0.85  # the bound matters here


def test_bounded_covariance_is_the_identity_far_from_the_bound_and_without_noise():
    cov = np.linalg.inv(np.asarray(whittle_information(K, GAMMA, DT, DT, 65536, T, 4e-18)))
    np.testing.assert_allclose(np.asarray(bounded_covariance(cov[None]))[0], cov, rtol=1e-9)
    two = cov[None, :2, :2]
    np.testing.assert_array_equal(np.asarray(bounded_covariance(two)), two)
    assert float(bound_probability(cov[None])[0]) < 1e-6


def test_design_predicts_the_scatter_of_fits_that_hit_the_bound():
    """W = 0.1 dt, 65 536 frames, eps = 1 nm: eps^2 lands on 0 in ~37 % of fits and the SD of
    log k and log gamma is ~0.70 of the Cramer-Rao bound. bt.design's predicted SE (with the
    bound) matches the scatter of 200 fits within 3 SEs of an SD estimate (15 %); the
    unconstrained bound (what the design predicted before) is ~40 % above it."""
    n, w, eps = 65536, 0.1 * DT, 1e-9
    x = circulant_frames(K, GAMMA, w, DT, eps**2, n, seed=18, reps=100, temperature=T)
    res = bt.calibrate_batch(x, frame_interval=DT, exposure=w, temperature=T)
    ok = np.array([s == "ok" for s in res.status])
    assert ok.mean() > 0.95
    d = bt.design(k=K, gamma=GAMMA, max_fps=1500, n_frames=n, tracking_std=eps,
                  current=[(DT, w, n)], series=())
    cur = next(c for c in d.candidates if c.label == "your current design")
    pred = np.array([cur.predicted_se["k"][0], cur.predicted_se["gamma"][0]])
    crb = np.array([cur.unconstrained_se["k"][0], cur.unconstrained_se["gamma"][0]])
    sd = np.array([np.std(np.log(np.asarray(res.k)[ok]), ddof=1),
                   np.std(np.log(np.asarray(res.gamma)[ok]), ddof=1)])
    tol = 3 * math.sqrt(1 / (2 * (ok.sum() - 1)))
    np.testing.assert_allclose(sd, pred, rtol=tol)
    assert np.all(crb > 1.3 * pred)
    at0 = np.mean(np.asarray(res.tracking_var)[ok] <= 1e-6 * eps**2)
    p = float(cur.bound_probability[0])
    assert at0 == pytest.approx(p, abs=3 * math.sqrt(p * (1 - p) / ok.sum()))
    assert "at its bound 0" in d.summary() or d.best is not cur
