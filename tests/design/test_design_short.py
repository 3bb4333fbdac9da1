"""Short records: the design's predicted Cramer-Rao SEs use the exact Gaussian information of
the frames (the dense Toeplitz covariance, here in numpy with finite-difference derivatives,
written apart from blurtrap), not only the Whittle approximation."""

import math

import numpy as np
from _circulant import frame_autocovariance
from scipy.linalg import toeplitz

import blurtrap as bt

T = 295.0
GAMMA = 6 * math.pi * 0.00095 * 1.53e-6
K = 5e-5
DT = 1 / 1500


def frame_cov(theta, w, n):
    """Toeplitz covariance of n frames (paper eqs. 7-8) at theta = log(k, gamma, eps2)."""
    k, gamma, eps2 = np.exp(theta)
    return toeplitz(frame_autocovariance(k, gamma, w, DT, eps2, n, T))


def exact_crb(w, n, eps2):
    th = np.log([K, GAMMA, eps2])
    s_inv = np.linalg.inv(frame_cov(th, w, n))
    d = []
    for i in range(3):
        h = np.zeros(3)
        h[i] = 1e-5
        d.append((frame_cov(th + h, w, n) - frame_cov(th - h, w, n)) / 2e-5)
    f = np.array([[0.5 * np.trace(s_inv @ d[i] @ s_inv @ d[j]) for j in range(3)]
                  for i in range(3)])
    return np.sqrt(np.diag(np.linalg.inv(f)))


def test_short_record_predictions_use_the_exact_information():
    n, eps = 256, 2e-9
    d = bt.design(k=K, gamma=GAMMA, max_fps=1500, n_frames=n, tracking_std=eps, series=(),
                  current=[(DT, 0.5 * DT, n)])
    for label, w in (("W = dt at the fastest frame rate", DT), ("your current design", 0.5 * DT)):
        c = next(c for c in d.candidates if c.label == label)
        ref = exact_crb(w, n, eps**2)
        got = np.array([c.unconstrained_se[p][0] for p in ("k", "gamma", "tracking_var")])
        # the Whittle form differs from the exact one by 0.2-0.4 % here: 2e-4 tells them apart
        np.testing.assert_allclose(got, ref, rtol=2e-4)
