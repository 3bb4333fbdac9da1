"""Drift (paper appendix B, DESIGN item 8): the variance left after a progressive ideal
high-pass, extrapolated to 0 Hz."""

from __future__ import annotations

import numpy as np


def highpass_variance_curve(y, frame_interval, cutoffs):
    """Variance of ``y`` after an ideal (FFT) high-pass at each cut-off frequency [Hz]."""
    y = np.asarray(y, dtype=float)
    n = y.size
    spec = np.fft.rfft(y - y.mean())
    f = np.fft.rfftfreq(n, frame_interval)
    p = np.abs(spec) ** 2 / n**2
    p[1:] *= 2.0
    if n % 2 == 0:
        p[-1] /= 2.0
    # variance that survives a cut at f1 = sum of power at f >= f1
    order = np.cumsum(p[::-1])[::-1]
    idx = np.searchsorted(f, np.asarray(cutoffs), side="left")
    return order[np.minimum(idx, len(order) - 1)]


def drift_extrapolation(y, frame_interval, *, corner_frequency, fraction=(0.1, 0.5), n_cut=20):
    """Progressive high-pass + linear extrapolation of variance to 0 Hz (appendix B).

    Fits ``var(f1) = v0 + s f1`` for cut-offs in ``fraction * f_c`` (the linear region below
    the corner frequency), where drift no longer contributes but the slope is still that of
    the flat low-frequency PSD. Returns ``(v0, slope, cutoffs, variances)``; for an ideal
    high-pass the expected slope is ``-2 P_d(0)`` (DESIGN item 8).
    """
    lo, hi = fraction
    cut = np.linspace(lo * corner_frequency, hi * corner_frequency, n_cut)
    v = highpass_variance_curve(y, frame_interval, cut)
    a = np.vstack([np.ones_like(cut), cut]).T
    coef, *_ = np.linalg.lstsq(a, v, rcond=None)
    return float(coef[0]), float(coef[1]), cut, v
