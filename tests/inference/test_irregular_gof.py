"""Goodness of fit and rounded time stamps of fits at irregular frame times (dropped frames).

The frames are drawn without blurtrap: a regular exact sequence by circulant embedding of the
frame autocovariance (tests/_circulant.py) with frames removed at random, or the dense
Cholesky factor of the covariance at the recorded times (tests/_irregular_gen.py)."""

from __future__ import annotations

import numpy as np
import pytest

import blurtrap as bt

K, GAMMA, TEMP, DT = 2e-5, 1e-8, 295.0, 1 / 1500


def _dropped(seed, n=32768, frac=0.1, eps=2e-9, rounding=None, line=0.0, tol=1e-3):
    """``n`` frames of a camera (W = dt) with a fraction ``frac`` dropped at random, correct
    time stamps (rounded to ``rounding`` [s] if given), plus a 120 Hz line of amplitude
    ``line`` [m]."""
    from _circulant import circulant_frames

    total = int(n / (1 - frac)) + 200
    y = circulant_frames(K, GAMMA, DT, DT, eps**2, total, seed, temperature=TEMP)
    keep = np.random.default_rng(seed + 1).random(total) >= frac
    t = (np.arange(total) * DT)[keep][:n]
    y = y[keep][:n] + line * np.sin(2 * np.pi * 120.0 * t)
    if rounding:
        t = np.round(t / rounding) * rounding
    return bt.Recording(y, frame_interval=DT, exposure=DT, temperature=TEMP, times=t,
                        allow_irregular=True, timing_tolerance=tol)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_dropped_frames_pass_the_goodness_of_fit(seed):
    """10 % dropped frames, correct stamps: the exact fit at the recorded times is right, and
    its goodness of fit must not call the model wrong (the periodogram of the frames as if
    regular gave p = 1e-5..1e-8 and a misfit note that sent the user to diagnose)."""
    res = bt.calibrate(_dropped(seed))
    assert "irregular" in res.gof["test"]
    assert res.gof["p_value"] > 1e-3
    assert not any("does not fit" in n for n in res.notes)
    assert abs(res.k - K) < 3 * res.k_err and abs(res.gamma - GAMMA) < 3 * res.gamma_err


def test_a_missing_effect_still_fails_the_goodness_of_fit():
    """A 6 nm line the model lacks, at irregular times: the innovations' test sees it."""
    res = bt.calibrate(_dropped(3, line=6e-9))
    assert res.gof["p_value"] < 1e-3
    assert any("does not fit" in n for n in res.notes)


@pytest.mark.parametrize("mean", ["zero", "reml"])
def test_standardised_innovations_whiten_like_the_dense_cholesky(mean):
    """At the true parameters the standardised innovations are the frames whitened by the
    Cholesky factor L of their covariance at the recorded times: r = L^-1 (y - mu 1), mu the
    GLS mean (0 with mean='zero')."""
    import _irregular_gen as gen

    from blurtrap.inference._innovations import standardised_innovations
    from blurtrap.inference._irregular import make_irregular_args
    from blurtrap.inference._models import get_model
    from blurtrap.inference._problems import make_layout

    r = np.random.default_rng(5)
    k, gamma, dt, w, eps2 = 3.6e-6, 9.0e-9, 1e-3, 0.5e-3, 4e-18
    t = gen.clock("dropped", 700, dt, 0.1, r)
    y = gen.frames(t, w, k, gamma, TEMP, eps2, r, offset=0.0 if mean == "zero" else 3e-7)
    rec = bt.Recording(y, frame_interval=dt, exposure=w, temperature=TEMP, times=t,
                       allow_irregular=True)
    mdl = get_model("standard")
    layout = make_layout([rec], "shared", mdl.noise, ())
    args = make_irregular_args([rec], layout, mdl, mean=mean)
    got = standardised_innovations(np.array([k, gamma, eps2]), args)[0]
    chol = np.linalg.cholesky(gen.frame_covariance(t, w, k, gamma, TEMP, eps2))
    white_y = np.linalg.solve(chol, y)
    if mean == "zero":
        want = white_y
    else:
        white_1 = np.linalg.solve(chol, np.ones_like(y))
        want = white_y - white_1 * (white_1 @ white_y) / (white_1 @ white_1)
    np.testing.assert_allclose(got, want, rtol=1e-7, atol=1e-7 * np.std(want))


def test_rounded_stamps_with_dropped_frames_are_read_as_rounding():
    """Stamps of a 1500 fps camera (W = dt) written in whole microseconds, 10 % dropped:
    steps of 666 and 667 us, some shorter than the exposure. That is rounding, not
    overlapping exposures: the fit goes on at the recorded times, and says so."""
    res = bt.calibrate(_dropped(4, rounding=1e-6))
    assert any("rounded to 1 us" in n and "read as the exposure" in n for n in res.notes)
    assert abs(res.k - K) < 3 * res.k_err and abs(res.gamma - GAMMA) < 3 * res.gamma_err
    assert res.gof["p_value"] > 1e-3


def test_overlap_beyond_rounding_is_still_refused():
    """Stamps rounded to 20 us (3 % of the exposure) cannot place the frames: refused with
    the reason; stamps jittered continuously closer than the exposure as before."""
    with pytest.raises(ValueError, match=r"rounded to 20 us.*more digits"):
        bt.calibrate(_dropped(5, n=4096, rounding=2e-5, tol=0.05))
    import _irregular_gen as gen

    rec = _dropped(6, n=4096)
    t = gen.clock("stamp", rec.n_frames, DT, 0.05, np.random.default_rng(6))  # jittered
    jittered = bt.Recording(rec.positions, frame_interval=DT, exposure=DT, temperature=TEMP,
                            times=t, allow_irregular=True)
    with pytest.raises(ValueError, match=r"exposures cannot overlap \(check the exposure"):
        bt.calibrate(jittered)


def test_rounded_stamps_with_dropped_frames_are_named_by_the_recording():
    """Stamps rounded to 20 us with dropped frames move the median step off the frame
    interval: the error names the rounding and the tolerance that accepts it (it blamed the
    units)."""
    with pytest.raises(ValueError, match=r"rounded to a resolution of 2e-05 s.*dropped frame.*"
                                         r"timing_tolerance=0\.03"):
        _dropped(5, n=4096, rounding=2e-5)


def test_stamp_quantum():
    from blurtrap.data.internal import stamp_quantum

    r = np.random.default_rng(7)
    steps = np.where(r.random(5000) < 0.1, 2, 1) * DT
    assert stamp_quantum(steps) is None  # full precision: "q" would be dt
    t = np.round(np.cumsum(steps) / 1e-6) * 1e-6 + 12.0
    assert stamp_quantum(np.diff(t)) == pytest.approx(1e-6, rel=1e-6)
    assert stamp_quantum(DT * (1 + 0.05 * r.normal(size=5000))) is None  # continuous jitter
