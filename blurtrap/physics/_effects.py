r"""Pure spectral building blocks of the physical effects (DESIGN section 3 and item 11).

All spectra are two-sided; discrete ones integrate to the variance over (-fs/2, fs/2).

- ``drift_psd``: a random-walk drift (stage/laser) sampled every dt,
  ``P(f) = D_d dt^2 / (2 sin^2(pi f dt))`` (increments of variance 2 D_d dt per frame).
- ``line_psd``: a narrow spectral line (mains, vibration): a sinusoid of amplitude A at f0
  seen through the periodogram is a Lorentzian of width ``line_width`` [Hz] with total
  power A^2/2 (split between +-f0).
- ``photodiode_transfer``: Berg-Sorensen et al. (2003) filter of a silicon photodiode,
  ``|H|^2 = a^2 + (1 - a^2) / (1 + (f/f_3dB)^2)``.
- ``hydro_lorentzian``, ``faxen_factor``, ``water_viscosity``: hydrodynamics and water,
  written once in ``blurtrap.physics._hydro`` and re-exported here under their old names
  (``water_viscosity`` is now the IAPWS 2008 formulation, not the former Vogel fit).
- ``fold_sum``: aliasing of a continuous PSD with an exact 1/f^2 tail:
  ``sum_n P(f + n fs) = sum_{|n|<=N} P(f + n fs) + A [pi^2/(fs^2 sin^2(pi f/fs)) -
  sum_{|n|<=N} 1/(f + n fs)^2]`` where ``A = lim f^2 P(f)``.
"""

from __future__ import annotations

import jax.numpy as jnp

from ._hydro import faxen_factor as faxen_factor
from ._hydro import hydro_lorentzian as hydro_lorentzian
from ._hydro import water_viscosity as water_viscosity


def drift_psd(f, frame_interval, drift_diffusion):
    """Discrete two-sided PSD of a sampled random-walk drift [m^2/Hz]."""
    s2 = jnp.sin(jnp.pi * f * frame_interval) ** 2
    return drift_diffusion * frame_interval**2 / (2.0 * jnp.maximum(s2, 1e-300))


def line_psd(f, line_frequency, line_amplitude, line_width):
    """Two-sided PSD of a narrow line (power A^2/2 shared by +-f0) [m^2/Hz]."""
    hw = 0.5 * line_width
    lor = lambda x: hw / jnp.pi / (x * x + hw * hw)  # noqa: E731 - unit-area Lorentzian
    return 0.25 * line_amplitude**2 * (lor(f - line_frequency) + lor(f + line_frequency))


def photodiode_transfer(f, f3db, alpha):
    """Berg-Sorensen photodiode filter ``|H(f)|^2`` (alpha = fraction of fast response)."""
    return alpha**2 + (1.0 - alpha**2) / (1.0 + (f / f3db) ** 2)


def fold_sum(psd_fn, f, fs, n_alias: int, tail_coeff=0.0):
    """``sum_n psd_fn(f + n fs)`` over all n: explicit for |n| <= N, plus the exact sum of an
    ``A/f^2`` tail (``tail_coeff = A``), so detector filters without blur converge."""
    n = jnp.arange(-n_alias, n_alias + 1, dtype=f.dtype)
    ff = f[..., None] + n * fs[..., None]
    explicit = jnp.sum(psd_fn(ff), axis=-1)
    inv2 = jnp.sum(1.0 / (ff * ff), axis=-1)
    total_inv2 = jnp.pi**2 / (fs**2 * jnp.sin(jnp.pi * f / fs) ** 2)
    return explicit + tail_coeff * (total_inv2 - inv2)
