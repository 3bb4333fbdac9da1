"""calibrate_anharmonic on a strongly quartic trap with tau ~ dt (finding 3).

k = 2e-5 N/m, 1 um bead (tau = 0.9 frames), 1000 fps, W = 0.5 ms, eps = 3 nm,
beta = k4 kT/k^2 = 0.3. Frames from an independent numpy Euler-Maruyama generator
(h = W/25, exposure average by the trapezoid rule over the substeps), not blurtrap's
simulator or moments.
"""

import math

import numpy as np
import pytest

import blurtrap as bt

KT = 1.380649e-23 * 295.0
K, GAMMA, DT, W = 2e-5, 6 * math.pi * 0.95e-3 * 1e-6, 1e-3, 0.5e-3
BETA = 0.3
K4 = BETA * K * K / KT


def quartic_frames(n, n_traces, seed, m=25, burn=100, eps=3e-9):
    """(n_traces, n) camera frames [m] of U = k x^2/2 + k4 x^4/4 (Euler-Maruyama, h = W/m)."""
    rng = np.random.default_rng(seed)
    h = W / m
    per = int(round(DT / h))
    a, sd = h / GAMMA, math.sqrt(2 * KT * h / GAMMA)
    x = rng.standard_normal(n_traces) * math.sqrt(KT / K)
    out = np.empty((n + burn, n_traces))
    for i in range(n + burn):
        z = rng.standard_normal((per, n_traces)) * sd
        acc = 0.5 * x
        for j in range(per):
            x = x - a * (K * x + K4 * x * x * x) + z[j]
            acc = acc + (x if j < m - 1 else 0.5 * x if j == m - 1 else 0.0)
        out[i] = acc / m
    frames = out[burn:].T
    return frames + eps * rng.standard_normal(frames.shape)


@pytest.fixture(scope="module")
def records():
    return [bt.Recording(x, frame_interval=DT, exposure=W, temperature=295.0)
            for x in quartic_frames(8192, 24, 11)]


def test_exactly_identified_fit_says_it_has_no_goodness_of_fit_check(records):
    r = bt.calibrate_anharmonic(records[0], lags=(1, 2), square_lags=(), profile=False)
    assert r.gof["dof"] == 0 and math.isnan(r.gof["p_value"])
    assert any("no goodness-of-fit check" in n for n in r.notes), r.notes
    assert "no goodness-of-fit check" in r.summary()


def test_default_moments_stay_overidentified_when_tau_is_about_a_frame(records):
    """The default lags used to collapse to (1, 2) here (0.25-3 tau round to 0-3 frames):
    4 moments for 4 parameters. Now lags 1-3 and the squared-frame covariance at lags 1, 2."""
    r = bt.calibrate_anharmonic(records[0], profile=False)
    assert r.lags == (1, 2, 3) and r.square_lags == (1, 2)
    assert r.gof["dof"] == 3 and 0.0 < r.gof["p_value"] <= 1.0
    assert not any("goodness-of-fit" in n for n in r.notes)
    assert abs(r.k - K) < 3 * r.k_err and abs(r.gamma - GAMMA) < 3 * r.gamma_err


def test_k4_profile_interval_covers_where_the_wald_interval_misses(records):
    """A record with a low kurtosis draw: k4 +- 1.96 SE misses the truth (the SE shrinks with
    the estimate), the profile interval of the GMM distance does not, and it is asymmetric."""
    r = bt.calibrate_anharmonic(records[10])
    lo, hi = r.intervals["k4"]
    assert r.interval_kinds["k4"].startswith("profile")
    assert abs(r.k4 - K4) > 1.96 * r.k4_err  # Wald misses
    assert lo < K4 < hi  # the profile covers
    assert hi - r.k4 > 1.5 * (r.k4 - lo)  # skewed upward
    assert any("intervals['k4']" in n for n in r.notes)
    d = r.to_dict()
    assert d["intervals"]["k4"] == [lo, hi] and d["interval_kinds"]["k4"] == r.interval_kinds["k4"]
    assert r.intervals["k"] == pytest.approx((r.k - 1.96 * r.k_err, r.k + 1.96 * r.k_err), rel=1e-4)


def test_squared_frame_covariance_is_gaussian_at_beta_zero():
    """E[m_0^2 m_l^2] = var^2 + 2 C(l)^2 for blurred OU frames (Isserlis)."""
    from blurtrap.inference._anharmonic_moments import frame_moments, square_covariance

    lags = np.array([1, 2, 3])
    var, cov, _ = (np.asarray(v) for v in frame_moments(0.0, 0.55, 1.1, lags, 241))
    sq = np.asarray(square_covariance(0.0, 0.55, 1.1, lags, 241))
    np.testing.assert_allclose(sq, var**2 + 2 * cov**2, rtol=1e-4)
