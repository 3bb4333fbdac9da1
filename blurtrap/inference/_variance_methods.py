"""The variance methods of ``calibrate``: variance vs exposure or laser power (least squares
with profile intervals), the overlapping Allan variance, and (blur-corrected)
equipartition."""

from __future__ import annotations

import math
from typing import Any

import jax.numpy as jnp
import numpy as np

from ..physics import BOLTZMANN
from ._allan import fit_allan
from ._assemble import _assemble, _given_intervals
from ._fit import chi2_sf
from ._pooling import alone_estimates, disagreements, pooling_note
from ._problems import rec_meta
from ._result import LAB as _LAB_UNITS
from ._result import CalibrationResult, FitError
from ._spectral import _psd_jit, _spectral_args
from ._starts import _start_vector
from ._variance import VarianceArgs, empirical_variance_se, fit_variances
from ._variance_profile import profile_intervals


def _joint_likelihood_se(recs, layout, model, p):
    """Standard errors the joint (Whittle) likelihood of the same recordings would give at
    ``p``: the expected Fisher information of the periodogram ordinates,
    ``sum_f w(f) grad log P(f) grad log P(f)^T``, with the package's spectral model
    (central differences of the compiled model spectrum that the likelihood fits use)."""
    sargs = _spectral_args(recs, layout, model, 1, None)
    p = np.asarray(p, dtype=float)
    floor = 1e-6 * float(np.median([np.var(np.asarray(r.positions)) for r in recs]))
    cols = []
    for i in range(p.size):
        h = 1e-5 * max(abs(p[i]), floor)
        up, dn = p.copy(), p.copy()
        up[i] += h
        dn[i] = max(dn[i] - h, 0.0)
        lp = [np.log(np.asarray(_psd_jit(jnp.asarray(q), sargs))) for q in (up, dn)]
        cols.append((lp[0] - lp[1]) / (up[i] - dn[i]))
    jac = np.stack(cols, axis=-1)  # (R, M, P)
    fisher = np.einsum("rmi,rmj->ij", jac * np.asarray(sargs.weight)[..., None], jac)
    try:
        return np.sqrt(np.clip(np.diag(np.linalg.inv(fisher)), 0, None))
    except np.linalg.LinAlgError:
        return np.full(p.size, np.nan)


def _fit_variance(recs, layout, model, method_name, notes):
    """Variance vs exposure or vs laser power: weighted least squares of the frame
    variances, with 95 % profile intervals and the joint likelihood's SE for comparison."""
    if len(recs) < len(layout.names):
        raise ValueError(
            f"{method_name} needs at least {len(layout.names)} recordings to fit "
            f"{layout.names}; got {len(recs)}"
        )
    v = np.array([np.var(np.asarray(r.positions, dtype=float)) for r in recs])
    n = np.array([float(r.n_frames) for r in recs])
    args = VarianceArgs(layout=layout, model=model, meta=rec_meta(recs), v=jnp.asarray(v),
                        n=jnp.asarray(n), se=jnp.asarray(v * np.sqrt(2.0 / n)))
    scale = _start_vector(recs, layout, model.noise)
    p, cov, chi2, ok, pd, fitted = fit_variances(args, scale)
    if not bool(ok):
        raise FitError(
            f"{method_name}: least squares did not converge; parameters {layout.names}"
            + (". With k = c P, a stiffness not proportional to the power (an offset, k = c "
               "(P - P0)) or a gamma that changes with it (heating) has no good fit: fit "
               "k='per_power' with method='likelihood', or diagnose the series"
               if layout.linear_power else
               ". The variances may not follow the model (check each recording's own fit), "
               "or the data do not determine these parameters: method='likelihood' uses "
               "all the frames"))
    if not bool(pd):
        raise FitError(
            f"{method_name}: parameters {layout.names} are not identifiable from these "
            "variances (need exposures spanning alpha ~ 0.3-10, or several powers)"
        )
    dof = max(len(recs) - len(layout.names), 0)
    gof = {"test": "weighted chi2 of variances", "statistic": float(chi2), "dof": dof,
           "p_value": float(chi2_sf(float(chi2), dof)) if dof > 0 else float("nan")}
    notes = list(notes)
    names = layout.names
    # 95 % profile-likelihood intervals: the Wald interval (value +- 1.96 SE) is not honest
    # here (k = kT/sigma^2 with sigma^2 and eps^2 separated only by the curvature of
    # S(alpha), and eps^2 >= 0: skewed, bounded estimates; benchmarks/RESULTS_variance_methods.md)
    info: dict[str, Any] = {}
    prof = profile_intervals(fitted, p, chi2, info=info)
    intervals = {names[i]: prof[i] for i in range(len(names))}
    wald = np.sqrt(np.clip(np.diag(cov), 0, None))
    txt = []
    for name, (lo, hi) in intervals.items():
        fac, unit = _LAB_UNITS.get(name.split("[")[0], (1.0, "SI"))
        txt.append(f"{name} [{lo * fac:.4g}, {hi * fac:.4g}] {unit}")
    notes.append("95 % profile-likelihood intervals (chi^2 profile, eps^2 >= 0, weights "
                 "re-evaluated along the profile; in result.intervals, SI): " + "; ".join(txt) + ". Use them rather "
                 "than value +- 1.96 SE: the variance methods' estimates are skewed and the "
                 "Wald interval under- or over-covers")
    if "second_branch" in info:
        q, d = info["second_branch"]
        alt = ", ".join(f"{nm} = {_lab(nm, x)}" for nm, x in zip(names, q))
        notes.append(f"{method_name}: the variances are also consistent (Delta chi^2 = {d:.2f} "
                     f"<= 3.84) with a second branch at {alt}, separated from the estimate (the "
                     "global minimum) by a ridge: the exposures or powers hardly separate the "
                     "thermal variance from tracking noise. The 95 % intervals span both "
                     "branches (the hull of the profile set)")
    unbounded = [nm for nm, (lo, hi) in intervals.items()
                 if not np.isfinite(hi) or (lo == 0.0 and nm != "tracking_var")]
    if unbounded:
        notes.append(f"{method_name}: the data do not bound {unbounded} within a factor 1000 "
                     "(weakly identified: exposures or powers too close, or alpha << 1)")
    extras: dict[str, Any] = {"intervals": intervals}
    notes += _comparison_notes(recs, layout, model, method_name, p, prof, wald, extras)
    return _assemble(recs, layout, model, method_name, p, cov, gof, notes, extras,
                     interval_source=_given_intervals(intervals))


def _comparison_notes(recs, layout, model, method_name, p, prof, wald, extras) -> list:
    """The variance method's estimate against the joint likelihood on the same recordings
    (how much smaller its errors are; ``extras["joint_se_ratio"]``), and the shared
    parameters the recordings' own fits disagree on (:mod:`._pooling`)."""
    notes: list[str] = []
    try:
        jse = _joint_likelihood_se(recs, layout, model, p)
        nk = 1 if layout.linear_power else layout.n_k
        # this method's effective SE: the 95 % profile interval's half width / 1.96 (the
        # Wald SE is inflated where eps^2 sits on its bound)
        eff = np.array([(hi - lo) / (2 * 1.959964) if np.isfinite(hi - lo) else w
                        for (lo, hi), w in zip(prof.values(), wald)])
        ratio = float(np.median(eff[:nk] / jse[:nk]))
        g_ratio = float(eff[nk] / jse[nk])
        if np.isfinite(ratio):
            extras["joint_se_ratio"] = ratio
            notes.append(f"the joint likelihood on these recordings gives ~{ratio:.2g}x smaller "
                         f"SE of k (and ~{g_ratio:.2g}x of gamma) than this method's 95 % intervals "
                         "imply: predicted from its Fisher information at this estimate; "
                         "calibrate(..., method='likelihood')")
    except Exception:  # noqa: BLE001 - an advisory note only
        pass
    # the method shares eps^2 (and gamma, and k across exposures): recordings whose own
    # fits disagree on one bias it with no sign in its few degrees of freedom
    try:
        pooled = pooling_note(disagreements(layout, alone_estimates(recs, layout, model)),
                              False, recs)
    except Exception:  # noqa: BLE001 - an advisory note only
        pooled = None
    if pooled:
        notes.append(f"{method_name}: {pooled}")
    return notes


def _lab(name, value):
    """``value`` (SI) of parameter ``name`` as text in lab units."""
    fac, unit = _LAB_UNITS.get(name.split("[")[0], (1.0, "SI"))
    return f"{value * fac:.4g} {unit}"


def _fit_allan(recs, layout, model, notes):
    """k, gamma, eps^2 from the overlapping Allan variance (exact expectation and covariance,
    iterated GLS); errors from the GLS information, goodness of fit from its chi^2."""
    if model.extra or not model.alias:
        raise ValueError("method 'allan' fits the closed-form frame model (naive, blur or "
                         f"standard); got model {model.name!r}")
    scale = _start_vector(recs, layout, model.noise)
    p, cov, chi2, dof, ok, pd, est, bound = fit_allan(recs, layout, rec_meta(recs), model.blur,
                                                      scale)
    if not bool(ok):
        raise FitError(f"allan: the fit did not converge; parameters {layout.names}")
    if not bool(pd):
        raise FitError(f"allan: parameters {layout.names} are not identifiable from these "
                       "Allan variances (dt >> tau leaves no temporal information)")
    gof = {"test": "chi2 of Allan variances (exact covariance)", "statistic": float(chi2),
           "dof": dof, "p_value": float(chi2_sf(float(chi2), dof)) if dof > 0 else float("nan")}
    notes = list(notes) + [f"allan: overlapping Allan variance at {len(e.m)} octave cluster "
                           f"sizes (1..{int(e.m[-1])} frames) of {e.n_frames} frames" for e in est]
    # the information is regular at eps^2 = 0: the unconstrained SE of a bound parameter
    # gives its interval (0, 1.96 SE) (_assemble makes its error NaN, as every fit's)
    bound_se = {n: float(np.sqrt(cov[i, i])) for i, n in enumerate(layout.names) if bound[i]}
    return _assemble(recs, layout, model, "allan", p, cov, gof, notes,
                     extras={"allan": [e.to_dict() for e in est], "bound_se": bound_se},
                     at_bound=bound)


def _equipartition(recs, diffusion, pade, tracking=None):
    """k per recording from its frame variance: naive ``kT/var``, or blur-corrected with a
    given D (exact or Pade inversion of var = kT/k S(alpha)); ``tracking``: a known
    tracking-error variance ``(eps2, se)`` [m^2] subtracted from the variance."""
    ks, kerr = [], []
    notes = []
    eps2, eps2_se = tracking if tracking is not None else (0.0, 0.0)
    for i, r in enumerate(recs):
        v, se = empirical_variance_se(r.positions)
        if eps2 > 0:
            if eps2 >= v:
                raise ValueError(f"fixed['tracking_var'] = {eps2:.4g} m^2 is not below the "
                                 f"frame variance {v:.4g} m^2 of recording {i}: the tracking "
                                 "error cannot exceed the whole variance (check its unit: m^2 "
                                 "in Python, nm^2 on the CLI)")
            v -= eps2
            se = math.hypot(se, eps2_se)
        kt = BOLTZMANN * float(r.temperature)
        if diffusion is None:
            k = kt / v
            ks.append(k)
            kerr.append(k * se / v)
        else:
            from ..physics import stiffness_from_variance

            meth = "pade" if pade else "exact"
            k = float(stiffness_from_variance(v, diffusion, float(r.exposure), float(r.temperature),
                                              method=meth))
            h = v * 1e-6
            dk = (float(stiffness_from_variance(v + h, diffusion, float(r.exposure),
                                                float(r.temperature), method=meth)) - k) / h
            ks.append(k)
            kerr.append(abs(dk) * se)
    if diffusion is None:
        notes.append("naive equipartition k = kT/var(X_m): biased high by motion blur "
                     "(var is reduced by S(alpha))")
        gamma, gerr = math.nan, math.nan
    else:
        notes.append(f"blur-corrected equipartition with given D = {diffusion:.4g} m^2/s "
                     f"({'Pade' if pade else 'exact'} inversion)")
        gamma = BOLTZMANN * float(recs[0].temperature) / diffusion
        gerr = 0.0
    if tracking is None:
        notes.append("equipartition assumes no tracking error (eps^2 = 0): tracking noise "
                     "raises the frame variance and biases k low by about eps^2/var (k too "
                     "small by 10 % when eps^2 is a tenth of the variance); give a known "
                     "tracking-error variance with fixed={'tracking_var': eps2} [m^2] (CLI: "
                     "--fix tracking_var=NM2), or fit it: method='likelihood'")
    else:
        notes.append(f"tracking-error variance eps^2 = {eps2:.4g} m^2 (held) subtracted from "
                     "the frame variance")
    names = tuple(f"k[{i}]" for i in range(len(recs))) if len(recs) > 1 else ("k",)
    values = np.array(ks + ([gamma] if diffusion is not None else []))
    errs = np.array(kerr + ([gerr] if diffusion is not None else []))
    names = names + (("gamma",) if diffusion is not None else ())
    return CalibrationResult(
        method="equipartition",
        model="naive" if diffusion is None else "blur",
        param_names=names,
        values=values,
        covariance=np.diag(errs**2),
        temperature=float(recs[0].temperature),
        k_per_recording=np.array(ks),
        k_per_recording_err=np.array(kerr),
        gof={},
        n_recordings=len(recs),
        n_frames=int(sum(r.n_frames for r in recs)),
        notes=tuple(notes),
    )

