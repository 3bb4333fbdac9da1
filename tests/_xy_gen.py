"""Independent numpy generator of x/y camera frames of a bead in an anisotropic, rotated trap.

Each principal axis is a stationary Gaussian sequence with the exact autocovariance of
exposure-averaged OU frames, written here from the formulas (C(0) = sigma2 S(a),
C(n) = sigma2 B(a) rho^n, a = W/tau, rho = exp(-dt/tau)) and drawn by circulant embedding
(FFT of length 2N, one complex Gaussian draw per axis). The frames
are then rotated by phi and isotropic white tracking noise is added to x and y. Nothing of
blurtrap is used.
"""

from __future__ import annotations

import numpy as np

KB = 1.380649e-23


def frame_acov(n_lags: int, k, gamma, w, dt, temperature=295.0) -> np.ndarray:
    """C(0..n_lags-1) of blurred OU frames (no tracking noise) [m^2]."""
    sigma2 = KB * temperature / k
    tau = gamma / k
    a = w / tau
    s = 2.0 / a - 2.0 * (1.0 - np.exp(-a)) / a**2
    b = (np.sinh(a / 2) / (a / 2)) ** 2
    lags = np.arange(n_lags)
    c = sigma2 * b * np.exp(-lags * dt / tau)
    c[0] = sigma2 * s
    return c


def principal_frames(n, k1, k2, gamma, w, dt, rng, temperature=295.0):
    """``(u, v)``: independent blurred OU frame sequences along axes 1 and 2 [m]."""
    m = 2 * n
    out = []
    for k in (k1, k2):
        c = frame_acov(n + 1, k, gamma, w, dt, temperature)
        row = np.concatenate([c, c[-2:0:-1]])
        lam = np.fft.fft(row).real
        assert lam.min() > -1e-12 * lam.max(), "circulant embedding not non-negative"
        out.append(np.sqrt(np.maximum(lam, 0.0) / m))
    z = rng.standard_normal(m) + 1j * rng.standard_normal(m)
    u = np.fft.fft(out[0] * z).real[:n]
    z2 = rng.standard_normal(m) + 1j * rng.standard_normal(m)
    v = np.fft.fft(out[1] * z2).imag[:n]
    return u, v


def xy_frames(n, k1, k2, gamma, w, dt, phi, eps, rng, temperature=295.0):
    """``(x, y)`` [m]: principal frames rotated by `phi` plus N(0, eps^2) on x and y."""
    u, v = principal_frames(n, k1, k2, gamma, w, dt, rng, temperature)
    c, s = np.cos(phi), np.sin(phi)
    x = c * u - s * v + eps * rng.standard_normal(n)
    y = s * u + c * v + eps * rng.standard_normal(n)
    return x, y
