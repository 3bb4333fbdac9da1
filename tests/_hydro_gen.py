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
- :func:`drive_response_d3` is the response of the bead to a fluid (stage) drive,
  Tolic-Norrelykke et al. (2006) eq. (D3) with the bulk friction of eq. (D4), as a complex
  transfer (the amplitude of eq. D3 and the phase of the equation of motion it comes from,
  ``m x'' = -k x - gamma(f) (x' - x_s')``), and :func:`generate_hydro_driven` adds that
  response to a trace of :func:`generate_hydro`: the drive's peak in the recording has the
  amplitude and the phase of eq. (D3). The stage is recorded at the frame times.
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


def drive_response_d3(f, k, radius, eta, rho_f, rho_b):
    """Complex ``x/x_s`` at f [Hz] for a stage moving as ``Re[S e^{+2 pi i f t}]``, bulk.

    In the ``e^{-i w t}`` convention of the paper, ``g = gamma(f)/gamma_0 = 1 + (1 - i)
    sqrt(f/f_nu) - (2i/9) f/f_nu`` (eq. D4) and ``f_m = gamma_0/(2 pi m_bead)``:
    ``x/x_s = -i f g/(f_c - f^2/f_m - i f g)``, whose modulus squared is eq. (D3)'s
    ``f^2 |g|^2/((f_c + f Im g - f^2/f_m)^2 + (f Re g)^2)``; ``e^{+2 pi i f t}`` takes the
    complex conjugate."""
    gamma0, f_nu, _ = _bead(radius, eta, rho_f, rho_b)
    f_m = gamma0 / (2.0 * math.pi * 4.0 / 3.0 * math.pi * radius**3 * rho_b)
    fc = k / (2.0 * math.pi * gamma0)
    s = math.sqrt(f / f_nu)
    g = 1.0 + (1.0 - 1j) * s - 2j / 9.0 * s * s
    return np.conj(-1j * f * g / (fc - f * f / f_m - 1j * f * g))


def generate_hydro_driven(n, fs, k, radius, seed, *, amplitude, frequency, phase=0.3,
                          temperature=295.0, eta=None, rho_f=997.803, rho_b=1050.0,
                          tracking_std=0.0, stage_noise=0.0):
    """``(positions, stage)`` [m]: :func:`generate_hydro` plus the response to a stage drive
    ``amplitude cos(2 pi frequency t_n + phase)`` (:func:`drive_response_d3`), ``t_n = n/fs``
    (an anti-aliased detector samples the position at the frame times); the stage as
    recorded, with white noise of std ``stage_noise`` [m]."""
    eta = 0.957812e-3 if eta is None else eta
    x = generate_hydro(n, fs, k, radius, seed, temperature=temperature, eta=eta, rho_f=rho_f,
                       rho_b=rho_b, tracking_std=tracking_std)
    h = drive_response_d3(frequency, k, radius, eta, rho_f, rho_b)
    drive = amplitude * np.exp(1j * (2.0 * math.pi * frequency * np.arange(n) / fs + phase))
    stage = drive.real + stage_noise * np.random.default_rng([seed, 1]).standard_normal(n)
    return x + (h * drive).real, stage
