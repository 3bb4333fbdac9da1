r"""Frequency-dependent friction of a KNOWN bead (``calibrate(..., hydrodynamics=...)``).

The field's passive calibration with a bead of known size (pylake's
``hydrodynamically_correct=True``; Berg-Sorensen & Flyvbjerg 2004, eq. 12; near a surface
Tolic-Norrelykke et al. 2006, eqs. D2/D6) fits the trap with the friction ``gamma(f)`` of a
sphere of the bead's radius in the medium: the ``hydrodynamics`` effect with ``hydro_radius``
held at the bead radius (no new free parameter), the distance to the surface, the bead and
fluid densities and the viscosity from the recordings' instrument settings (water at T where
not given). ``gamma`` (the zero-frequency friction) is held at Stokes x Faxen with
``friction="stokes"`` or fitted.

**When "auto" turns it on.** With the bead radius known, the linearised bias of the Whittle
fit that ignores ``gamma(f)`` is computed from the model spectra at a rough estimate of
(k, gamma, eps^2) (below), on the fitted band's Fourier ordinates (the core detector model:
exposure average, folding, tracking noise; other effects left out, which can only overstate
the bias):

``d theta = -F^{-1} sum_j grad log P0_j (1 - P1_j / P0_j)``,  ``F = sum_j grad log P0_j
grad log P0_j^T``,

``P1`` with and ``P0`` without the frequency-dependent friction, ``theta = (log k,
log gamma, eps^2)`` (free ones only), ``F^{-1}`` the Whittle covariance. For positions in
metres the point is the bead's friction (Stokes x Faxen, or the held gamma) and the
blur-corrected variance's k (robust where dt ~ tau); k's bias is predicted with gamma held,
and with gamma free as well where the record determines gamma (SE of log gamma < 0.25, where
the linearisation holds). In volts the point is the moment estimate. Where the corner
frequency at that point is above the fitted band (dt >~ tau) "auto" leaves it off: k then
comes from the spectrum's level, and the linearisation is not trusted (a 500 fps camera with
f_c = 835 Hz, R = 0.54 um: predicted +2 %, while the fit with the correction moved k by
-4 %). It is on when the largest |bias| / SE of k (and gamma) exceeds
:data:`AUTO_THRESHOLD` = 1/3 (over several recordings, the root sum of squares: the pooled
ratio when they share k). At 1/3 SE a 95 % interval still covers ~94 %.

**Active calibration** (a stage drive, Tolic-Norrelykke et al. 2006 eq. D3). With the
correction on, the drive response uses the same friction: ``_hydro_drive.drive_friction`` gives
``G(f_d) = gamma(f_d)/gamma`` and the bead's dissipation frequency ``f_m`` for
``blurtrap.inference._active.fluid_response``; in volts the effect carries the bead's
Stokes x Faxen friction for the inertia terms (the fitted gamma is in volts units). "auto"
for positions in volts with a drive (Rd, gamma and k all come through the drive response)
predicts, at the moment estimate, the biases of ``ln Rd = ln|H(f_c)| - ln|r| + const``,
``ln gamma = ln gamma_V - 2 ln Rd``, ``ln k = ln k_V - 2 ln Rd`` and ``ln Rf``: the passive
fit's linearised bias in ``ln f_c`` times ``d ln|H|/d ln f_c`` plus
``ln|H_Lorentz(f_c)| - ln|H_hydro(f_c)|`` at f_d, with SEs from the Whittle covariance and the
ratio's; on above the same :data:`AUTO_THRESHOLD`. In metres the drive only checks the
position scale, and the passive rule above decides. R = 2 um, 78.125 kHz anti-aliased, 2^17
samples, f_c ~ 600 Hz, 200 nm drive (the setting of tests/inference/test_active_hydro.py):
predicted Rd +24 % (32 Hz) and +11 % (300 Hz), measured +29/+31 % and +15/+18 % on two seeds
each; R = 1.5 um, f_c = 588 Hz: predicted +17 % and +7.9 % (6.4 and 4.9 SE), measured over 50
seeds +22 to +40 % and +11 to +22 % (benchmarks/RESULTS_instruments.md, 6b): the
linearisation understates the size, not the decision. Near a surface (eq. D6 with
``distance_to_surface_m``) the same holds, and leaving the distance out is worse than no
correction (6b: h = 1.6 R, 32 Hz, Rd -24 % against -9 %); the bead radius's error reaches the
active results through the passive fit and ``G(f_d)`` alike (:mod:`._radius_error`).

Numbers (R = 1.5 um polystyrene in water at 295 K, k = 0.1 pN/nm, f_c ~ 590 Hz; predicted /
measured over 50 seeds in benchmarks/RESULTS_instruments.md):

- photodiode 78.125 kHz, anti-aliased (band to 0.4 fs), 2^17 samples: gamma free, predicted
  gamma +17 % (21 SE), measured +22.9 %; gamma held, k -1.7 % (0.9 SE): on;
- camera 1 kHz, W = dt, 2^14 frames: f_c above the band (and k +0.35 %, 0.18 SE): off; the
  same camera with a softer trap (f_c = 59 Hz, band to 8.5 f_c) k -1.2 % (0.66 SE): on;
  2^16 frames at 5 kHz: k -4 % (6 SE): on. A camera needs the correction when its band
  reaches well past f_c and the record is long.
"""

from __future__ import annotations

import math
from typing import cast

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._constants import BOLTZMANN

#: "auto" turns the correction on above this predicted bias of k or gamma (in SE)
AUTO_THRESHOLD = 1.0 / 3.0
#: the wall form of eq. D6 holds for distances above this many radii (as pylake requires)
MIN_DISTANCE_RADII = 1.5
_N_BINS = 256
#: the linearised bias is trusted where the SE of log k / log gamma is below this
_SE_VALID = 0.25


def check_hydrodynamics(value, what="hydrodynamics"):
    """``value`` if it is None, "auto", True or False; a ValueError naming it otherwise."""
    if isinstance(value, np.bool_):
        value = bool(value)
    if value is None or value is True or value is False or (isinstance(value, str)
                                                          and value == "auto"):
        return value
    raise ValueError(f"{what} must be None (the recordings' setting), 'auto', True or False; "
                     f"got {what} = {value!r}")


def _recording_setting(rec, st, i):
    v = st.get("hydrodynamics")
    if v is None:
        meta = getattr(rec, "metadata", None) or {}
        v = meta.get("hydrodynamics") if hasattr(meta, "get") else None
    v = check_hydrodynamics(v, f"recording {i}: hydrodynamics")
    return "auto" if v is None else v


def _same_inputs(sts, key):
    vals = [s.get(key) for s in sts]
    if any(v != vals[0] for v in vals[1:]):
        raise ValueError(f"hydrodynamics: the recordings disagree on {key} ({vals}); the model "
                         "has one bead, so calibrate them separately")
    return vals[0]


def known_bead_effect(sts, gamma_known=None):
    """The ``hydrodynamics`` effect of the recordings' bead (radius, distance, densities and
    viscosity from the settings) and the radius ``(R, se)``; ``gamma_known`` [N s/m] sets the
    bead's friction for its inertia (positions in volts)."""
    from ..effects import make_effect
    from ..physics import POLYSTYRENE_DENSITY

    rad = _same_inputs(sts, "bead_radius_m")
    h = _same_inputs(sts, "distance_to_surface_m")
    if h is not None and h < MIN_DISTANCE_RADII * rad:
        raise ValueError(f"hydrodynamics: distance_to_surface_m = {h:.4g} m is below "
                         f"{MIN_DISTANCE_RADII:g} bead radii (R = {rad:.4g} m), where the "
                         "near-wall friction of Tolic-Norrelykke et al. (2006) eq. D6 does not "
                         "hold; use hydrodynamics=False there")
    rho_b = _same_inputs(sts, "bead_density_kg_per_m3")
    eff = make_effect("hydrodynamics", distance=h,
                      bead_density=POLYSTYRENE_DENSITY if rho_b is None else float(rho_b),
                      viscosity=_same_inputs(sts, "viscosity_Pa_s"),
                      fluid_density=_same_inputs(sts, "fluid_density_kg_per_m3"),
                      bead_friction=gamma_known)
    err = _same_inputs(sts, "bead_radius_err_m")
    return eff, (float(rad), float(err or 0.0))


def _ordinates(rec, band, excluded):
    """Representative frequencies and weights (counts) of the fitted Fourier ordinates."""
    n, dt = rec.positions.shape[0], float(rec.frame_interval)
    f = np.arange(1, n // 2 + 1) / (n * dt)
    keep = np.ones(f.size, bool)
    if band is not None:
        keep &= (f >= band[0]) & (f <= band[1])
    for a, b in excluded:
        keep &= ~((f >= a) & (f <= b))
    f = f[keep]
    if f.size <= _N_BINS:
        return f, np.ones(f.size)
    edges = np.geomspace(f[0], f[-1] * (1 + 1e-12), _N_BINS + 1)
    idx = np.clip(np.searchsorted(edges, f, side="right") - 1, 0, _N_BINS - 1)
    w = np.bincount(idx, minlength=_N_BINS).astype(float)
    s = np.bincount(idx, weights=f, minlength=_N_BINS)
    ok = w > 0
    return s[ok] / w[ok], w[ok]


def predicted_bias(rec, model, effect, radius, band, excluded, gamma_fixed=None,
                   gamma_guess=None, with_cov=False):
    """``(bias, se)`` of (log k, log gamma) of a fit of ``rec`` that ignores ``effect``
    (module docstring) at ``gamma_guess`` (the bead's friction, positions in metres) and the
    blur-corrected variance's k, else at the moment estimate; the gamma entries are NaN when
    ``gamma_fixed`` holds it. ``(0, inf)`` when the corner frequency at that point is not
    inside the fitted band (dt >~ tau: the spectrum's shape is not fitted). ``with_cov``:
    also the point ``(k0, gamma0)`` and the Whittle covariance of (log k, log gamma) (NaN rows
    for a held gamma), ``(bias, se, point, cov)``."""
    from ._models import TrapModel
    from ._starts import moment_start

    k0, g0, e0, rho = moment_start(rec)
    if gamma_guess is not None:
        # the bead's friction and the blur-corrected variance (robust where dt ~ tau)
        from ..physics import stiffness_from_variance

        x = np.asarray(rec.positions, dtype=float)
        kt = BOLTZMANN * float(rec.temperature)
        k0 = kt / float(np.var(x))
        if model.blur:
            k0 = float(stiffness_from_variance(float(np.var(x)), kt / gamma_guess,
                                               float(rec.exposure), float(rec.temperature)))
        g0 = gamma_guess
    elif not 0.02 < rho < 0.99999:
        return _untrusted(with_cov, k0, g0)
    f, w = _ordinates(rec, band, excluded)
    if f.size < 3 or not k0 / (2.0 * math.pi * g0) < f[-1]:
        # the corner is not inside the fitted band: k comes from the spectrum's level, and
        # the linearisation is not trusted there (an e2e camera case, f_c = 3.3 f_Nyquist:
        # predicted +2 %, a fit with the correction moved k by -4 %)
        return _untrusted(with_cov, k0, g0)
    core = TrapModel(blur=model.blur, alias=model.alias, noise=model.noise, name="rule")
    # padded to _N_BINS ordinates (at weight 0): one compiled program per model
    fj = np.concatenate([f, np.full(_N_BINS - f.size, f[-1])])[None, :]
    w = np.concatenate([w, np.zeros(_N_BINS - w.size)])
    theta = np.array([math.log(k0), math.log(g0), 1.0])
    meta = np.array([float(rec.frame_interval), float(rec.exposure), float(rec.temperature),
                     e0, float(radius)])
    p0, p1, jac = (np.asarray(z) for z in _rule_spectra(core, core.add(effect), fj, theta,
                                                         meta))
    free = [0] + ([] if gamma_fixed is not None else [1]) + ([2] if model.noise else [])
    jac = jac[:, free]
    fisher = (jac * w[:, None]).T @ jac
    cov = np.linalg.pinv(fisher)
    step = -cov @ (jac.T @ (w * (1.0 - p1 / p0)))
    bias, se = np.full(2, np.nan), np.full(2, np.nan)
    cov2 = np.full((2, 2), np.nan)
    for j, idx in enumerate(free):
        if idx < 2:
            bias[idx], se[idx] = step[j], math.sqrt(max(cov[j, j], 0.0))
            for i, jdx in enumerate(free):
                if jdx < 2:
                    cov2[idx, jdx] = cov[j, i]
    return (bias, se, (k0, g0), cov2) if with_cov else (bias, se)


@eqx.filter_jit
def _rule_spectra(core, full, fj, theta, meta):
    """The spectrum without the effect ``p0`` at ``theta`` = (log k, log gamma, eps^2 / e0),
    with it ``p1`` (``full``: the core model with the effect, hydrodynamic radius
    ``meta[4]``) and the Jacobian of log ``p0`` in ``theta``; ``meta`` = (dt, W, T, e0,
    radius). Compiled once per model and padded frequency count."""
    args = tuple(jnp.reshape(meta[i], (1,)) for i in range(3))

    def log_p0(t):
        return jnp.log(core.psd(fj, jnp.exp(t[:1]), jnp.exp(t[1]), t[2] * meta[3], *args)[0])

    p1 = full.psd(fj, jnp.exp(theta[:1]), jnp.exp(theta[1]), meta[3], *args,
                  extras={"hydro_radius": meta[4]})[0]
    return jnp.exp(log_p0(theta)), p1, jax.jacfwd(log_p0)(theta)


def _untrusted(with_cov, k0, g0):
    out = (np.zeros(2), np.full(2, np.inf))
    return out + ((k0, g0), np.full((2, 2), np.inf)) if with_cov else out


def _describe(eff, rad, rec):
    from ..physics import water_density, water_viscosity

    t = float(rec.temperature)
    eta = eff.viscosity if eff.viscosity is not None else float(water_viscosity(t))
    rho = eff.fluid_density if eff.fluid_density is not None else float(water_density(t))
    f_nu = eta / (math.pi * rho * rad**2)
    return (f"R = {rad * 1e6:.4g} um held, viscosity {eta * 1e3:.4g} mPa s"
            + (" (water at T)" if eff.viscosity is None else "")
            + f", fluid density {rho:.5g} kg/m^3" + (" (water)" if eff.fluid_density is None
                                                      else "")
            + f", bead density {eff.bead_density:.5g} kg/m^3, "
            + ("bulk" if eff.distance is None else
               f"{eff.distance * 1e6:.4g} um from the surface (eq. D6)")
            + f"; f_nu = {f_nu / 1e3:.4g} kHz")


def _bead_gamma(eff, rad, rec):
    """Stokes friction x Faxen's factor of the bead (the zero-frequency friction)."""
    from ..physics import faxen_factor, water_viscosity

    eta = eff.viscosity if eff.viscosity is not None else \
        float(water_viscosity(float(rec.temperature)))
    fax = 1.0 if eff.distance is None else float(faxen_factor(rad, eff.distance))
    return 6.0 * math.pi * eta * rad * fax


def _auto_ratio(recs, model, eff, rad, band, excluded, gamma_fixed, volts):
    """(pooled bias/SE ratio, mean bias of (log k, log gamma)) over the recordings. In
    metres k's bias is predicted with gamma held at the bead's friction (or the fixed
    value) and, when gamma is free, also with gamma free where the record determines it
    (SE of log gamma below :data:`_SE_VALID`: the linearisation holds)."""
    ratios, biases = [], []
    for r in recs:
        if volts:
            b, s = cast(tuple, predicted_bias(r, model, eff, rad, band, excluded))
            ok = np.isfinite(s) & (s < _SE_VALID)
            ratios.append(float(np.max(np.abs(b[ok]) / s[ok])) if ok.any() else 0.0)
            biases.append(b)
            continue
        g = gamma_fixed or _bead_gamma(eff, rad, r)
        b, s = cast(tuple, predicted_bias(r, model, eff, rad, band, excluded, g, g))
        ratio = abs(b[0]) / s[0] if np.isfinite(s[0]) else 0.0
        if gamma_fixed is None:
            bf, sf = cast(tuple, predicted_bias(r, model, eff, rad, band, excluded, None, g))
            if np.all(sf < _SE_VALID):
                ratio = max(ratio, float(np.max(np.abs(bf) / sf)))
                b = bf
        ratios.append(ratio)
        biases.append(b)
    mean = np.mean(biases, axis=0)
    return float(np.sqrt(np.sum(np.square(ratios)))), {
        n: b for n, b in zip(("k", "gamma"), mean) if not np.isnan(b)}


def plan_hydrodynamics(recs, sts, model, method, arg, held, notes, *, volts=False,
                       gamma_known=None, band=None, excluded=(), drive=None,
                       likelihood="auto"):
    """The model with the known bead's hydrodynamics when the setting (``arg``, else the
    recordings' ``hydrodynamics``, default "auto") asks for it; holds ``hydro_radius`` in
    ``held`` and says what was used in ``notes``."""
    arg = check_hydrodynamics(arg)
    if arg is None:
        vals = [_recording_setting(r, s, i) for i, (r, s) in enumerate(zip(recs, sts))]
        if any(v != vals[0] for v in vals[1:]):
            raise ValueError(f"recordings disagree on hydrodynamics ({vals}); calibrate them "
                             "separately")
        arg = vals[0]
    if arg is False:
        if all(s.get("bead_radius_m") is not None for s in sts):
            notes.append("hydrodynamics: off (hydrodynamics=False): friction independent of "
                         "frequency")
        return model
    explicit = arg is True
    reason = None
    if any(s.get("bead_radius_m") is None for s in sts):
        reason = "needs the bead radius (bead_radius_m in the manifest or metadata)"
    elif model.has("hydrodynamics"):
        reason = "the model already has the hydrodynamics effect (with a fitted hydro_radius)"
    elif method not in ("auto", "likelihood", "psd"):
        reason = f"applies to the spectral fits (likelihood, psd); got method = {method!r}"
    elif likelihood == "exact":
        reason = ("the exact time-domain likelihood (likelihood='exact') covers the "
                  "closed-form model only")
    if reason is None and not explicit:
        rad, h = sts[0]["bead_radius_m"], sts[0].get("distance_to_surface_m")
        if h is not None and h < MIN_DISTANCE_RADII * rad:
            notes.append(f"hydrodynamics: off (auto): the bead centre is {h / rad:.3g} radii "
                         f"from the surface, below the {MIN_DISTANCE_RADII:g} where the "
                         "near-wall model holds")
            return model
    if reason is not None:
        if explicit:
            raise ValueError(f"hydrodynamics=True {reason}")
        if sts[0].get("bead_radius_m") is not None and likelihood == "exact":
            notes.append(f"hydrodynamics: off (auto): {reason}")
        return model
    eff, (rad, rad_se) = known_bead_effect(sts, gamma_known[0] if volts and gamma_known
                                           else None)
    if volts and gamma_known is None:
        # active calibration in volts: the bead's inertia from its Stokes x Faxen friction
        eff, _ = known_bead_effect(sts, _bead_gamma(eff, rad, recs[0]))
    desc = _describe(eff, rad, recs[0])
    gamma_fixed = held.get("gamma", (None,))[0]
    if explicit:
        why = "hydrodynamics=True"
    else:
        if volts and drive is not None:
            # active calibration in volts: Rd, gamma and k all come through the drive
            from ._hydro_drive import drive_ratio

            ratio, bias = drive_ratio(recs[drive[4]], model, eff, rad, band, excluded, drive)
        else:
            ratio, bias = _auto_ratio(recs, model, eff, rad, band, excluded, gamma_fixed, volts)
        if ratio == 0.0:
            notes.append("hydrodynamics: off (auto): the correction's size could not be "
                         "predicted (the corner frequency is not inside the fitted band, dt >~ "
                         "tau, or the record determines k and gamma too poorly for the "
                         "linearised prediction); hydrodynamics=True to include it")
            return model
        pred = ("ignoring it would bias " + ", ".join(
            f"{n} by {np.expm1(b) * 100:+.2g} %" for n, b in bias.items())
                + f" ({ratio:.2g} SE, predicted from the model spectra on the fitted band"
                + (" and the drive response)" if volts and drive is not None else ")"))
        if not ratio > AUTO_THRESHOLD:
            notes.append(f"hydrodynamics: off (auto): {pred}, below {AUTO_THRESHOLD:.2g} SE; "
                         "hydrodynamics=True to include it")
            return model
        why = f"auto: {pred}"
    held["hydro_radius"] = (rad, rad_se)
    notes.append(f"hydrodynamics: on ({why}): frequency-dependent friction of the known bead "
                 f"(Berg-Sorensen & Flyvbjerg 2004 eq. 12), no new parameter: {desc}"
                 + ("" if drive is None else "; the drive response with the same friction and "
                    "the bead's inertia (Tolic-Norrelykke et al. 2006 eq. D3)"))
    return model.add(eff)
