"""From a fit's values and covariance to a :class:`CalibrationResult`, and where its profile
intervals come from."""

from __future__ import annotations

import numpy as np

from .._config import float64_scope
from ._heating import heating_rows
from ._profile import ProfileIntervals
from ._result import CalibrationResult


def _assemble(recs, layout, model, method, values, cov, gof, notes=(), extras=None,
              at_bound=None, interval_source=None, conditional=None):
    """The result of a fit. ``at_bound``: the fit's bound flags (``FitOutput.at_bound``, the
    one rule :func:`blurtrap.inference._fit.at_lower_bound`); those parameters get a NaN error,
    and the others' errors are the fit's: the unconstrained Cramer-Rao bound at the estimate
    (:func:`blurtrap.inference._bound_errors.release_bound`), or, where ``conditional``
    (``FitOutput.conditional``: the full information was not positive definite), conditional
    on the bound and too small; the note says which. ``interval_source``: where the result's
    profile intervals come from (:class:`blurtrap.inference._profile.ProfileIntervals`;
    default: Wald intervals only)."""
    values = np.asarray(values, dtype=float)
    cov = np.asarray(cov, dtype=float)
    names = layout.names
    nk = 1 if layout.linear_power else layout.n_k
    if layout.linear_power:
        powers = np.asarray(layout.power)
        k_rec = values[0] * powers
        k_err = np.sqrt(cov[0, 0]) * powers
    else:
        idx = np.asarray(layout.k_index)
        k_rec = values[:nk][idx]
        k_err = np.sqrt(np.clip(np.diag(cov)[:nk], 0, None))[idx]
    if "power_offset" in names:
        p0 = values[names.index("power_offset")]
        k_rec = k_rec * (1.0 - p0 / np.asarray(layout.power))
    bound = np.zeros(len(names), bool) if at_bound is None else np.asarray(at_bound, bool)
    at_bounds = [n for n, b in zip(names, bound) if b]
    if bound.any():  # NaN error, whatever the caller's covariance says
        cov = cov.copy()
        cov[bound, :] = 0.0
        cov[:, bound] = 0.0
        cov[bound, bound] = np.nan  # (as the fit's own covariance: decoupled, NaN variance)
        notes = tuple(notes) + (_bound_note(at_bounds, conditional, interval_source is not None),)
    temps = {float(r.temperature) for r in recs}
    temperature = float(np.mean(list(temps)))  # one value, or the mean of the recordings'
    change = _viscosity_change(min(temps), max(temps)) if len(temps) > 1 else 0.0
    if change > 1.0:  # (0.4 K apart in water)
        notes = tuple(notes) + (
            f"the recordings are at different temperatures ({min(temps):g}-{max(temps):g} "
            f"K): the result's temperature, kT and D = kT/gamma use their mean "
            f"{temperature:g} K, while k of each recording uses its own; one shared gamma "
            f"assumes one viscosity (water's changes by ~{change:.0f} % between them), so "
            "recordings at different temperatures are better calibrated apart",)
    if "drift_diffusion" in names:
        notes = tuple(notes) + (
            "drift_diffusion: its standard error is ~3x too small (half the drift power is the "
            "record's one end-to-end ramp, so the periodogram ordinates are not independent; "
            "the docstring of blurtrap.inference.EFFECTS['drift']); treat it as an order of "
            "magnitude. The errors of k, gamma and eps^2 stay calibrated.",)
    extras = dict(extras or {})
    rows = heating_rows(recs, names, values, cov)
    if rows:
        extras["per_recording"] = rows
    return CalibrationResult(
        method=method,
        model=model.name,
        param_names=tuple(names),
        values=values,
        covariance=cov,
        temperature=temperature,
        k_per_recording=np.asarray(k_rec, dtype=float),
        k_per_recording_err=np.asarray(k_err, dtype=float),
        gof=gof,
        n_recordings=len(recs),
        n_frames=int(sum(r.n_frames for r in recs)),
        converged=True,
        at_bounds=tuple(at_bounds),
        notes=tuple(notes),
        extras=extras,
        interval_source=interval_source,
    )


def _viscosity_change(lo: float, hi: float) -> float:
    """Water's viscosity change between ``lo`` and ``hi`` [K], in % of the lower-T value."""
    from ..physics import water_viscosity

    return 100.0 * (1.0 - float(water_viscosity(hi)) / float(water_viscosity(lo)))


def _bound_note(at_bounds, conditional, profile=True) -> str:
    """The note of a fit with parameters at their lower bound 0 (``conditional``: the others'
    errors could not be freed from the bound; ``profile``: the result has profile
    intervals)."""
    head = f"{', '.join(at_bounds)} at the lower bound 0: NaN error there"
    if conditional is not None and bool(np.any(conditional)):
        return (head + "; the other errors are CONDITIONAL on the bound (the full Fisher "
                "information, the bound parameter free, is not positive definite) and too "
                "small: use result.intervals (profile likelihood), which account for the bound")
    return (head + "; the other errors are the unconstrained Cramer-Rao bound at the estimate "
            "(the bound parameter counted as free: conservative near the bound); "
            + ("result.intervals gives profile-likelihood intervals that account for the bound"
               if profile else "result.intervals gives (0, 1.96 x its unconstrained error) "
               "for it where the method has that error (no profile likelihood here)"))


def _given_bound(out):
    """The covariance the profile intervals start from: conditional on a bound where one is
    reached (``FitOutput.cov_given_bound``), else the fit's."""
    return out.cov if out.cov_given_bound is None else out.cov_given_bound


def _interval_source(nll, args, scale, out, held, hessian="auto"):
    """Profile intervals of the fit (of its free parameters when some are held; none when
    a held input has an error: its Wald errors include the propagated input error, which a
    profile with the input held would leave out)."""
    if held is None:
        return ProfileIntervals(nll, args, scale, out.value, _given_bound(out), out.at_bound,
                                hessian)
    red, fscale, fargs, rout, free, has_error = held
    if has_error:
        return None
    src = ProfileIntervals(red, fargs, fscale, rout.value, _given_bound(rout), rout.at_bound,
                           hessian)
    return lambda result: float64_scope(src._compute)(
        tuple(result.param_names[i] for i in free))


def _k_mode_of(layout):
    """How the layout shares k across recordings (``result.extras['k_mode']``)."""
    if layout.linear_power:
        return "linear_power"
    return "shared" if layout.n_k == 1 else "per_group"


def _given_intervals(intervals):
    """An ``interval_source`` for intervals already computed (all profile intervals)."""
    table = {n: (float(lo), float(hi)) for n, (lo, hi) in intervals.items()}
    return lambda result: (table, {n: "profile" for n in table})

