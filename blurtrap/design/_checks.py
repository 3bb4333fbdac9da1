"""Argument checks of :func:`blurtrap.design.design` (clear errors naming the parameter, its
value and what was expected)."""

from __future__ import annotations

import math

import numpy as np

from ..physics import water_viscosity

#: the design targets (the SE each minimises; see design's docstring)
TARGETS = ("k", "gamma", "both", "determinant", "force_sensitivity")


def _check(name, value, lo=0.0, unit=""):
    if value is None or not np.isfinite(value) or value <= lo:
        raise ValueError(f"{name} must be a finite number > {lo:g} {unit}; got {name} = "
                         f"{value!r}")
    return float(value)


def _checked_friction(target, friction_error) -> float:
    """The target and the friction prior checked: ``friction_se`` (< 0: friction fitted)."""
    if target not in TARGETS:
        raise ValueError(f"target must be one of {TARGETS}; got target = {target!r}")
    if friction_error is None:
        if target == "force_sensitivity":
            raise ValueError("target='force_sensitivity' is the passive calibration in volts "
                             "with the friction known from the bead: give friction_error (its "
                             "relative SE, >= 0)")
    else:
        if (isinstance(friction_error, bool) or not np.isfinite(friction_error)
                or friction_error < 0):
            raise ValueError(f"friction_error must be a relative SE >= 0 (or None: friction "
                             f"fitted); got friction_error = {friction_error!r}")
        if friction_error == 0 and target in ("gamma", "both", "determinant"):
            raise ValueError(f"target={target!r} needs the SE of gamma, but friction_error = 0 "
                             "says gamma is known exactly; use target='k' or "
                             "'force_sensitivity', or give friction_error > 0")
    return -1.0 if friction_error is None else float(friction_error)


def _checked_noise(tracking_std, photon_limited) -> float:
    """eps_ref^2 [m^2] from the tracking-error rms, checked."""
    if tracking_std < 0 or not np.isfinite(tracking_std):
        raise ValueError(f"tracking_std must be >= 0 [m]; got {tracking_std!r}")
    if photon_limited and tracking_std == 0:
        raise ValueError("photon_limited needs tracking_std > 0 at the reference exposure")
    return float(tracking_std) ** 2


def checked_trap(k, gamma, radius, viscosity, temperature):
    """``(ks, gamma, temperature)``: the stiffnesses (a range ``(k_min, k_max)`` becomes three
    log-spaced values), the friction (given, or Stokes from the radius and viscosity, water
    at the temperature by default) and the temperature, checked."""
    ks = tuple(float(v) for v in np.atleast_1d(np.asarray(k, dtype=float)))
    if len(ks) == 2:
        ks = tuple(np.geomspace(ks[0], ks[1], 3))
    for v in ks:
        _check("k", v, unit="N/m")
    temperature = _check("temperature", temperature, unit="K")
    if gamma is None:
        if radius is None:
            raise ValueError("give gamma [N s/m] or the bead radius [m]")
        eta = viscosity if viscosity is not None else float(water_viscosity(temperature))
        gamma = 6.0 * math.pi * _check("viscosity", eta, unit="Pa s") * _check(
            "radius", radius, unit="m")
    return ks, _check("gamma", gamma, unit="N s/m"), temperature
