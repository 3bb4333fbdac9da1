"""The ``hydrodynamics`` effect (DESIGN section 3): its parameters, hooks and measured detectability."""

from __future__ import annotations

from typing import ClassVar

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from .._constants import BOLTZMANN
from ..physics import POLYSTYRENE_DENSITY, hydro_lorentzian, water_density, water_viscosity
from . import injections
from ._base import AbstractEffect, DataContext, Param, StartContext, value_field


def _stokes_radius(c: StartContext) -> float:
    """The radius whose Stokes friction in water is the trap fit's gamma."""
    import math

    import numpy as np

    eta = float(water_viscosity(float(np.clip(c.temperature, 274.0, 373.0))))
    return c.gamma / (6.0 * math.pi * eta)


class Hydrodynamics(AbstractEffect):
    """Frequency-dependent friction of a sphere of hydrodynamic radius ``hydro_radius`` [m]
    (Berg-Sorensen & Flyvbjerg 2004, eq. 12; fluid inertia + Basset force; water viscosity and
    density at T, ``blurtrap.physics.water_viscosity`` / ``water_density``). Faxen's law near a
    surface rescales gamma (which stays free: ``gamma`` is the zero-frequency friction), so a
    physical fit has ``hydro_radius <= gamma/(6 pi eta)``; ``diagnose`` rejects candidates that
    violate it by more than 50 %. Simulate it with ``blurtrap.simulate.HydrodynamicFriction``
    (``method="spectral"``).

    Static options: ``distance`` [m] from the bead centre to a surface (default ``None``:
    bulk); with it the frequency dependence is that of Tolic-Norrelykke et al. (2006), eq. D6
    (``blurtrap.physics.complex_friction``), meant for ``distance >~ 1.5 hydro_radius``.
    ``bead_density`` [kg/m^3] (default polystyrene, 1050). ``viscosity`` [Pa s] and
    ``fluid_density`` [kg/m^3] of the medium (default ``None``: water at T). ``bead_friction``
    [N s/m]: the bead's zero-frequency friction for its inertia, ``f_m = gamma/(2 pi m*)``
    (default ``None``: the fitted gamma; a fit of positions in volts, whose gamma is in volts
    units, passes the known friction).

    Signature: relative to the best Lorentzian a high-frequency deficit growing like
    sqrt(f/f_nu), f_nu = nu/(pi R^2) (~130 kHz for R = 1.5 um). Not visible in camera data.
    Detectability (measured, benchmarks/RESULTS_diagnose.md; photodiode, W -> 0, k = 0.05 pN/nm,
    eps = 0.2 nm): the standard model failed in every record for every radius tried (6/6 each
    at R = 1.5, 1.0, 0.5 and 0.25 um, 200 kHz, 2^16 samples = 0.33 s; gof p < 1e-240 at
    1.5 um, a high-frequency candidate at p < 1e-9 at 0.25 um). Naming it correctly is harder
    than detecting it: a 2-parameter photodiode filter mimics the deficit to within a few
    log-likelihood units (expected gap 2.0 per 2^14 samples at 100 kHz, R = 1.5 um). Ranked
    first, refit adequate with k and gamma within 3 SE (6 seeds each, rough rates): R = 1.5 um
    6/6 and R = 1.0 um 6/6 at 200 kHz, 2^16 samples; R = 0.5 um 4/6 and R = 0.25 um 3/6 (the
    others named detector_filter); R = 1.5 um at 100 kHz, 2^14 samples 5/6. So beads of
    R >= 1 um are named reliably with >= 2^16 samples at 200 kHz; smaller beads need longer
    records than that to be named rather than merely detected.

    Value: ``hydro_radius`` [m] (> 0, scalar to simulate): ``injections.HydrodynamicFriction``
    with this effect's ``distance`` and ``bead_density`` (``method="spectral"``)."""

    name: ClassVar[str] = "hydrodynamics"
    kind: ClassVar[str] = "friction"
    params: ClassVar = (Param("hydro_radius", "m", 1e6, "um", "hydrodynamic radius",
                              bounds=(1e-9, 1e-3), start=_stokes_radius),)
    signature: ClassVar[str] = "small high-frequency excess over the Lorentzian"

    distance: float | None = eqx.field(static=True, default=None)
    bead_density: float = eqx.field(static=True, default=POLYSTYRENE_DENSITY)
    hydro_radius: np.ndarray | None = value_field("m", "> 0")
    viscosity: float | None = eqx.field(static=True, default=None)
    fluid_density: float | None = eqx.field(static=True, default=None)
    bead_friction: float | None = eqx.field(static=True, default=None)
    order: ClassVar[float] = 80.0

    @classmethod
    def applies(cls, ctx: DataContext) -> bool:
        return ctx.sampling_rate >= 10_000.0  # not visible in camera data

    def to_injection(self) -> injections.HydrodynamicFriction:
        return injections.HydrodynamicFriction(self._value("hydro_radius", scalar=True),
                                               bead_density=self.bead_density,
                                               distance=self.distance,
                                               viscosity=self.viscosity,
                                               fluid_density=self.fluid_density)

    def __check_init__(self):
        checks = [("bead_density", self.bead_density, "kg/m^3")]
        if self.distance is not None:
            checks.append(("distance", self.distance, "m (or None: bulk)"))
        for nm, unit in (("viscosity", "Pa s"), ("fluid_density", "kg/m^3"),
                         ("bead_friction", "N s/m")):
            if getattr(self, nm) is not None:
                checks.append((nm, getattr(self, nm), f"{unit} (or None)"))
        for nm, v, unit in checks:
            try:
                ok = not isinstance(v, bool) and 0 < float(v) < float("inf")
            except (TypeError, ValueError):
                ok = False
            if not ok:
                raise ValueError(f"{nm} must be a finite number > 0 {unit}; got {nm} = {v!r}")

    def lorentzian(self, f, sigma2, tau, temp, extras):
        radius = extras["hydro_radius"]
        eta = water_viscosity(temp) if self.viscosity is None else self.viscosity
        rho = water_density(temp) if self.fluid_density is None else self.fluid_density
        k = BOLTZMANN * temp / sigma2
        gamma = tau * k
        d = BOLTZMANN * temp / gamma
        fc = k / (2.0 * jnp.pi * gamma)
        f_nu = eta / rho / (jnp.pi * radius**2)
        m_star = (4.0 / 3.0 * self.bead_density + 2.0 / 3.0 * rho) * jnp.pi * radius**3
        g_m = gamma if self.bead_friction is None else self.bead_friction
        f_m = g_m / (2.0 * jnp.pi * m_star)
        x = 0.0 if self.distance is None else radius / self.distance
        return hydro_lorentzian(f, d, fc, f_nu, f_m, x)
