r"""A photodiode whose instrument oversamples, low-passes and decimates (anti-aliasing):
:func:`simulate_photodiode` and its FIR filter :func:`antialias_taps`.

The instrument samples the (optionally :class:`PhotodiodeFilter`-ed) position ``M`` times
faster than the output rate ``fs = 1/dt`` (``M = oversample``), instantaneously, applies a
linear-phase windowed-sinc FIR low-pass and keeps every ``M``-th sample. The output is then
neither blurred (no exposure average) nor aliased in its passband, so its PSD there is the
continuous Lorentzian ``2 sigma2 tau / (1 + (2 pi f tau)^2)`` (times ``|H_pd|^2`` with a
photodiode filter) plus the tracking noise ``eps2 dt``.

**Filter (defaults):** cutoff ``0.45 fs`` (``-6 dB`` point), Kaiser window for
``attenuation_db = 100`` dB over a transition band of width ``0.1 fs`` (``0.4 fs`` to
``0.5 fs``). Passband ``f <= 0.4 fs``: amplitude gain within ``1 +- 2e-5`` (measured
1.2e-5; power ``1 +- 4e-5``); stopband ``f >= 0.5 fs``: gain below ``1e-5`` (everything that
could fold onto ``[0, fs/2]`` is removed); gain 0.5 at ``0.45 fs``. Between ``0.4 fs`` and
``0.5 fs`` the gain rolls off: **fit only ``f < 0.4 fs``** (or model the gain with
:func:`antialias_gain`). The filter has
about ``64 M`` taps (``M = 16``: 1029), is centred (zero delay: output sample ``n`` is the
filtered signal at ``t_n = n dt``, like :func:`stage_positions`) and is applied to the whole
record by FFT (no loop over frames); the fast record carries a margin of half the filter
length on both sides, so there are no edge effects.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import jax
import jax.numpy as jnp
import jax.random as jr
import numpy as np

from ..physics import DEFAULT_TEMPERATURE
from ._injections import (
    AbstractInjection,
    HydrodynamicFriction,
    PhotodiodeFilter,
    TimingJitter,
)
from ._instruments import Sensitivity, StageDrive

_INSTANT = 1e-6  # "instantaneous" fast samples: exposure of this fraction of the fast interval


def _check_filter(oversample, cutoff, transition, attenuation_db):
    if isinstance(oversample, bool) or not isinstance(oversample, int | np.integer) or oversample < 2:
        raise ValueError(f"oversample must be an integer >= 2; got oversample = {oversample!r}")
    if not (0.0 < transition and 0.0 < cutoff - transition / 2 and cutoff + transition / 2 <= 0.5):
        raise ValueError(
            "cutoff and transition [units of the output rate fs] must satisfy 0 < cutoff - "
            f"transition/2 and cutoff + transition/2 <= 0.5; got cutoff = {cutoff!r}, "
            f"transition = {transition!r}")
    if not attenuation_db > 21.0:
        raise ValueError(f"attenuation_db must be > 21 dB; got {attenuation_db!r}")


def antialias_taps(oversample: int, cutoff: float = 0.45, transition: float = 0.1,
                   attenuation_db: float = 100.0) -> np.ndarray:
    """Taps of the anti-aliasing FIR at the fast rate (odd length ``2K + 1``, symmetric, unit
    DC gain; NumPy float64): Kaiser-windowed sinc with cut-off `cutoff` and transition width
    `transition`, both in units of the output rate ``fs`` (the fast rate is ``oversample fs``),
    window parameter and length from Kaiser's formulas for `attenuation_db` (the stopband
    attenuation and the passband ripple ``10^(-attenuation_db/20)``)."""
    _check_filter(oversample, cutoff, transition, attenuation_db)
    a = float(attenuation_db)
    beta = 0.1102 * (a - 8.7) if a > 50 else 0.5842 * (a - 21) ** 0.4 + 0.07886 * (a - 21)
    width = 2.0 * np.pi * transition / oversample  # rad per fast sample
    n = int(math.ceil((a - 7.95) / (2.285 * width))) + 1
    half = n // 2 + 1
    j = np.arange(-half, half + 1)
    fc = cutoff / oversample  # cycles per fast sample
    h = 2.0 * fc * np.sinc(2.0 * fc * j) * np.kaiser(j.size, beta)
    return h / h.sum()


def antialias_gain(f, frame_interval, oversample: int = 16, cutoff: float = 0.45,
                   transition: float = 0.1, attenuation_db: float = 100.0):
    """Real amplitude gain of the anti-aliasing filter at frequencies `f` [Hz] (the filter is
    centred and symmetric, so it has no phase); the PSD is multiplied by its square."""
    h = antialias_taps(oversample, cutoff, transition, attenuation_db)
    half = h.size // 2
    dtf = float(frame_interval) / oversample
    f = np.asarray(f, dtype=np.float64)
    j = np.arange(-half, half + 1)
    return np.cos(2.0 * np.pi * f[..., None] * dtf * j) @ h


def _fft_len(n):
    """Smallest 2^a 3^b >= n (fast FFT sizes)."""
    best = 1 << (n - 1).bit_length()
    p3 = 3
    while p3 < best:
        best = min(best, p3 * (1 << (-(-n // p3) - 1).bit_length()))
        p3 *= 3
    return best


def _fir_decimate(x, h, oversample, n_frames):
    """Centred FIR of `x` (..., n_fast) by the symmetric taps `h`, then every `oversample`-th
    sample: output n is centred on fast sample K + n oversample (K = len(h)//2)."""
    n_fast = x.shape[-1]
    half = h.size // 2
    size = _fft_len(n_fast)  # circular wrap only touches the first 2K outputs, never used
    hf = jnp.fft.rfft(jnp.asarray(h, x.dtype), size)
    y = jnp.fft.irfft(jnp.fft.rfft(x, size) * hf, size)
    return y[..., 2 * half : 2 * half + (n_frames - 1) * oversample + 1 : oversample]


def simulate_photodiode(
    k,
    gamma,
    frame_interval,
    n_frames: int,
    *,
    key,
    oversample: int = 16,
    cutoff: float = 0.45,
    transition: float = 0.1,
    attenuation_db: float = 100.0,
    temperature=DEFAULT_TEMPERATURE,
    n_traces: int = 1,
    tracking_std=0.0,
    injections: Sequence = (),
    dtype=None,
):
    r"""Frames of an oversampling, anti-aliasing photodiode instrument (module docstring).

    The position is simulated exactly (``simulate(method="exact_frames")``, or ``"spectral"``
    with :class:`HydrodynamicFriction`) at the fast interval ``dt / oversample`` with
    instantaneous samples (an exposure of ``1e-6`` of the fast interval), filtered by
    :func:`antialias_taps` and decimated. Effects acting on the continuous signal run at the
    fast rate: :class:`PhotodiodeFilter`, :class:`HydrodynamicFriction` and
    :class:`StageDrive` (its response at the output is also multiplied by
    :func:`antialias_gain` at ``f_d``, ``1 +- 2e-5`` in the passband). At the output rate come,
    in this order: white tracking noise ``tracking_std`` [m] (i.i.d. per output frame, so the
    PSD floor is ``eps2 dt``), the other additive injections (drift, :class:`TrackingNoise`)
    at ``t_n = n dt``, and :class:`Sensitivity` (volts).

    **Arguments:** `k` [N/m], `gamma` [N s/m], `frame_interval` dt [s] of the output,
    `temperature` [K] and `tracking_std` [m] broadcast to a grid ``G`` as in
    :func:`simulate`; `n_frames` output frames per trace; `key` a single JAX PRNG key;
    `oversample` M (int >= 2; 8-32 is typical); `cutoff`, `transition` [units of fs] and
    `attenuation_db` of the filter; `n_traces`; `injections`; `dtype`.

    **Returns:** frames [m] (or [V] with :class:`Sensitivity`) of shape
    ``(*G, n_traces, n_frames)``; frame ``n`` is the filtered signal at ``t = n dt``.

    **Raises:** ``ValueError`` for a bad filter, :class:`TimingJitter`, or the arguments
    :func:`simulate` refuses. Cost: ``M`` exact fast frames plus an FFT per output frame.
    """
    from ._simulate import simulate
    from ._validate import as_keys as _as_keys

    h = antialias_taps(oversample, cutoff, transition, attenuation_db)
    half = h.size // 2
    if isinstance(n_frames, bool) or not isinstance(n_frames, int | np.integer) or n_frames < 1:
        raise ValueError(f"n_frames must be an integer >= 1; got n_frames = {n_frames!r}")
    if np.ndim(frame_interval):
        raise ValueError("simulate_photodiode needs a scalar frame_interval (the filter is "
                         f"shared); got shape {np.shape(frame_interval)}")
    dt = float(frame_interval)
    if not (np.isfinite(dt) and dt > 0):
        raise ValueError(f"frame_interval must be finite and > 0 s; got {frame_interval!r} s")
    h_fast = dt / oversample
    fast, slow, sens = _split(injections, half * h_fast)  # the fast record starts at -K h_fast
    method = "spectral" if any(isinstance(i, HydrodynamicFriction) for i in fast) else "exact_frames"
    n_fast = (n_frames - 1) * oversample + 1 + 2 * half
    eps = np.asarray(tracking_std, dtype=np.float64)
    if np.any(~np.isfinite(eps) | (eps < 0)):
        raise ValueError(f"tracking_std must be finite and >= 0 m; got {tracking_std!r} m")
    key = _as_keys(key)
    if key.ndim:
        raise ValueError(f"simulate_photodiode takes a single PRNG key; got keys of shape {key.shape}")
    k_sim, k_out = jr.split(key)
    x = simulate(k, gamma, _INSTANT * h_fast, h_fast, n_fast, key=k_sim, temperature=temperature,
                 n_traces=n_traces, method=method, injections=tuple(fast), dtype=dtype)
    y = _fir_decimate(x, h, oversample, n_frames)
    return _output_rate(y, k_out, eps, slow, sens, dt)


def _split(injections, lead):
    """(fast, slow, sensitivity) injections: those acting on the continuous signal run at the
    fast rate (a drive's phase moved to the fast record's start, ``-lead`` [s]), the additive
    ones and the volts at the output rate."""
    if any(isinstance(i, TimingJitter) for i in injections):
        raise ValueError("simulate_photodiode does not support TimingJitter (regular samples)")
    fast_types = (PhotodiodeFilter, HydrodynamicFriction, StageDrive)
    fast = []
    for inj in injections:
        if isinstance(inj, StageDrive):
            ph = inj.phase - 2.0 * np.pi * inj.frequency * lead
            fast.append(StageDrive(inj.amplitude, inj.frequency, ph, inj.mode))
        elif isinstance(inj, fast_types):
            fast.append(inj)
    slow = [i for i in injections if not isinstance(i, fast_types + (Sensitivity,))]
    sens = [i for i in injections if isinstance(i, Sensitivity)]
    if len(sens) > 1:
        raise ValueError("at most one Sensitivity may be given in injections")
    for inj in slow:
        if not isinstance(inj, AbstractInjection):
            raise ValueError(f"unsupported injection for simulate_photodiode: {inj!r}")
    return fast, slow, sens


def _output_rate(y, key, eps, slow, sens, dt):
    """Tracking noise (grid-broadcast std [m]), the additive injections at ``t_n = n dt`` (each
    grid point with its own key) and the volts scaling, on the decimated frames."""
    grid = np.broadcast_shapes(y.shape[:-2], eps.shape)
    y = jnp.broadcast_to(y, grid + y.shape[-2:])
    keys = jr.split(key, len(slow) + 1)
    if eps.any():
        std = jnp.asarray(np.broadcast_to(eps, grid), y.dtype)[..., None, None]
        y = y + std * jr.normal(keys[0], y.shape, y.dtype)
    if slow:
        g_n = int(np.prod(grid, dtype=np.int64))
        times = jnp.asarray(np.arange(y.shape[-1]) * dt, y.dtype)
        yg = y.reshape((g_n,) + y.shape[-2:])
        for i, inj in enumerate(slow):
            ks = jr.split(keys[i + 1], g_n)
            yg = jax.vmap(lambda xx, kk, inj=inj: inj.apply(xx, times, kk))(yg, ks)
        y = yg.reshape(y.shape)
    if sens:
        y = y / sens[0].rd.astype(y.dtype)
    return y
