"""In-memory arrays -> recordings, and :func:`load` dispatching on the file extension."""

from __future__ import annotations

import math
import os
from pathlib import Path

import numpy as np

from .._constants import DEFAULT_TEMPERATURE
from ._recording import DEFAULT_TIMING_TOLERANCE, Recording, numeric_array
from ._recording_set import RecordingSet
from ._units import canonical_unit, check_pixel_size, to_metres


def _per_row(name: str, value, n: int) -> list:
    """Broadcast a scalar (or None) to n rows, or check a per-row sequence has length n."""
    if value is None or isinstance(value, (str, bool)) or np.ndim(value) == 0:
        return [value] * n
    arr = np.asarray(value)
    if arr.ndim != 1 or arr.shape[0] != n:
        raise ValueError(
            f"{name} must be a scalar or have one value per recording ({n}); got shape {arr.shape}"
        )
    return list(arr.tolist()) if arr.dtype.kind in "iufb" else list(value)


def _power(p):
    """A laser power, with NaN read as unknown (None)."""
    if p is None:
        return None
    try:
        return None if math.isnan(float(p)) else p
    except (TypeError, ValueError):
        return p  # let Recording report it


def _row_names(name, n: int) -> list:
    """One name per row: ``name[i]`` for a str, the entries of a sequence, or None."""
    if name is None or isinstance(name, str):
        return [None if name is None else f"{name}[{i}]" for i in range(n)]
    names = list(name)
    if len(names) != n:
        raise ValueError(f"name must have one entry per recording ({n}); got {len(names)}")
    return names


def _row_times(times, n: int) -> list:
    """One time-stamp row (or None) per recording, from None, a shared 1-D or a 2-D array."""
    if times is None:
        return [None] * n
    t = np.asarray(times)
    if t.ndim == 1:
        return [t] * n
    if t.ndim == 2 and t.shape[0] == n:
        return list(t)
    raise ValueError(
        f"times must be 1-D (shared) or 2-D with one row per recording ({n}); got "
        f"shape {t.shape}"
    )


def _column_vector(raw, times):
    """``(positions, times)`` with a column vector (N, 1) of positions (and of times) read as
    1-D: as rows = recordings it would be N recordings of one frame, which no recording can
    be; it is one recording's column, as a CSV's single position column is."""
    if raw.ndim == 2 and raw.shape[1] == 1 and raw.shape[0] >= 2:
        raw = raw[:, 0]
        if times is not None and np.shape(times) == (raw.shape[0], 1):
            times = np.asarray(times)[:, 0]
    return raw, times


def from_arrays(
    positions,
    *,
    frame_interval,
    exposure,
    temperature=DEFAULT_TEMPERATURE,
    times=None,
    laser_power=None,
    position_unit: str = "m",
    pixel_size_m=None,
    metadata=None,
    name=None,
    allow_irregular: bool = False,
    timing_tolerance: float = DEFAULT_TIMING_TOLERANCE,
    check_units: bool = True,
) -> Recording | RecordingSet:
    """Build recordings from numpy or JAX arrays.

    **Arguments:**

    - `positions`: 1-D (one recording -> :class:`Recording`) or 2-D (rows are recordings ->
      :class:`RecordingSet`; a column vector of shape (N, 1) is one recording, as 1-D), in
      `position_unit` (m, mm, um/µm, nm, or px with `pixel_size_m` [m]); converted to
      float64 metres. ``"V"``: a detector signal in volts, kept in volts
      (``Recording.position_unit == "V"``).
    - `frame_interval`, `exposure` [s], `temperature` [K], `laser_power` [W] (NaN or None:
      unknown): scalars, or one value per row for 2-D input.
    - `times` [s]: None, 1-D (shared by all rows) or 2-D (one row per recording).
    - `name`: str (rows get ``name[i]``) or a sequence of names.
    - other keywords: see :class:`Recording`.

    **Raises:** ``ValueError`` as :class:`Recording`; for 2-D input the message starts
    with the row index.
    """
    unit = canonical_unit(position_unit)
    px = check_pixel_size(unit, pixel_size_m)
    raw = numeric_array(positions, "positions", position_unit)
    if raw.ndim not in (1, 2):
        raise ValueError(
            f"positions must be 1-D (one recording) or 2-D (rows = recordings); got shape "
            f"{raw.shape}"
        )
    raw, times = _column_vector(raw, times)
    meta = {} if metadata is None else dict(metadata)
    if raw.dtype != np.float64:
        meta.setdefault("input_dtype", raw.dtype.name)
    if unit != "m":
        meta["position_unit"] = unit
    pos = to_metres(raw, unit, px)
    if raw.ndim == 1:
        return Recording(
            pos,
            frame_interval=frame_interval,
            exposure=exposure,
            temperature=temperature,
            times=times,
            laser_power=_power(laser_power),
            metadata=meta,
            name=name,
            allow_irregular=allow_irregular,
            timing_tolerance=timing_tolerance,
            check_units=check_units,
        )
    n = raw.shape[0]
    fis = _per_row("frame_interval", frame_interval, n)
    ws = _per_row("exposure", exposure, n)
    temps = _per_row("temperature", temperature, n)
    powers = _per_row("laser_power", laser_power, n)
    names = _row_names(name, n)
    trows = _row_times(times, n)
    recs = []
    for i in range(n):
        try:
            recs.append(
                Recording(
                    pos[i],
                    frame_interval=fis[i],
                    exposure=ws[i],
                    temperature=temps[i],
                    times=trows[i],
                    laser_power=_power(powers[i]),
                    metadata=meta,
                    name=names[i],
                    allow_irregular=allow_irregular,
                    timing_tolerance=timing_tolerance,
                    check_units=check_units,
                )
            )
        except ValueError as e:
            rows, cols = raw.shape
            hint = (f" (positions has shape {raw.shape}: rows are recordings, so this is {rows} "
                    f"recordings of {cols} frames each; if the recordings are in columns, pass "
                    "positions.T)" if rows > cols else "")
            raise ValueError(f"recording {i} (row {i} of positions): {e}{hint}") from None
    return RecordingSet(recs)


_LOADERS = {
    ".json": "manifest",
    ".npz": "npz",
    ".csv": "csv",
    ".h5": "h5",
    ".hdf5": "h5",
    ".tdms": "tdms",
}


def load(path, **kwargs):
    """Load recordings from ``path`` by extension (keywords are passed on):

    - ``.json`` -> :func:`load_manifest` (RecordingSet, or a list of XYRecording for a
      manifest of x/y recordings), ``.npz`` -> :func:`load_npz`, ``.csv`` ->
      :func:`load_csv`, or :func:`load_xy_csv` (XYRecording) when the header has a
      ``y_<unit>`` column right after the ``x_<unit>`` column;
    - ``.h5`` / ``.hdf5`` -> :func:`load_bluelake` when ``channel=`` is given or the file looks
      like a Bluelake export (a ``Bluelake version`` root attribute or a ``Force HF`` group),
      else :func:`load_h5`, which needs ``dataset=`` (the error lists the datasets);
    - ``.tdms`` -> :func:`load_tdms` (``group=``, ``channel=``).

    HDF5 and TDMS need the optional dependencies h5py (``pip install "blurtrap[h5py]"``) and
    npTDMS (``pip install "blurtrap[tdms]"``).
    """
    p = Path(os.fspath(path))
    kind = _LOADERS.get(p.suffix.lower())
    if kind is None:
        raise ValueError(
            f"{p}: unknown file type {p.suffix!r}; expected one of {sorted(_LOADERS)} "
            "(manifest JSON, NPZ, CSV, HDF5, TDMS)"
        )
    if kind == "manifest":
        from ._manifest import load_manifest

        return load_manifest(p, **kwargs)
    if kind == "npz":
        from ._npz import load_npz

        return load_npz(p, **kwargs)
    if kind == "csv":
        from ._xy import is_xy_csv, load_xy_csv

        if is_xy_csv(p):
            return load_xy_csv(p, **kwargs)
        from ._csv import load_csv

        return load_csv(p, **kwargs)
    if kind == "h5":
        from ._h5 import load_h5_any

        return load_h5_any(p, **kwargs)
    from ._tdms import load_tdms

    return load_tdms(p, **kwargs)


def holds_xy(path) -> bool:
    """True when ``path`` is an x/y CSV (header ``[t_s,]x_<unit>,y_<unit>``) or a manifest
    whose entries are x/y recordings (``"axes": "xy"``, or no ``axes`` and an x/y CSV), read
    from the headers only. A file the loaders would refuse gives False: loading it reports
    the problem."""
    import json

    from ._xy import is_xy_csv

    p = Path(os.fspath(path))
    suffix = p.suffix.lower()
    if suffix == ".csv":
        return is_xy_csv(p)
    if suffix != ".json":
        return False
    try:
        entries = json.loads(p.read_text(encoding="utf-8-sig"))["recordings"]
        entry = entries[0]
        axes = entry.get("axes")
        return axes == "xy" or (axes is None and is_xy_csv(p.parent / entry["file"]))
    except (OSError, ValueError, KeyError, IndexError, TypeError, AttributeError):
        return False
