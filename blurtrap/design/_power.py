"""The laser powers of :func:`blurtrap.design.design`: their check and the power-series
candidates (k = c P, paper section 6.3: recording i at p_i times the power k is given at has
k_i = k p_i; gamma and eps^2 shared; the information in log c is each recording's in log k_i,
summed, as :func:`._fisher._informations` does for recordings ``(dt, W, N, p)``)."""

from __future__ import annotations

import numpy as np


def checked_powers(laser_powers) -> tuple | None:
    """The available laser powers (multiples of the power k is given at), checked and sorted."""
    if laser_powers is None:
        return None
    expected = ("a sequence of at least 2 distinct finite powers > 0, as multiples of the "
                "power at which k is given (e.g. (0.5, 1, 2))")
    if isinstance(laser_powers, (str, bytes)) or np.ndim(laser_powers) != 1:
        raise ValueError(f"laser_powers must be {expected}; got laser_powers = "
                         f"{laser_powers!r}")
    vals = []
    for p in laser_powers:
        if isinstance(p, (bool, str, bytes)) or not isinstance(p, (int, float, np.number)) \
                or not np.isfinite(p) or p <= 0:
            raise ValueError(f"laser_powers must be {expected}; got laser_powers = "
                             f"{laser_powers!r} (bad value {p!r})")
        vals.append(float(p))
    if len(vals) < 2 or len(set(vals)) != len(vals):
        raise ValueError(f"laser_powers must be {expected}; got laser_powers = "
                         f"{laser_powers!r}")
    return tuple(sorted(vals))


def power_candidates(powers: tuple, common: tuple, dt_min: float, w_min: float,
                     dead_time: float, budget: float, by_time: bool) -> list:
    """The power-series candidates: every power at W = dt (the budget split equally), every
    power with its own exposure and a common frame interval optimised by gradients, and the
    best single power (its exposure and frame interval optimised; the least worst-case
    objective over the powers)."""
    from ._design import _acquisition, _optimised  # (that module imports this one)

    n_p = len(powers)
    names = "/".join(f"{p:g}" for p in powers) + " P"
    n_each = budget / dt_min / n_p if by_time else budget
    cands = [_acquisition(f"power series {names}, W = dt",
                          [(dt_min, dt_min - dead_time, n_each, p) for p in powers], *common)]
    opt = _optimised(n_p, common, dt_min, w_min, dead_time, budget, by_time, powers=powers,
                     label=f"optimised power series {names}")
    singles = [_optimised(1, common, dt_min, w_min, dead_time, budget, by_time, powers=(p,),
                          label=f"best single power ({p:g} P)") for p in powers]
    singles = [c for c in singles if c is not None]
    if singles:
        cands.append(min(singles, key=lambda c: c.objective))
    return cands + ([opt] if opt is not None else [])
