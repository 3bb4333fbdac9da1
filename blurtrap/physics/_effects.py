r"""Pure spectral building blocks of the physical effects (DESIGN section 3 and item 11).

All spectra are two-sided; discrete ones integrate to the variance over (-fs/2, fs/2).

- ``drift_psd``: a random-walk drift (stage/laser) sampled every dt,
  ``P(f) = D_d dt^2 / (2 sin^2(pi f dt))`` (increments of variance 2 D_d dt per frame).
- ``line_psd``: a narrow spectral line (mains, vibration): a sinusoid of amplitude A at f0
  seen through the periodogram is a Lorentzian of width ``line_width`` [Hz] with total
  power A^2/2 (split between +-f0).
- ``photodiode_transfer``: Berg-Sorensen et al. (2003) filter of a silicon photodiode,
  ``|H|^2 = a^2 + (1 - a^2) / (1 + (f/f_3dB)^2)``.
- ``hydro_lorentzian``: frequency-dependent Stokes friction (Berg-Sorensen & Flyvbjerg 2004,
  eq. 12) for a sphere of radius R: with ``f_nu = nu/(pi R^2)`` and
  ``f_m = gamma0/(2 pi m*)``, ``m* = m_bead + 2/3 pi rho_fluid R^3``,
  ``P(f) = D/(2 pi^2) (1 + sqrt(f/f_nu)) / ((f_c - f^(3/2)/sqrt(f_nu) - f^2/f_m)^2
  + (f + f^(3/2)/sqrt(f_nu))^2)``.
- ``faxen_factor``: Faxen's law for motion parallel to a wall at height h (centre),
  ``gamma/gamma_0 = 1 / (1 - 9/16 x + 1/8 x^3 - 45/256 x^4 - 1/16 x^5)``, x = R/h.
- ``water_viscosity``: Vogel-type fit to the IAPWS data (0-100 C, ~1 %):
  ``eta(T) = 2.414e-5 * 10^(247.8/(T - 140))`` Pa s.
- ``fold_sum``: aliasing of a continuous PSD with an exact 1/f^2 tail:
  ``sum_n P(f + n fs) = sum_{|n|<=N} P(f + n fs) + A [pi^2/(fs^2 sin^2(pi f/fs)) -
  sum_{|n|<=N} 1/(f + n fs)^2]`` where ``A = lim f^2 P(f)``.
"""

from __future__ import annotations

import jax.numpy as jnp


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


def hydro_lorentzian(f, diffusion, corner_frequency, f_nu, f_m):
    """BS&F 2004 hydrodynamically correct two-sided PSD of the true position [m^2/Hz]."""
    af = jnp.abs(f)
    r = jnp.sqrt(af / f_nu)
    re = corner_frequency - af * r - af * af / f_m
    im = af + af * r
    return diffusion / (2.0 * jnp.pi**2) * (1.0 + r) / (re * re + im * im)


def faxen_factor(radius, height):
    """gamma(h)/gamma_bulk for motion parallel to a surface (Faxen)."""
    x = radius / height
    return 1.0 / (1.0 - 9.0 / 16.0 * x + x**3 / 8.0 - 45.0 / 256.0 * x**4 - x**5 / 16.0)


def water_viscosity(temperature):
    """Viscosity of water [Pa s] at temperature [K] (Vogel fit, ~1 % over 273-373 K)."""
    return 2.414e-5 * 10.0 ** (247.8 / (temperature - 140.0))


def fold_sum(psd_fn, f, fs, n_alias: int, tail_coeff=0.0):
    """``sum_n psd_fn(f + n fs)`` over all n: explicit for |n| <= N, plus the exact sum of an
    ``A/f^2`` tail (``tail_coeff = A``), so detector filters without blur converge."""
    n = jnp.arange(-n_alias, n_alias + 1, dtype=f.dtype)
    ff = f[..., None] + n * fs[..., None]
    explicit = jnp.sum(psd_fn(ff), axis=-1)
    inv2 = jnp.sum(1.0 / (ff * ff), axis=-1)
    total_inv2 = jnp.pi**2 / (fs**2 * jnp.sin(jnp.pi * f / fs) ** 2)
    return explicit + tail_coeff * (total_inv2 - inv2)
