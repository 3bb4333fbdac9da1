"""Narrow spectral lines (sinusoids) in a position trace: find, refine, remove, mask.

A line (stage drive, mains pickup, a vibrating fan) is a sinusoid on top of the thermal
motion. A passive fit must never absorb it: a slow sinusoid looks like slow relaxation
(issue 17: a 16.8 Hz drive made k 42 % wrong at 40 SE). This module finds lines with a
test whose false-alarm rate is fixed by construction, refines their frequencies beyond the
Fourier grid and subtracts them (or masks them out of a spectral fit). NumPy only: these are
O(N log N) pre-processing steps.

**Periodogram convention** (as :func:`blurtrap.inference.periodogram`): two-sided,
``I_j = dt/N |sum_n (y_n - ybar) e^{-2 pi i j n/N}|^2`` at ``f_j = j/(N dt)``, j = 1 .. N//2,
so that ``E[I_j] = P_d(f_j)``. A sinusoid ``A cos(2 pi f t + phi)`` exactly on a Fourier
frequency adds ``N dt A^2 / 4`` to its ordinate.

**The test.** Away from lines, ``I_j / P(f_j)`` is Exp(1). The local spectrum ``P`` is
estimated by a running median over a window of about +-10 % in frequency (0.2 in ln f, 1.5-2 %
of the log-frequency span of a 10^4-10^6-bin periodogram; at least +-100 bins; symmetric in
bins about the ordinate, so that a monotone spectrum such as a Lorentzian's fall or 1/f^2 drift
is not biased), divided by the mean of that order statistic of Exp(1) (-> ln 2). The medians
are taken at centres 2 % apart in frequency and interpolated in log-log between them. For a
window of ``m`` other ordinates whose median is the k-th smallest, the probability of a ratio
above ``r`` is exact (Renyi's representation of exponential order statistics):
``p(r) = prod_{i=m-k+1}^{m} i / (i + r/c)`` with ``c = E[X_(k)]``, which accounts for the
noise of the reference itself. The ordinates half-way between Fourier frequencies (a 2x
zero-padded FFT) are tested too, against the geometric mean of their neighbours' references, so a
line between two bins loses at most 19 % of its ordinate (sinc^2(1/4)) instead of 59 %. An
ordinate is a line when ``M p(r) < p_value`` (Bonferroni over the ``M`` tested ordinates, about
N), so the family-wise false-alarm rate per record is at most about ``p_value``. Lines are found
one at a time, the strongest significant ordinate first, each subtracted before the next search,
so a strong line's leakage is never mistaken for more lines.

**Refinement.** Around the peak bin the exact least-squares sinusoid power (mean, cos and sin
regressed jointly) is evaluated on a 0.15-bin grid, interpolated by a parabola, maximised by a
few golden-section steps and polished by Gauss-Newton steps. The frequency's standard error is
the Cramer-Rao form for a sinusoid in white noise with the local spectrum in place of
``sigma^2 dt``. With several lines, each is refined once more with the others subtracted.

**References:** Fisher (1929) and Priestley, *Spectral Analysis and Time Series* (1981),
section 6.1.4 (tests for periodicities); Renyi (1953) for exponential order statistics;
Rife & Boorstyn (1974), IEEE Trans. Inf. Theory 20, 591 (single-tone frequency estimation).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from ._sinusoids import (
    check_frequency,
    check_positive,
    check_trace,
    component,
    fit_sinusoids,
    line_errors,
    periodogram,
    refine_frequency,
)

__all__ = ["Line", "find_lines", "remove_lines", "line_mask", "excluded_ranges_mask"]

_HALF_WINDOW = 0.10  # running-median half-width, relative to the frequency
_MIN_HALF_BINS = 100  # ... but at least this many bins each side (symmetric cap at low f)
_CENTER_RATIO = 1.02  # spacing of the median's centres in frequency (interpolated between)
_GUARD_BINS = 2  # bins either side of a found line that are not searched again
_LGAMMA = np.frompyfunc(math.lgamma, 1, 1)


class Line(NamedTuple):
    """One narrow line: the component ``amplitude * cos(2 pi frequency t_n + phase)``, t_n = n dt.

    - `frequency`: [Hz] refined beyond the Fourier grid; `frequency_se` its standard error [Hz].
    - `amplitude`: in the unit of the positions; `amplitude_se` its standard error.
    - `phase`: [rad] at the first frame (t_0 = 0), in (-pi, pi].
    - `power_ratio`: ``N dt amplitude^2 / (4 P_local)``, how many times the line's periodogram
      ordinate stands above the local thermal spectrum ``P_local`` (lines removed).
    - `p_value`: probability that noise alone gives this ratio: Bonferroni-adjusted over the
      searched ordinates for a found line (compare with ``find_lines(p_value=...)``), unadjusted for a
      ``known`` one. The refined frequency maximises the ratio, so for weak lines it is slightly
      optimistic.
    - `known`: True when the line was given in ``known`` (always modelled, whatever its p-value).
    """

    frequency: float
    amplitude: float
    phase: float
    power_ratio: float
    p_value: float
    frequency_se: float
    amplitude_se: float
    known: bool


# ---------------------------------------------------------------- spectrum and reference


def _windows(n_bins: int):
    """Running-median centres (1-based bins) and their windows [lo, hi]."""
    num = int(np.ceil(np.log(max(n_bins, 2)) / np.log(_CENTER_RATIO))) + 2
    centres = np.unique(np.round(np.geomspace(1, n_bins, num)).astype(np.int64))
    h = np.maximum(_MIN_HALF_BINS, np.round(_HALF_WINDOW * centres)).astype(np.int64)
    h = np.minimum(h, centres - 1)  # symmetric about the centre at low frequency
    lo, hi = centres - h, centres + h
    over = hi > n_bins  # near Nyquist (where P_d is even) shift the window down
    lo[over] = np.maximum(1, n_bins - 2 * h[over])
    hi[over] = n_bins
    return centres, lo, hi


def _order_stat_mean(m, k):
    """E[X_(k)] of m iid Exp(1) = sum_{i=m-k+1}^{m} 1/i (tends to ln 2 at the median)."""
    harmonic = np.concatenate([[0.0], np.cumsum(1.0 / np.arange(1, int(np.max(m)) + 1))])
    return harmonic[m] - harmonic[m - k]


def _local_reference(power):
    """Robust local spectrum at every ordinate of ``power`` (..., M).

    **Returns:** ``(reference, m, k)``: the reference (same shape as ``power``), and per bin the
    number ``m`` of other ordinates in its window and the rank ``k`` of its median among them.
    """
    n_bins = power.shape[-1]
    centres, lo, hi = _windows(n_bins)
    width = hi - lo + 1
    k = (width + 1) // 2  # the lower median of the window, an order statistic
    med = np.stack([np.partition(power[..., a - 1:b], kk - 1, axis=-1)[..., kk - 1]
                    for a, b, kk in zip(lo, hi, k)], axis=-1)
    m_c, k_c = np.maximum(width - 1, 1), np.minimum(k, np.maximum(width - 1, 1))
    ref_c = np.maximum(med, np.finfo(np.float64).tiny) / np.where(width > 1, _order_stat_mean(m_c, k_c), 1.0)
    j = np.arange(1, n_bins + 1)
    logj, logc = np.log(j), np.log(centres)
    if centres.size == 1:
        ref = np.broadcast_to(ref_c, power.shape).copy()
    else:
        ref = np.exp(np.stack([np.interp(logj, logc, r) for r in np.log(ref_c).reshape(-1, centres.size)])
                     ).reshape(power.shape)
    right = np.clip(np.searchsorted(centres, j), 0, centres.size - 1)
    left = np.clip(right - 1, 0, centres.size - 1)
    pick = np.where(m_c[left] < m_c[right], left, right)  # the smaller window: conservative
    return ref, m_c[pick], k_c[pick]


def _log_tail(ratio, m, k):
    """log P(I/ref > ratio) for I ~ Exp(1) and ref the k-th of m Exp(1) over its mean (exact)."""
    ratio, m, k = np.broadcast_arrays(np.asarray(ratio, float), np.asarray(m), np.asarray(k))
    s = ratio / _order_stat_mean(m, k)
    lg = lambda x: np.asarray(_LGAMMA(x), dtype=np.float64)
    return lg(m + 1.0) - lg(m - k + 1.0) - lg(m + 1.0 + s) + lg(m - k + 1.0 + s)


def _tested(n: int):
    """``q`` (f = q/(2 N dt), q = 2 .. N) and which are tested: the Fourier bins j = q/2 = 2 .. N/2
    without the Nyquist ordinate, and the half-way ordinates between two tested bins."""
    n_bins = n // 2
    q = np.arange(2, 2 * n_bins + 1)
    top = n_bins - 1 if n % 2 == 0 else n_bins  # the last tested Fourier bin
    return q, np.where(q % 2 == 0, (q >= 4) & (q <= 2 * top), (q >= 5) & (q <= 2 * top - 1))


def _scan(y, dt: float, p_value: float):
    """Bonferroni-adjusted p-values of a trace's (or a batch's, (..., N)) periodogram ordinates at
    the Fourier frequencies and half-way between them (a 2x zero-padded FFT: a line between two
    bins loses at most 1 - sinc^2(1/4) = 19 % of its power instead of 59 %).

    The reference at a half-way ordinate is the geometric mean of its neighbours'. Only
    ordinates whose ratio can reach the level are evaluated exactly (the rest are 1): the
    reference is unbiased, so ``p(r) >= exp(-r)`` (Jensen) and a line needs ``r > ln(M/p_value)``;
    the candidates ``r > ln(M/p_value)/2.2`` are a generous superset (interpolated references).

    **Returns:** ``(f, adjusted p (..., 2 N/2 - 1), ratio, n_tested)``, f = q/(2 N dt), q = 2 .. N.
    """
    n, n_bins = y.shape[-1], y.shape[-1] // 2
    spec = np.fft.rfft(y - y.mean(axis=-1, keepdims=True), n=2 * n, axis=-1)[..., 2:2 * n_bins + 1]
    power = (spec.real**2 + spec.imag**2) * (dt / n)
    ref, m, k = _local_reference(power[..., 0::2])
    ref_all = np.empty_like(power)
    ref_all[..., 0::2], ref_all[..., 1::2] = ref, np.sqrt(ref[..., :-1] * ref[..., 1:])
    narrow = np.where(m[:-1] < m[1:], 0, 1) + np.arange(n_bins - 1)  # the smaller window
    m_all, k_all = np.empty(power.shape[-1], np.int64), np.empty(power.shape[-1], np.int64)
    m_all[0::2], m_all[1::2], k_all[0::2], k_all[1::2] = m, m[narrow], k, k[narrow]
    q, tested = _tested(n)
    n_tested = max(int(tested.sum()), 1)
    ratio = power / ref_all
    idx = np.nonzero(tested & (ratio > np.log(n_tested / p_value) / 2.2))
    adj = np.ones_like(ratio)
    if idx[0].size:
        logp = _log_tail(ratio[idx], m_all[idx[-1]], k_all[idx[-1]])
        adj[idx] = np.minimum(1.0, n_tested * np.exp(logp))
    return q / (2 * n * dt), adj, ratio, n_tested


# ---------------------------------------------------------------- public API


def find_lines(positions, frame_interval, *, p_value: float = 1e-6, known=(), max_lines: int = 8
               ) -> tuple[Line, ...]:
    """Find strong narrow lines (sinusoids) in a position trace.

    **Arguments:**

    - `positions`: 1-D trace (any unit; amplitudes come back in it), equally spaced frames.
    - `frame_interval`: dt [s].
    - `p_value`: family-wise false-alarm probability per record (Bonferroni over the tested
      ordinates: Fourier bins j = 2 .. N/2 without the Nyquist bin, and the ordinates half-way
      between them). The default 1e-6 needs an ordinate about 25-33 times the local spectrum
      (N = 1e4 .. 1e6). At N = 4096 (benchmarks/RESULTS_active.md) a line whose on-bin ordinate
      would be 30x the local spectrum is found in 60-70 % of records, 40x in 89-97 % and 60x in
      99-100 %, wherever it falls between bins.
    - `known`: frequencies [Hz] known to carry a line (a stage drive, mains): always modelled,
      refined within +-1 bin, reported with an unadjusted p-value and ``known=True``.
    - `max_lines`: the most lines to search for besides the known ones.

    **Returns:** a tuple of :class:`Line`, the known lines first, then the found ones in the order
    they were found (strongest first). Empty when the trace has no line.

    Lines in the lowest bins are hard to tell from drift and are found only when very strong
    (the median window there is the few bins below and above). A line that is not a pure
    sinusoid (amplitude or frequency modulated) leaves a residual; the +-2 bins around a found
    line are not searched again, so it is reported once.

    **Raises:** ``ValueError`` for a trace that is not 1-D and finite (16 frames at least), a
    non-positive frame interval, ``p_value`` outside (0, 1), a negative ``max_lines`` or a known
    frequency outside (0, Nyquist).
    """
    y, dt = check_trace(positions, frame_interval)
    if not (isinstance(p_value, (int, float, np.floating)) and 0.0 < float(p_value) < 1.0):
        raise ValueError(f"p_value must be a probability in (0, 1); got {p_value!r}.")
    if isinstance(max_lines, bool) or not isinstance(max_lines, (int, np.integer)) or max_lines < 0:
        raise ValueError(f"max_lines must be a non-negative integer; got {max_lines!r}.")
    known = np.atleast_1d(np.asarray(known, dtype=np.float64)) if np.size(known) else np.zeros(0)
    if known.ndim != 1:
        raise ValueError(f"known must be a sequence of frequencies [Hz]; got shape {known.shape}.")
    known_f = [check_frequency(f, dt, f"known[{i}]") for i, f in enumerate(known)]
    n, df = y.size, 1.0 / (y.size * dt)
    freqs: list[float] = []
    for f0 in known_f:
        freqs.append(refine_frequency(y - fit_sinusoids(y, dt, freqs)[0], dt, f0, df))
    for _ in range(int(max_lines)):
        resid = y - fit_sinusoids(y, dt, freqs)[0]
        f, adj, ratio, _ = _scan(resid, dt, float(p_value))
        if freqs:
            near = np.min(np.abs(f[:, None] - np.asarray(freqs)[None, :]), axis=1) <= _GUARD_BINS * df
            adj[near] = 1.0
        significant = adj < p_value
        if not significant.any():
            break
        # the strongest significant ordinate (a strong line's sidelobes are significant too, and
        # their p-values underflow to 0 like the peak's)
        j = int(np.argmax(np.where(significant, ratio, -np.inf)))
        freqs.append(refine_frequency(resid, dt, f[j], 0.6 * df))
    if len(freqs) > 1:  # one backfitting pass: each line refined without the others
        for i in range(len(freqs)):
            others = freqs[:i] + freqs[i + 1:]
            freqs[i] = refine_frequency(y - fit_sinusoids(y, dt, others)[0], dt, freqs[i], 0.3 * df)
    return _summarise(y, dt, freqs, len(known_f), max(int(_tested(n)[1].sum()), 1))


def _summarise(y, dt: float, freqs, n_known: int, n_tested: int) -> tuple[Line, ...]:
    if not freqs:
        return ()
    part, coef = fit_sinusoids(y, dt, freqs)
    resid = y - part
    f, power = periodogram(resid, dt)
    ref, m, k = _local_reference(power)
    n, t_mid = y.size, 0.5 * (y.size - 1) * dt
    lines = []
    for i, fl in enumerate(freqs):
        a, b = coef[1 + 2 * i], coef[2 + 2 * i]
        amp = float(np.hypot(a, b))
        psd = float(np.exp(np.interp(np.log(fl), np.log(f), np.log(ref))))
        jb = int(np.clip(np.rint(fl * n * dt) - 1, 0, f.size - 1))
        ratio = n * dt * amp**2 / (4 * psd)
        p = float(np.exp(_log_tail(ratio, m[jb], k[jb])))
        known = i < n_known
        p = p if known else min(1.0, n_tested * p)
        phase = float(np.angle(np.exp(1j * (np.arctan2(-b, a) - 2 * np.pi * fl * t_mid))))
        f_se, a_se = line_errors(resid + component(n, dt, fl, a, b), dt, fl, psd)
        lines.append(Line(float(fl), amp, phase, float(ratio), p, f_se, a_se, known))
    return tuple(lines)


def _frequencies(lines, dt: float, name: str = "lines"):
    try:
        items = list(lines)
    except TypeError:
        raise ValueError(f"{name} must be a sequence of Line or frequencies [Hz]; got {lines!r}.") from None
    return [check_frequency(getattr(x, "frequency", x), dt, f"{name}[{i}]") for i, x in enumerate(items)]


def remove_lines(positions, frame_interval, lines) -> np.ndarray:
    """Subtract the least-squares sinusoids at the lines' frequencies from a trace.

    All lines are fitted jointly with the mean (and nothing else), by linear least squares at
    the given frequencies (their amplitudes and phases are refitted); only the sinusoids are
    subtracted, so the mean stays in the trace.

    Each line costs 2 degrees of freedom (3 when its frequency was estimated from the same
    trace): the cleaned trace is the thermal trace minus its projection on 2-3 narrowband
    regressors, which changes any quadratic statistic by O(1/N), so the Gaussian frame
    likelihood of the cleaned trace stays valid to O(1/N). (A spectral fit may instead exclude the
    ordinates around each line: :func:`line_mask`.)

    **Arguments:** `positions` (1-D trace), `frame_interval` [s], `lines`: :class:`Line` objects
    or frequencies [Hz] (each in (0, Nyquist)).

    **Returns:** the cleaned trace (float64 NumPy array, same length).
    """
    y, dt = check_trace(positions, frame_interval)
    freqs = _frequencies(lines, dt)
    return y - fit_sinusoids(y, dt, freqs)[0]


def line_mask(f, lines, frame_interval, n_frames, half_width_bins: float = 2) -> np.ndarray:
    """Boolean mask (True = exclude) of periodogram ordinates within ``half_width_bins`` Fourier
    bins (1/(n_frames dt) each) of any line.

    **Arguments:** `f` [Hz] the periodogram's frequencies; `lines`: :class:`Line` objects or
    frequencies [Hz]; `frame_interval` [s]; `n_frames` the length of the periodogram's record;
    `half_width_bins` (>= 0; the default 2 covers the main lobe of a line between two bins).
    """
    dt = check_positive(frame_interval, "frame_interval", "s")
    if isinstance(n_frames, bool) or not isinstance(n_frames, (int, np.integer)) or n_frames < 2:
        raise ValueError(f"n_frames must be an integer >= 2; got {n_frames!r}.")
    hw = float(half_width_bins)
    if not (np.isfinite(hw) and hw >= 0):
        raise ValueError(f"half_width_bins must be a finite number >= 0; got {half_width_bins!r}.")
    f = np.asarray(f, dtype=np.float64)
    freqs = np.asarray(_frequencies(lines, dt))
    if freqs.size == 0:
        return np.zeros(f.shape, bool)
    return np.any(np.abs(f[..., None] - freqs) <= hw / (n_frames * dt) * (1 + 1e-12), axis=-1)


def excluded_ranges_mask(f, excluded_ranges_Hz, frame_interval) -> np.ndarray:
    """Boolean mask (True = exclude) of frequencies inside any of the user's ranges ``[[a, b], ...]``.

    **Raises:** ``ValueError`` naming ``excluded_ranges_Hz`` unless it is a list of pairs with
    ``0 <= a < b <= fs/2`` [Hz].
    """
    dt = check_positive(frame_interval, "frame_interval", "s")
    nyq = 0.5 / dt
    try:
        r = np.asarray(excluded_ranges_Hz, dtype=np.float64)
    except (TypeError, ValueError):
        raise ValueError("excluded_ranges_Hz must be a list of [a, b] pairs [Hz]; "
                         f"got {excluded_ranges_Hz!r}.") from None
    if r.size == 0:
        return np.zeros(np.shape(f), bool)
    if r.ndim == 1 and r.size == 2:
        r = r[None, :]
    if r.ndim != 2 or r.shape[1] != 2:
        raise ValueError(f"excluded_ranges_Hz must be a list of [a, b] pairs [Hz]; got {excluded_ranges_Hz!r}.")
    for i, (a, b) in enumerate(r.tolist()):
        if not (np.isfinite(a) and np.isfinite(b) and 0.0 <= a < b <= nyq * (1 + 1e-12)):
            raise ValueError(f"excluded_ranges_Hz[{i}] = [{a!r}, {b!r}] must satisfy 0 <= a < b <= "
                             f"{nyq:.6g} Hz (the Nyquist frequency for frame_interval {dt:.6g} s).")
    f = np.asarray(f, dtype=np.float64)
    return np.any((f[..., None] >= r[:, 0]) & (f[..., None] <= r[:, 1]), axis=-1)
