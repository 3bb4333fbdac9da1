"""Frames at irregular times, exactly, without blurtrap: the covariance of the exposure
averages written out from the OU kernel, then a dense Cholesky factor (numpy only; for tests
and benchmarks, N up to a few thousand frames)."""

from __future__ import annotations

import numpy as np

BOLTZMANN = 1.380649e-23


def frame_covariance(starts, w, k, gamma, temperature, eps2=0.0):
    """Covariance of frames averaged over [s_i, s_i + w] (w <= every interval)."""
    s = np.asarray(starts, float)
    sigma2, tau = BOLTZMANN * temperature / k, gamma / k
    lag = np.abs(s[:, None] - s[None, :])
    if w == 0.0:
        cov = sigma2 * np.exp(-lag / tau)
    else:
        al = w / tau
        off = sigma2 * np.exp(-lag / tau) * (np.exp(al) - 1.0) * (1.0 - np.exp(-al)) / al**2
        cov = off
        np.fill_diagonal(cov, sigma2 * 2.0 * (al - 1.0 + np.exp(-al)) / al**2)
    return cov + eps2 * np.eye(len(s))


def clock(kind: str, n: int, dt: float, size: float, rng) -> np.ndarray:
    """Frame start times: ``"stamp"`` (each stamp off by N(0, (size dt)^2), ordered),
    ``"wander"`` (independent intervals dt (1 + size N(0, 1))), ``"dropped"`` (a fraction
    ``size`` of the frames missing: their interval is 2 dt)."""
    if kind == "stamp":
        t = dt * np.arange(n) + size * dt * rng.normal(size=n)
        return np.sort(t)
    if kind == "wander":
        d = dt * (1.0 + size * rng.normal(size=n - 1))
    elif kind == "dropped":
        d = np.where(rng.random(n - 1) < size, 2.0 * dt, dt)
    else:
        raise ValueError(f"clock kind must be 'stamp', 'wander' or 'dropped'; got {kind!r}")
    return np.concatenate([[0.0], np.cumsum(d)])


def frames(starts, w, k, gamma, temperature, eps2, rng, offset=0.0):
    cov = frame_covariance(starts, w, k, gamma, temperature, eps2)
    return offset + np.linalg.cholesky(cov) @ rng.normal(size=len(starts))
