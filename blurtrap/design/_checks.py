"""Argument checks of :func:`blurtrap.design.design` (clear errors naming the parameter, its
value and what was expected)."""

from __future__ import annotations

import math
import warnings

import numpy as np

from ..data.internal import (
    MAX_BEAD_RADIUS_M,
    MAX_PLAUSIBLE_INTERVAL_S,
    MAX_PLAUSIBLE_POSITION_STD_M,
    check_temperature,
    in_ms_message,
    likely_position_unit,
)
from ..effects import QUANTITIES
from ..physics import water_viscosity

#: the design targets (the SE each minimises; see design's docstring)
TARGETS = ("k", "gamma", "both", "determinant", "force_sensitivity")


#: the paper's exposure series relative to the fastest frame interval (W/dt_min); section 5.4
PAPER_SERIES = (0.15, 0.3, 0.6, 1.0)
#: the fewest frames per recording a design may plan
MIN_FRAMES = 64


def largest_candidate(series, powers) -> int:
    """The most recordings any candidate splits the budget into: the paper's series, the
    longest of `series`, or one per laser power."""
    return max([len(PAPER_SERIES), *series, len(powers or ())])


def total_time_needed(max_fps: float, n_rec: int) -> float:
    """The shortest total time [s] that gives each of `n_rec` recordings at least
    ``MIN_FRAMES`` frames at `max_fps`, rounded up to 3 significant digits."""
    need = MIN_FRAMES * n_rec / max_fps
    step = 10.0 ** (math.floor(math.log10(need)) - 2)
    return math.ceil(need / step * (1 - 1e-12)) * step


def checked_budget(n_frames, total_time, max_fps: float, series, powers) -> None:
    """Exactly one of `n_frames` (>= 64 per recording) or `total_time` (at least 64 frames
    for each recording of the largest candidate at `max_fps`), and the `series` lengths."""
    if (n_frames is None) == (total_time is None):
        raise ValueError("give exactly one of n_frames (per recording) or total_time [s]")
    if n_frames is not None and (isinstance(n_frames, bool) or int(n_frames) != n_frames
                                 or n_frames < MIN_FRAMES):
        raise ValueError(f"n_frames must be an integer >= {MIN_FRAMES}; got n_frames = {n_frames!r}")
    for n_exp in series:
        if isinstance(n_exp, bool) or not isinstance(n_exp, (int, np.integer)) or n_exp < 1:
            raise ValueError(f"series must hold whole numbers of exposures >= 1; got {n_exp!r}")
    if total_time is None:
        return
    _check("total_time", total_time, unit="s")
    n_rec = largest_candidate(series, powers)
    if total_time * max_fps * (1 + 1e-12) < MIN_FRAMES * n_rec:
        raise ValueError(f"total_time = {total_time:g} s is {total_time * max_fps:.4g} frames at max_fps = "
                         f"{max_fps:g} Hz, too few to split into {n_rec} recordings (the largest candidate) "
                         f"of at least {MIN_FRAMES} frames each: give total_time >= "
                         f"{total_time_needed(max_fps, n_rec):.3g} s")


def _check(name, value, lo=0.0, unit=""):
    if value is None or not np.isfinite(value) or value <= lo:
        raise ValueError(f"{name} must be a finite number > {lo:g} {unit}; got {name} = "
                         f"{value!r}")
    return float(value)


def _checked_friction(target, friction_error) -> float:
    """The target and the friction prior checked: ``friction_se`` (< 0: friction fitted)."""
    if target not in TARGETS:
        raise ValueError(f"target must be one of {TARGETS}; got target = {target!r}")
    if friction_error is None:
        if target == "force_sensitivity":
            raise ValueError("target='force_sensitivity' is the passive calibration in volts "
                             "with the friction known from the bead: give friction_error (its "
                             "relative SE, >= 0)")
    else:
        if (isinstance(friction_error, bool) or not np.isfinite(friction_error)
                or friction_error < 0):
            raise ValueError(f"friction_error must be a relative SE >= 0 (or None: friction "
                             f"fitted); got friction_error = {friction_error!r}")
        if friction_error == 0 and target in ("gamma", "both", "determinant"):
            raise ValueError(f"target={target!r} needs the SE of gamma, but friction_error = 0 "
                             "says gamma is known exactly; use target='k' or "
                             "'force_sensitivity', or give friction_error > 0")
    return -1.0 if friction_error is None else float(friction_error)


class NotIdentifiedError(ValueError):
    """No candidate design identifies what the fit must identify (`what`: ``"k"`` or ``"both
    k and gamma"``; `friction_fitted`: the friction is fitted, not known from the bead)."""

    def __init__(self, message: str, what: str, friction_fitted: bool):
        super().__init__(message)
        self.what = what
        self.friction_fitted = friction_fitted


def distinct(a: float, b: float) -> tuple[str, str]:
    """`a` and `b` formatted with 3 significant digits, or as many more as tell them apart."""
    for digits in (3, 6, 9):
        if f"{a:.{digits}g}" != f"{b:.{digits}g}":
            break
    return f"{a:.{digits}g}", f"{b:.{digits}g}"


def check_timing(max_fps: float, min_exposure: float, dead_time: float) -> None:
    """Room for an exposure in the frame interval at the fastest frame rate: min_exposure
    shorter than 1/max_fps, and 0 <= dead_time < 1/max_fps - min_exposure (each named with
    its value, never as a range whose upper end is negative)."""
    dt_min = 1.0 / max_fps
    if not min_exposure < dt_min:
        w, dt = distinct(min_exposure, dt_min)
        longer = min_exposure > dt_min
        raise ValueError(f"min_exposure = {w} s is {'longer than' if longer else 'as long as'} the frame "
                         f"interval at max_fps = {max_fps:g} Hz (1/max_fps = {dt} s): "
                         + ("an exposure cannot be longer than the frame interval" if longer else
                            "design needs exposures shorter than the frame interval")
                         + "; lower min_exposure or max_fps")
    if not dead_time >= 0:
        raise ValueError(f"dead_time must be >= 0 s; got dead_time = {dead_time!r}")
    if not dead_time < dt_min - min_exposure:
        raise ValueError(f"dead_time = {dead_time:g} s leaves no time for an exposure: the frame interval "
                         f"at max_fps = {max_fps:g} Hz is {dt_min:.3g} s and the shortest exposure "
                         f"min_exposure = {min_exposure:g} s, so dead_time must be below 1/max_fps - "
                         f"min_exposure = {dt_min - min_exposure:.3g} s")


def _checked_noise(tracking_std, photon_limited) -> float:
    """eps_ref^2 [m^2] from the tracking-error rms, checked."""
    if tracking_std < 0 or not np.isfinite(tracking_std):
        raise ValueError(f"tracking_std must be >= 0 [m]; got {tracking_std!r}")
    if photon_limited and tracking_std == 0:
        raise ValueError("photon_limited needs tracking_std > 0 at the reference exposure")
    return float(tracking_std) ** 2


def checked_trap(k, gamma, radius, viscosity, temperature, check_units: bool = True):
    """``(ks, gamma, temperature)``: the stiffnesses (a range ``(k_min, k_max)`` becomes three
    log-spaced values), the friction (given, or Stokes from the radius and viscosity, water
    at the temperature by default) and the temperature, checked (with `check_units`, each
    within its plausible range in SI: a value in lab units is named as such)."""
    given = tuple(float(v) for v in np.atleast_1d(np.asarray(k, dtype=float)))
    for v in given:
        _check("k", v, unit="N/m")
    if check_units:
        _check_range("k", given)
    ks = tuple(np.geomspace(given[0], given[1], 3)) if len(given) == 2 else given
    temperature = check_temperature(temperature, check_units)
    stokes = ""
    if gamma is None:
        if radius is None:
            raise ValueError("give gamma [N s/m] or the bead radius [m]")
        radius = _check("radius", radius, unit="m")
        if check_units:
            _check_radius(radius)
        eta = viscosity if viscosity is not None else float(water_viscosity(temperature))
        gamma = 6.0 * math.pi * _check("viscosity", eta, unit="Pa s") * radius
        stokes = f" (the Stokes friction 6 pi eta r of radius = {radius:g} m, viscosity = {eta:g} Pa s)"
    gamma = _check("gamma", gamma, unit="N s/m")
    if check_units:
        _check_range("gamma", (gamma,), stokes)
    return ks, gamma, temperature


#: lab units a stiffness or friction given in the wrong unit may be in, with their SI factor
_LAB_UNITS = {"k": (("pN/um", 1e-6), ("pN/nm", 1e-3)),
              "gamma": (("pN s/um", 1e-6), ("pN s/nm", 1e-3))}
#: radii a bead in the wrong unit may have: it fits the optical tweezers' beads, 10 nm..100 um
_RADIUS_UNITS = (("um", 1e-6), ("nm", 1e-9))
_MIN_LISTED_RADIUS_M, _MAX_LISTED_RADIUS_M = 1e-8, 1e-4
_ESCAPE = "; pass check_units=False if the value is right"


def _check_range(name: str, values, given_as: str = "") -> None:
    """Each of `values` within the plausible range of quantity `name` (``Param.bounds``, the
    support of calibrate's default priors), else a ValueError naming the lab unit that fits."""
    q = QUANTITIES[name]
    assert q.bounds is not None  # k and gamma have plausible ranges
    lo, hi = q.bounds
    for v in values:
        if lo <= v <= hi:
            continue
        fits = [f"{v:g} {u} = {v * f:g} {q.unit}" for u, f in _LAB_UNITS[name] if lo <= v * f <= hi]
        hint = (f"this looks like lab units ({' or '.join(fits)}), not {q.unit}" if fits
                else "this looks like a unit slip")
        raise ValueError(f"{name} = {v:g} {q.unit}{given_as} is outside the plausible range of the "
                         f"{q.description}, {lo:g}..{hi:g} {q.unit}: {hint}. design takes SI "
                         f"({q.unit}){_ESCAPE}")


def _check_radius(radius: float) -> None:
    """A bead radius [m] below the data layer's limit (1 mm), else a ValueError naming the
    unit the number fits."""
    if radius < MAX_BEAD_RADIUS_M:
        return
    fits = [f"{radius:g} {u} = {radius * f:g} m" for u, f in _RADIUS_UNITS
            if _MIN_LISTED_RADIUS_M <= radius * f <= _MAX_LISTED_RADIUS_M]
    hint = f"this looks like {' or '.join(fits)}" if fits else "this looks like um or nm"
    raise ValueError(f"radius = {radius:g} m is not below {MAX_BEAD_RADIUS_M:g} m, larger than any "
                     f"trapped bead: {hint}, not metres (a 1 um bead has radius = 5e-7 m: the "
                     f"radius, not the diameter). design takes metres{_ESCAPE}")


def check_units_of(tracking_std: float, max_fps: float, min_exposure: float,
                   reference_exposure) -> None:
    """The unit checks of design's acquisition settings: a tracking error above what any
    trapped bead moves (nm given as metres), exposures of 0.1 s or more (ms given as s). A
    frame rate below 10 frames/s is accepted (a slow camera on a soft trap), with a warning
    that it may be kHz and that the loaders take such intervals for ms."""
    if tracking_std > MAX_PLAUSIBLE_POSITION_STD_M:
        unit = likely_position_unit(tracking_std, "m")
        hint = f"{unit} ({tracking_std:g} {unit})" if unit else "nm or um"
        raise ValueError(f"tracking_std = {tracking_std:g} m is above {MAX_PLAUSIBLE_POSITION_STD_M:g} m "
                         "(10 um), more than a trapped bead moves (0.6 nm..0.2 um): the tracking "
                         f"error (its rms) looks like {hint}, not metres. design takes metres"
                         f"{_ESCAPE}")
    for name, value in (("min_exposure", min_exposure), ("reference_exposure", reference_exposure)):
        if value is not None and value >= MAX_PLAUSIBLE_INTERVAL_S:
            raise ValueError(in_ms_message(name, float(value)))
    if 1.0 / max_fps >= MAX_PLAUSIBLE_INTERVAL_S:  # stacklevel: design, its float64_scope, the caller
        warnings.warn(f"max_fps = {max_fps:g} Hz is below {1 / MAX_PLAUSIBLE_INTERVAL_S:g} frames/s: "
                      f"if the camera runs at {max_fps:g} kHz, pass max_fps={max_fps * 1e3:g} (Hz). "
                      "If it is this slow, the data loaders take frame intervals of "
                      f"{MAX_PLAUSIBLE_INTERVAL_S:g} s or more for ms unless given check_units=False "
                      "(design(check_units=False) does not warn)", UserWarning, stacklevel=4)


def checked_current(current, check_units: bool) -> list:
    """The user's design ``[(frame interval, exposure, frames[, laser power]), ...]`` as
    tuples of floats, checked."""
    cur = [tuple(float(x) for x in r) for r in current]
    for i, r in enumerate(cur):
        if len(r) not in (3, 4) or not (0 < r[1] <= r[0]) or (len(r) == 4 and not r[3] > 0):
            raise ValueError(f"current: each recording needs (frame interval, exposure, "
                             f"frames[, laser power > 0]) with 0 < exposure <= frame "
                             f"interval; got {r}")
        if not r[2] >= 2:
            raise ValueError(f"current[{i}]: frames = {r[2]:g}; a recording needs at least 2 "
                             f"frames (frame interval, exposure, frames); got {r}")
        if check_units and r[0] >= MAX_PLAUSIBLE_INTERVAL_S:
            raise ValueError(f"current[{i}]: " + in_ms_message("frame_interval", r[0]))
    if len({len(r) for r in cur}) > 1:
        raise ValueError("current: give a laser power for every recording or for none")
    return cur
