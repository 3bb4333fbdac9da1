"""Fitting a stored power spectrum (``bt.fit_psd``): for users who kept the averaged spectrum
(frequencies, power, number of averaged blocks or points) but not the trace.

The ordinates are Gamma distributed with shape ``n`` (the number of averaged periodogram
ordinates behind each) around the model spectrum, exactly as in the blocked-PSD method
(paper appendix C): the same objective, model and goodness of fit as
``calibrate(method="psd")``. When the frequencies lie on the Fourier grid ``j / (M dt)`` of
blocks of ``M`` frames (a plain block average, no window), the closed-form models use the
exact expected periodogram of such a block (finite-block leakage included); otherwise (log
binned or windowed spectra) the discrete spectrum ``P_d(f)``.
"""

from __future__ import annotations

import math
import types

import jax.numpy as jnp
import numpy as np

from .._config import float64_scope
from .._constants import BOLTZMANN, DEFAULT_TEMPERATURE
from ._fit import fit_ml
from ._models import get_model
from ._problems import SpectralArgs, make_layout, rec_meta, spectral_model_psd, spectral_nll
from ._result import CalibrationResult


def _array(name, value, shape=None, positive=True):
    a = np.asarray(value, dtype=float)
    if shape is not None:
        a = np.broadcast_to(a, shape).copy() if a.ndim == 0 else a
        if a.shape != shape:
            raise ValueError(f"{name} must have the shape of frequencies {shape}; got {a.shape}")
    if a.ndim != 1 or a.size < 4:
        raise ValueError(f"{name} must be a 1-d array of at least 4 values; got shape {a.shape}")
    bad = ~np.isfinite(a) | ((a <= 0) if positive else False)
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        raise ValueError(f"{name}[{i}] = {a[i]!r}: expected finite values > 0")
    return a


def _start(f, p, dt, temp, noise):
    """Closed-form start values from the spectrum's plateau, half-power point and floor."""
    p0 = float(np.median(p[: max(3, f.size // 50)]))
    below = np.flatnonzero(p < 0.5 * p0)
    fc = float(f[below[0]]) if below.size else 0.25 / dt
    d = 2.0 * math.pi**2 * fc**2 * p0  # two-sided Lorentzian plateau D / (2 pi^2 fc^2)
    gamma = BOLTZMANN * temp / d
    vec = [2.0 * math.pi * fc * gamma, gamma]
    if noise:
        vec.append(max(0.05 * float(np.min(p)) / dt, 1e-30))
    return vec


_EXTRA_START = {"f3db": lambda dt: min(0.25 / dt, 8000.0), "diode_alpha": lambda dt: 0.3,
                "rise_fraction": lambda dt: 0.1}


def _grid_block(f, dt):
    """Frames per block M when every frequency is a multiple of 1/(M dt), else None."""
    m = round(1.0 / (dt * float(np.min(np.diff(f)))))
    j = f * dt * m
    return m if m >= 4 and np.allclose(j, np.round(j), atol=1e-6) else None


@float64_scope
def fit_psd(frequencies, power, *, frame_interval, exposure, n_blocks=1,
            temperature=DEFAULT_TEMPERATURE, onesided=False, model=None, f_range=None,
            excluded_ranges=None, block_frames=None) -> CalibrationResult:
    """k, gamma, eps^2 from a stored, averaged power spectrum.

    **Arguments:**

    - `frequencies` [Hz], `power` [m^2/Hz]: the ordinates (positive frequencies below
      Nyquist). blurtrap's convention is the two-sided density (the periodogram
      ``|FFT|^2 dt / M``); `onesided=True` for a one-sided spectrum (twice that, as pylake
      and most lab software store it).
    - `n_blocks`: how many periodogram ordinates were averaged into each value (blocks x
      points per bin): a number or one per frequency.
    - `frame_interval`, `exposure` [s], `temperature` [K]: of the recording.
    - `model`: as in ``calibrate`` (default ``"standard"``).
    - `f_range`, `excluded_ranges`: the band fitted and bands left out [Hz].
    - `block_frames`: frames per block ``M`` (default: inferred when the frequencies lie on
      the grid ``j / (M dt)``).
    """
    f = _array("frequencies", frequencies)
    p = _array("power", power, f.shape)
    nb = _array("n_blocks", n_blocks, f.shape)
    dt, w = float(frame_interval), float(exposure)
    if not (dt > 0 and 0 <= w <= dt * (1 + 1e-9)):
        raise ValueError(f"need frame_interval > 0 and 0 <= exposure <= frame_interval (s); "
                         f"got {frame_interval!r}, {exposure!r}")
    if np.any(np.diff(f) <= 0) or f[-1] > 0.5 / dt * (1 + 1e-9):
        raise ValueError(f"frequencies must increase and end at or below Nyquist "
                         f"{0.5 / dt:g} Hz; got {f[0]:g}..{f[-1]:g} Hz")
    if onesided:
        p = p / 2.0
    weight = nb.copy()
    if f_range is not None:
        lo, hi = (float(v) for v in f_range)
        weight = np.where((f >= lo) & (f <= hi), weight, 0.0)
    for a, b in excluded_ranges or ():
        weight = np.where((f >= float(a)) & (f <= float(b)), 0.0, weight)
    if not np.any(weight > 0):
        raise ValueError("f_range and excluded_ranges leave no frequencies to fit")
    mdl = get_model(model)
    rec = types.SimpleNamespace(frame_interval=dt, exposure=w, temperature=float(temperature),
                                laser_power=None, name=None, n_frames=0)
    layout = make_layout([rec], "shared", mdl.noise, tuple(q.name for q in mdl.extra_params))
    if block_frames is None:
        block_frames = _grid_block(f, dt)
    use_block = block_frames is not None and mdl.closed_form and mdl.alias
    args = SpectralArgs(
        layout=layout, model=mdl, meta=rec_meta([rec]), f=jnp.asarray(f[None]),
        s2=jnp.asarray(np.sin(np.pi * f * dt)[None] ** 2), power=jnp.asarray(p[None]),
        weight=jnp.asarray(weight[None]), log_ref=jnp.asarray(math.log(float(np.mean(p)))),
        block_len=jnp.asarray([float(block_frames or 0)]) if use_block else None)
    vec = _start(f, p, dt, float(temperature), mdl.noise)
    from ._assemble import _assemble
    from ._refusals import _check_fit
    from ._spectral import spectral_gof

    for name in layout.extra_names:
        if name not in _EXTRA_START:
            raise ValueError(f"fit_psd: effect parameter {name!r} is not supported for a "
                             f"stored spectrum (supported: {sorted(_EXTRA_START)})")
        vec.append(_EXTRA_START[name](dt))
    out = fit_ml(spectral_nll, jnp.asarray(np.array(vec)), args)
    _check_fit(out, layout.names, "psd (stored)")
    ratio = np.asarray(args.power / spectral_model_psd(out.value, args))
    gof = spectral_gof(ratio, np.asarray(args.weight), len(layout.names))
    notes = [f"stored spectrum: {int(np.sum(weight > 0))} ordinates, "
             + ("exact expected periodogram of blocks of "
                f"{block_frames} frames" if use_block else "model P_d(f)")]
    rec.n_frames = int(round(float(np.sum(nb)) * 2))
    return _assemble([rec], layout, mdl, "psd (stored)", out.value, out.cov, gof, notes,
                     {"f": f, "ratio": ratio[0], "weight": weight}, at_bound=out.at_bound,
                     conditional=out.conditional)
