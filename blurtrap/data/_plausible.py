"""Unit-slip heuristics of :class:`Recording` (disabled with ``check_units=False``): the
plausible ranges of frame interval, exposure, temperature, laser power and the positions'
standard deviation, and the messages that name the likely mistake."""

from __future__ import annotations

import math
from collections.abc import Mapping

import numpy as np

from ._units import canonical_unit
from ._values import fmt_g as _g
from ._values import numeric_array, scalar

# Heuristic unit-slip thresholds (disabled with check_units=False).
# Frame interval / exposure: trap calibrations are recorded by cameras at ~20 frames/s to
# ~100 kHz and by photodiodes at ~10 kHz to ~1 MHz, i.e. intervals of 1e-6..5e-2 s. The same
# numbers in ms read as seconds give 1e-3..50 "s". Intervals of 0.1 s (10 frames/s) or more
# are therefore taken for ms: this catches every ms slip of a rate up to 10 kHz (e.g. 1500
# frames/s -> 0.667 "s", which the old 1 s limit let through) and leaves 2x room above the
# slowest genuine acquisitions (20 frames/s = 0.05 s). A slip of a faster (>= 20 kHz) record
# gives <= 0.05 "s" and cannot be told from a slow camera by its interval alone; a time
# column in ms is still caught by the frame_interval check when the stamps disagree with a
# frame_interval given in seconds.
_MAX_PLAUSIBLE_INTERVAL_S = 0.1
# Temperature: liquid water (the medium of these experiments) exists between ~273 K and
# 373 K; 100 K and 400 K leave a wide margin. Below: Celsius (22 -> 22 K); above: mK
# (295000) or a typo.
_MIN_PLAUSIBLE_TEMPERATURE_K = 100.0
_MAX_PLAUSIBLE_TEMPERATURE_K = 400.0
_MAX_PLAUSIBLE_LASER_POWER_W = 10.0

# Plausible fluctuation of a trapped bead: the standard deviation of the positions (mean
# removed), in metres. The thermal std sqrt(kB T / k) at 295 K is 203 nm for a very soft trap
# (k = 1e-7 N/m) and 0.64 nm for a very stiff one (k = 1e-2 N/m). Motion blur lowers the
# measured variance by S(W / tau) ~ 2 tau / W for W >> tau; tracking noise and drift only add.
# - Lower bound 2e-11 m (0.02 nm): 32x below the stiffest trap's thermal std, i.e. the
#   variance may be blurred down 1000-fold (W ~ 2000 tau, beyond which a record holds almost
#   no trap information) before a genuine trace trips it. Unit slips land below it: metres
#   declared as nm give ~1e-17 m, um declared as nm give 1e-12..2e-10 m (caught up to a true
#   std of 20 nm; a softer trap's um-as-nm trace overlaps real stiff traps and cannot be told
#   apart by its size alone).
# - Upper bound 1e-5 m (10 um): 50x the softest trap's thermal std; a trap holds a bead only
#   within about its radius (0.1-3 um), so a bead wandering by 10 um is not trapped. nm
#   declared as metres give metres; nm declared as um give 1e-6..2e-4 m (caught above a true
#   std of 10 nm).
_MIN_PLAUSIBLE_POSITION_STD_M = 2e-11
_MAX_PLAUSIBLE_POSITION_STD_M = 1e-5
_TYPICAL_POSITION_STD_M = 1e-8  # to pick the likeliest unit when several would fit
_UNIT_METRES = {"m": 1.0, "mm": 1e-3, "um": 1e-6, "nm": 1e-9}
_UNIT_WORDS = {"m": "metres", "mm": "mm", "um": "um", "nm": "nm", "px": "px"}
# Plausible fluctuation of a position-detector signal in volts (a QPD / PSD behind its
# amplifier, positions not yet converted with the displacement sensitivity beta [m/V]):
# beta is ~1e-8..1e-5 m/V, the bead's std 0.6..200 nm, so the signal's std is ~1e-4..10 V,
# and ADC ranges are +-10 V at most. 1e-7 V leaves 1000x below; anything in metres (std
# ~1e-11..1e-5) declared as volts stays below it up to a std of 0.1 um. 100 V is 10x any ADC
# range: nm, pixels or mV declared as volts.
_MIN_PLAUSIBLE_POSITION_STD_V = 1e-7
_MAX_PLAUSIBLE_POSITION_STD_V = 100.0
#: units of the positions a Recording holds
RECORDING_UNITS = ("m", "V")
# A driven (nano)stage moves the sample by ~10 nm..1 um peak at the drive frequency, within a
# travel of ~100 um: a stage std above 1e-4 m is nm or um declared as metres.
_MAX_PLAUSIBLE_STAGE_STD_M = 1e-4


def in_ms_message(name: str, value: float) -> str:
    rate = "" if name != "frame_interval" else f", {1e3 / value:.6g} frames/s"
    frames = (" - or, with a time column counting 0, 1, 2, ..., frame numbers rather than "
              "times: then give frame_interval [s] explicitly"
              if name == "frame_interval" and value == 1.0 else "")
    return (
        f"{name} = {value!r} s is at least {_g(_MAX_PLAUSIBLE_INTERVAL_S)} s (10 frames/s or "
        f"slower): this looks like ms, not s (did you mean {value * 1e-3!r} s{rate}?{frames}). "
        f"Expected seconds, below {_g(_MAX_PLAUSIBLE_INTERVAL_S)} s; if the acquisition really "
        "is this slow, pass check_units=False"
    )



def check_positions(positions, check_units: bool, declared_unit: str = "m") -> tuple[np.ndarray, str | None]:
    """``positions`` as a new float64 1-D array, and the input dtype's name when it was not
    float64. `declared_unit` is the unit they were given in (``"V"``: volts, kept as such;
    anything else: converted to metres already)."""
    u = "V" if declared_unit == "V" else "m"
    arr = numeric_array(positions, "positions", u)
    if arr.ndim != 1:
        raise ValueError(
            f"positions must be a 1-D array (one trace) [{u}]; got shape {arr.shape}. "
            "For several traces use blurtrap.data.from_arrays (rows = recordings)."
        )
    note = None if arr.dtype == np.float64 else arr.dtype.name
    arr = np.array(arr, dtype=np.float64, copy=True)
    n = arr.shape[0]
    if n < 2:
        raise ValueError(f"positions must hold at least 2 frames; got {n}")
    bad = np.flatnonzero(~np.isfinite(arr))
    if bad.size:
        shown = ", ".join(str(i) for i in bad[:5]) + (", ..." if bad.size > 5 else "")
        raise ValueError(
            f"positions contains {bad.size} non-finite value(s) (NaN/inf) at index [{shown}]; "
            f"first: positions[{bad[0]}] = {float(arr[bad[0]])!r}. blurtrap never drops frames "
            "silently: fix or remove them (the CSV loaders offer on_bad_rows='exclude')"
        )
    if np.all(arr == arr[0]):
        raise ValueError(_constant_message(float(arr[0]), declared_unit))
    if check_units and declared_unit == "V":
        _check_volts_scale(float(np.std(arr)))
    elif check_units:  # (unchecked: no overflow in np.std for |x| > 1e154)
        _check_position_scale(float(np.std(arr)), declared_unit)
    return arr, note


def _constant_message(value: float, declared: str) -> str:
    """Why a trace is one value: positions rounded to whole pixels (declared in px), or no
    position trace at all (or one rounded coarser than the motion)."""
    head = f"positions is constant (zero variance; every value = {value!r})"
    if declared == "px":
        return (
            f"{head}: the positions in pixels (position_unit 'px') look quantised, rounded to "
            "whole pixels, and a pixel (~100 nm in the sample) is larger than the bead's "
            "motion (a trapped bead moves ~1-100 nm), so every frame rounds to the same pixel "
            "and the trace holds no motion to calibrate. Export sub-pixel positions (the "
            "tracker's fitted centres, not integer pixel indices)"
        )
    unit = _UNIT_WORDS.get(declared, declared)
    return (
        f"{head}: a trapped bead always fluctuates, so this is not a position trace (a column "
        f"of zeros, a constant channel?), or one quantised: rounded to a resolution (e.g. whole "
        f"{unit}) coarser than the bead's motion. Write the positions with more digits"
    )


def declared_unit(metadata) -> str:
    """The unit the positions were given in (``metadata["position_unit"]``, which the loaders
    and from_arrays set), or "m"."""
    unit = metadata.get("position_unit") if isinstance(metadata, Mapping) else None
    try:
        return canonical_unit(unit)
    except ValueError:
        return "m"


def _likely_unit(std: float, declared: str) -> str | None:
    """The unit (other than `declared`) in which the numbers give a plausible std, if any."""
    if declared not in _UNIT_METRES:
        return None
    best, best_dist = None, math.inf
    for unit, metres in _UNIT_METRES.items():
        if unit == declared:
            continue
        true_std = std * metres / _UNIT_METRES[declared]
        if _MIN_PLAUSIBLE_POSITION_STD_M <= true_std <= _MAX_PLAUSIBLE_POSITION_STD_M:
            dist = abs(math.log(true_std / _TYPICAL_POSITION_STD_M))
            if dist < best_dist:
                best, best_dist = unit, dist
    return best


def _check_position_scale(std: float, declared: str) -> None:
    """Raise if the positions' std [m] is outside what any trapped bead shows (a unit slip)."""
    low = std < _MIN_PLAUSIBLE_POSITION_STD_M
    if not (low or std > _MAX_PLAUSIBLE_POSITION_STD_M):
        return
    what = (
        f"below {_g(_MIN_PLAUSIBLE_POSITION_STD_M)} m (0.02 nm), less than a bead fluctuates in "
        "even the stiffest trap (k = 1e-2 N/m: 0.6 nm)"
        if low
        else f"above {_g(_MAX_PLAUSIBLE_POSITION_STD_M)} m (10 um), more than a bead fluctuates "
        "in even the softest trap (k = 1e-7 N/m: 0.2 um)"
    )
    likely = _likely_unit(std, declared)
    word = _UNIT_WORDS.get(declared, declared)
    if declared == "px":
        slip = "positions look like they are not pixels of the given pixel_size_m"
    elif likely is None:
        slip = f"positions do not look like {word}"
    elif declared == "m" and not low:
        slip = (
            f"positions look like {_UNIT_WORDS[likely]} or pixels, not metres (or a detector "
            "signal in volts: declare position_unit='V')"
        )
    else:
        slip = f"positions look like {_UNIT_WORDS[likely]} declared as {word}"
    fix = (
        f"declare the unit the numbers are in (e.g. position_unit='{likely}' or a column "
        f"x_{likely}; arrays in metres need no unit)"
        if likely
        else "check the position unit (and pixel_size_m)"
    )
    raise ValueError(
        f"positions have standard deviation {_g(std)} m, {what}: {slip}. Expected positions "
        f"in metres after conversion from the declared unit {declared!r}; {fix}, or pass "
        "check_units=False"
    )



def _check_volts_scale(std: float) -> None:
    """Raise if a signal declared in volts has a std no detector signal shows."""
    if _MIN_PLAUSIBLE_POSITION_STD_V <= std <= _MAX_PLAUSIBLE_POSITION_STD_V:
        return
    if std < _MIN_PLAUSIBLE_POSITION_STD_V:
        what = (
            f"below {_g(_MIN_PLAUSIBLE_POSITION_STD_V)} V, less than any position detector's "
            "signal fluctuates (~1e-4..10 V): these look like positions in metres declared as "
            "volts. Declare the unit the numbers are in (position_unit='m', a column x_m; "
            "arrays in metres need no unit)"
        )
    else:
        what = (
            f"above {_g(_MAX_PLAUSIBLE_POSITION_STD_V)} V, more than any detector amplifier "
            "outputs (ADC ranges are +-10 V at most): these look like nm, pixels or mV "
            "declared as volts. Declare the unit the numbers are in (e.g. position_unit='nm' "
            "or a column x_nm), or convert mV to V"
        )
    raise ValueError(
        f"positions declared in volts (position_unit 'V') have standard deviation {_g(std)} V, "
        f"{what}, or pass check_units=False"
    )


def check_stage(stage, n: int, check_units: bool) -> np.ndarray:
    """The stage positions [m] as a new float64 array of `n` finite values (one per frame)."""
    arr = numeric_array(stage, "stage", "m")
    if arr.ndim != 1 or arr.shape[0] != n:
        raise ValueError(
            f"stage must be a 1-D array with one stage position per frame ({n}) [m]; got shape "
            f"{arr.shape}"
        )
    arr = np.array(arr, dtype=np.float64, copy=True)
    bad = np.flatnonzero(~np.isfinite(arr))
    if bad.size:
        raise ValueError(
            f"stage contains {bad.size} non-finite value(s) (NaN/inf); first: stage[{bad[0]}] = "
            f"{float(arr[bad[0]])!r}"
        )
    std = float(np.std(arr))
    if check_units and std > _MAX_PLAUSIBLE_STAGE_STD_M:
        raise ValueError(
            f"stage has standard deviation {_g(std)} m, above {_g(_MAX_PLAUSIBLE_STAGE_STD_M)} m "
            "(100 um), more than a calibration drive moves a stage (~10 nm..1 um): the stage "
            "positions look like nm or um, not metres. Pass metres (a CSV column stage_nm or "
            "stage_um is converted), or check_units=False"
        )
    return arr


def check_acquisition(frame_interval, exposure, temperature, laser_power, timing_tolerance,
                      check_units: bool):
    """The acquisition settings of :class:`Recording` as floats ``(dt, W, T, P, timing
    tolerance)``, each checked (positive, W <= dt, and with `check_units` plausible in SI:
    not ms, Celsius or mW)."""
    dt = scalar("frame_interval", frame_interval, "s")
    if dt <= 0:
        raise ValueError(f"frame_interval must be > 0 [s]; got frame_interval = {dt!r}")
    if check_units and dt >= _MAX_PLAUSIBLE_INTERVAL_S:
        raise ValueError(in_ms_message("frame_interval", dt))
    w = scalar("exposure", exposure, "s")
    if w <= 0:
        raise ValueError(f"exposure must be > 0 [s]; got exposure = {w!r}")
    if check_units and w >= _MAX_PLAUSIBLE_INTERVAL_S:
        raise ValueError(in_ms_message("exposure", w))
    if w > dt:
        raise ValueError(
            f"exposure = {w!r} s is longer than frame_interval = {dt!r} s; a frame cannot "
            "integrate longer than the time between frames (expected exposure <= "
            "frame_interval)"
        )
    temp = _check_temperature(temperature, check_units)
    if laser_power is None:
        power = None
    else:
        power = scalar("laser_power", laser_power, "W")
        if power < 0:
            raise ValueError(f"laser_power must be >= 0 [W]; got laser_power = {power!r}")
        if check_units and power > _MAX_PLAUSIBLE_LASER_POWER_W:
            raise ValueError(
                f"laser_power = {power!r} W is above 10 W: this looks like mW, not W "
                f"(did you mean {power * 1e-3!r} W?). Pass watts, or check_units=False"
            )
    tol = scalar("timing_tolerance", timing_tolerance, "1")
    if not tol > 0:
        raise ValueError(f"timing_tolerance must be > 0; got {tol!r}")
    return dt, w, temp, power, tol


def _check_temperature(temperature, check_units: bool) -> float:
    """The temperature [K]; with `check_units`, Celsius and millikelvin are caught."""
    temp = scalar("temperature", temperature, "K")
    if temp <= 0:
        raise ValueError(f"temperature must be > 0 [K]; got temperature = {temp!r}")
    if check_units and temp < _MIN_PLAUSIBLE_TEMPERATURE_K:
        raise ValueError(
            f"temperature = {temp!r} K is below 100 K: this looks like Celsius; pass "
            f"kelvin (e.g. {temp + 273.15:.2f} K), or check_units=False"
        )
    if check_units and temp > _MAX_PLAUSIBLE_TEMPERATURE_K:
        as_mk = 1e3 * _MIN_PLAUSIBLE_TEMPERATURE_K <= temp <= 1e3 * _MAX_PLAUSIBLE_TEMPERATURE_K
        hint = (
            f"this looks like millikelvin (did you mean {temp * 1e-3:.6g} K?)"
            if as_mk
            else "no trapping experiment in liquid water runs this hot (water boils at "
            "373 K)"
        )
        raise ValueError(
            f"temperature = {temp!r} K is above 400 K: {hint}. Expected kelvin between "
            "100 and 400 K; pass kelvin, or check_units=False"
        )
    return temp
