"""Time stamps of a recording: strictly increasing, regular to a tolerance (or kept
irregular on request), and the :class:`TimingJitter` that describes them."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from ._values import fmt_g as _g
from ._values import numeric_array

#: Default tolerance on time-stamp irregularity, relative to the frame interval.
DEFAULT_TIMING_TOLERANCE = 1e-3


class TimingJitter(NamedTuple):
    """Irregularity of the time stamps ``t``.

    **Fields** (all [s]):

    - ``std``: the per-interval jitter, the standard deviation of the frame intervals
      ``t[i+1] - t[i]``. If each stamp has an independent error of std sigma (e.g.
      ``blurtrap.simulate.TimingJitter(sigma)``) this is ``sqrt(2) * sigma``; if the intervals
      vary independently (a clock that wanders) it is their std.
    - ``max_deviation``: the largest absolute deviation of ``t`` from the best-fitting
      regular grid ``t0 + i * dt`` (what ``timing_tolerance`` is compared with).
    - ``fitted_interval``: the slope ``dt`` of that grid.
    - ``grid_std``: the standard deviation of the deviations from that grid. For a wandering
      clock it is the accumulated wander and grows with the record length, so it can be far
      larger than ``std`` (it was reported as ``std`` before).
    """

    std: float
    max_deviation: float
    fitted_interval: float
    grid_std: float | None = None



def check_times(times, n: int, frame_interval: float, tol: float, allow_irregular: bool):
    t = numeric_array(times, "times", "s")
    if t.ndim != 1 or t.shape[0] != n:
        raise ValueError(
            f"times must be a 1-D array with one time stamp per frame ({n}) [s]; "
            f"got shape {t.shape}"
        )
    t = np.array(t, dtype=np.float64, copy=True)
    bad = np.flatnonzero(~np.isfinite(t))
    if bad.size:
        raise ValueError(
            f"times contains {bad.size} non-finite value(s) (NaN/inf); first: "
            f"times[{bad[0]}] = {float(t[bad[0]])!r}"
        )
    d = np.diff(t)
    nonincr = np.flatnonzero(d <= 0)
    if nonincr.size:
        i = int(nonincr[0]) + 1
        raise ValueError(
            f"times must be strictly increasing; times[{i}] = {float(t[i])!r} s is not after "
            f"times[{i - 1}] = {float(t[i - 1])!r} s ({nonincr.size} non-increasing step(s) in all)"
        )
    d_max, d_min = float(d.max()), float(d.min())
    interval_std = float(np.std(d))
    h = d.size // 2  # np.median(d) without another copy (d is a temporary)
    if d.size % 2:
        d.partition(h)
        med = float(d[h])
    else:
        d.partition((h - 1, h))
        med = float(np.mean(d[h - 1 : h + 1]))
    del d
    if abs(med - frame_interval) > tol * frame_interval:
        ratio = med / frame_interval
        hint = (
            f" (the steps are {_g(ratio)} x frame_interval: the times look like ms)"
            if abs(ratio / 1e3 - 1) < 0.05
            else f" (frame_interval is {_g(1 / ratio)} x the steps: frame_interval looks like ms)"
            if abs(1 / ratio / 1e3 - 1) < 0.05
            else ""
        )
        raise ValueError(
            f"times imply a frame interval of {_g(med)} s (median step) but frame_interval = "
            f"{_g(frame_interval)} s; they differ by more than timing_tolerance = {tol:g} "
            f"(relative){hint}. Check the units of both (seconds)"
        )
    # deviation from the least-squares regular grid t0 + i * dt (in place: long records
    # are validated with a few temporaries of their own size)
    ic = np.arange(n, dtype=np.float64)
    ic -= ic.mean()
    resid = t - t.mean()
    slope = float(np.dot(ic, resid) / np.dot(ic, ic))
    ic *= slope
    resid -= ic
    del ic
    max_dev = max(float(resid.max()), -float(resid.min()))
    jitter = TimingJitter(interval_std, max_dev, slope, float(np.std(resid)))
    if jitter.max_deviation > tol * frame_interval and not allow_irregular:
        k = int(np.argmax(np.abs(resid)))
        raise ValueError(
            f"times are irregular: per-interval jitter (std of the frame intervals) "
            f"std {_g(jitter.std)} s and max deviation from the best regular grid "
            f"{_g(jitter.max_deviation)} s (at times[{k}] = {float(t[k])!r}; grid deviation "
            f"std {_g(jitter.grid_std)} s), i.e. {_g(jitter.max_deviation / frame_interval)} "
            f"frame intervals > timing_tolerance = {tol:g}. Largest step {_g(d_max)} s, "
            f"smallest {_g(d_min)} s (dropped frames?). Pass allow_irregular=True (a manifest "
            "key too) to keep them (reported in timing_jitter)"
        )
    return t, jitter

