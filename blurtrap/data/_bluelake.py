"""Lumicks Bluelake HDF5 exports (:func:`load_bluelake`), read with the layout pylake uses.

h5py is optional and imported only when a file is read (``_h5_common``).
"""

from __future__ import annotations

import math
import os
from pathlib import Path

import numpy as np

from ._csv import infer_frame_interval
from ._h5_common import _attr_text, _datasets, _import_h5py, _open
from ._recording import Recording
from ._trace import (
    _is_volts,
    _listing,
    build_recording,
    check_increasing_times,
    missing_exposure,
    numeric_trace,
    positive_number,
)

#: Default channel of :func:`load_bluelake`: trap 1, x, high-frequency force.
BLUELAKE_DEFAULT_CHANNEL = "Force HF/Force 1x"


def _bluelake_kind(dset) -> str | None:
    """The channel kind as pylake decides it (``lumicks/pylake/channel.py``, channel_class):
    the ``Kind`` attribute of format-2 files, else continuous if the dataset has a
    ``Sample rate (Hz)`` attribute, else a time series if it has fields."""
    if "Kind" in dset.attrs:
        return str(_attr_text(dset.attrs["Kind"]))
    if dset.dtype.names is None:
        return "Continuous" if "Sample rate (Hz)" in dset.attrs else None
    return "TimeSeries"


def is_bluelake(f) -> bool:
    """Whether an open HDF5 file looks like a Bluelake export: pylake requires the root
    attribute ``Bluelake version``; a ``Force HF`` group is also taken as a sign."""
    return "Bluelake version" in f.attrs or "Force HF" in f


def _bluelake_channels(h5py, f) -> list[str]:
    return [n for n in _datasets(h5py, f) if _bluelake_kind(f[n]) in ("Continuous", "TimeSeries")]


def _force_calibrations(h5py, f, name: str) -> list[str]:
    """``"<item>: Rf = <pN/V>, offset = <pN>"`` for the channel's items under ``Calibration``."""
    leaf = name.split("/")[-1]
    cal = f.get("Calibration")
    out = []
    if isinstance(cal, h5py.Group):
        for item, grp in cal.items():
            if isinstance(grp, h5py.Group) and leaf in grp:
                a = grp[leaf].attrs
                if "Rf (pN/V)" in a:
                    off = a.get("Offset (pN)", "?")
                    out.append(f"{item}: Rf = {_attr_text(a['Rf (pN/V)'])} pN/V, offset = {_attr_text(off)} pN")
    return out


def load_bluelake(
    path,
    channel: str = BLUELAKE_DEFAULT_CHANNEL,
    *,
    position_unit: str = "V",
    exposure=None,
    displacement_sensitivity_m_per_V=None,
    force_sensitivity_pN_per_V=None,
    force_offset_pN=0.0,
    **recording_kwargs,
) -> Recording:
    """Load one channel of a Lumicks Bluelake HDF5 export as a photodiode recording.

    The layout is the one pylake reads: continuous channels are datasets such as
    ``Force HF/Force 1x`` with attributes ``Sample rate (Hz)`` and ``Start time (ns)`` (and
    ``Kind = "Continuous"`` in format 2); timeline channels (``Force LF/...``,
    ``Distance/...``) are compound arrays of ``Timestamp`` [ns] and ``Value``.

    **Arguments:**

    - `channel`: ``"group/name"`` of the dataset.
    - `position_unit`: the unit of the signal. ``"V"`` (default) converts with
      `displacement_sensitivity_m_per_V` [m/V] when given, else keeps the signal in volts
      (``Recording.position_unit == "V"``); a length unit (m, mm, um, nm) takes the values as
      positions.
    - `force_sensitivity_pN_per_V`, `force_offset_pN`: Bluelake stores the ``Force ...``
      channels in pN, already calibrated with Bluelake's own calibration (the file's
      ``Calibration`` group holds ``Rf (pN/V)`` and ``Offset (pN)``). Recalibrating needs the
      detector signal, ``volts = (force - offset) / Rf``: pass the Rf of the calibration that
      was active when the data were taken (required for ``Force`` channels; the error lists
      those found in the file).
    - `exposure` [s]: for continuous channels and the ``Force`` timeline channels, default the
      sample interval, as for a photodiode read by an integrating ADC (noted in
      ``metadata["defaults_applied"]``); required for other timeline channels (e.g. the
      camera-tracked ``Distance``), whose exposure the file does not record.
    - the remaining keywords (``temperature``, ``laser_power``, ``name``, ``metadata``,
      ``check_units``, ...) are passed to :class:`Recording`.

    **Returns:** a :class:`Recording` with ``frame_interval = 1 / sample rate`` (continuous) or
    the time stamps in seconds from the first one (timeline channels).

    **Raises:** ``ImportError`` without h5py; ``ValueError`` naming the file and channel (a
    missing channel lists the channels present).
    """
    h5py = _import_h5py()
    path = Path(os.fspath(path))
    if not isinstance(channel, str) or not channel.strip("/"):
        raise ValueError(f"{path}: channel must be a 'group/name' string; got {channel!r}")
    name = channel.strip("/")
    where = f"{path}, channel {name!r}"
    meta: dict = {"source": str(path), "channel": name}
    with _open(h5py, path) as f:
        obj = f.get(name)
        if not isinstance(obj, h5py.Dataset):
            found = "a group, not a dataset" if isinstance(obj, h5py.Group) else "not in the file"
            raise ValueError(
                f"{where}: {found}; the channels present are {_listing(_bluelake_channels(h5py, f))}"
            )
        kind = _bluelake_kind(obj)
        values, frame_interval, times, source = _read_channel(h5py, f, obj, kind, where, meta)
        if name.split("/")[0].startswith("Force"):
            if force_sensitivity_pN_per_V is None:
                raise _missing_force_sensitivity(h5py, f, name, where)
            values = _force_to_volts(
                values, force_sensitivity_pN_per_V, force_offset_pN, position_unit, where, meta
            )
        elif force_sensitivity_pN_per_V is not None or force_offset_pN != 0.0:
            raise ValueError(
                f"{where}: force_sensitivity_pN_per_V / force_offset_pN were given but this is not "
                "a Force channel (they convert Bluelake's force channels, in pN, to volts; they "
                "would be ignored): remove them"
            )
    # Continuous channels are photodiode signals sampled by an integrating ADC, and the
    # timeline force channels (Force LF) are their averages over each interval: both integrate
    # over the whole sample interval. Other timeline channels (e.g. camera-tracked Distance)
    # have an exposure the file does not record.
    if kind == "Continuous" or name.split("/")[0].startswith("Force"):
        meta["detector"] = "photodiode"
        if exposure is None:
            exposure = frame_interval
            meta["defaults_applied"] = {"exposure_s": frame_interval}
    elif exposure is None:
        raise missing_exposure(where, frame_interval)
    return build_recording(
        values,
        where,
        position_unit=position_unit,
        displacement_sensitivity_m_per_V=displacement_sensitivity_m_per_V,
        frame_interval=frame_interval,
        exposure=exposure,
        times=times,
        meta=meta,
        recording_kwargs=recording_kwargs,
        interval_source=source,
    )


def _read_channel(h5py, f, obj, kind, where: str, meta: dict):
    """``(values, frame_interval, times, source of the interval)`` of a continuous or timeline
    channel; other kinds are errors that list the channels present."""
    if kind == "Continuous":
        if "Sample rate (Hz)" not in obj.attrs:
            raise ValueError(
                f"{where}: continuous channel without a 'Sample rate (Hz)' attribute "
                f"(attributes: {_listing(obj.attrs)})"
            )
        rate = positive_number(obj.attrs["Sample rate (Hz)"], "'Sample rate (Hz)'", "Hz", where)
        values = numeric_trace(obj[()], where, "the channel")
        frame_interval, times = 1.0 / rate, None
        meta["sample_rate_Hz"] = rate
        if "Start time (ns)" in obj.attrs:
            meta["start_time_ns"] = int(np.asarray(obj.attrs["Start time (ns)"]))
        return values, frame_interval, times, f"the channel's 'Sample rate (Hz)' = {rate!r} Hz"
    if kind == "TimeSeries":
        return _read_timeline(obj, where, meta)
    if kind == "TimeTags":
        raise ValueError(
            f"{where}: holds photon time tags (arrival times), not a sampled signal; choose a "
            f"continuous or timeline channel: {_listing(_bluelake_channels(h5py, f))}"
        )
    what = f"channel kind {kind!r}" if kind else "no 'Kind' or 'Sample rate (Hz)' attribute"
    raise ValueError(
        f"{where}: not a Bluelake signal channel ({what}); the channels present are "
        f"{_listing(_bluelake_channels(h5py, f))}"
    )


def _read_timeline(obj, where: str, meta: dict):
    """A timeline channel: compound ``Timestamp`` [ns] and ``Value`` fields."""
    fields = obj.dtype.names or ()
    if "Timestamp" not in fields or "Value" not in fields:
        raise ValueError(
            f"{where}: timeline channel with fields {list(fields)}; expected 'Timestamp' "
            "[ns] and 'Value'"
        )
    data = obj[()]
    stamps = numeric_trace(data["Timestamp"], where, "Timestamp")
    values = numeric_trace(data["Value"], where, "Value")
    if stamps.dtype.kind not in "iu":
        raise ValueError(
            f"{where}: Timestamp must hold integer nanoseconds; got dtype {stamps.dtype}"
        )
    check_increasing_times(stamps, where, "Timestamp")
    times = (stamps - stamps[0]).astype(np.float64) / 1e9  # correctly rounded seconds
    frame_interval = infer_frame_interval(times) if times.shape[0] >= 2 else 1.0
    meta["start_time_ns"] = int(stamps[0])
    meta["frame_interval_inferred"] = True
    return values, frame_interval, times, "the median step of the channel's time stamps"


def _missing_force_sensitivity(h5py, f, name: str, where: str) -> ValueError:
    cals = _force_calibrations(h5py, f, name)
    listed = (
        f"the file's calibration items for {name.split('/')[-1]!r}: {'; '.join(cals)}"
        if cals
        else "the file has no calibration items for this channel"
    )
    return ValueError(
        f"{where}: Bluelake stores force channels in pN, already calibrated; "
        "recalibrating needs the detector signal in volts = (force - offset) / Rf. "
        "Pass force_sensitivity_pN_per_V=<Rf> (and force_offset_pN=<offset>) of the "
        f"calibration that was active when the data were taken ({listed})"
    )


def _force_to_volts(values, force_sensitivity_pN_per_V, force_offset_pN, position_unit, where, meta):
    """A force channel [pN] back to the detector signal: ``(force - offset) / Rf`` [V]."""
    rf = positive_number(force_sensitivity_pN_per_V, "force_sensitivity_pN_per_V", "pN/V", where)
    try:
        off = float(force_offset_pN)
    except (TypeError, ValueError):
        off = math.nan
    if not math.isfinite(off) or isinstance(force_offset_pN, bool):
        raise ValueError(f"{where}: force_offset_pN must be a finite number [pN]; got {force_offset_pN!r}")
    if not _is_volts(position_unit):
        raise ValueError(
            f"{where}: a force channel divided by force_sensitivity_pN_per_V is a signal "
            f"in volts; position_unit must be 'V', not {position_unit!r}"
        )
    values = (values.astype(np.float64) - off) / rf
    meta["force_sensitivity_pN_per_V"] = rf
    meta["force_offset_pN"] = off
    return values
