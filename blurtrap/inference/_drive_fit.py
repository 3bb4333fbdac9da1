"""Rd from an active calibration's drive response and a passive fit (``calibrate`` with a
stage drive; :mod:`._instrument` module docstring): ``Rd = sinc(f_d W) |H(f_d)| |T(f_d)| /
|r|`` with the bead's ``H`` (:func:`._active.fluid_response`; with the known bead's
hydrodynamics in the model, Tolic-Norrelykke et al. 2006 eq. D3, :mod:`._hydro_drive`).
:func:`drive_shape_at` takes the bead's radius from the fit vector, so that the uncertainty of
a given radius reaches Rd through ``G(f_d)`` too (:mod:`._radius_error`).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

__all__ = ["rd_from_drive", "drive_shape_of", "drive_shape_at", "drive_check"]


def rd_from_drive(values, names, drive, model, shape=(1.0, None)):
    """Rd from the drive response ``drive = (|r|, se, f_d, W, i)``; ``values``: the fit's, in
    the trace's units; ``shape``: the bead's ``(G, f_m)`` at f_d (:func:`drive_shape_of`)."""
    from ._active import fluid_response

    mag, _, f_d, w = drive[:4]
    ks = [v for n, v in zip(names, values) if n == "k" or n.startswith("k[")]
    fc = ks[0] / (2.0 * math.pi * values[names.index("gamma")])
    h = abs(fluid_response(f_d, fc, *shape)[0])
    blur = abs(float(np.sinc(f_d * w))) if model.blur else 1.0
    t = 1.0
    if "f3db" in names:
        from ..physics import photodiode_transfer

        t = math.sqrt(float(photodiode_transfer(f_d, values[names.index("f3db")],
                                                values[names.index("diode_alpha")])))
    return blur * h * t / mag


def drive_shape_of(plan, gamma=None):
    """``(G, f_m)`` of the plan's bead at the drive (``_hydro_drive.drive_shape``): the
    Lorentzian ``(1, None)`` without a drive or hydrodynamics; `gamma` [N s/m]: the fitted
    friction in metres (None in volts, where the effect carries the bead's)."""
    from ._hydro_drive import drive_shape

    if plan.drive is None:
        return 1.0, None
    rec = plan.recordings[plan.drive[4]]
    return drive_shape(plan.model, plan.fixed, rec.temperature, plan.drive[2], gamma)


def drive_shape_at(plan, values, names):
    """``(G, f_m)`` of the plan's bead at the drive with the radius the fit vector ``values``
    holds for ``hydro_radius`` (the bead's inertia friction rescaled with it,
    :func:`._radius_error.model_at`), so that a derivative of the outputs in that entry
    carries the radius's route through the drive response; :func:`drive_shape_of` without
    the known bead's hydrodynamics."""
    from ._hydro_drive import drive_shape
    from ._radius_error import model_at

    if plan.drive is None or "hydro_radius" not in plan.fixed or "hydro_radius" not in names:
        return drive_shape_of(plan)
    rec = plan.recordings[plan.drive[4]]
    nominal = plan.fixed["hydro_radius"][0]
    radius = float(values[list(names).index("hydro_radius")])
    mdl = model_at(plan.model, rec, radius, nominal)
    return drive_shape(mdl, {"hydro_radius": (radius, 0.0)}, rec.temperature, plan.drive[2])


def drive_check(res, plan):
    """For positions in metres: the drive's position scale (1 when the trace's calibration and
    the drive agree), with the errors of the ratio and of f_c (the fit's k and gamma), as a
    note of ``res``."""
    names = list(res.param_names)
    values = np.asarray(res.values, float)
    shape = drive_shape_of(plan, values[names.index("gamma")])
    rd = rd_from_drive(values, names, plan.drive, plan.model, shape)
    # the error of f_c (k and gamma of the fit) and of the drive's ratio
    idx = [next(i for i, n in enumerate(names) if n == "k" or n.startswith("k[")),
           names.index("gamma")]
    grad = np.zeros(len(idx))
    for j, i in enumerate(idx):
        up, dn = values.copy(), values.copy()
        up[i], dn[i] = values[i] * (1 + 1e-6), values[i] * (1 - 1e-6)
        grad[j] = (rd_from_drive(up, names, plan.drive, plan.model, shape)
                   - rd_from_drive(dn, names, plan.drive, plan.model, shape)) / (
                       2e-6 * values[i])
    c = np.asarray(res.covariance, float)[np.ix_(idx, idx)]
    var_fit = float(grad @ np.where(np.isfinite(c), c, 0.0) @ grad)
    se = math.hypot(rd * plan.drive[1] / plan.drive[0], math.sqrt(max(var_fit, 0.0)))
    z = (rd - 1.0) / se
    return dataclasses.replace(res, notes=res.notes + (
        f"drive: the stage drive gives a position scale of {rd:.5g} +- {se:.2g} m per m of "
        f"the trace ({z:+.1f} SE from 1" + ("): the position calibration and the drive "
                                            "disagree; check the units and the stage "
                                            "amplitude" if abs(z) > 3 else ")"),))
