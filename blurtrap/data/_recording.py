"""The :class:`Recording` container: one position trace with its acquisition metadata.

All validation happens at construction and raises ``ValueError`` naming the parameter, the
offending value and what was expected. Nothing is ever dropped or repaired silently; the few
conversions that are made (integer or float32 positions -> float64) are noted in ``metadata``.
"""

from __future__ import annotations

import math
import types
from collections.abc import Mapping
from typing import Any, NamedTuple

import numpy as np

from .._constants import DEFAULT_TEMPERATURE
from ._units import canonical_unit

#: Default tolerance on time-stamp irregularity, relative to the frame interval.
DEFAULT_TIMING_TOLERANCE = 1e-3
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


def _g(x) -> str:
    return f"{x:.6g}"


def _freeze(obj, path: str = "metadata"):
    """Copy metadata into an immutable-ish, JSON-compatible form."""
    if isinstance(obj, (dict, types.MappingProxyType)):
        out = {}
        for k, v in obj.items():
            if not isinstance(k, str):
                raise ValueError(f"{path} keys must be strings; got key {k!r}")
            out[k] = _freeze(v, f"{path}[{k!r}]")
        return types.MappingProxyType(out)
    if isinstance(obj, (list, tuple)):
        return tuple(_freeze(v, f"{path}[{i}]") for i, v in enumerate(obj))
    if isinstance(obj, np.ndarray):
        return _freeze(obj.tolist(), path)
    if isinstance(obj, np.generic):
        return obj.item()
    if obj is None or isinstance(obj, (str, bool, int, float)):
        return obj
    raise ValueError(
        f"{path} = {obj!r} has type {type(obj).__name__}; metadata values must be str, "
        "int, float, bool, None, lists or dicts of these (so that they can be saved)"
    )


def thaw(obj):
    """JSON-serialisable plain copy of frozen metadata."""
    if isinstance(obj, (dict, types.MappingProxyType)):
        return {k: thaw(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [thaw(v) for v in obj]
    return obj


def _scalar(name: str, value, unit: str) -> float:
    if isinstance(value, bool) or value is None:
        raise ValueError(f"{name} must be a number [{unit}]; got {value!r}")
    try:
        arr = np.asarray(value)
    except Exception:  # pragma: no cover - exotic objects
        raise ValueError(f"{name} must be a number [{unit}]; got {value!r}") from None
    if arr.ndim != 0 or arr.dtype.kind not in "iuf":
        raise ValueError(f"{name} must be a real scalar [{unit}]; got {value!r}")
    v = float(arr)
    if not math.isfinite(v):
        raise ValueError(f"{name} must be finite [{unit}]; got {name} = {v!r}")
    return v


def _in_ms_message(name: str, value: float) -> str:
    rate = "" if name != "frame_interval" else f", {1e3 / value:.6g} frames/s"
    return (
        f"{name} = {value!r} s is at least {_g(_MAX_PLAUSIBLE_INTERVAL_S)} s (10 frames/s or "
        f"slower): this looks like ms, not s (did you mean {value * 1e-3!r} s{rate}?). "
        f"Expected seconds, below {_g(_MAX_PLAUSIBLE_INTERVAL_S)} s; if the acquisition really "
        "is this slow, pass check_units=False"
    )


def numeric_array(values, name: str, unit: str) -> np.ndarray:
    """``values`` as an integer or float array; text, booleans, complex numbers and objects
    that are not numbers are a ``ValueError`` naming `name`, never a silent cast."""
    try:
        arr = np.asarray(values)
    except Exception as e:
        raise ValueError(f"{name} could not be converted to an array: {e}") from None
    kind = arr.dtype.kind
    flat = arr.reshape(-1)
    text = kind in "US" or (kind == "O" and any(isinstance(v, (str, bytes)) for v in flat))
    if text:
        first = next((v for v in flat if isinstance(v, (str, bytes, np.str_, np.bytes_))), None)
        raise ValueError(
            f"{name} must be numeric [{unit}]; got text (an array of dtype {arr.dtype}, e.g. "
            f"{str(first)[:40]!r}). Convert the values to numbers first (np.asarray(values, "
            "dtype=float)), or read the file with load_csv, which parses them"
        )
    if kind == "b":
        raise ValueError(f"{name} must be numeric [{unit}]; got a boolean array")
    if kind == "c":
        raise ValueError(f"{name} must be real [{unit}]; got a complex array")
    if kind not in "iuf":
        try:
            arr = arr.astype(np.float64)
        except (TypeError, ValueError):
            bad = next((v for v in flat if not isinstance(v, (int, float, np.number))), None)
            raise ValueError(
                f"{name} must be numeric [{unit}]; got an array of dtype {arr.dtype} holding "
                f"{type(bad).__name__} {bad!r:.40}"
            ) from None
    return arr


def _positions(positions, check_units: bool, declared_unit: str = "m") -> tuple[np.ndarray, str | None]:
    arr = numeric_array(positions, "positions", "m")
    if arr.ndim != 1:
        raise ValueError(
            f"positions must be a 1-D array (one trace) [m]; got shape {arr.shape}. "
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
        raise ValueError(
            f"positions is constant (zero variance; every value = {float(arr[0])!r}): a trapped "
            "bead always fluctuates, so this is not a position trace"
        )
    if check_units:  # (unchecked: no overflow in np.std for |x| > 1e154)
        _check_position_scale(float(np.std(arr)), declared_unit)
    return arr, note


def _declared_unit(metadata) -> str:
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
        slip = f"positions look like {_UNIT_WORDS[likely]} or pixels, not metres"
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


def _timing(times, n: int, frame_interval: float, tol: float, allow_irregular: bool):
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


class Recording:
    r"""One 1-D position trace of a trapped bead and how it was acquired.

    Immutable: arrays are private read-only copies and attributes cannot be set.

    **Arguments:**

    - `positions`: 1-D array of positions [m]. Integer or float32 input is converted to
      float64 and the original dtype recorded in ``metadata["input_dtype"]``. numpy or JAX.
    - `frame_interval`: time between frame starts, :math:`\Delta t` [s].
    - `exposure`: integration time per frame, :math:`W` [s], ``0 < W <= frame_interval``.
    - `temperature`: [K] (default 295).
    - `times`: optional frame time stamps [s], strictly increasing and regular to within
      ``timing_tolerance * frame_interval`` of a regular grid.
    - `laser_power`: trapping laser power [W], or None when unknown.
    - `metadata`: free-form JSON-like mapping (stored as a read-only copy).
    - `name`: optional label.
    - `allow_irregular`: keep irregular time stamps instead of raising; see `timing_jitter`.
    - `timing_tolerance`: relative tolerance for time stamps (default 1e-3).
    - `check_units`: run the unit-slip heuristics (temperature outside 100..400 K, frame
      interval or exposure >= 0.1 s, position std outside 2e-11..1e-5 m, laser power > 10 W). Default True. The position
      check names the likely unit, using ``metadata["position_unit"]`` (set by the loaders
      and :func:`from_arrays`) as the declared one.

    **Raises:** ``ValueError`` for any invalid or implausible input, with the value and a hint.
    """

    __slots__ = (
        "_positions",
        "_frame_interval",
        "_exposure",
        "_temperature",
        "_times",
        "_laser_power",
        "_metadata",
        "_name",
        "_allow_irregular",
        "_timing_tolerance",
        "_check_units",
        "_jitter",
    )

    def __init__(
        self,
        positions,
        *,
        frame_interval,
        exposure,
        temperature=DEFAULT_TEMPERATURE,
        times=None,
        laser_power=None,
        metadata=None,
        name: str | None = None,
        allow_irregular: bool = False,
        timing_tolerance: float = DEFAULT_TIMING_TOLERANCE,
        check_units: bool = True,
    ):
        check_units = bool(check_units)
        pos, dtype_note = _positions(positions, check_units, _declared_unit(metadata))

        dt = _scalar("frame_interval", frame_interval, "s")
        if dt <= 0:
            raise ValueError(f"frame_interval must be > 0 [s]; got frame_interval = {dt!r}")
        if check_units and dt >= _MAX_PLAUSIBLE_INTERVAL_S:
            raise ValueError(_in_ms_message("frame_interval", dt))
        w = _scalar("exposure", exposure, "s")
        if w <= 0:
            raise ValueError(f"exposure must be > 0 [s]; got exposure = {w!r}")
        if check_units and w >= _MAX_PLAUSIBLE_INTERVAL_S:
            raise ValueError(_in_ms_message("exposure", w))
        if w > dt:
            raise ValueError(
                f"exposure = {w!r} s is longer than frame_interval = {dt!r} s; a frame cannot "
                "integrate longer than the time between frames (expected exposure <= "
                "frame_interval)"
            )
        temp = _scalar("temperature", temperature, "K")
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
        if laser_power is None:
            power = None
        else:
            power = _scalar("laser_power", laser_power, "W")
            if power < 0:
                raise ValueError(f"laser_power must be >= 0 [W]; got laser_power = {power!r}")
            if check_units and power > _MAX_PLAUSIBLE_LASER_POWER_W:
                raise ValueError(
                    f"laser_power = {power!r} W is above 10 W: this looks like mW, not W "
                    f"(did you mean {power * 1e-3!r} W?). Pass watts, or check_units=False"
                )
        tol = _scalar("timing_tolerance", timing_tolerance, "1")
        if not tol > 0:
            raise ValueError(f"timing_tolerance must be > 0; got {tol!r}")
        if name is not None and not isinstance(name, str):
            raise ValueError(f"name must be a str or None; got {name!r}")

        if metadata is not None and not isinstance(metadata, (dict, types.MappingProxyType)):
            raise ValueError(
                f"metadata must be a dict (or None); got {type(metadata).__name__} {metadata!r:.60}"
            )
        frozen = _freeze({} if metadata is None else metadata)
        assert isinstance(frozen, types.MappingProxyType)  # _freeze maps a dict to a mapping proxy
        meta = dict(frozen)
        if dtype_note is not None:
            meta.setdefault("input_dtype", dtype_note)
        if times is None:
            t, jitter = None, None
        else:
            t, jitter = _timing(times, pos.shape[0], dt, tol, bool(allow_irregular))
            t.flags.writeable = False
        pos.flags.writeable = False

        s = object.__setattr__
        s(self, "_positions", pos)
        s(self, "_frame_interval", dt)
        s(self, "_exposure", w)
        s(self, "_temperature", temp)
        s(self, "_times", t)
        s(self, "_laser_power", power)
        s(self, "_metadata", types.MappingProxyType(meta))
        s(self, "_name", name)
        s(self, "_allow_irregular", bool(allow_irregular))
        s(self, "_timing_tolerance", tol)
        s(self, "_check_units", check_units)
        s(self, "_jitter", jitter)

    # -- immutability -------------------------------------------------------------------
    def __setattr__(self, key, value):
        raise AttributeError(f"Recording is immutable; use .replace({key.lstrip('_')}=...)")

    def __delattr__(self, key):
        raise AttributeError("Recording is immutable")

    # -- fields -------------------------------------------------------------------------
    @property
    def positions(self) -> np.ndarray:
        """Positions [m], float64, read-only."""
        return self._positions

    @property
    def frame_interval(self) -> float:
        """Time between frame starts [s]."""
        return self._frame_interval

    @property
    def exposure(self) -> float:
        """Integration time per frame [s]."""
        return self._exposure

    @property
    def temperature(self) -> float:
        """[K]"""
        return self._temperature

    @property
    def times(self) -> np.ndarray | None:
        """Frame time stamps [s] (read-only) or None."""
        return self._times

    @property
    def laser_power(self) -> float | None:
        """Laser power [W] or None."""
        return self._laser_power

    @property
    def metadata(self) -> types.MappingProxyType:
        return self._metadata

    @property
    def name(self) -> str | None:
        return self._name

    @property
    def allow_irregular(self) -> bool:
        return self._allow_irregular

    @property
    def timing_tolerance(self) -> float:
        return self._timing_tolerance

    @property
    def check_units(self) -> bool:
        return self._check_units

    # -- derived ------------------------------------------------------------------------
    @property
    def n_frames(self) -> int:
        return int(self._positions.shape[0])

    @property
    def duration(self) -> float:
        """Record length ``n_frames * frame_interval`` [s]."""
        return self.n_frames * self._frame_interval

    @property
    def sampling_rate(self) -> float:
        """``1 / frame_interval`` [Hz]."""
        return 1.0 / self._frame_interval

    @property
    def timing_jitter(self) -> TimingJitter | None:
        """Deviation of ``times`` from a regular grid (None without time stamps)."""
        return self._jitter

    @property
    def is_regular(self) -> bool:
        """False only when irregular time stamps were kept with ``allow_irregular=True``."""
        j = self._jitter
        return j is None or j.max_deviation <= self._timing_tolerance * self._frame_interval

    def replace(self, **changes: Any) -> Recording:
        """A new, re-validated Recording with some fields changed."""
        fields = dict(
            positions=self._positions,
            frame_interval=self._frame_interval,
            exposure=self._exposure,
            temperature=self._temperature,
            times=self._times,
            laser_power=self._laser_power,
            metadata=self._metadata,
            name=self._name,
            allow_irregular=self._allow_irregular,
            timing_tolerance=self._timing_tolerance,
            check_units=self._check_units,
        )
        unknown = set(changes) - set(fields)
        if unknown:
            raise ValueError(f"replace() got unknown field(s) {sorted(unknown)}")
        fields.update(changes)
        return Recording(**fields)

    def __eq__(self, other):
        if not isinstance(other, Recording):
            return NotImplemented
        same_times = (self._times is None and other._times is None) or (
            self._times is not None
            and other._times is not None
            and np.array_equal(self._times, other._times)
        )
        return (
            np.array_equal(self._positions, other._positions)
            and same_times
            and self._frame_interval == other._frame_interval
            and self._exposure == other._exposure
            and self._temperature == other._temperature
            and self._laser_power == other._laser_power
            and self._name == other._name
            and self._allow_irregular == other._allow_irregular
            and self._timing_tolerance == other._timing_tolerance
            and self._check_units == other._check_units
            and self._metadata == other._metadata
        )

    __hash__ = None  # type: ignore[assignment]

    def __repr__(self) -> str:
        power = "None" if self._laser_power is None else f"{_g(self._laser_power)} W"
        return (
            f"Recording(name={self._name!r}, n_frames={self.n_frames}, "
            f"frame_interval={_g(self._frame_interval)} s, exposure={_g(self._exposure)} s, "
            f"temperature={_g(self._temperature)} K, laser_power={power}, "
            f"times={'yes' if self._times is not None else 'no'})"
        )
