"""Shared by the instrument-file loaders (HDF5, TDMS): a raw numeric trace checked and turned
into a :class:`Recording` (unit conversion, volts, validation with the file and channel in
every message)."""

from __future__ import annotations

import math
from collections.abc import Mapping

import numpy as np

from .._constants import DEFAULT_TEMPERATURE
from ._io import from_arrays
from ._recording import Recording
from ._units import ALLOWED_UNITS, canonical_unit

_VOLT_SPELLINGS = ("v", "volt", "volts")
_MAX_PLAUSIBLE_DISPLACEMENT_SENSITIVITY = 1e-3  # m/V; real PSDs give ~1e-8..1e-5 m/V
_MAX_LISTED = 30


def _listing(names, n: int = _MAX_LISTED) -> str:
    names = list(names)
    shown = ", ".join(repr(x) for x in names[:n])
    more = f", ... ({len(names)} in all)" if len(names) > n else ""
    return f"[{shown}{more}]" if names else "[] (none)"


def positive_number(value, name: str, unit: str, where: str) -> float:
    """``value`` as a finite float > 0, or a ``ValueError`` naming it."""
    if isinstance(value, (bool, np.bool_)) or value is None:
        raise ValueError(f"{where}: {name} must be a number [{unit}]; got {value!r}")
    try:
        arr = np.asarray(value)
        v = float(arr) if arr.ndim == 0 and arr.dtype.kind in "iuf" else None
    except (TypeError, ValueError):
        v = None
    if v is None:
        raise ValueError(f"{where}: {name} must be a real number [{unit}]; got {value!r}")
    if not (math.isfinite(v) and v > 0):
        raise ValueError(f"{where}: {name} must be finite and > 0 [{unit}]; got {v!r}")
    return v


def numeric_trace(values, where: str, what: str) -> np.ndarray:
    """``values`` as a numeric (integer or float) array; anything else is a ``ValueError``
    saying what was found (never a silent cast)."""
    arr = np.asarray(values)
    if arr.dtype.names:
        raise ValueError(
            f"{where}: {what} is a table with fields {list(arr.dtype.names)}, not a numeric "
            "trace; expected a 1-D array of numbers"
        )
    kind = arr.dtype.kind
    if kind not in "iuf":
        found = {
            "U": "text",
            "S": "text",
            "O": "objects (e.g. variable-length text)",
            "b": "booleans",
            "c": "complex numbers",
            "M": "date-times",
            "m": "time differences",
        }.get(kind, "non-numeric values")
        raise ValueError(
            f"{where}: {what} holds {found} (dtype {arr.dtype}); expected real numbers "
            "(integer or float)"
        )
    if arr.ndim == 0:
        raise ValueError(f"{where}: {what} is a single number ({arr.item()!r}), not a trace")
    if arr.size == 0:
        raise ValueError(f"{where}: {what} is empty (shape {arr.shape}); expected at least 2 samples")
    return arr


def check_increasing_times(times: np.ndarray, where: str, what: str) -> None:
    """Raise naming the first non-finite or non-increasing time stamp."""
    bad = np.flatnonzero(~np.isfinite(times))
    if bad.size:
        raise ValueError(
            f"{where}: {what} holds {bad.size} non-finite value(s); first: {what}[{bad[0]}] = "
            f"{float(times[bad[0]])!r}"
        )
    d = np.diff(times)
    bad = np.flatnonzero(~(d > 0))
    if bad.size:
        i = int(bad[0])
        raise ValueError(
            f"{where}: {what} must increase strictly; {what}[{i + 1}] = {times[i + 1].item()!r} "
            f"follows {what}[{i}] = {times[i].item()!r} ({bad.size} such step(s))"
        )


def _is_volts(unit) -> bool:
    return isinstance(unit, str) and unit.strip().lower() in _VOLT_SPELLINGS


def _volts_supported() -> bool:
    try:
        canonical_unit("V")
    except ValueError:
        return False
    return True


def resolve_unit(values: np.ndarray, position_unit, displacement_sensitivity_m_per_V, where: str, meta: dict):
    """Positions and the unit to declare to :func:`from_arrays`.

    A signal in volts (``position_unit="V"``) is converted to metres with
    ``displacement_sensitivity_m_per_V`` when given (recorded in ``meta``); without it, it is
    passed on in volts only if blurtrap's recordings accept a ``'V'`` unit, else a clear error.
    """
    sens = displacement_sensitivity_m_per_V
    if sens is not None:
        if not _is_volts(position_unit):
            raise ValueError(
                f"{where}: displacement_sensitivity_m_per_V = {sens!r} was given but "
                f"position_unit = {position_unit!r}, not 'V'; it only converts a signal in volts "
                "(it would be ignored): remove it, or declare position_unit='V'"
            )
        s = positive_number(sens, "displacement_sensitivity_m_per_V", "m/V", where)
        if s > _MAX_PLAUSIBLE_DISPLACEMENT_SENSITIVITY:
            raise ValueError(
                f"{where}: displacement_sensitivity_m_per_V = {s!r} m/V is larger than 1 mm/V: "
                "this looks like nm/V or um/V, not m/V (a position detector gives ~1e-7 m/V, "
                "i.e. 100 nm/V)"
            )
        meta["signal_unit"] = "V"
        meta["displacement_sensitivity_m_per_V"] = s
        return values.astype(np.float64) * s, "m"
    if _is_volts(position_unit):
        if _volts_supported():
            return values, canonical_unit("V")
        raise ValueError(
            f"{where}: the signal is in volts (position_unit = {position_unit!r}), but blurtrap "
            "recordings hold positions, and volts need a displacement sensitivity to become "
            "positions: pass displacement_sensitivity_m_per_V=<m/V> (e.g. 1e-7 for 100 nm/V) "
            f"to convert, or a length unit ({', '.join(ALLOWED_UNITS)}) if the values already "
            "are positions"
        )
    try:
        return values, canonical_unit(position_unit)
    except ValueError as e:
        raise ValueError(
            f"{where}: {e}; or 'V' for a detector signal in volts (with "
            "displacement_sensitivity_m_per_V)"
        ) from None


def build_recording(
    values: np.ndarray,
    where: str,
    *,
    position_unit,
    displacement_sensitivity_m_per_V,
    frame_interval: float,
    exposure,
    times,
    meta: dict,
    recording_kwargs: dict,
    interval_source: str = "",
) -> Recording:
    """One :class:`Recording` from a 1-D numeric trace; every ``ValueError`` starts with
    ``where`` (the file and channel). ``meta`` holds the loader's metadata (it wins over the
    user's ``metadata`` for the same keys, as in :func:`load_csv`)."""
    if values.ndim != 1:
        raise ValueError(f"{where}: the data have shape {values.shape}; expected a 1-D trace")
    kw = dict(recording_kwargs)
    user_meta = kw.pop("metadata", None)
    if user_meta is not None and not isinstance(user_meta, Mapping):
        raise ValueError(f"{where}: metadata must be a dict (or None); got {type(user_meta).__name__}")
    full = {} if user_meta is None else dict(user_meta)
    positions, unit = resolve_unit(values, position_unit, displacement_sensitivity_m_per_V, where, meta)
    full.update(meta)
    if kw.get("temperature") is None:
        kw["temperature"] = DEFAULT_TEMPERATURE
        full.setdefault("defaults_applied", {})
        full["defaults_applied"] = {**full["defaults_applied"], "temperature_K": DEFAULT_TEMPERATURE}
    try:
        rec = from_arrays(
            positions,
            frame_interval=frame_interval,
            exposure=exposure,
            times=times,
            position_unit=unit,
            metadata=full,
            **kw,
        )
    except ValueError as e:
        msg = str(e)
        extra = ""
        if interval_source and msg.startswith(("frame_interval = ", "exposure = ")):
            extra = f" (frame_interval = {frame_interval!r} s comes from {interval_source})"
        raise ValueError(f"{where}: {msg}{extra}") from None
    assert isinstance(rec, Recording)  # a 1-D trace gives one recording
    return rec


def missing_exposure(where: str, frame_interval: float) -> ValueError:
    return ValueError(
        f"{where}: exposure not given; pass exposure [s], the time each sample integrates "
        f"the motion over: a camera's shutter time, or for a photodiode read by an integrating "
        f"ADC the sample interval ({frame_interval!r} s here)"
    )
