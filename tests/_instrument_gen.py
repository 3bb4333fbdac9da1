"""Independent NumPy generator of instrument data for end-to-end tests (no blurtrap code).

:func:`generate` draws exact Ornstein-Uhlenbeck paths on a fine uniform grid,
``x_{i+1} = x_i e^{-h/tau} + sqrt(kT/k (1 - e^{-2h/tau})) xi_i`` (``tau = gamma/k``; the
recursion runs in blocks of 256 steps as a matrix product, vectorised over traces), starting
in the stationary law, and turns them into what an instrument records:

- a camera (``anti_aliasing=False``): frame ``n`` starts at ``t_n = n dt`` and is the
  trapezoid average of the fine points over ``[t_n, t_n + W]`` (``substeps`` fine steps per
  frame interval; relative variance bias about ``alpha / (6 n_W^2 S(alpha))``, ``n_W`` the
  fine steps per exposure: 1e-4 at alpha = 1, n_W = 32);
- an anti-aliasing photodiode (``anti_aliasing=True``): instantaneous samples every
  ``dt / oversample``, a Kaiser-windowed-sinc FIR (cut-off 0.45 fs, transition 0.4-0.5 fs,
  100 dB; zero-phase, centred) and every ``oversample``-th sample kept: sample ``n`` is the
  filtered position at ``t_n = n dt``; flat to ~1e-5 below 0.4 fs, nothing folded.

A sinusoidal stage drive ``x_s(t) = A sin(2 pi f_d t + phi)`` enters on the same fine grid
before the averaging / filtering: ``mode="fluid"`` adds the bead's exact steady-state
response ``Im[A H e^{i(2 pi f_d t + phi)}]``, ``H = i f_d / (f_c + i f_d)``,
``f_c = k / (2 pi gamma)`` (the stage moves the fluid; trap and detector fixed);
``mode="additive"`` adds ``x_s(t)`` itself (the trace contains the stage motion). The
recorded stage positions are ``x_s(t_n)``, instantaneous.

Then white tracking noise ``tracking_std`` [m] is added per frame, and with `volts_per_m`
the output is ``x [m] * volts_per_m`` (``volts_per_m = 1 / Rd``, Rd in m/V).
"""

from __future__ import annotations

import math

import numpy as np

BOLTZMANN = 1.380649e-23  # J/K (exact, SI 2019)
_BLOCK = 256


def _ou_paths(rng, n_traces, n_points, c, s, sigma):
    """(n_traces, n_points) exact OU samples: stationary start, x' = c x + s xi."""
    out = np.empty((n_traces, n_points))
    out[:, 0] = sigma * rng.standard_normal(n_traces)
    i = np.arange(_BLOCK)
    # x_{b+i+1} = c^{i+1} x_b + sum_{j<=i} c^{i-j} s xi_{b+j}
    lower = np.where(i[:, None] >= i[None, :], c ** np.maximum(i[:, None] - i[None, :], 0), 0.0)
    powers = c ** (i + 1)
    start = 0
    while start < n_points - 1:
        m = min(_BLOCK, n_points - 1 - start)
        xi = rng.standard_normal((n_traces, m))
        out[:, start + 1 : start + 1 + m] = (out[:, start : start + 1] * powers[:m]
                                             + s * xi @ lower[:m, :m].T)
        start += m
    return out


def kaiser_lowpass(oversample, cutoff=0.45, transition=0.1, attenuation_db=100.0):
    """Symmetric, unit-DC-gain Kaiser-windowed sinc taps at the fast rate (cut-off and
    transition in units of the output rate); Kaiser's formulas for beta and the length."""
    beta = 0.1102 * (attenuation_db - 8.7)
    n = int(math.ceil((attenuation_db - 7.95) / (2.285 * 2 * np.pi * transition / oversample))) + 1
    half = n // 2 + 1
    j = np.arange(-half, half + 1)
    taps = np.sinc(2 * cutoff / oversample * j) * np.kaiser(2 * half + 1, beta)
    return taps / taps.sum()


def _drive_fine(drive, k, gamma, t):
    """The drive's term on the fine grid [m]: exact steady-state response (fluid) or the
    stage motion itself (additive)."""
    amp, freq = float(drive["amplitude_m"]), float(drive["frequency_Hz"])
    phase = float(drive.get("phase", 0.0))
    mode = drive.get("mode", "fluid")
    if mode == "fluid":
        fc = k / (2 * np.pi * gamma)
        resp = 1j * freq / (fc + 1j * freq)
    elif mode == "additive":
        resp = 1.0 + 0j
    else:
        raise ValueError(f"drive mode must be 'fluid' or 'additive'; got {mode!r}")
    return np.imag(amp * resp * np.exp(1j * (2 * np.pi * freq * t + phase)))


def generate(k, gamma, frame_interval, exposure, n_frames, seed, *, temperature=296.15,
             n_traces=1, tracking_std=0.0, drive=None, anti_aliasing=False, oversample=16,
             volts_per_m=None, substeps=64):
    """Instrument frames from exact OU paths (module docstring). SI units throughout.

    - `k` [N/m], `gamma` [N s/m], `frame_interval` dt [s], `exposure` W [s] (0 < W <= dt;
      ignored, may be ``None``, with `anti_aliasing`), `n_frames`, `seed` (int, for
      ``numpy.random.default_rng``), `temperature` [K], `n_traces`.
    - `tracking_std`: white noise std [m] added per frame (before the volts scaling).
    - `drive`: ``None`` or a dict ``{"amplitude_m": A, "frequency_Hz": f_d, "phase": phi
      (rad, default 0), "mode": "fluid" | "additive" (default "fluid")}``.
    - `anti_aliasing`: photodiode path (instantaneous samples every dt/oversample, FIR,
      decimation) instead of the camera's exposure average.
    - `volts_per_m`: ``None`` (output in m) or 1/Rd [V/m] (output in V).
    - `substeps`: camera path: fine steps per frame interval; ``substeps * W / dt`` must be
      an integer (the fine steps per exposure).

    Returns ``(positions, stage)``: positions shape ``(n_traces, n_frames)`` [m or V], stage
    positions ``x_s(n dt)`` [m] shape ``(n_frames,)`` or ``None`` without a drive.
    """
    rng = np.random.default_rng(seed)
    dt = float(frame_interval)
    sigma = math.sqrt(BOLTZMANN * temperature / k)
    tau = gamma / k
    if anti_aliasing:
        taps = kaiser_lowpass(oversample)
        half = taps.size // 2
        h = dt / oversample
        n_fine = (n_frames - 1) * oversample + 1 + 2 * half
        t = (np.arange(n_fine) - half) * h
    else:
        n_w = substeps * float(exposure) / dt
        if not (abs(n_w - round(n_w)) < 1e-6 and 1 <= round(n_w) <= substeps):
            raise ValueError(f"substeps * exposure / frame_interval must be an integer in "
                             f"[1, substeps]; got {n_w!r}")
        n_w = round(n_w)
        h = dt / substeps
        n_fine = n_frames * substeps + 1
        t = np.arange(n_fine) * h
    c = math.exp(-h / tau)
    x = _ou_paths(rng, n_traces, n_fine, c, sigma * math.sqrt(-math.expm1(-2 * h / tau)), sigma)
    if drive is not None:
        x = x + _drive_fine(drive, k, gamma, t)
    if anti_aliasing:
        size = 1 << (n_fine - 1).bit_length()
        full = np.fft.irfft(np.fft.rfft(x, size) * np.fft.rfft(taps, size), size)
        frames = full[:, 2 * half : 2 * half + (n_frames - 1) * oversample + 1 : oversample]
    else:
        wts = np.full(n_w + 1, 1.0)
        wts[[0, -1]] = 0.5
        wts /= n_w
        idx = np.arange(n_frames)[:, None] * substeps + np.arange(n_w + 1)[None, :]
        frames = x[:, idx] @ wts
    frames = frames + tracking_std * rng.standard_normal(frames.shape)
    if volts_per_m is not None:
        frames = frames * volts_per_m
    stage = None
    if drive is not None:
        tn = np.arange(n_frames) * dt
        stage = float(drive["amplitude_m"]) * np.sin(
            2 * np.pi * float(drive["frequency_Hz"]) * tn + float(drive.get("phase", 0.0)))
    return frames, stage
