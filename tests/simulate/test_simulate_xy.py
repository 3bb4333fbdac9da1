"""simulate_xy: the frame covariance at lags 0 and 1 of (x, y) against
R diag(C1(n), C2(n)) R^T + eps^2 I (n = 0) from the exact frame autocovariances, written
independently in tests/_xy_gen.py."""

import math
import os
import sys

import jax
import numpy as np
import pytest

import blurtrap as bt

sys.path.insert(0, os.path.dirname(os.path.dirname(__file__)))
from _xy_gen import frame_acov  # noqa: E402

K1, K2, GAMMA, W, DT, PHI, EPS = 2e-5, 5e-5, 1e-8, 4e-4, 5e-4, 0.5, 3e-9


def test_frame_covariance_matches_rotated_principal_axes():
    n_tr, n = 64, 1024
    out = np.asarray(bt.simulate_xy(K1, K2, GAMMA, W, DT, n, key=jax.random.key(7), angle=PHI,
                                    tracking_std=EPS, n_traces=n_tr))
    assert out.shape == (n_tr, n, 2)
    c1, c2 = frame_acov(2, K1, GAMMA, W, DT), frame_acov(2, K2, GAMMA, W, DT)
    rot = np.array([[math.cos(PHI), -math.sin(PHI)], [math.sin(PHI), math.cos(PHI)]])
    for lag in (0, 1):
        want = rot @ np.diag([c1[lag], c2[lag]]) @ rot.T + (EPS**2 * np.eye(2) if lag == 0
                                                            else 0.0)
        a, b = out[:, : n - lag, :], out[:, lag:, :]
        per_trace = np.einsum("tni,tnj->tij", a, b) / (n - lag)  # known mean 0
        est = per_trace.mean(axis=0)
        se = per_trace.std(axis=0, ddof=1) / math.sqrt(n_tr)
        z = (est - want) / se
        assert np.all(np.abs(z) < 4), (lag, z)
    # the cross-covariance is really there (phi != 0): far from 0 in SE units
    assert abs(want[0, 1]) > 0 and abs(est[0, 1] / se[0, 1]) > 5


def test_keys_and_errors():
    a = bt.simulate_xy(K1, K2, GAMMA, W, DT, 64, key=jax.random.key(1), angle=0.2)
    b = bt.simulate_xy(K1, K2, GAMMA, W, DT, 64, key=jax.random.key(1), angle=0.2)
    c = bt.simulate_xy(K1, K2, GAMMA, W, DT, 64, key=jax.random.key(2), angle=0.2)
    np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
    assert not np.allclose(np.asarray(a), np.asarray(c))
    # at angle 0 the axes are the principal axes: x has the soft axis's larger variance
    with pytest.raises(ValueError, match="tracking_std must be >= 0"):
        bt.simulate_xy(K1, K2, GAMMA, W, DT, 64, key=jax.random.key(1), tracking_std=-1e-9)
    with pytest.raises(ValueError, match="injections are not supported"):
        bt.simulate_xy(K1, K2, GAMMA, W, DT, 64, key=jax.random.key(1), injections=())
