"""Time stamps of a recording: strictly increasing, regular to a tolerance (or kept
irregular on request), and the :class:`TimingJitter` that describes them."""

from __future__ import annotations

import math
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



def rounded_resolution(steps: np.ndarray) -> float | None:
    """The resolution q [s] to which time stamps were rounded, when their `steps` take only
    two or three adjacent multiples of q (float noise merged), at least 2 q each, with their
    mean strictly between the smallest and the largest: stamps of a regular clock written
    with too few digits (1500 frames/s in 0.1 ms: steps of 0.6 and 0.7 ms, mean 0.6667 ms).
    None otherwise, e.g. for dropped frames (steps of dt and 2 dt)."""
    u = np.unique(steps)  # sorted
    mean = float(np.mean(steps))
    cut = np.flatnonzero(np.diff(u) > 1e-6 * mean) + 1
    if not 1 <= cut.size <= 2:
        return None
    centres = np.array([float(g.mean()) for g in np.split(u, cut)])
    q = float(np.min(np.diff(centres)))
    m = centres / q
    adjacent = np.all(np.abs(m - np.round(m)) < 0.01) and np.all(np.diff(np.round(m)) == 1)
    # m[0] >= 2: the resolution is at most half the shortest step (dropped frames give steps
    # of dt and 2 dt: "q" = dt, m[0] = 1)
    if not (adjacent and m[0] > 1.5 and centres[0] + 0.01 * q < mean < centres[-1] - 0.01 * q):
        return None
    return q


def stamp_quantum(steps: np.ndarray) -> float | None:
    """The resolution q [s] of time stamps whose `steps` (dropped frames and all) take a few
    values (at most 64, float noise merged), every one an integer multiple of q, the shortest
    at least 2 q: stamps written with too few digits (1500 frames/s in us with dropped frames:
    steps of 666, 667, 1333 and 1334 us). None otherwise: stamps at full precision (steps of
    dt and 2 dt: "q" = dt), or continuous jitter (many values)."""
    steps = np.asarray(steps, dtype=float)
    if steps.size < 2 or not np.all(steps > 0):
        return None
    u = np.unique(steps)  # sorted
    cut = np.flatnonzero(np.diff(u) > 1e-6 * float(np.median(steps))) + 1
    if not 1 <= cut.size <= 63:
        return None
    centres = np.array([float(g.mean()) for g in np.split(u, cut)])
    q = float(np.min(np.diff(centres)))
    m = centres / q
    if not (np.all(np.abs(m - np.round(m)) < 0.01) and m[0] > 1.5):
        return None
    return q


def _tolerance_for(q: float, frame_interval: float) -> float:
    """``q / frame_interval`` rounded up to two significant digits: a timing_tolerance that
    accepts stamps rounded to q (their median step is within q of the interval, and they lie
    within q / 2 of a regular grid)."""
    x = q / frame_interval
    scale = 10.0 ** (1 - math.floor(math.log10(x)))
    return math.ceil(x * scale - 1e-6) / scale


def _rounded_hint(steps: np.ndarray, t: np.ndarray, frame_interval: float, tol: float,
                  irregular: bool = False) -> str:
    """A sentence naming rounded time stamps as the cause (and the timing_tolerance that
    accepts them) when the steps are those of a regular clock at `frame_interval` rounded to
    a resolution; else ""."""
    q = rounded_resolution(steps)
    mean = float(t[-1] - t[0]) / (t.shape[0] - 1)
    if q is None or not abs(mean - frame_interval) <= tol * frame_interval + q / (t.shape[0] - 1):
        return _rounded_dropped_hint(steps, frame_interval)
    values = ", ".join(_g(v) for v in np.unique(np.round(steps / q)) * q)
    not_what = "jitter or dropped frames" if irregular else "a unit slip"
    return (
        f". The time stamps look rounded to a resolution of {_g(q)} s, "
        f"{_g(q / frame_interval)} frame intervals (written with too few digits): the steps "
        f"take only the values {values} s, multiples of {_g(q)} s, and their mean "
        f"{_g(mean)} s matches frame_interval = {_g(frame_interval)} s. This is rounding, not "
        f"{not_what}: pass timing_tolerance={_tolerance_for(q, frame_interval):g} (relative; a "
        "manifest key too) to accept them, or write the times with more digits"
    )


def _rounded_dropped_hint(steps: np.ndarray, frame_interval: float) -> str:
    """The sentence of :func:`_rounded_hint` for rounded stamps with dropped frames: steps of
    a few multiples of a resolution q (:func:`stamp_quantum`), each within q of a whole number
    of frame intervals; else ""."""
    q = stamp_quantum(steps)
    if q is None or q > 0.25 * frame_interval:
        return ""
    whole = np.maximum(np.round(steps / frame_interval), 1.0)
    if float(np.max(np.abs(steps - whole * frame_interval))) > q * (1.0 + 1e-6):
        return ""
    values = np.unique(np.round(steps / q)) * q
    shown = ", ".join(_g(v) for v in values[:6]) + (" ..." if values.size > 6 else "")
    return (
        f". The time stamps look rounded to a resolution of {_g(q)} s, "
        f"{_g(q / frame_interval)} frame intervals (written with too few digits): the steps "
        f"take only the values {shown} s, multiples of {_g(q)} s, each within {_g(q)} s of a "
        f"whole number of frame intervals ({int(np.count_nonzero(whole > 1))} dropped "
        f"frame(s)). Pass timing_tolerance={_tolerance_for(q, frame_interval):g} (relative; a "
        "manifest key too) and allow_irregular=True to keep them, or write the times with more "
        "digits"
    )


def _median_message(d, med: float, t, frame_interval: float, tol: float) -> str:
    """Why the median step `med` disagrees with `frame_interval`: rounded time stamps
    (named with the tolerance that accepts them), or a unit slip of either."""
    head = (f"times imply a frame interval of {_g(med)} s (median step) but frame_interval = "
            f"{_g(frame_interval)} s; they differ by more than timing_tolerance = {tol:g} (relative)")
    rounded = _rounded_hint(d, t, frame_interval, tol)
    if rounded:
        return head + rounded
    ratio = med / frame_interval
    hint = (
        f" (the steps are {_g(ratio)} x frame_interval: the times look like ms)"
        if abs(ratio / 1e3 - 1) < 0.05
        else f" (frame_interval is {_g(1 / ratio)} x the steps: frame_interval looks like ms)"
        if abs(1 / ratio / 1e3 - 1) < 0.05
        else ""
    )
    return f"{head}{hint}. Check the units of both (seconds)"


def infer_frame_interval(times: np.ndarray, tol: float = DEFAULT_TIMING_TOLERANCE) -> float:
    """Frame interval [s] from time stamps: the median step, refined to the least-squares
    slope of ``t`` against frame index when the two agree to ``tol`` (regular stamps) or
    when the stamps are rounded (:func:`rounded_resolution`: the median is one of the two
    rounded steps, the slope the clock's interval)."""
    d = np.diff(times)
    med = float(np.median(d))
    i = np.arange(times.shape[0], dtype=np.float64)
    ic = i - i.mean()
    slope = float(np.dot(ic, times - times.mean()) / np.dot(ic, ic))
    if abs(slope - med) <= tol * med:
        return slope
    q = rounded_resolution(d) if d.size and np.all(d > 0) else None
    return slope if q is not None and abs(slope - med) <= q else med


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
    if abs(med - frame_interval) > tol * frame_interval:
        raise ValueError(_median_message(d, med, t, frame_interval, tol))
    del d
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
        rounded = _rounded_hint(np.diff(t), t, frame_interval, tol, irregular=True)
        raise ValueError(
            f"times are irregular: per-interval jitter (std of the frame intervals) "
            f"std {_g(jitter.std)} s and max deviation from the best regular grid "
            f"{_g(jitter.max_deviation)} s (at times[{k}] = {float(t[k])!r}; grid deviation "
            f"std {_g(jitter.grid_std)} s), i.e. {_g(jitter.max_deviation / frame_interval)} "
            f"frame intervals > timing_tolerance = {tol:g}. Largest step {_g(d_max)} s, "
            f"smallest {_g(d_min)} s" + (rounded or " (dropped frames?). Pass allow_irregular=True "
                                         "(a manifest key too) to keep them (reported in timing_jitter)")
        )
    return t, jitter

