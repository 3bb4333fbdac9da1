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

__all__ = ["rd_from_drive", "driven_k", "drive_shape_of", "drive_shape_at", "drive_check",
           "check_drive_frequency", "check_drive_response", "drive_phase_note"]


def driven_k(res, plan) -> tuple[int, float]:
    """``(j, scale)``: the driven recording's stiffness is ``values[j] * scale`` in the fit
    vector of ``res`` (its own k of per_recording / per_power, or ``c P_i``)."""
    names = list(res.param_names)
    i = int(plan.drive[4])
    if "c" in names:
        return names.index("c"), float(plan.recordings[i].laser_power)
    values = np.asarray(res.values, float)
    idx = [j for j, n in enumerate(names) if n == "k" or n.startswith("k[")]
    ki = float(res.k_per_recording[i])
    return idx[int(np.argmin([abs(values[j] - ki) for j in idx]))], 1.0


def rd_from_drive(values, names, drive, model, shape=(1.0, None), pick=None):
    """Rd from the drive response ``drive = (|r|, se, f_d, W, i, ratio)``; ``values``: the
    fit's, in the trace's units; ``shape``: the bead's ``(G, f_m)`` at f_d
    (:func:`drive_shape_of`); ``pick``: the driven recording's k (:func:`driven_k`; None: the
    first k)."""
    from ._active import fluid_response

    mag, _, f_d, w = drive[:4]
    if pick is None:
        k = next(v for n, v in zip(names, values) if n == "k" or n.startswith("k["))
    else:
        k = values[pick[0]] * pick[1]
    fc = k / (2.0 * math.pi * values[names.index("gamma")])
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
    pick = driven_k(res, plan)
    rd = rd_from_drive(values, names, plan.drive, plan.model, shape, pick)
    # the error of f_c (k and gamma of the fit) and of the drive's ratio
    idx = [pick[0], names.index("gamma")]
    grad = np.zeros(len(idx))
    for j, i in enumerate(idx):
        up, dn = values.copy(), values.copy()
        up[i], dn[i] = values[i] * (1 + 1e-6), values[i] * (1 - 1e-6)
        grad[j] = (rd_from_drive(up, names, plan.drive, plan.model, shape, pick)
                   - rd_from_drive(dn, names, plan.drive, plan.model, shape, pick)) / (
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


#: the bead's response to the drive must stand this many standard errors above the thermal
#: noise at f_d: below it Rd ~ 1/|x/x_stage| is dominated by noise and biased (|ratio| is
#: biased up by ~(se/|ratio|)^2), and a drive that never reached the bead gives ~1-2 SE
DRIVE_MIN_SNR = 5.0
#: a phase of the response that differs from the model's by more than this many standard
#: errors and more than this many radians (a few degrees: stage and position clocks a few
#: samples apart, a detector's low-pass far above f_d) is named
PHASE_Z, PHASE_MIN = 5.0, 0.05


#: a declared drive frequency is refused when the stage's line near it sits off it by more
#: than this fraction of a Fourier bin and this fraction of the frequency (a typo: 31 Hz for a
#: 32 Hz drive biased Rd by 2.4 SE), or when another line of the stage (drift removed) is
#: this many times stronger than the stage's sinusoid at the declared frequency (kHz given
#: as Hz)
FREQ_BINS, FREQ_REL, FREQ_DOMINANCE = 0.05, 1e-3, 10.0


def check_drive_frequency(stage, dt: float, declared: float, i: int) -> None:
    """``ValueError`` when the stage (a straight line removed: piezo creep, drift) does not
    move at the declared drive frequency."""
    from ._sinusoids import periodogram, refine_frequency, regression_power

    s = np.asarray(stage, dtype=float)
    n = s.size
    t = np.arange(n) - 0.5 * (n - 1)
    s = s - s.mean()
    s = s - t * float(s @ t) / float(t @ t)
    dur, f_d = n * dt, float(declared)
    near = refine_frequency(s, dt, f_d, 2.0 / dur)
    f, p = periodogram(s, dt)
    p = np.where(f > 5.0 / dur, p, 0.0)  # a drive makes >= 5 periods; creep lives below
    top = refine_frequency(s, dt, float(f[int(np.argmax(p))]), 0.6 / dur)
    at_declared, at_top = regression_power(s, dt, f_d), regression_power(s, dt, top)
    moved = abs(near - f_d) > max(FREQ_BINS / dur, FREQ_REL * f_d)
    dominated = at_top > FREQ_DOMINANCE**2 * at_declared
    if not (moved or dominated):
        return
    # the line near the declared frequency where it is a real one (a typo), else the
    # strongest (a unit slip)
    real_near = regression_power(s, dt, near) > at_top / FREQ_DOMINANCE**2
    other = near if moved and real_near else top
    dominated = other == top
    raise ValueError(
        f"recording {i}: the drive is declared at {f_d:.6g} Hz but the stage (its drift "
        f"removed) moves at {other:.6g} Hz" + (
            f" (its strongest line, {math.sqrt(at_top / max(at_declared, 1e-300)):.3g}x the "
            "amplitude at the declared frequency)" if dominated else
            " (the line near the declared frequency, refined by least squares)")
        + ": a typo or a unit slip (kHz as Hz)? Declare drive frequency_Hz = "
        f"{other:.6g}; a response fitted at the wrong frequency biases Rd")


def check_drive_response(resp, i: int, unit: str = "m") -> None:
    """``ValueError`` when recording ``i``'s response to the stage drive is not clearly above
    the thermal noise (:data:`DRIVE_MIN_SNR`)."""
    z = abs(resp.ratio) / resp.ratio_se if resp.ratio_se > 0 else math.inf
    if z < DRIVE_MIN_SNR:
        raise ValueError(
            f"recording {i}: the bead's response to the stage drive at {resp.frequency:.6g} Hz "
            f"is only {z:.2g} standard errors above the thermal noise there (|x/x_stage| = "
            f"{abs(resp.ratio):.4g} +- {resp.ratio_se:.2g} {unit} per m; needed: > "
            f"{DRIVE_MIN_SNR:g}): "
            "the drive did not reach the bead (stage channel recorded from the function "
            "generator, amplifier off, wrong channel) or its amplitude "
            f"({resp.stage_amplitude * 1e9:.3g} nm) is too small for this record, and Rd from "
            "it would be noise. Check the drive, raise its amplitude or record longer; or "
            "calibrate without it (friction='stokes' with the bead radius)")


def drive_phase_note(res, plan) -> str | None:
    """A note when the phase of the drive response ``x/x_stage`` disagrees with the model's
    (:mod:`._active`: ``arg[sinc(f_d W) e^{-i pi f_d W} H(f_d)]``, ``H`` at the fitted f_c):
    an inverted detector (pi), a trace of the bead relative to the stage ((H - 1) x_s: then
    Rd is wrong), or a timing offset between the stage and the positions. ``res`` in the
    fit's units (volts or metres: Rd > 0 does not change the phase); None when it agrees."""
    from ._active import fluid_response

    if plan.drive is None:
        return None
    names = list(res.param_names)
    values = np.asarray(res.values, float)
    if "gamma" not in names:
        return None
    i = int(plan.drive[4])  # the driven recording: its own k (per_recording, per_power, c P)
    k, k_se = float(res.k_per_recording[i]), float(res.k_per_recording_err[i])
    gamma, g_se = float(res.gamma), float(res.gamma_err)
    fc = k / (2.0 * math.pi * gamma)
    rel = math.hypot(k_se / k if math.isfinite(k_se) else 0.0,
                     g_se / gamma if math.isfinite(g_se) else 0.0)
    fc_se = fc * rel  # (k and gamma taken as independent: an allowance, not a test input)
    mag, se, f_d, w = plan.drive[:4]
    ratio = complex(plan.drive[5])
    shape = drive_shape_at(plan, values, names) if plan.volts else drive_shape_of(plan, gamma)
    h, _, darg = fluid_response(f_d, fc, *shape)
    # the exposure's average as rd_from_drive takes it (a model without blur: none)
    blur = np.sinc(f_d * w) * np.exp(-1j * math.pi * f_d * w) if plan.model.blur else 1.0
    mismatch = float(np.angle(ratio / (blur * h)))
    m_se = math.hypot(se / mag, darg * fc_se)
    slack = math.atan(f_d / values[names.index("f3db")]) if "f3db" in names else 0.0
    if not plan.model.alias:  # an anti-aliasing filter: its phase lag at f_d is not modelled
        # (an 8-pole Butterworth with its corner at >= 0.64 Nyquist lags < 8 f_d/f_Nyquist)
        nyquist = 0.5 / float(plan.recordings[i].frame_interval)
        slack += 8.0 * f_d / nyquist
    if abs(mismatch) <= max(PHASE_Z * m_se, PHASE_MIN + slack):
        return None
    head = (f"drive: the phase of the bead's response at {f_d:.6g} Hz is {math.degrees(mismatch):+.1f}"
            f" deg from the model's ({abs(mismatch) / m_se:.0f} SE)")
    if abs(abs(mismatch) - math.pi) <= max(PHASE_Z * m_se, 0.3):
        return (head + ": the response is inverted, the detector's axis points opposite to the "
                "stage's. Rd is quoted as a magnitude: positions and forces from this "
                "calibration have the opposite sign of the stage's axis")
    relative = float(np.angle(ratio / (blur * (h - 1.0))))
    if abs(relative) <= max(PHASE_Z * m_se, PHASE_MIN):
        return (head + " and matches a trace of the bead relative to the stage, (H - 1) "
                "x_stage, not relative to the trap. NOT TRUSTWORTHY: then Rd (and in metres k, "
                f"gamma and Rf) is wrong, Rd {abs(h - 1.0) / abs(h):.3g}x too small; record the "
                "position relative to the trap (the detector's usual signal) or check the "
                "drive geometry")
    return (head + f": a timing offset of {abs(mismatch) / (2 * math.pi * f_d) * 1e3:.3g} ms "
            "between the stage and the position samples (Rd unaffected), or a drive or "
            "detector the model does not describe (a filter, the bead's hydrodynamics, a drive "
            "that does not move the fluid as assumed: Rd biased); check the two clocks and "
            "the drive")
