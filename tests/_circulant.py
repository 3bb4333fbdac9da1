"""Exact stationary camera frames by circulant embedding of the frame autocovariance (numpy
only, not blurtrap's simulator): blurred Ornstein-Uhlenbeck frames (exposure W <= frame
interval dt) plus white tracking noise, C(0) = kT/k S(a) + eps2, C(m) = kT/k B(a) rho^m with
a = W/tau, rho = exp(-dt/tau) (paper eqs. 7-8)."""

from __future__ import annotations

import math

import numpy as np

KB = 1.380649e-23


def frame_autocovariance(k, gamma, w, dt, eps2, n_lags, temperature=295.0) -> np.ndarray:
    """C(0), ..., C(n_lags - 1) of the frames [m^2]."""
    tau = gamma / k
    a = w / tau
    s = 2 / a - 2 * (1 - math.exp(-a)) / a**2
    b = 2 * (math.cosh(a) - 1) / a**2
    c = KB * temperature / k * b * math.exp(-dt / tau) ** np.arange(n_lags)
    c[0] = KB * temperature / k * s + eps2
    return c


def circulant_frames(k, gamma, w, dt, eps2, n, seed, reps=None, temperature=295.0):
    """``n`` frames (``reps=None``), or ``2 reps`` independent records of ``n`` frames (the
    real and imaginary parts of ``reps`` complex draws), from ``default_rng(seed)``."""
    c = frame_autocovariance(k, gamma, w, dt, eps2, n + 1, temperature)
    lam = np.fft.fft(np.concatenate([c, c[-2:0:-1]])).real
    shape = (2, lam.size) if reps is None else (2, reps, lam.size)
    z = np.random.default_rng(seed).standard_normal(shape)
    out = np.fft.fft(np.sqrt(np.maximum(lam, 0) / lam.size) * (z[0] + 1j * z[1]), axis=-1)
    if reps is None:
        return out.real[:n]
    return np.concatenate([out.real[:, :n], out.imag[:, :n]])
