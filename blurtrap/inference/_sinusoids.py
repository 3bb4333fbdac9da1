"""Least-squares sinusoids in an equally spaced trace: fit, refine the frequency, errors.

Shared by :mod:`._lines` (finding and removing lines) and :mod:`._active` (the response to a
stage drive). Time is centred, ``tc_n = (n - (N-1)/2) dt``, which decouples frequency from
phase and keeps the normal equations well conditioned; a component is
``a cos(2 pi f tc) + b sin(2 pi f tc)``, i.e. the complex amplitude ``a - i b`` about the
record's midpoint. NumPy only (O(N) per frequency, O(N log N) for a periodogram).
"""

from __future__ import annotations

import numpy as np

from ._spectral import _np_periodogram

_GRID_POINTS = 9  # refinement grid over +-half_width (0.15-bin steps for +-0.6 bin)
_GOLDEN_STEPS = 8  # within +-half a grid step of the parabola's vertex: to 0.5 % of a step
_NEWTON_STEPS = 3


# ---------------------------------------------------------------- validation


def check_positive(value, name: str, unit: str) -> float:
    """``float(value)`` if it is a positive finite number, else a ValueError naming it."""
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a positive number [{unit}]; got {value!r}.") from None
    if not (np.isfinite(v) and v > 0):
        raise ValueError(f"{name} must be a positive, finite number [{unit}]; got {value!r}.")
    return v


def check_trace(positions, frame_interval, name: str = "positions", min_frames: int = 16):
    """``(float64 1-D array, dt)``, or a ValueError naming the argument and the bad value."""
    y = np.asarray(positions, dtype=np.float64)
    if y.ndim != 1:
        raise ValueError(f"{name} must be a 1-D trace; got an array of shape {y.shape}.")
    if y.size < min_frames:
        raise ValueError(f"{name} must hold at least {min_frames} frames; got {y.size}.")
    if not np.all(np.isfinite(y)):
        bad = int(np.flatnonzero(~np.isfinite(y))[0])
        raise ValueError(f"{name} must be finite; frame {bad} is {float(y[bad])!r}.")
    return y, check_positive(frame_interval, "frame_interval", "s")


def check_frequency(freq, dt: float, name: str) -> float:
    """A frequency [Hz] in (0, Nyquist), else a ValueError naming it."""
    f = check_positive(freq, name, "Hz")
    if f >= 0.5 / dt:
        raise ValueError(f"{name} must be below the Nyquist frequency {0.5 / dt:.6g} Hz "
                         f"(frame_interval {dt:.6g} s); got {f!r} Hz.")
    return f


# ---------------------------------------------------------------- spectra and fits


def periodogram(y, dt: float):
    """Periodogram ``dt/N |FFT(y - mean)|^2`` at f_j = j/(N dt), j = 1 .. N//2 (batched over
    leading axes): ``(f, power)`` (:func:`blurtrap.inference._spectral._np_periodogram`)."""
    f, p, _ = _np_periodogram(y, dt)
    return f, p


def centred_time(n: int, dt: float):
    return (np.arange(n) - 0.5 * (n - 1)) * dt


def fit_sinusoids(y, dt: float, freqs):
    """Joint least squares of the mean and sinusoids at ``freqs`` [Hz].

    **Returns:** ``(sinusoidal part, coef)``, coef = [mean, a_1, b_1, a_2, b_2, ...] (centred time).
    """
    if len(freqs) == 0:
        return np.zeros_like(y), np.array([y.mean()])
    arg = np.outer(centred_time(y.size, dt), 2 * np.pi * np.asarray(freqs, dtype=np.float64))
    x = np.empty((y.size, 1 + 2 * arg.shape[1]))
    x[:, 0] = 1.0
    x[:, 1::2], x[:, 2::2] = np.cos(arg), np.sin(arg)
    coef = np.linalg.lstsq(x, y, rcond=None)[0]
    return x[:, 1:] @ coef[1:], coef


def component(n: int, dt: float, freq: float, a: float, b: float):
    """``a cos(2 pi f tc) + b sin(2 pi f tc)`` on the centred time grid."""
    arg = 2 * np.pi * freq * centred_time(n, dt)
    return a * np.cos(arg) + b * np.sin(arg)


def regression_power(u, dt: float, freq: float) -> float:
    """Sum of squares explained by cos and sin at ``freq`` (with the mean) in ``u`` (mean zero).

    Exact least squares; on centred time the cross products have closed forms
    (``sum cos(x m) = D(x) = sin(N x/2)/sin(x/2)``, ``sum sin(x m) = sum cos sin = 0``,
    ``sum cos^2 = (N + D(2x))/2``), so only ``u . cos`` and ``u . sin`` cost O(N).
    """
    n, x = u.size, 2 * np.pi * freq * dt
    arg = x * (np.arange(n) - 0.5 * (n - 1))
    cu, su = float(np.cos(arg) @ u), float(np.sin(arg) @ u)
    d1 = np.sin(0.5 * n * x) / np.sin(0.5 * x)
    d2 = np.sin(n * x) / np.sin(x)
    cc = 0.5 * (n + d2) - d1 * d1 / n  # cos column with its mean removed
    ss = 0.5 * (n - d2)
    return (cu * cu / cc if cc > 1e-9 * n else 0.0) + (su * su / ss if ss > 1e-9 * n else 0.0)


def refine_frequency(y, dt: float, f0: float, half_width: float) -> float:
    """Frequency [Hz] maximising the least-squares sinusoid power within ``f0 +- half_width``.

    The exact regression power on a 9-point grid, parabolic interpolation through the best
    point and its neighbours, a few golden-section steps within half a grid step of the vertex,
    then Gauss-Newton steps on the frequency (each kept only if it raises the power).
    """
    n = y.size
    u = y - y.mean()
    f_lo, f_hi = 0.25 / (n * dt), 0.5 / dt - 0.25 / (n * dt)
    grid = np.clip(f0 + np.linspace(-half_width, half_width, _GRID_POINTS), f_lo, f_hi)
    power = np.array([regression_power(u, dt, g) for g in grid])
    i = int(np.argmax(power))
    h = max(grid[1] - grid[0], 1e-3 / (n * dt))
    vertex = grid[i]
    if 0 < i < grid.size - 1:
        curv = power[i - 1] - 2 * power[i] + power[i + 1]
        if curv < 0:
            vertex += float(np.clip(0.5 * h * (power[i - 1] - power[i + 1]) / curv, -h, h))
    a, b = max(vertex - 0.5 * h, f_lo), min(vertex + 0.5 * h, f_hi)
    g = 0.5 * (np.sqrt(5.0) - 1.0)
    x1, x2 = b - g * (b - a), a + g * (b - a)
    p1, p2 = regression_power(u, dt, x1), regression_power(u, dt, x2)
    for _ in range(_GOLDEN_STEPS):
        if p1 >= p2:
            b, x2, p2 = x2, x1, p1
            x1 = b - g * (b - a)
            p1 = regression_power(u, dt, x1)
        else:
            a, x1, p1 = x1, x2, p2
            x2 = a + g * (b - a)
            p2 = regression_power(u, dt, x2)
    best, p_best = (x1, p1) if p1 >= p2 else (x2, p2)
    if power[i] > p_best:
        best, p_best = float(grid[i]), float(power[i])
    for _ in range(_NEWTON_STEPS):
        jac, coef = line_jacobian(u, dt, best)
        step = np.linalg.solve(jac.T @ jac, jac.T @ (u - jac[:, :3] @ coef))[3] / (2 * np.pi)
        cand = float(np.clip(best + step, f_lo, f_hi))
        p_cand = regression_power(u, dt, cand)
        if not (abs(step) < h and p_cand >= p_best):
            break
        best, p_best = cand, p_cand
    return float(best)


def line_jacobian(u, dt: float, freq: float):
    """Columns [1, cos, sin, d/dw] of one sinusoid at ``freq`` and its LS coefficients [mean, a, b]."""
    tc = centred_time(u.size, dt)
    arg = (2 * np.pi * freq) * tc
    c, s = np.cos(arg), np.sin(arg)
    x = np.column_stack([np.ones_like(tc), c, s])
    coef = np.linalg.lstsq(x, u, rcond=None)[0]
    return np.column_stack([x, tc * (coef[2] * c - coef[1] * s)]), coef


def line_errors(u, dt: float, freq: float, psd: float):
    """Standard errors of (frequency [Hz], amplitude) of the one line in ``u``, local PSD ``psd``.

    ``cov = (psd/dt) (J^T J)^-1`` with J the columns of :func:`line_jacobian`: near ``freq``
    the noise acts like white noise of variance ``psd/dt`` (two-sided PSD) -- the Cramer-Rao
    bound of Rife & Boorstyn (1974) with the local spectrum.
    """
    jac, coef = line_jacobian(u, dt, freq)
    cov = (psd / dt) * np.linalg.inv(jac.T @ jac)
    amp = np.hypot(coef[1], coef[2])
    grad = np.array([coef[1], coef[2]]) / max(amp, np.finfo(float).tiny)
    return float(np.sqrt(cov[3, 3]) / (2 * np.pi)), float(np.sqrt(grad @ cov[1:3, 1:3] @ grad))
