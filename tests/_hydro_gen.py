"""Independent NumPy reference for the frequency-dependent friction of a bead (no blurtrap code).

- :func:`hydro_psd_bsf` is Berg-Sorensen & Flyvbjerg (2004), eq. (12), bulk, two-sided
  (``D/(2 pi^2)`` in front, so that it integrates to ``kT/k`` over all f), with
  ``f_nu = eta/(pi rho_f R^2)``, ``f_m = gamma_0/(2 pi m*)``, ``m* = m_bead + (2/3) pi rho_f R^3``.
- :func:`hydro_psd_d6` is Tolic-Norrelykke et al. (2006), eqs. (D2) and (D6) (near a wall), in
  mpmath complex arithmetic, same normalisation.
- :func:`generate_hydro` draws traces with that PSD by spectral synthesis on a circulant of
  length ``2 N``: complex Gaussian Fourier coefficients of variance ``M fs P(f_j)``, the
  inverse FFT, the real part times sqrt(2), the first ``N`` samples. What an anti-aliased
  photodiode records: the true position's spectrum below Nyquist, unfolded, no exposure
  average, plus white tracking noise.
"""

from __future__ import annotations

import math

import mpmath
import numpy as np

BOLTZMANN = 1.380649e-23


def _bead(radius, eta, rho_f, rho_b):
    gamma0 = 6.0 * math.pi * eta * radius
    f_nu = eta / (math.pi * rho_f * radius**2)
    m_star = 4.0 / 3.0 * math.pi * radius**3 * rho_b + 2.0 / 3.0 * math.pi * rho_f * radius**3
    return gamma0, f_nu, gamma0 / (2.0 * math.pi * m_star)


def hydro_psd_bsf(f, k, radius, temperature, eta, rho_f, rho_b):
    """Two-sided PSD [m^2/Hz] in bulk, Berg-Sorensen & Flyvbjerg (2004) eq. (12)."""
    gamma0, f_nu, f_m = _bead(radius, eta, rho_f, rho_b)
    d = BOLTZMANN * temperature / gamma0
    fc = k / (2.0 * math.pi * gamma0)
    f = np.abs(np.asarray(f, dtype=float))
    r = np.sqrt(f / f_nu)
    num = 1.0 + r
    den = (fc - f * r - f**2 / f_m) ** 2 + (f + f * r) ** 2
    return d / (2.0 * math.pi**2) * num / den


def hydro_psd_d6(f, k, radius, temperature, eta, rho_f, rho_b, distance):
    """Two-sided PSD [m^2/Hz] near a wall, Tolic-Norrelykke et al. (2006) (D2) with (D6).
    Here ``gamma(f)`` already holds the fluid's added mass (its ``-2i/9 f/f_nu`` term), so
    ``f_m = gamma_0/(2 pi m_bead)`` with the bead's mass alone (their footnote 30)."""
    mpmath.mp.dps = 30
    gamma0, f_nu, _ = _bead(radius, eta, rho_f, rho_b)
    f_m = gamma0 / (2.0 * math.pi * 4.0 / 3.0 * math.pi * radius**3 * rho_b)
    d = BOLTZMANN * temperature / gamma0
    fc = k / (2.0 * math.pi * gamma0)
    out = []
    for fi in np.atleast_1d(f):
        fi = mpmath.mpf(abs(float(fi)))
        s = mpmath.sqrt(fi / f_nu)
        bulk = 1 + (1 - 1j) * s - 2j / 9 * fi / f_nu
        eps = (2 * distance - radius) / radius * s
        den = 1 - 9 / 16 * radius / distance * (
            1 - (1 - 1j) / 3 * s + 2j / 9 * fi / f_nu - 4 / 3 * (1 - mpmath.exp(-(1 - 1j) * eps)))
        g = bulk / den
        p = d / (2 * mpmath.pi**2) * g.real / (
            (fc + fi * g.imag - fi**2 / f_m) ** 2 + (fi * g.real) ** 2)
        out.append(float(p))
    return np.array(out)


def generate_hydro(n, fs, k, radius, seed, *, temperature=295.0, eta=None, rho_f=997.803,
                   rho_b=1050.0, tracking_std=0.0):
    """(n,) positions [m] sampled at ``fs`` [Hz] by an anti-aliased detector (module
    docstring); ``eta`` default: water at 295 K (0.9578 mPa s, IAPWS 2008)."""
    eta = 0.957812e-3 if eta is None else eta
    m = 2 * n
    f = np.fft.fftfreq(m, d=1.0 / fs)
    p = hydro_psd_bsf(f, k, radius, temperature, eta, rho_f, rho_b)
    p[0] = 0.0  # zero mean
    rng = np.random.default_rng(seed)
    z = (rng.standard_normal(m) + 1j * rng.standard_normal(m)) / math.sqrt(2.0)
    x = math.sqrt(2.0) * np.fft.ifft(np.sqrt(m * fs * p) * z).real[:n]
    return x + tracking_std * rng.standard_normal(n)
