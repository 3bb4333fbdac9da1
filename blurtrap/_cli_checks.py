"""The options of ``blurtrap simulate``, ``design`` and ``calibrate`` checked in the command
line's own units before any work: a value in the wrong unit is named by its flag, the value,
the unit the flag takes and the likely slip (``--radius is in um; 1.53e-06 um is below any
trapped bead's radius (0.001..1000 um): did you give metres? use --radius 1.53``), never by
the Python API's parameter names or options (``check_units=False``, ``min_exposure``, ...).
The limits are the data layer's (what :class:`blurtrap.Recording` and the loaders accept) and
the plausible ranges of k and gamma (``QUANTITIES[...].bounds``), in lab units."""

from __future__ import annotations

import math
import re

from .cli import CliError
from .data.internal import (
    MAX_BEAD_RADIUS_M,
    MAX_PLAUSIBLE_INTERVAL_S,
    MAX_PLAUSIBLE_LASER_POWER_W,
    MAX_PLAUSIBLE_POSITION_STD_M,
    MAX_PLAUSIBLE_TEMPERATURE_K,
    MIN_PLAUSIBLE_POSITION_STD_M,
    MIN_PLAUSIBLE_TEMPERATURE_K,
)
from .design.internal import MIN_FRAMES, largest_candidate, total_time_needed

#: the temperatures [K] and the largest laser power [mW] blurtrap.Recording accepts with its
#: unit checks (blurtrap.data's own limits)
TEMPERATURE_K = (MIN_PLAUSIBLE_TEMPERATURE_K, MAX_PLAUSIBLE_TEMPERATURE_K)
MAX_POWER_MW = MAX_PLAUSIBLE_LASER_POWER_W * 1e3
#: bead radii [um]: from 1 nm up to the data layer's largest bead (1 mm, excluded)
RADIUS_UM = (1e-3, MAX_BEAD_RADIUS_M * 1e6)
MIN_FPS = 1.0 / MAX_PLAUSIBLE_INTERVAL_S  # slower: frame intervals the loaders read as ms
MAX_EXPOSURE_MS = MAX_PLAUSIBLE_INTERVAL_S * 1e3
MAX_TRACKING_NM = MAX_PLAUSIBLE_POSITION_STD_M * 1e9


def _num(v: float) -> str:
    return f"{v:.6g}"


def _distinct(a: float, b: float) -> tuple[str, str]:
    """`a` and `b` formatted with 3 significant digits, or as many more as tell them apart."""
    for digits in (3, 6, 9):
        if f"{a:.{digits}g}" != f"{b:.{digits}g}":
            break
    return f"{a:.{digits}g}", f"{b:.{digits}g}"


def _short(v: float) -> str:
    """`v` as ``:g``, or with 3 significant digits where that is shorter."""
    return min(f"{v:g}", f"{v:.3g}", key=len)


def _span(lo: float, hi: float, unit: str, hi_open: bool) -> str:
    if math.isinf(hi):
        return f"{_short(lo)} {unit} or more"
    if lo == 0:
        return f"{'below' if hi_open else 'up to'} {_short(hi)} {unit}"
    return f"{_short(lo)}..{_short(hi)} {unit}"


def out_of_range(flag: str, value: float, unit: str, what: str, lo: float, hi: float,
                 slips=(), typical: float = 1.0, hi_open: bool = False, given: str = "") -> None:
    """A CliError when `value` [`unit`] of `flag` lies outside ``lo..hi`` (``hi`` excluded
    with `hi_open`): ``"FLAG is in UNIT; VALUE UNIT is below|above WHAT (lo..hi UNIT): did
    you give SLIP? use FLAG FIXED"``, SLIP the first of `slips` (``(unit name, value -> value
    in UNIT)``) that lands in range, nearest `typical` on a log scale; `given`: how the value
    came about, put before the value (``"with --radius 1 um, "``)."""
    def inside(v):
        return lo <= v and (v < hi if hi_open else v <= hi)

    if inside(value):
        return
    fits = sorted((abs(math.log(max(fixed, 1e-300) / typical)), name, fixed) for name, convert in slips
                  if inside(fixed := convert(value)))
    head = (f"{flag} is in {unit}; {given}{_num(value)} {unit} is {'below' if value < lo else 'above'} "
            f"{what} ({_span(lo, hi, unit, hi_open)})")
    if fits:
        _, name, fixed = fits[0]
        raise CliError(f"{head}: did you give {name}? use {flag} {_num(fixed)}")
    raise CliError(f"{head}: check the value and its unit")


def positive(flag: str, value, unit: str, zero: bool = False) -> None:
    """A CliError unless `value` (a number or a list of them) is finite and > 0 (>= 0 with
    `zero`)."""
    values = value if isinstance(value, (list, tuple)) else [value]
    if all(math.isfinite(v) and (v >= 0 if zero else v > 0) for v in values):
        return
    shown = " ".join(f"{v:g}" for v in values)
    raise CliError(f"{flag} must be {'>=' if zero else '>'} 0 {unit}; got {shown}")


def check_stiffness(flag: str, values) -> None:
    """Stiffnesses [pN/nm] within the plausible range of k."""
    from .effects import QUANTITIES

    positive(flag, list(values), "pN/nm")
    lo, hi = (b * 1e3 for b in QUANTITIES["k"].bounds or (0.0, math.inf))
    for v in values:
        out_of_range(flag, v, "pN/nm", "the stiffness of any optical trap", lo, hi,
                     (("N/m", lambda x: x * 1e3), ("pN/um", lambda x: x * 1e-3)), typical=0.05)


def _gamma_range() -> tuple[float, float]:
    from .effects import QUANTITIES

    lo, hi = QUANTITIES["gamma"].bounds or (0.0, math.inf)
    return lo * 1e6, hi * 1e6


def check_friction(gamma_flag: str, gamma, radius_flag: str, radius, viscosity) -> None:
    """The friction [pN s/um], or the bead radius [um] (and the viscosity [Pa s], when given,
    with the Stokes friction it gives), each plausible."""
    lo, hi = _gamma_range()
    if gamma is not None:
        positive(gamma_flag, gamma, "pN s/um")
        out_of_range(gamma_flag, gamma, "pN s/um", "the friction of any trapped bead", lo, hi,
                     (("N s/m", lambda x: x * 1e6),), typical=0.01)
        return
    positive(radius_flag, radius, "um")
    out_of_range(radius_flag, radius, "um", "any trapped bead's radius", *RADIUS_UM,
                 (("metres", lambda x: x * 1e6), ("nm", lambda x: x * 1e-3)), hi_open=True)
    if viscosity is None:  # water at the temperature: plausible for any plausible radius
        return
    positive("--viscosity", viscosity, "Pa s")
    per_viscosity = 6 * math.pi * radius  # the Stokes friction [pN s/um] per Pa s
    out_of_range("--viscosity", viscosity, "Pa s", "the viscosity that gives any trapped bead's friction",
                 lo / per_viscosity, hi / per_viscosity, (("mPa s", lambda x: x * 1e-3),), typical=1e-3,
                 given=f"with {radius_flag} {radius:g} um, ")


def check_temperature(value: float) -> None:
    """--temperature [K] within the data layer's limits: Celsius and mK are named."""
    out_of_range("--temperature", value, "K", "the temperature of any experiment in water", *TEMPERATURE_K,
                 (("Celsius", lambda x: x + 273.15), ("mK", lambda x: x * 1e-3)), typical=295.0)


def check_tracking(value: float) -> None:
    """--tracking-nm [nm]: >= 0 and less than a trapped bead moves."""
    positive("--tracking-nm", value, "nm", zero=True)
    out_of_range("--tracking-nm", value, "nm", "what a trapped bead moves", 0.0, MAX_TRACKING_NM)


def check_simulate(args) -> None:
    """``blurtrap simulate``'s options, before anything is simulated."""
    if args.frames < 16:
        raise CliError(f"--frames must be >= 16; got {args.frames}")
    if not args.fps > 0:
        raise CliError(f"--fps must be > 0 Hz; got {args.fps:g}")
    out_of_range("--fps", args.fps, "Hz", "the frame rates blurtrap takes", MIN_FPS, math.inf,
                 (("kHz", lambda x: x * 1e3),), typical=1e3)
    check_stiffness("--k", args.k)
    check_friction("--gamma", args.gamma, "--radius", args.radius,
                   None if args.gamma is not None else args.viscosity)
    check_temperature(args.temperature)
    check_tracking(args.tracking_nm)
    if args.power_mw is not None:
        positive("--power-mw", list(args.power_mw), "mW", zero=True)
        for p in args.power_mw:
            out_of_range("--power-mw", p, "mW", "any trapping laser's power", 0.0, MAX_POWER_MW,
                         (("uW", lambda x: x * 1e-3),), typical=100.0)


def check_simulated_spread(x, k: float, w_ms: float, gamma: float, args) -> None:
    """The simulated positions ``x`` [m] of stiffness `k` [pN/nm] and exposure `w_ms` scatter
    as much as the loaders accept (0.02 nm..10 um), else a CliError naming the flags (the
    manifest written could not be loaded)."""
    import numpy as np

    std = float(np.std(x))
    if MIN_PLAUSIBLE_POSITION_STD_M <= std <= MAX_PLAUSIBLE_POSITION_STD_M:
        return
    fric = (f"--gamma {args.gamma:g} pN s/um" if args.gamma is not None
            else f"--radius {args.radius:g} um: gamma = {gamma:.3g} pN s/um")
    head = f"with --k {k:g} pN/nm and --exposure-ms {w_ms:g} the simulated positions scatter by {std * 1e9:.3g} nm"
    if std > MAX_PLAUSIBLE_POSITION_STD_M:
        raise CliError(f"{head}, above {MAX_TRACKING_NM:g} nm, more than a trapped bead moves, which blurtrap "
                       f"takes for a unit slip when it loads positions: check --tracking-nm [nm] and --k [pN/nm]")
    tau_ms = gamma / k  # (pN s/um) / (pN/nm) = 1e-3 s
    blur = (f": the exposure is {w_ms / tau_ms:.3g} times the trap's relaxation time gamma/k = "
            f"{tau_ms:.3g} ms ({fric}), and the blur averages the motion away" if w_ms > 2 * tau_ms else
            f" ({fric})")
    raise CliError(f"{head}, below {MIN_PLAUSIBLE_POSITION_STD_M * 1e9:g} nm, which blurtrap takes for a "
                   f"unit slip when it loads positions{blur}; check --k [pN/nm] and the friction "
                   f"(--gamma [pN s/um] or --radius [um]), or simulate shorter exposures")


def check_design(args) -> list[str]:
    """``blurtrap design``'s options, before any design is computed; the warnings to print."""
    if len(args.k) not in (1, 2):
        raise CliError(f"--k takes one stiffness or a range K_MIN K_MAX [pN/nm]; got {args.k}")
    check_stiffness("--k", args.k)
    check_friction("--gamma", args.gamma, "--radius-um", args.radius_um, args.viscosity)
    check_temperature(args.temperature)
    positive("--max-fps", args.max_fps, "Hz")
    positive("--min-exposure-ms", args.min_exposure_ms, "ms")
    positive("--dead-time-ms", args.dead_time_ms, "ms", zero=True)
    if args.frames is not None and args.frames < MIN_FRAMES:
        raise CliError(f"--frames must be >= {MIN_FRAMES} frames per recording; got {args.frames}")
    _check_design_candidates(args)
    if args.friction_error is not None and not (math.isfinite(args.friction_error) and args.friction_error >= 0):
        raise CliError(f"--friction-error is a relative error in %, >= 0; got {args.friction_error:g}")
    check_tracking(args.tracking_nm)
    out_of_range("--min-exposure-ms", args.min_exposure_ms, "ms", "the exposures blurtrap takes", 0.0,
                 MAX_EXPOSURE_MS, (("us", lambda x: x * 1e-3),), typical=0.1, hi_open=True)
    _check_design_timing(args)
    _check_design_target(args)
    if args.max_fps < MIN_FPS:
        return [f"--max-fps is in Hz; {args.max_fps:g} Hz is below {MIN_FPS:g} frames/s, frame intervals "
                f"blurtrap's loaders read as ms: if the camera runs at {args.max_fps:g} kHz, use --max-fps "
                f"{_num(args.max_fps * 1e3)}"]
    return []


def _check_design_candidates(args) -> None:
    """--series, --powers and a --total-s long enough for every candidate's recordings."""
    if any(n < 1 for n in args.series):
        raise CliError("--series takes numbers of exposures >= 1 to try (e.g. --series 1 2 3); got --series "
                       + " ".join(str(n) for n in args.series))
    powers = args.powers or ()
    if args.powers is not None and (len(set(powers)) < 2 or len(set(powers)) != len(powers)
                                    or not all(math.isfinite(p) and p > 0 for p in powers)):
        raise CliError("--powers takes at least 2 distinct powers > 0, as multiples of the power --k is at "
                       f"(e.g. --powers 0.5,1,2); got --powers {','.join(f'{p:g}' for p in powers)}")
    if args.total_s is None:
        return
    positive("--total-s", args.total_s, "s")
    n_rec = largest_candidate(args.series, powers)
    need = total_time_needed(args.max_fps, n_rec)
    if args.total_s * args.max_fps * (1 + 1e-12) < MIN_FRAMES * n_rec:
        raise CliError(f"--total-s {args.total_s:g} is {args.total_s * args.max_fps:.4g} frames at --max-fps "
                       f"{args.max_fps:g}, too few to split into {n_rec} recordings (the largest candidate) of "
                       f"at least {MIN_FRAMES} frames each: use --total-s {need:.3g} or more"
                       + (", or fewer exposures in --series" if n_rec == max(args.series) > largest_candidate((), ())
                          else ""))


def _check_design_timing(args) -> None:
    """Room for an exposure in the frame interval at --max-fps (after --dead-time-ms)."""
    w, dead, fps = args.min_exposure_ms, args.dead_time_ms, args.max_fps
    dt = 1e3 / fps
    at = f"the frame interval at --max-fps {fps:g}"
    if not w < dt:
        w_txt, dt_txt = _distinct(w, dt)
        if w > dt:
            raise CliError(f"--min-exposure-ms {w_txt} is longer than {at} ({dt_txt} ms): an exposure cannot "
                           "be longer than the frame interval; lower --min-exposure-ms or --max-fps")
        raise CliError(f"--min-exposure-ms {w_txt} is as long as {at} ({dt_txt} ms): design needs exposures "
                       "shorter than the frame interval; lower --min-exposure-ms or --max-fps")
    room = dt - w
    if dead >= room:
        slip = (f": did you give us? use --dead-time-ms {_num(dead * 1e-3)}" if dead > dt and dead * 1e-3 < room
                else "; lower --dead-time-ms or --max-fps")
        raise CliError(f"--dead-time-ms {dead:g} leaves no time for an exposure: {at} is {dt:.3g} ms and "
                       f"the shortest exposure --min-exposure-ms {w:g}, so the dead time must be below "
                       f"{room:.3g} ms{slip}")


def _check_design_target(args) -> None:
    """--target, --friction-error and --photon-limited that go together."""
    if args.target == "force_sensitivity" and args.friction_error is None:
        raise CliError("--target force_sensitivity is the passive calibration in volts with the friction "
                       "known from the bead: give its relative error, --friction-error PCT (>= 0)")
    if args.friction_error == 0 and args.target in ("gamma", "both", "determinant"):
        raise CliError(f"--target {args.target} needs the error of gamma, but --friction-error 0 says gamma "
                       "is known exactly; use --target k or force_sensitivity, or give --friction-error > 0")
    if args.photon_limited and args.tracking_nm == 0:
        raise CliError("--photon-limited needs the tracking error at the reference exposure: give "
                       "--tracking-nm > 0")


def not_identified_message(exc, args) -> str:
    """design's "no candidate design identifies ..." in the command's flags."""
    return (f"no candidate design identifies {exc.what} with these settings (dt >> tau at --max-fps "
            f"{args.max_fps:g}?): allow a faster frame rate (--max-fps) or shorter exposures "
            "(--min-exposure-ms)" + (", or give the friction from the bead size (--radius-um with "
                                     "--friction-error PCT) and calibrate k with it"
                                     if exc.friction_fitted else ""))


def check_bands(args) -> None:
    """calibrate's --f-range and --exclude bands [Hz]: 0 <= low < high."""
    bands = ([("--f-range", "FMIN FMAX", args.f_range)] if args.f_range is not None else []) + \
        [("--exclude", "F_LOW F_HIGH", b) for b in args.exclude or ()]
    for flag, names, (a, b) in bands:
        if not (0 <= a < b and math.isfinite(b)):
            lo, hi = names.split()
            raise CliError(f"{flag} {names} needs 0 <= {lo} < {hi} [Hz]; got {flag} {a:g} {b:g}")


_PAIR = r"\(\s*([-+.\deE]+),\s*([-+.\deE]+)\s*\)"


def _exclude_flags(match) -> str:
    return " ".join(f"--exclude {float(a):g} {float(b):g}" for a, b in re.findall(_PAIR, match.group(1)))


def band_flag_words(msg: str) -> str:
    """calibrate's band messages (``f_range = (0.1, 0.5) Hz``, ``excluded_ranges = [...]``,
    ``f_max``) in the command line's flags (``--f-range 0.1 0.5``, ``--exclude A B``, FMAX)."""
    msg = re.sub(rf"did you mean {_PAIR} Hz\?", lambda m: f"did you mean --f-range {m[1]} {m[2]}?", msg)
    msg = re.sub(rf"f_range = {_PAIR} Hz", lambda m: f"--f-range {m[1]} {m[2]}", msg)
    msg = re.sub(r"excluded_ranges = \[(.*?)\] Hz", _exclude_flags, msg)
    msg = re.sub(r"\bf_max\b", "FMAX", msg)
    return re.sub(r"\bf_range\b", "--f-range", msg)
