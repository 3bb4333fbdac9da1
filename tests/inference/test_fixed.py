"""Held parameters (``calibrate(..., fixed=...)``) and the propagation of a held input's error.

Data: exact stationary camera frames by circulant embedding (numpy only, not blurtrap's
simulator). Tolerances from the stated standard errors.
"""

import math

import numpy as np
import pytest
from _circulant import circulant_frames

import blurtrap as bt

T = 296.15
DT = 1 / 1500
GAMMA = 6 * math.pi * 0.00093 * 1.53e-6
K = 5e-5


def _frames(k, w, eps2, n, seed, dt=DT, gamma=GAMMA):
    """Circulant-embedded exact frames (paper eqs. 7-8; numpy, not blurtrap's simulator)."""
    return circulant_frames(k, gamma, w, dt, eps2, n, seed, temperature=T)


def _rec(seed, n=2**14, w=DT, eps2=4e-18, **kw):
    return bt.Recording(_frames(K, w, eps2, n, seed, **kw), frame_interval=kw.get("dt", DT),
                        exposure=w, temperature=T)


def test_fixed_gamma_unbiased_and_honest():
    """gamma held at the truth: k unbiased, its SE the spread over seeds, and smaller than
    with gamma free (the variance now carries k)."""
    ks, ses, free_se = [], [], []
    for seed in range(40):
        rec = _rec(seed)
        r = bt.calibrate(rec, method="likelihood", likelihood="whittle",
                         fixed={"gamma": GAMMA})
        assert r["gamma"].value == GAMMA and r["gamma"].error == 0.0
        ks.append(r.k)
        ses.append(r.k_err)
        if seed < 3:
            free_se.append(bt.calibrate(rec, method="likelihood", likelihood="whittle").k_err)
    ks, ses = np.array(ks), np.array(ses)
    sd = ks.std(ddof=1)
    assert abs(ks.mean() - K) < 3 * sd / math.sqrt(ks.size)
    # SD of a 40-sample SD is ~11 %: 0.7-1.4 is > 3 of its SEs
    assert 0.7 < np.median(ses) / sd < 1.4
    assert np.median(ses) < 0.6 * np.median(free_se)


def test_held_input_error_is_propagated():
    """gamma held at a value that is itself off by a N(0, 6 %) error, stated as its SE: the
    z-scores of k over seeds have SD ~1 only if that error is propagated (without it, the
    ratio of the two stated errors, ~2 here)."""
    rng = np.random.default_rng(7)
    z, z_naive, ratio = [], [], []
    for seed in range(40):
        g = GAMMA * (1 + 0.06 * rng.standard_normal())
        rec = _rec(100 + seed)
        r = bt.calibrate(rec, method="likelihood", likelihood="whittle",
                         fixed={"gamma": (g, 0.06 * g)})
        r0 = bt.calibrate(rec, method="likelihood", likelihood="whittle", fixed={"gamma": g})
        assert r["gamma"].error == pytest.approx(0.06 * g)
        ratio.append(r.k_err / r0.k_err)
        assert r.k == pytest.approx(r0.k, rel=1e-9)
        z.append((r.k - K) / r.k_err)
        z_naive.append((r0.k - K) / r0.k_err)
    assert 0.7 < np.std(z, ddof=1) < 1.4
    assert np.median(ratio) > 1.5
    assert 0.7 < np.std(z_naive, ddof=1) / np.median(ratio) < 1.4


def test_propagation_matches_refits():
    """The propagated sensitivity dk/dgamma equals refits at gamma +- 1 % (central
    difference of the estimator itself, not of the likelihood)."""
    rec = _rec(3)
    se = 0.02 * GAMMA
    r = bt.calibrate(rec, method="likelihood", likelihood="whittle",
                     fixed={"gamma": (GAMMA, se)})
    up = bt.calibrate(rec, method="likelihood", likelihood="whittle",
                      fixed={"gamma": 1.01 * GAMMA}).k
    dn = bt.calibrate(rec, method="likelihood", likelihood="whittle",
                      fixed={"gamma": 0.99 * GAMMA}).k
    dk_dg = (up - dn) / (0.02 * GAMMA)
    names = r.param_names
    cov_kg = r.covariance[names.index("k"), names.index("gamma")]
    assert cov_kg / se**2 == pytest.approx(dk_dg, rel=0.02)


def test_exact_likelihood_with_fixed_gamma_agrees_with_whittle():
    rec = _rec(11)
    a = bt.calibrate(rec, method="likelihood", likelihood="exact", fixed={"gamma": GAMMA})
    b = bt.calibrate(rec, method="likelihood", likelihood="whittle", fixed={"gamma": GAMMA})
    assert abs(a.k - b.k) < 0.3 * a.k_err
    assert a.k_err == pytest.approx(b.k_err, rel=0.1)


def test_tracking_noise_held_at_zero():
    rec = _rec(5, eps2=0.0)
    r = bt.calibrate(rec, method="likelihood", likelihood="whittle",
                     fixed={"tracking_var": 0.0})
    assert r["tracking_var"].value == 0.0
    assert abs(r.k - K) < 4 * r.k_err and abs(r.gamma - GAMMA) < 4 * r.gamma_err


@pytest.mark.parametrize("fixed, match", [
    ({"stiffness": 1e-5}, "stiffness"),
    ({"gamma": -1e-8}, "gamma"),
    ({"gamma": float("nan")}, "gamma"),
    ({"gamma": (1e-8, -1e-9)}, "standard error"),
    ({"gamma": 0.0}, "positive"),
    ([("gamma", 1e-8)], "dict"),
    ({"k": 1e-5, "gamma": 1e-8, "tracking_var": 1e-18}, "every parameter"),
])
def test_bad_fixed_is_refused(fixed, match):
    with pytest.raises(ValueError, match=match):
        bt.calibrate(_rec(0, n=4096), method="likelihood", likelihood="whittle", fixed=fixed)


def test_fixed_refused_for_methods_without_a_likelihood():
    with pytest.raises(ValueError, match="fixed"):
        bt.calibrate(_rec(0, n=4096), method="equipartition", fixed={"gamma": GAMMA})
