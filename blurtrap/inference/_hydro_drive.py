"""The drive response of a known bead with hydrodynamic friction (active calibration,
Tolic-Norrelykke et al. 2006, appendix D, eqs. D3, D4 and D6), for ``calibrate`` with a stage
drive and ``hydrodynamics`` on (:mod:`._hydro_known`, module docstring: "Active calibration").

- :func:`drive_friction`: ``G(f_d) = gamma(f_d)/gamma`` and ``f_m = gamma/(2 pi m_bead)`` of
  the bead, the friction of the passive model with the fluid's added mass put back in, for
  ``_active.fluid_response``;
- :func:`drive_shape`: the same from a model and its held ``hydro_radius``, or the Lorentzian;
- :func:`drive_ratio`: "auto"'s predicted bias of Rd, gamma and k of an active calibration in
  volts that ignores the hydrodynamics, in SE.
"""

from __future__ import annotations

import math
from typing import cast

import numpy as np

from .._config import float64_scope
from ._hydro_known import _SE_VALID, predicted_bias

__all__ = ["drive_friction", "drive_shape", "drive_ratio"]


@float64_scope
def drive_friction(eff, radius, temperature, frequency, gamma=None):
    """``(G, f_m)`` of the known bead at the drive ``frequency`` [Hz] for
    ``blurtrap.inference._active.fluid_response``: ``G = gamma(f)/gamma`` (complex, the sign
    convention of ``blurtrap.physics.complex_friction``), the friction of the passive model
    (``blurtrap.physics.hydro_lorentzian``'s ``h``, scaled to the zero-frequency ``gamma``)
    with the fluid's added mass put back in, and ``f_m = gamma/(2 pi m_bead)`` [Hz].

    ``gamma`` [N s/m] is the zero-frequency friction in SI for the inertia terms: the
    effect's ``bead_friction`` when it has one (positions in volts), else `gamma` (the fitted
    one, positions in metres). With ``gamma = 6 pi eta R/(1 - 9R/(16h))`` (the zero-frequency
    limit of eq. D6) ``G`` is eq. D6's ``gamma(f)/gamma(0)`` and ``fluid_response`` is
    Tolic-Norrelykke et al. (2006) eq. D3 exactly."""
    from ..physics import complex_friction, water_density, water_viscosity

    t = float(temperature)
    eta = eff.viscosity if eff.viscosity is not None else float(water_viscosity(t))
    rho = eff.fluid_density if eff.fluid_density is not None else float(water_density(t))
    g_m = eff.bead_friction if eff.bead_friction is not None else gamma
    if g_m is None:
        raise ValueError("drive_friction needs the bead's zero-frequency friction gamma [N s/m]")
    dist = math.inf if eff.distance is None else eff.distance
    g = complex(np.asarray(complex_friction(float(frequency), radius, eta, rho, dist)))
    x = 0.0 if eff.distance is None else radius / eff.distance
    s2 = float(frequency) * math.pi * rho * radius**2 / eta  # f/f_nu
    gamma0 = 6.0 * math.pi * eta * radius
    added = 2j / 9.0 * s2
    g_rel = (g + added) * (1.0 - 9.0 / 16.0 * x) - added * gamma0 / g_m
    m_bead = 4.0 / 3.0 * math.pi * radius**3 * eff.bead_density
    return g_rel, g_m / (2.0 * math.pi * m_bead)


def drive_shape(model, fixed, temperature, frequency, gamma=None):
    """``(G, f_m)`` of :func:`drive_friction` when ``model`` has the known bead's
    hydrodynamics (its radius held in ``fixed``), else ``(1, None)`` (the Lorentzian)."""
    eff = next((e for e in model.extra if e.name == "hydrodynamics"), None)
    if eff is None or "hydro_radius" not in fixed:
        return 1.0, None
    return drive_friction(eff, fixed["hydro_radius"][0], temperature, frequency, gamma)


def drive_ratio(rec, model, eff, rad, band, excluded, drive):
    """(largest predicted |bias|/SE of ln Rd, ln gamma, ln k, ln Rf, the biases) of an
    active calibration in volts that ignores the bead's hydrodynamics, in the passive fit
    and in the drive response alike (linearised, as :func:`predicted_bias`)."""
    from ._active import fluid_response

    mag, mag_se, f_d = drive[:3]
    bias, se, (k0, g0), cov = cast(tuple, predicted_bias(rec, model, eff, rad, band,
                                                         excluded, with_cov=True))
    if not (np.all(np.isfinite(se)) and np.all(se < _SE_VALID)):
        return 0.0, {}
    fc = k0 / (2.0 * math.pi * g0)
    h0 = abs(fluid_response(f_d, fc)[0])
    h1 = abs(fluid_response(f_d, fc, *drive_friction(eff, rad, rec.temperature, f_d))[0])
    c = -fc * fc / (fc * fc + f_d * f_d)  # d ln|H0| / d ln f_c
    # rows: ln Rd, ln gamma, ln k, ln Rf in (ln k_V, ln gamma_V, ln|r|); bias: the naive fit's
    jac = np.array([[c, -c, -1.0], [-2 * c, 1 + 2 * c, 2.0], [1 - 2 * c, 2 * c, 2.0],
                    [1 - c, c, 1.0]])
    delta = np.array([math.log(h0 / h1), -2 * math.log(h0 / h1), -2 * math.log(h0 / h1),
                      -math.log(h0 / h1)])
    b_out = jac[:, :2] @ bias + delta
    cov3 = np.zeros((3, 3))
    cov3[:2, :2] = cov
    cov3[2, 2] = (mag_se / mag) ** 2
    se_out = np.sqrt(np.diag(jac @ cov3 @ jac.T))
    return float(np.max(np.abs(b_out) / se_out)), dict(zip(("Rd", "gamma", "k"), b_out[:3]))
