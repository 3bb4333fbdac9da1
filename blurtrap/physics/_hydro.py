r"""Hydrodynamics and properties of water for calibration with known friction (SI units).

Pure ``jnp`` functions: ``jit``, ``vmap`` and ``grad`` go through all of them. Checks of
concrete inputs raise ``ValueError``; what each one does with traced inputs is stated in its
docstring.

- Water at 0.1 MPa: :func:`water_density` (Kell's equation on ITS-90), :func:`iapws_viscosity`
  (IAPWS 2008 at a given density) and :func:`water_viscosity` (the two combined).
- A sphere's friction: :func:`stokes_friction`, with a plane wall :func:`faxen_factor`
  (motion parallel to the wall) and :func:`brenner_factor` (perpendicular).
- Frequency-dependent friction: :func:`complex_friction`, ``gamma(f)/gamma_0`` in bulk and
  near a wall, and the position PSD of a trapped bead it gives, :func:`hydro_lorentzian`
  (dimensionless inputs, used by the model and the simulator) and :func:`hydro_psd` (SI
  inputs).

**References**

- Huber, M. L. et al., "New international formulation for the viscosity of H2O",
  J. Phys. Chem. Ref. Data 38, 101 (2009) (IAPWS R12-08), eqs. (2), (11), (12), Tables 1-3.
- Kell, G. S., J. Chem. Eng. Data 20, 97 (1975); on ITS-90: Bettin, H. & Spieweck, F.,
  PTB-Mitteilungen 100, 195 (1990).
- Faxen, H. (1923); Happel, J. & Brenner, H., *Low Reynolds number hydrodynamics* (1965).
- Brenner, H., Chem. Eng. Sci. 16, 242 (1961); approximant of Schaffer, E., Norrelykke,
  S. F. & Howard, J., Langmuir 23, 3654 (2007).
- Berg-Sorensen, K. & Flyvbjerg, H., Rev. Sci. Instrum. 75, 594 (2004), section IV
  (frequency-dependent Stokes friction and the PSD of eq. (12)).
- Tolic-Norrelykke, S. F. et al., Rev. Sci. Instrum. 77, 103101 (2006), appendix D,
  eqs. (D2), (D4)-(D6).
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jax.typing import ArrayLike

from ._checks import as_float, check_positive, is_concrete
from ._constants import BOLTZMANN, DEFAULT_TEMPERATURE

POLYSTYRENE_DENSITY = 1050.0
"""Density of polystyrene beads [kg/m^3], the default bead density."""

WATER_TEMPERATURE_RANGE = (273.15, 373.15)
"""Temperatures [K] where :func:`water_density` and :func:`water_viscosity` are checked."""

# Kell (1975) on ITS-90 (Bettin & Spieweck 1990): numerator coefficients of t^0..t^5 and
# the denominator coefficient of t, t in degrees Celsius
_KELL_NUM = (999.83952, 16.952577, -7.9905127e-3, -46.241757e-6, 105.84601e-9,
             -281.03006e-12)
_KELL_DEN = 16.887236e-3

# IAPWS 2008 (Huber et al. 2009): reduced units (eq. 3), Table 1 (H_i) and Table 2 (H_ij,
# row i multiplies (1/T - 1)^i, column j multiplies (rho - 1)^j)
_T_STAR, _RHO_STAR, _MU_STAR = 647.096, 322.0, 1.0e-6
_H0 = (1.67752, 2.20462, 0.6366564, -0.241605)
_H1 = np.array([
    [5.20094e-1, 2.22531e-1, -2.81378e-1, 1.61913e-1, -3.25372e-2, 0.0, 0.0],
    [8.50895e-2, 9.99115e-1, -9.06851e-1, 2.57399e-1, 0.0, 0.0, 0.0],
    [-1.08374, 1.88797, -7.72479e-1, 0.0, 0.0, 0.0, 0.0],
    [-2.89555e-1, 1.26613, -4.89837e-1, 0.0, 6.98452e-2, 0.0, -4.35673e-3],
    [0.0, 0.0, -2.57040e-1, 0.0, 0.0, 8.72102e-3, 0.0],
    [0.0, 1.20573e-1, 0.0, 0.0, 0.0, 0.0, -5.93264e-4],
])


def _horner(coeffs, x):
    """``sum_n coeffs[n] x^n`` with Python-float coefficients (weakly typed: any dtype)."""
    out = coeffs[-1] * jnp.ones_like(x)
    for c in coeffs[-2::-1]:
        out = out * x + c
    return out


def _powers(y, n: int):
    """``[1, y, ..., y^(n-1)]`` on a new last axis (products: finite gradients at y = 0)."""
    out = [jnp.ones_like(y), y]
    while len(out) < n:
        out.append(out[-1] * y)
    return jnp.stack(out, axis=-1)


def _water_temperature(temperature):
    """``temperature`` as a float array; a concrete one outside the range raises."""
    temperature = as_float(temperature, "temperature")
    if is_concrete(temperature):
        lo, hi = WATER_TEMPERATURE_RANGE
        arr = np.asarray(temperature)
        bad = arr[~((arr >= lo) & (arr <= hi))]
        if bad.size:
            raise ValueError(
                f"temperature must be within [{lo}, {hi}] K for the properties of liquid water "
                f"at 0.1 MPa; got temperature = {bad.ravel()[0]:.6g} K (in kelvin, not Celsius?)"
            )
    return temperature


def water_density(temperature):
    r"""Density of air-free water at 0.1 MPa [kg/m^3] (Kell 1975, on ITS-90).

    $$\rho = \frac{\sum_{n=0}^5 a_n t^n}{1 + b t},\quad t = T - 273.15\ \mathrm{K}$$
    in degrees Celsius, with the ITS-90 coefficients of Bettin & Spieweck (1990). It agrees
    with IAPWS-95 at 0.1 MPa to better than 6e-6 relative over 273.16-372.75 K (checked in the
    tests); the maximum, 999.972 kg/m^3, is at 3.98 C.

    **Arguments:** `temperature` [K], within :data:`WATER_TEMPERATURE_RANGE`.

    **Raises:** ``ValueError`` for a concrete temperature outside the range. Traced
    temperatures (under ``jit``/``grad``) are not checked: the polynomial extrapolates.
    """
    t = _water_temperature(temperature) - 273.15
    return _horner(_KELL_NUM, t) / (1.0 + _KELL_DEN * t)


def iapws_viscosity(temperature, density):
    r"""Viscosity of water [Pa s] at ``temperature`` [K] and ``density`` [kg/m^3], IAPWS 2008.

    Huber et al. (2009), eq. (2) without the critical enhancement (``mu_2 = 1``, exact
    outside the immediate vicinity of the critical point, and in particular for the liquid
    at 0.1 MPa):
    $$\mu = \mu^*\,\bar\mu_0(\bar T)\,\bar\mu_1(\bar T, \bar\rho),\quad
      \bar\mu_0 = \frac{100\sqrt{\bar T}}{\sum_{i=0}^3 H_i/\bar T^i},\quad
      \bar\mu_1 = \exp\Big[\bar\rho\sum_{i=0}^5\Big(\frac1{\bar T} - 1\Big)^i
      \sum_{j=0}^6 H_{ij}(\bar\rho - 1)^j\Big]$$
    with ``T* = 647.096 K``, ``rho* = 322 kg/m^3``, ``mu* = 1e-6 Pa s``. Reproduces the check
    values of the release (Table 4, e.g. 889.735100 uPa s at 298.15 K and 998 kg/m^3).
    No range check: the formulation covers fluid water far beyond the liquid range.
    """
    tb = as_float(temperature, "temperature") / _T_STAR
    rb = as_float(density, "density") / _RHO_STAR
    tb, rb = jnp.broadcast_arrays(tb, rb)
    mu0 = 100.0 * jnp.sqrt(tb) / _horner(_H0, 1.0 / tb)
    h1 = jnp.asarray(_H1, dtype=tb.dtype)
    series = jnp.einsum("...i,ij,...j->...", _powers(1.0 / tb - 1.0, 6), h1,
                        _powers(rb - 1.0, 7))
    return _MU_STAR * mu0 * jnp.exp(rb * series)


def water_viscosity(temperature):
    r"""Viscosity of liquid water at 0.1 MPa [Pa s] at ``temperature`` [K].

    :func:`iapws_viscosity` at the density :func:`water_density`; within ~1e-5 of the full
    IAPWS-95/IAPWS 2008 value over the range (the release's own uncertainty of the
    viscosity is ~1-2 %; e.g. 0.8900 mPa s at 298.15 K).

    **Raises:** ``ValueError`` for a concrete temperature outside
    :data:`WATER_TEMPERATURE_RANGE`; traced temperatures are not checked.
    """
    temperature = _water_temperature(temperature)
    return iapws_viscosity(temperature, water_density(temperature))


def stokes_friction(radius, viscosity):
    r"""Stokes friction of a sphere in an unbounded fluid, ``gamma_0 = 6 pi eta R`` [N s/m].

    **Arguments:** `radius` R [m]; `viscosity` eta [Pa s] (e.g. :func:`water_viscosity`).
    """
    return 6.0 * jnp.pi * as_float(viscosity, "viscosity") * as_float(radius, "radius")


def _wall_ratio(radius, distance):
    """``x = R/h`` after checking ``h > R > 0`` (concrete: ValueError; traced: error_if)."""
    radius = check_positive("radius", radius, "m")
    distance = as_float(distance, "distance")
    msg = "distance (bead centre to surface) must exceed the radius"
    if is_concrete(radius) and is_concrete(distance):
        r, h = np.broadcast_arrays(np.asarray(radius), np.asarray(distance))
        bad = ~(h > r)
        if bad.any():
            raise ValueError(f"{msg}; got distance = {h[bad][0]:.6g} m with radius = "
                             f"{r[bad][0]:.6g} m")
        return radius / distance
    return eqx.error_if(radius / distance, ~(distance > radius), msg)


def faxen_factor(radius, distance):
    r"""Faxen's correction for motion parallel to a plane wall, ``gamma_par(h)/gamma_0``.

    $$\frac{\gamma_\parallel}{\gamma_0} = \Big(1 - \tfrac{9}{16}x + \tfrac18 x^3
      - \tfrac{45}{256}x^4 - \tfrac1{16}x^5\Big)^{-1},\quad x = R/h$$
    (Faxen 1923; Happel & Brenner 1965). Accurate for ``h >~ 1.5 R``; it
    underestimates the divergence as the gap closes.

    **Arguments:** `radius` R [m]; `distance` h [m] from the bead centre to the surface,
    ``inf`` for bulk (factor 1).

    **Raises:** ``ValueError`` if ``distance <= radius`` (traced inputs: ``eqx.error_if``).
    """
    x = _wall_ratio(radius, distance)
    return 1.0 / (1.0 - 9.0 / 16.0 * x + x**3 / 8.0 - 45.0 / 256.0 * x**4 - x**5 / 16.0)


def brenner_factor(radius, distance):
    r"""Correction for motion perpendicular to a plane wall, ``gamma_perp(h)/gamma_0``.

    Brenner's (1961) exact result is an infinite series; this is the approximant of Schaffer
    et al. (2007),
    $$\frac{\gamma_\perp}{\gamma_0} \approx \Big(1 - \tfrac98 x + \tfrac12 x^3
      - \tfrac{57}{100}x^4 + \tfrac15 x^5 + \tfrac{7}{200}x^{11} - \tfrac1{25}x^{12}\Big)^{-1},
      \quad x = R/h,$$
    within 0.3 % of Brenner's series for ``h >= 1.01 R`` and within 0.04 % for ``h >= 1.1 R``
    (checked in the tests).

    **Raises:** ``ValueError`` if ``distance <= radius`` (traced inputs: ``eqx.error_if``).
    """
    x = _wall_ratio(radius, distance)
    den = (1.0 - 9.0 / 8.0 * x + x**3 / 2.0 - 0.57 * x**4 + x**5 / 5.0 + 0.035 * x**11
           - 0.04 * x**12)
    return 1.0 / den


def viscous_frequency(radius, viscosity, fluid_density):
    r"""``f_nu = eta / (pi rho_f R^2)`` [Hz]: the frequency at which the viscous penetration
    depth of an oscillating sphere equals its radius (Berg-Sorensen & Flyvbjerg 2004)."""
    radius = as_float(radius, "radius")
    return as_float(viscosity, "viscosity") / (jnp.pi * as_float(fluid_density, "fluid_density")
                                               * radius**2)


def _sqrt_ratio(f, f_nu):
    """``sqrt(|f| / f_nu)`` with finite gradients at f = 0."""
    af = jnp.abs(f)
    pos = af > 0
    return jnp.where(pos, jnp.sqrt(jnp.where(pos, af, 1.0) / f_nu), 0.0)


def _wall_delta(s, x):
    """``d - 1`` of the wall denominator ``d`` of Tolic-Norrelykke et al. (2006), eq. (D6),
    as (re, im): ``-(9/16) x [1 - (1-i)/3 s + (2i/9) s^2 - (4/3)(1 - e^{-(1-i) eps})]`` with
    ``eps = (2/x - 1) s``; exactly 0 at ``x = 0`` (bulk), with finite gradients there."""
    wall = x > 0
    xs = jnp.where(wall, x, 1.0)
    eps = (2.0 - xs) / xs * s
    decay = 4.0 / 3.0 * jnp.exp(-eps)
    b_re = -1.0 / 3.0 - s / 3.0 + decay * jnp.cos(eps)
    b_im = s / 3.0 + 2.0 / 9.0 * s * s + decay * jnp.sin(eps)
    c = -9.0 / 16.0 * x
    return c * b_re, c * b_im


def _divide(a_re, a_im, b_re, b_im):
    den = b_re * b_re + b_im * b_im
    return (a_re * b_re + a_im * b_im) / den, (a_im * b_re - a_re * b_im) / den


def _friction_ratio(s, x):
    """(re, im) of ``gamma(f)/gamma_0`` at ``s = sqrt(f/f_nu)`` (f >= 0), ``x = R/h``."""
    d_re, d_im = _wall_delta(s, x)
    return _divide(1.0 + s, -s - 2.0 / 9.0 * s * s, 1.0 + d_re, d_im)


def complex_friction(f, radius, viscosity, fluid_density, distance=jnp.inf):
    r"""Frequency-dependent friction of a sphere, ``gamma(f)/gamma_0`` (complex).

    In bulk (Berg-Sorensen & Flyvbjerg 2004; Tolic-Norrelykke et al. 2006, eq. D4), with
    ``gamma_0 = 6 pi eta R`` and :func:`viscous_frequency` ``f_nu``,
    $$\frac{\gamma(f)}{\gamma_0} = 1 + (1 - i)\sqrt{f/f_\nu} - \frac{2i}{9}\frac{f}{f_\nu},$$
    and at a distance h from a plane wall (motion parallel to it; Tolic-Norrelykke et al.
    2006, eq. D6, first order in ``R/h``)
    $$\frac{\gamma(f)}{\gamma_0} = \frac{\gamma_{\rm bulk}(f)/\gamma_0}
      {1 - \frac{9}{16}\frac{R}{h}\big[1 - \frac{1-i}{3}\sqrt{f/f_\nu}
      + \frac{2i}{9}\frac{f}{f_\nu} - \frac43\big(1 - e^{-(1-i)\epsilon}\big)\big]},\quad
      \epsilon = \frac{2h - R}{R}\sqrt{f/f_\nu}.$$
    At f = 0 this is 1 in bulk and ``1/(1 - 9R/(16h))`` (Faxen to first order) at the wall.
    Negative frequencies give the complex conjugate (a real response in time). The wall form
    is meant for ``h >~ 1.5 R``.

    **Arguments:** `f` [Hz]; `radius` R [m]; `viscosity` [Pa s]; `fluid_density` [kg/m^3];
    `distance` h [m] from the bead centre to the surface (``inf``: bulk).

    **Returns:** complex ``gamma(f)/gamma_0`` (dimensionless), the shape of ``f`` broadcast.

    **Raises:** ``ValueError`` if ``distance <= radius``.
    """
    f = as_float(f, "f")
    x = _wall_ratio(radius, distance)
    s = _sqrt_ratio(f, viscous_frequency(radius, viscosity, fluid_density))
    re, im = _friction_ratio(s, x)
    return jax.lax.complex(re, jnp.where(f < 0, -im, im))


def hydro_lorentzian(f, diffusion, corner_frequency, f_nu, f_m,
                     radius_over_distance: ArrayLike = 0.0):
    r"""Two-sided PSD of the position of a bead in a harmonic trap with frequency-dependent
    friction [m^2/Hz] (dimensionless-ready form: all inputs may be in units of tau).

    With ``g(f) = gamma(f)/gamma(0)`` (:func:`complex_friction` normalised to 1 at f = 0) and
    ``h = g + (2i/9)(f/f_nu) gamma_0/gamma(0)`` (the friction less the fluid's added mass),
    $$P(f) = \frac{D}{2\pi^2}\,\frac{{\rm Re}\,h}
      {(f_c + f\,{\rm Im}\,h - f^2/f_m)^2 + (f\,{\rm Re}\,h)^2}$$
    (Tolic-Norrelykke et al. 2006, eq. D2, two-sided). In bulk this is Berg-Sorensen &
    Flyvbjerg (2004), eq. (12):
    ``D/(2 pi^2) (1 + sqrt(f/f_nu)) / ((f_c - f^{3/2}/sqrt(f_nu) - f^2/f_m)^2
    + (f + f^{3/2}/sqrt(f_nu))^2)``.

    **Arguments:**

    - `diffusion` ``D = kT/gamma`` and `corner_frequency` ``f_c = k/(2 pi gamma)``, with
      ``gamma = gamma(0)`` the zero-frequency friction (Faxen's wall correction included).
    - `f_nu`: :func:`viscous_frequency`.
    - `f_m = gamma / (2 pi m*)`, ``m* = m_bead + m_fluid/2`` (half the displaced fluid's mass
      is the added mass of a sphere).
    - `radius_over_distance`: ``R/h`` in [0, 1); 0 (default) is bulk. The wall enters only
      through the shape of ``g(f)``; its size at f = 0 is whatever ``gamma`` holds.

    This is eq. D2 exactly when ``gamma = 6 pi eta R / (1 - 9R/(16h))`` (the zero-frequency
    limit of eq. D6). For any other ``gamma`` (a free fit parameter) the friction ``h``
    scales with ``gamma`` and the bulk entrained mass ``m_fluid/2`` (in ``f_m``) does not,
    as in the bulk formula.
    """
    af = jnp.abs(f)
    s = _sqrt_ratio(af, f_nu)
    x = radius_over_distance
    d_re, d_im = _wall_delta(s, x)
    # h = (h_bulk + (2i/9) s^2 (d - 1)) / d with h_bulk = 1 + s - i s: exact in bulk
    a = 2.0 / 9.0 * s * s
    h_re, h_im = _divide(1.0 + s - a * d_im, -s + a * d_re, 1.0 + d_re, d_im)
    norm = 1.0 - 9.0 / 16.0 * x
    h_re, h_im = h_re * norm, h_im * norm
    re = corner_frequency + af * h_im - af * af / f_m
    im = af * h_re
    return diffusion / (2.0 * jnp.pi**2) * h_re / (re * re + im * im)


def hydro_psd(f, k, gamma, radius, temperature=DEFAULT_TEMPERATURE, *, viscosity=None,
              fluid_density=None, bead_density=POLYSTYRENE_DENSITY, distance=jnp.inf):
    r"""Two-sided PSD [m^2/Hz] of the true position of a bead in a harmonic trap with
    hydrodynamic friction, bead and entrained-fluid inertia (:func:`hydro_lorentzian` in SI).

    **Arguments:**

    - `f` [Hz]; `k` [N/m]; `gamma` [N s/m]: the zero-frequency friction where the bead is
      (e.g. ``stokes_friction(R, eta) * faxen_factor(R, h)``; with
      ``stokes_friction(R, eta) / (1 - 9R/(16h))`` this is eq. D2 exactly, see
      :func:`hydro_lorentzian`); `radius` R [m]; `temperature` [K].
    - `viscosity` [Pa s] and `fluid_density` [kg/m^3]: ``None`` for water at `temperature`
      (:func:`water_viscosity`, :func:`water_density`).
    - `bead_density` [kg/m^3] (default polystyrene, :data:`POLYSTYRENE_DENSITY`).
    - `distance` h [m] from the bead centre to the surface; ``inf`` (default) is bulk.

    Integrates to ``kT/k`` over f (equipartition).

    **Raises:** ``ValueError`` for ``distance <= radius`` or (``None`` viscosity/density)
    a temperature outside :data:`WATER_TEMPERATURE_RANGE`.
    """
    temperature = as_float(temperature, "temperature")
    eta = water_viscosity(temperature) if viscosity is None else viscosity
    rho = water_density(temperature) if fluid_density is None else as_float(fluid_density)
    x = _wall_ratio(radius, distance)
    m_star = 4.0 / 3.0 * jnp.pi * radius**3 * (bead_density + 0.5 * rho)
    return hydro_lorentzian(
        as_float(f, "f"),
        BOLTZMANN * temperature / gamma,
        k / (2.0 * jnp.pi * gamma),
        viscous_frequency(radius, eta, rho),
        gamma / (2.0 * jnp.pi * m_star),
        x,
    )
