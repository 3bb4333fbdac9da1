"""Host-side inputs of :func:`blurtrap.calibrate_batch`: block periodograms of every row,
closed-form start values from their lag moments, and the per-row checks, computed a block of
rows at a time."""

from __future__ import annotations

import functools

import numpy as np

from .._constants import BOLTZMANN
from . import _batch_checks as checks
from ._spectral import _np_periodogram


def _lag_moments(power, m, dt):
    """Circular autocovariances at lags 0, 1, 2 of the (mean-removed) blocks, from their
    periodograms ``power`` (B, M//2) at j = 1..M//2: ``c_k = 1/(M dt) sum_j w_j I_j
    cos(2 pi j k / M)`` over the full circle (w_j = 2, 1 at the Nyquist ordinate of an even M;
    j = 0 is 0 after mean removal). They differ from the lag products of ``moment_start``
    by O(1/M), immaterial for start values, for a small matrix product instead of three
    passes over the frames."""
    return (power @ _lag_basis(m, dt)).T


@functools.lru_cache(maxsize=8)
def _lag_basis(m, dt):
    j = np.arange(1, m // 2 + 1)
    wt = np.full(j.shape, 2.0)
    if m % 2 == 0:
        wt[-1] = 1.0
    return wt[:, None] * np.cos(2.0 * np.pi * np.outer(j, np.arange(3)) / m) / (m * dt)


def _moment_starts(c0, c1, c2, dt, w, temp):
    """Vectorised closed-form starts from lag moments (same estimator as ``moment_start``)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        rho = np.where(c1 > 0, c2 / c1, np.exp(-1.0))
    rho = np.clip(np.nan_to_num(rho, nan=np.exp(-1.0)), 0.05, 0.99999)
    tau = -dt / np.log(rho)
    a, r = w / tau, dt / tau
    phi1 = np.where(a < 1e-6, 1.0 - a / 2, -np.expm1(-a) / np.maximum(a, 1e-300))
    rho_b = phi1**2 * np.exp(a - r)
    s = np.where(a < 1e-3, 1 - a / 3 + a * a / 12, 2 / np.maximum(a, 1e-300)
                 * (1 + np.expm1(-a) / np.maximum(a, 1e-300)))
    sigma2 = np.where(c1 > 0, c1 / rho_b, c0)
    sigma2 = np.clip(sigma2, 0.3 * c0 / s, 3.0 * c0 / s)
    eps2 = np.maximum(c0 - sigma2 * s, 0.02 * c0)
    k = BOLTZMANN * temp / sigma2
    return np.stack([k, k * tau, eps2], axis=1)


#: rows per block of the host-side preparation (periodograms, start values): the same
#: per-row arithmetic as whole-array numpy calls, without GB-sized temporaries, whose fresh
#: pages cost more than the FFTs (1000 x 65 536 frames: 2.2 s -> 0.4 s for the start values)
_HOST_ROWS = 16


def _periodograms(y, n_blocks, m, dt, first=0):
    """Block-averaged periodograms (B, M//2) of every row: mean removed per block, ordinates
    j = 1..M/2, ``dt/M |FFT|^2`` averaged over the blocks; with the lag moments of
    :func:`_lag_moments` (3, B), the mean ordinate (B,), the per-row checks of
    :func:`_batch_checks.row_stats` (B, 6) and the frame refusals of
    :func:`_batch_checks.frame_status` (B,), all taken while a block of rows is at hand."""
    out = np.empty((y.shape[0], m // 2))
    mom = np.empty((3, y.shape[0]))
    avg = np.empty(y.shape[0])
    stats = np.empty((y.shape[0], 6))
    frames = np.full(y.shape[0], "", dtype=object)
    for i in range(0, y.shape[0], _HOST_ROWS):
        stats[i:i + _HOST_ROWS] = checks.row_stats(y[i:i + _HOST_ROWS])
        frames[i:i + _HOST_ROWS] = checks.frame_status(y[i:i + _HOST_ROWS], first + i)
        with np.errstate(all="ignore"):  # rows with NaN/inf are replaced in _prepare
            rows = out[i:i + _HOST_ROWS]
            rows[:] = _np_periodogram(y[i:i + _HOST_ROWS, : m * n_blocks], dt, n_blocks)[1]
            mom[:, i:i + _HOST_ROWS] = _lag_moments(rows, m, dt)
            avg[i:i + _HOST_ROWS] = rows.mean(axis=1)
    return out, mom, avg, stats, frames


def _prepare(y, n_blocks, m, dt, w, temp, noise, check_units, first=0):
    """Host-side inputs of the fit for rows ``y``: periodograms (B, M//2), start values, log
    reference levels, the per-row checks (B, 6) and the status of rows that are not fitted
    (``""`` for the others; ``first`` numbers the rows in messages). Rows not fitted get a
    stand-in spectrum (not reported)."""
    power, mom, avg, stats, frames = _periodograms(y, n_blocks, m, dt, first)
    pre = checks.prefit_status(stats, check_units)
    pre = np.where((pre == "") & (frames != ""), frames, pre)  # after the Recording checks
    skip = pre != ""
    if skip.any():  # harmless stand-in data for the vmapped fit only
        power[skip] = power[~skip].mean(axis=0) if (~skip).any() else 1e-20
        mom[:, skip] = _lag_moments(power[skip], m, dt)
        avg[skip] = power[skip].mean(axis=1)
    starts = _moment_starts(mom[0], mom[1], mom[2], dt, w, temp)
    if not noise:
        starts = starts[:, :2]
    return power, starts, np.log(avg), stats, pre


def _check_batch(positions, n_blocks, check_units, gof_threshold):
    """``(positions as (B, N) float64, frames per block, gof_threshold)``, each checked."""
    y = np.asarray(positions, dtype=float)
    if y.ndim != 2:
        raise ValueError(f"positions must have shape (batch, frames); got shape {y.shape}")
    b, n = y.shape
    if b == 0:
        raise ValueError(f"positions holds no records (shape {y.shape}): nothing to calibrate")
    if isinstance(n_blocks, bool) or not isinstance(n_blocks, (int, np.integer)) or n_blocks < 1:
        raise ValueError(f"n_blocks must be an integer >= 1; got n_blocks = {n_blocks!r}")
    m = n // n_blocks
    if m < 8:
        raise ValueError(f"n_blocks = {n_blocks} leaves {m} frames per block; need >= 8")
    if not isinstance(check_units, (bool, np.bool_)):
        raise ValueError(f"check_units must be True or False; got {check_units!r}")
    gof_threshold = float(gof_threshold)
    if not 0.0 <= gof_threshold < 1.0:
        raise ValueError(f"gof_threshold must be in [0, 1); got {gof_threshold!r}")
    return y, m, gof_threshold


def _check_some_row_usable(y) -> None:
    """A batch with no finite, fluctuating row has nothing to calibrate."""
    for row in y:  # stops at the first usable row (the first, as a rule)
        if np.isfinite(row).all() and row.max() != row.min():
            return
    bad = np.argwhere(~np.isfinite(y))
    where = f" (NaN/inf first at row {bad[0][0]}, frame {bad[0][1]})" if bad.size else ""
    raise ValueError("positions hold no finite, fluctuating row: every row is constant or "
                     f"contains NaN/inf{where}. There is nothing to calibrate.")
