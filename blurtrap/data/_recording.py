"""The :class:`Recording` container: one position trace with its acquisition metadata.

All validation happens at construction and raises ``ValueError`` naming the parameter, the
offending value and what was expected. Nothing is ever dropped or repaired silently; the few
conversions that are made (integer or float32 positions -> float64) are noted in ``metadata``.
"""

from __future__ import annotations

import types
from collections.abc import Mapping
from typing import Any

import numpy as np

from .._constants import DEFAULT_TEMPERATURE
from ._plausible import _MAX_PLAUSIBLE_INTERVAL_S as _MAX_PLAUSIBLE_INTERVAL_S
from ._plausible import _MAX_PLAUSIBLE_LASER_POWER_W as _MAX_PLAUSIBLE_LASER_POWER_W
from ._plausible import _MAX_PLAUSIBLE_POSITION_STD_M as _MAX_PLAUSIBLE_POSITION_STD_M
from ._plausible import _MAX_PLAUSIBLE_TEMPERATURE_K as _MAX_PLAUSIBLE_TEMPERATURE_K
from ._plausible import _MIN_PLAUSIBLE_POSITION_STD_M as _MIN_PLAUSIBLE_POSITION_STD_M
from ._plausible import _MIN_PLAUSIBLE_TEMPERATURE_K as _MIN_PLAUSIBLE_TEMPERATURE_K
from ._plausible import RECORDING_UNITS, check_acquisition, check_positions, check_stage, declared_unit
from ._timing import DEFAULT_TIMING_TOLERANCE as DEFAULT_TIMING_TOLERANCE
from ._timing import TimingJitter as TimingJitter
from ._timing import check_times
from ._values import fmt_g as _g
from ._values import freeze
from ._values import numeric_array as numeric_array
from ._values import thaw as thaw


def _metadata(metadata, dtype_note, unit) -> dict:
    """The recording's metadata as a plain dict, with the input dtype and volts noted."""
    if metadata is not None and not isinstance(metadata, (dict, types.MappingProxyType)):
        raise ValueError(
            f"metadata must be a dict (or None); got {type(metadata).__name__} {metadata!r:.60}"
        )
    frozen = freeze({} if metadata is None else metadata)
    assert isinstance(frozen, types.MappingProxyType)  # _freeze maps a dict to a mapping proxy
    meta = dict(frozen)
    if dtype_note is not None:
        meta.setdefault("input_dtype", dtype_note)
    if unit == "V":
        meta["position_unit"] = "V"
    return meta


class Recording:
    r"""One 1-D position trace of a trapped bead and how it was acquired.

    Immutable: arrays are private read-only copies and attributes cannot be set.

    **Arguments:**

    - `positions`: 1-D array of positions [m], or [V] for a detector signal whose
      displacement sensitivity is not known (``position_unit="V"``). Integer or float32 input
      is converted to float64 and the original dtype recorded in ``metadata["input_dtype"]``.
      numpy or JAX.
    - `frame_interval`: time between frame starts, :math:`\Delta t` [s].
    - `exposure`: integration time per frame, :math:`W` [s], ``0 < W <= frame_interval``.
    - `temperature`: [K] (default 295).
    - `times`: optional frame time stamps [s], strictly increasing and regular to within
      ``timing_tolerance * frame_interval`` of a regular grid.
    - `laser_power`: trapping laser power [W], or None when unknown.
    - `stage`: optional stage (nanostage) positions at the frame times [m], one per frame,
      for an active calibration with a driven stage (``metadata["drive"]``).
    - `position_unit`: ``"m"`` or ``"V"``: the unit of `positions`. Stored as
      ``metadata["position_unit"]`` (which it sets for ``"V"``); None (default) takes it from
      there: ``"V"`` there means volts, anything else (or nothing) metres (the loaders note
      the unit a file gave before converting it to metres, e.g. ``"nm"``).
    - `metadata`: free-form JSON-like mapping (stored as a read-only copy). The instrument
      keys (``detector``, ``bead_radius_m``, ``drive``, ...) are read and validated by
      :func:`instrument_settings`.
    - `name`: optional label.
    - `allow_irregular`: keep irregular time stamps instead of raising; see `timing_jitter`.
    - `timing_tolerance`: relative tolerance for time stamps (default 1e-3).
    - `check_units`: run the unit-slip heuristics (temperature outside 100..400 K, frame
      interval or exposure >= 0.1 s, position std outside 2e-11..1e-5 m (1e-7..100 V in
      volts), stage std above 1e-4 m, laser power > 10 W). Default True. The position check
      names the likely unit, using ``metadata["position_unit"]`` (set by the loaders and
      :func:`from_arrays`) as the declared one.

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
        "_stage",
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
        stage=None,
        position_unit: str | None = None,
    ):
        check_units = bool(check_units)
        unit = _position_unit(position_unit, metadata)
        pos, dtype_note = check_positions(
            positions, check_units, "V" if unit == "V" else declared_unit(metadata)
        )
        stage_arr = None if stage is None else check_stage(stage, pos.shape[0], check_units)

        dt, w, temp, power, tol = check_acquisition(
            frame_interval, exposure, temperature, laser_power, timing_tolerance, check_units
        )
        if name is not None and not isinstance(name, str):
            raise ValueError(f"name must be a str or None; got {name!r}")

        meta = _metadata(metadata, dtype_note, unit)
        if times is None:
            t, jitter = None, None
        else:
            t, jitter = check_times(times, pos.shape[0], dt, tol, bool(allow_irregular))
            t.flags.writeable = False
        pos.flags.writeable = False
        if stage_arr is not None:
            stage_arr.flags.writeable = False

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
        s(self, "_stage", stage_arr)

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
    def position_unit(self) -> str:
        """``"m"`` (positions in metres) or ``"V"`` (a detector signal in volts)."""
        return "V" if self._metadata.get("position_unit") == "V" else "m"

    @property
    def stage(self) -> np.ndarray | None:
        """Stage positions at the frame times [m] (read-only), or None."""
        return self._stage

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
            stage=self._stage,
            position_unit=None,  # kept in metadata
        )
        unknown = set(changes) - set(fields)
        if unknown:
            raise ValueError(f"replace() got unknown field(s) {sorted(unknown)}")
        new_meta = changes.get("metadata")
        if (
            "metadata" in changes
            and changes.get("position_unit") is None
            and self.position_unit == "V"
            and not (isinstance(new_meta, Mapping) and "position_unit" in new_meta)
        ):
            changes["position_unit"] = "V"  # new metadata without a unit: still volts
        fields.update(changes)
        return Recording(**fields)

    def __eq__(self, other):
        if not isinstance(other, Recording):
            return NotImplemented
        same_times = _same_optional(self._times, other._times)
        same_stage = _same_optional(self._stage, other._stage)
        return (
            np.array_equal(self._positions, other._positions)
            and same_times
            and same_stage
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
            f"times={'yes' if self._times is not None else 'no'}"
            + (", position_unit='V'" if self.position_unit == "V" else "")
            + (", stage=yes" if self._stage is not None else "")
            + ")"
        )


def _same_optional(a: np.ndarray | None, b: np.ndarray | None) -> bool:
    return (a is None and b is None) or (a is not None and b is not None and np.array_equal(a, b))


def _position_unit(given, metadata) -> str:
    """``"m"`` or ``"V"`` from the `position_unit` argument, else from the metadata."""
    meta_unit = declared_unit(metadata)
    if given is None:
        return "V" if meta_unit == "V" else "m"
    if given not in RECORDING_UNITS:
        raise ValueError(
            f"position_unit must be 'm' (positions in metres) or 'V' (a detector signal in "
            f"volts); got {given!r}. Positions in other length units: convert them to metres "
            "(blurtrap.data.from_arrays(..., position_unit=...) does)"
        )
    raw = metadata.get("position_unit") if isinstance(metadata, Mapping) else None
    if raw is not None and (given == "V") != (meta_unit == "V"):
        raise ValueError(
            f"position_unit = {given!r} but metadata['position_unit'] = {raw!r}; they must "
            "agree (metadata['position_unit'] 'V' means volts; another unit, the one the "
            "positions were given in before conversion to metres)"
        )
    return given
