r"""The reported result of a calibration in volts or with a stage drive (the second half of
:mod:`._instrument`, whose module doc gives the physics): ``Rd`` [m/V] from the known friction
or the drive, every parameter turned into metres (``k = k_V / Rd^2`` ...), the force
sensitivity ``Rf = k Rd`` [N/V] of one recording (the note gives every recording's where
their k differ), and the input errors propagated to first order."""

from __future__ import annotations

import dataclasses
import math
from typing import TYPE_CHECKING

import numpy as np

from ._drive_fit import drive_check, drive_phase_note, drive_shape_at, driven_k, rd_from_drive

if TYPE_CHECKING:
    from ._instrument import Plan

#: parameters that scale with the position unit: name -> power of Rd (x_m = Rd x_V)
_SCALING = {"k": -2, "c": -2, "gamma": -2, "tracking_var": 2, "drift_diffusion": 2,
            "line_amplitude": 1}


def _power_of(name):
    base = name.split("[")[0]
    return _SCALING.get(base, 0)


def _outputs(theta, names, plan, n_fit, pick=None):
    """The reported vector from the fit vector (volts units) and the inputs after it;
    ``pick``: the driven recording's k (:func:`._drive_fit.driven_k`)."""
    values = theta[:n_fit]
    if plan.drive is not None:
        shape = drive_shape_at(plan, values, names)  # the bead's radius from the vector
        rd = rd_from_drive(values, names, (theta[n_fit],) + plan.drive[1:], plan.model, shape,
                           pick)
    else:
        assert plan.gamma_known is not None
        rd = math.sqrt(values[names.index("gamma")] / theta[n_fit])
    out = [v * rd ** _power_of(n) for n, v in zip(names, values)]
    return np.array(out + [rd, _rf_stiffness(out, names, plan, pick) * rd])


def _rf_stiffness(out, names, plan, pick) -> float:
    """The stiffness [N/m] of Rf = k Rd: the driven recording's (``pick``), else recording
    0's; with k = c P (linear_power) c times its power (c Rd is not a force per volt)."""
    if pick is not None:
        return out[pick[0]] * pick[1]
    if "c" in names:
        p0 = float(plan.recordings[0].laser_power)
        off = out[names.index("power_offset")] if "power_offset" in names else 0.0
        return out[names.index("c")] * (p0 - off)
    return next(v for n, v in zip(names, out) if n == "k" or n.startswith("k["))


def _volts_result(res, plan):
    from ._radius_error import input_covariance, radius_error_applies, radius_note

    names = list(res.param_names)
    n_fit = len(names)
    if plan.drive is not None:
        inp, inp_var = plan.drive[0], plan.drive[1] ** 2
    else:
        inp, inp_var = plan.gamma_known[0], plan.gamma_known[1] ** 2
    theta = np.append(np.asarray(res.values, float), inp)
    cov_in = np.zeros((n_fit + 1, n_fit + 1))
    c, u = np.asarray(res.covariance, float), None
    if radius_error_applies(plan):  # the radius through the whole fit and G(f_d)
        c, u = input_covariance(res, plan)
    nan = ~np.isfinite(np.diag(c))
    cov_in[:n_fit, :n_fit] = np.where(np.isfinite(c), c, 0.0)
    cov_in[n_fit, n_fit] = inp_var
    pick = driven_k(res, plan) if plan.drive is not None else None
    base = _outputs(theta, names, plan, n_fit, pick)
    jac = np.zeros((base.size, theta.size))
    for j in range(theta.size):
        h = 1e-6 * abs(theta[j]) if theta[j] != 0 else 1e-30
        up, dn = theta.copy(), theta.copy()
        up[j] += h
        dn[j] -= h
        jac[:, j] = (_outputs(up, names, plan, n_fit, pick)
                     - _outputs(dn, names, plan, n_fit, pick)) / (
            2 * h)
    cov = jac @ cov_in @ jac.T
    if nan.any():
        idx = np.flatnonzero(nan)
        cov[idx, :] = 0.0
        cov[:, idx] = 0.0
        cov[idx, idx] = np.nan
    rd = base[n_fit]
    k_rec, k_err = _k_per_recording(res, names, base, cov)
    out_names = tuple(names) + ("displacement_sensitivity", "force_sensitivity")
    extra = () if u is None else (radius_note(jac[:, :n_fit] @ u, out_names, base, cov, plan),)
    return dataclasses.replace(
        res, param_names=out_names,
        values=base, covariance=cov, k_per_recording=k_rec, k_per_recording_err=k_err,
        interval_source=None,
        notes=res.notes + (
            f"volts: displacement sensitivity Rd = {rd * 1e9:.6g} +- "
            f"{math.sqrt(cov[n_fit, n_fit]) * 1e9:.3g} nm/V from "
            + ("the stage drive (active calibration, no Stokes assumption)"
               if plan.drive is not None else "the known friction")
            + f"; force sensitivity Rf = k Rd = {base[n_fit + 1] * 1e12:.6g} +- "
            f"{math.sqrt(cov[n_fit + 1, n_fit + 1]) * 1e12:.3g} pN/V"
            + _rf_which(k_rec, rd, int(plan.drive[4]) if plan.drive is not None else 0)
            + "; k, gamma and eps^2 are in SI (m), errors include the sensitivity's",) + extra)


def _rf_which(k_rec, rd: float, i: int) -> str:
    """Which recording's k Rf uses, and every recording's Rf, when their k differ."""
    k_rec = np.atleast_1d(np.asarray(k_rec, float))
    if k_rec.size < 2 or np.allclose(k_rec, k_rec[0], rtol=1e-9):
        return ""
    each = ", ".join(f"{v * rd * 1e12:.4g}" for v in k_rec)
    return (f" with recording {i}'s k (k differs per recording: Rf_i = k_i Rd = {each} pN/V, "
            "recording by recording)")


def _k_per_recording(res, names, base, cov):
    """Per-recording k and error in SI from the transformed parameters (each recording's
    k parameter found by its value in volts units; k = c P scales with its power)."""
    k_v = np.asarray(res.k_per_recording, float)
    values_v = np.asarray(res.values, float)
    err = np.sqrt(np.clip(np.diag(cov), 0, None))
    if "c" in names:
        j = names.index("c")
        powers = k_v / values_v[j]
        return base[j] * powers, err[j] * powers
    idx = [i for i, n in enumerate(names) if n == "k" or n.startswith("k[")]
    pick = [idx[int(np.argmin(np.abs(values_v[idx] - kv)))] for kv in k_v]
    return base[pick], err[pick]


def finish_instrument(res, plan: Plan):
    """The reported result: volts turned into metres with Rd and Rf (module docstring); for
    a drive on a trace in metres, the drive's check of the position calibration."""
    phase = drive_phase_note(res, plan)
    if plan.volts:
        out = _volts_result(res, plan)
    elif plan.drive is not None and "gamma" in res.param_names:
        out = drive_check(res, plan)
    else:
        out = res
    return out if phase is None else dataclasses.replace(out, notes=out.notes + (phase,))
