"""Independent NumPy reference for a bead near a plane wall, driven by the stage (no blurtrap
code): Tolic-Norrelykke, Schaffer, Howard, Pavone, Julicher & Flyvbjerg (2006), Rev. Sci.
Instrum. 77, 103101, appendix D.

In the paper's ``e^{-i w t}`` convention, with ``gamma_0 = 6 pi eta R``,
``f_nu = eta/(pi rho_f R^2)``, ``s = sqrt(f/f_nu)`` and a wall at distance ``h`` from the
bead's centre (motion parallel to it), the friction is (eq. D6)

    ``g = gamma(f)/gamma_0 = [1 + (1 - i) s - (2i/9) s^2]
          / (1 - (9R/16h) [1 - (1 - i) s/3 + (2i/9) s^2 - (4/3)(1 - e^{-(1 - i) eps})])``,
    ``eps = (2h - R) s / R``

(bulk, eq. D4: the numerator alone), which holds the fluid's added mass, so the bead's
inertia is ``f_m = gamma_0/(2 pi m_bead)`` with the bead's own mass. Then

- the two-sided PSD of the position (eq. D2, normalised to integrate to ``kT/k``):
  ``P(f) = D_0/(2 pi^2) Re g / ((f_c + f Im g - f^2/f_m)^2 + (f Re g)^2)``,
  ``D_0 = kT/gamma_0``, ``f_c = k/(2 pi gamma_0)``;
- the response to a fluid (stage) drive (eq. D3 and the equation of motion it comes from):
  ``x/x_s = -i f g/(f_c - f^2/f_m - i f g)``; for a stage moving as ``Re[S e^{+2 pi i f t}]``
  (the convention of the generator below) it is the complex conjugate.

The zero-frequency friction is ``gamma_0/(1 - 9R/16h)`` (the first-order Faxen factor of
eq. D6): the truth for the fitted gamma.

:func:`generate_wall_driven` draws a trace with that PSD by spectral synthesis on a circulant
of length ``2 N`` (complex Gaussian Fourier coefficients of variance ``M fs P(f_j)``, the
inverse FFT, the real part times sqrt(2), the first ``N`` samples: what an anti-aliased
photodiode records, no exposure average, nothing folded), adds white tracking noise and the
drive's response ``Re[x/x_s S e^{i (2 pi f_d t_n + phase)}]``, and records the stage at the
frame times with white noise.
"""

from __future__ import annotations

import math

import numpy as np

BOLTZMANN = 1.380649e-23


def wall_friction(f, radius, eta, rho_f, distance=None):
    """``g = gamma(f)/gamma_0`` of eq. D6 (eq. D4 when ``distance`` is None), complex, in the
    paper's ``e^{-i w t}`` convention; ``f`` >= 0 [Hz] (array)."""
    f_nu = eta / (math.pi * rho_f * radius**2)
    s = np.sqrt(np.abs(np.asarray(f, dtype=float)) / f_nu)
    g = 1.0 + (1.0 - 1j) * s - 2j / 9.0 * s * s
    if distance is None:
        return g
    eps = (2.0 * distance - radius) / radius * s
    wall = 1.0 - (1.0 - 1j) / 3.0 * s + 2j / 9.0 * s * s - 4.0 / 3.0 * (
        1.0 - np.exp(-(1.0 - 1j) * eps))
    return g / (1.0 - 9.0 * radius / (16.0 * distance) * wall)


def _bead(k, radius, eta, rho_b):
    gamma0 = 6.0 * math.pi * eta * radius
    f_m = gamma0 / (2.0 * math.pi * 4.0 / 3.0 * math.pi * radius**3 * rho_b)
    return gamma0, k / (2.0 * math.pi * gamma0), f_m


def zero_frequency_friction(radius, eta, distance=None):
    """``gamma(0) = 6 pi eta R / (1 - 9R/16h)`` [N s/m] (the zero-frequency limit of eq. D6)."""
    g0 = 6.0 * math.pi * eta * radius
    return g0 if distance is None else g0 / (1.0 - 9.0 * radius / (16.0 * distance))


def wall_psd(f, k, radius, temperature, eta, rho_f, rho_b, distance=None):
    """Two-sided PSD [m^2/Hz] of eq. D2 with the friction of eq. D6 (module docstring)."""
    gamma0, fc, f_m = _bead(k, radius, eta, rho_b)
    af = np.abs(np.asarray(f, dtype=float))
    g = wall_friction(af, radius, eta, rho_f, distance)
    d0 = BOLTZMANN * temperature / gamma0
    den = (fc + af * g.imag - af**2 / f_m) ** 2 + (af * g.real) ** 2
    return d0 / (2.0 * math.pi**2) * g.real / den


def wall_drive_response(f, k, radius, eta, rho_f, rho_b, distance=None):
    """Complex ``x/x_s`` at the drive frequency ``f`` [Hz] for a stage moving as
    ``Re[S e^{+2 pi i f t}]`` (the complex conjugate of eq. D3's response)."""
    _, fc, f_m = _bead(k, radius, eta, rho_b)
    g = complex(wall_friction(f, radius, eta, rho_f, distance))
    return np.conj(-1j * f * g / (fc - f * f / f_m - 1j * f * g))


def generate_wall_driven(n, fs, k, radius, seed, *, amplitude, frequency, distance=None,
                         phase=0.3, temperature=295.0, eta=0.957812e-3, rho_f=997.803,
                         rho_b=1050.0, tracking_std=0.0, stage_noise=0.0):
    """``(positions, stage)`` [m], ``n`` samples at ``fs`` [Hz] (module docstring): the bead
    at ``distance`` [m] from the wall (None: bulk) in a trap of stiffness ``k`` [N/m], a stage
    drive ``amplitude cos(2 pi frequency t_n + phase)`` [m]."""
    m = 2 * n
    f = np.fft.fftfreq(m, d=1.0 / fs)
    p = wall_psd(f, k, radius, temperature, eta, rho_f, rho_b, distance)
    p[0] = 0.0  # zero mean
    rng = np.random.default_rng(seed)
    z = (rng.standard_normal(m) + 1j * rng.standard_normal(m)) / math.sqrt(2.0)
    x = math.sqrt(2.0) * np.fft.ifft(np.sqrt(m * fs * p) * z).real[:n]
    x = x + tracking_std * rng.standard_normal(n)
    h = wall_drive_response(frequency, k, radius, eta, rho_f, rho_b, distance)
    drive = amplitude * np.exp(1j * (2.0 * math.pi * frequency * np.arange(n) / fs + phase))
    stage = drive.real + stage_noise * rng.standard_normal(n)
    return x + (h * drive).real, stage
