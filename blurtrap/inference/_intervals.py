"""The result's 95 % intervals: the Wald table with the profile intervals merged in."""

from __future__ import annotations

import math

#: two-sided 95 % normal quantile (Wald intervals: estimate +- Z95 SE)
Z95 = 1.959963984540054
#: parameters that are positive by construction (their Wald interval is taken on log scale
#: where it would reach below 0)
_POSITIVE = ("k", "c", "gamma", "displacement_sensitivity", "force_sensitivity",
             "hydro_radius", "f3db")


def wald_intervals(names, values, errors, at_bounds, extras):
    """``(intervals, kinds)`` from the estimates and their errors: Wald; log-Wald for a positive
    parameter whose interval would reach below 0; eps^2's cut at 0; a parameter at its bound 0
    ``(0, Z95 x unconstrained SE)`` where the fit gives that SE (``extras["bound_se"]``,
    method 'allan'), else ``(0, NaN)`` (a profile, where there is one, replaces it)."""
    ivs, kinds = {}, {}
    for n, v, se in zip(names, values, errors, strict=True):
        h = Z95 * float(se)
        ivs[n], kinds[n] = (float(v - h), float(v + h)), "wald"
        # a positive quantity whose Wald interval reaches below 0 (a large relative
        # error): the same delta-method error on log scale, which stays positive
        if n.split("[")[0] in _POSITIVE and v > 0 and v - h < 0:
            ivs[n] = (float(v * math.exp(-h / v)), float(v * math.exp(h / v)))
            kinds[n] = "log-wald"
        elif n == "tracking_var" and v - h < 0 <= v:  # a variance: not below its bound
            ivs[n], kinds[n] = (0.0, float(v + h)), "wald (cut at 0)"
    for n in (extras or {}).get("held", ()):  # held without an input error: no interval to speak of
        if n in ivs and float(errors[list(names).index(n)]) == 0.0:
            kinds[n] = "held"
    bound_se = (extras or {}).get("bound_se") or {}
    for n in at_bounds:
        if n in ivs:
            se = float(bound_se.get(n, math.nan))
            ivs[n] = (0.0, Z95 * se if math.isfinite(se) else math.nan)
            if math.isfinite(se):
                kinds[n] = "wald (at the bound 0)"
    return ivs, kinds


def merge(ivs: dict, kinds: dict, more: dict, more_kinds: dict) -> None:
    """Put the intervals ``more`` (a profile's, ``(low, high)`` with NaN for an end whose
    root find or profile fit did not converge) into the Wald table ``ivs`` / ``kinds``, in
    place. Both ends converged: the profile interval. One end: that end, and the Wald (or
    log-Wald) end on the other side, labelled ``"profile (upper end wald: its profile did not
    converge)"``; a converged end was discarded with its twin before (intervals of records a
    few relaxation times long). None: the Wald interval, labelled ``"wald (profile did not
    converge)"``."""
    for n, iv in more.items():
        ends = [math.isfinite(e) for e in iv]
        if all(ends):
            ivs[n], kinds[n] = iv, more_kinds[n]
        elif any(ends):
            ivs[n] = tuple(e if ok else w for e, ok, w in zip(iv, ends, ivs[n]))
            side = "lower" if ends[1] else "upper"
            kinds[n] = f"{more_kinds[n]} ({side} end {kinds[n]}: its {more_kinds[n]} did not converge)"
        else:
            kinds[n] += f" ({more_kinds[n]} did not converge)"
