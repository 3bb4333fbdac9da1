"""HDF5 recordings: Lumicks Bluelake exports (:func:`load_bluelake`) and plain datasets
(:func:`load_h5`).

h5py is an optional dependency (``pip install "blurtrap[h5py]"``), imported only when a file
is read, so ``import blurtrap.data`` never needs it. The helpers that turn a raw numeric trace
into a :class:`Recording` (unit conversion, volts, validation with the file and dataset in every
message) are shared with the TDMS loader (``_trace.py``).
"""

from __future__ import annotations

import math
import os
from pathlib import Path

import numpy as np

from ._csv import infer_frame_interval
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

H5PY_INSTALL = 'pip install "blurtrap[h5py]"'
#: Dataset attributes read as the sample rate [Hz] by :func:`load_h5`, in this order.
SAMPLE_RATE_ATTRS = ("Sample rate (Hz)", "sample_rate", "fs")
#: Default channel of :func:`load_bluelake`: trap 1, x, high-frequency force.
BLUELAKE_DEFAULT_CHANNEL = "Force HF/Force 1x"


def _import_h5py():
    try:
        import h5py
    except ImportError as e:
        raise ImportError(
            "reading HDF5 files needs h5py, an optional dependency of blurtrap; install it with "
            f"{H5PY_INSTALL} (or pip install h5py)"
        ) from e
    return h5py


# -- reading HDF5 -------------------------------------------------------------------------------


def _open(h5py, path: Path):
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no such file")
    try:
        return h5py.File(path, "r")
    except OSError as e:
        raise ValueError(f"{path}: cannot be read as an HDF5 file ({e})") from None


def _datasets(h5py, f) -> list[str]:
    out: list[str] = []
    f.visititems(lambda name, obj: out.append(name) if isinstance(obj, h5py.Dataset) else None)
    return out


def _dataset_listing(h5py, f) -> list[str]:
    """``"<name> <shape>"`` for each dataset in the file."""
    return [f"{n} {f[n].shape}" for n in _datasets(h5py, f)]


def _attr_text(value):
    if isinstance(value, bytes):
        return value.decode("utf-8", "replace")
    if isinstance(value, np.ndarray) and value.ndim == 0:
        return _attr_text(value.item())
    return value


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
            source = f"the channel's 'Sample rate (Hz)' = {rate!r} Hz"
        elif kind == "TimeSeries":
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
            source = "the median step of the channel's time stamps"
        elif kind == "TimeTags":
            raise ValueError(
                f"{where}: holds photon time tags (arrival times), not a sampled signal; choose a "
                f"continuous or timeline channel: {_listing(_bluelake_channels(h5py, f))}"
            )
        else:
            what = f"channel kind {kind!r}" if kind else "no 'Kind' or 'Sample rate (Hz)' attribute"
            raise ValueError(
                f"{where}: not a Bluelake signal channel ({what}); the channels present are "
                f"{_listing(_bluelake_channels(h5py, f))}"
            )
        if name.split("/")[0].startswith("Force"):
            if force_sensitivity_pN_per_V is None:
                cals = _force_calibrations(h5py, f, name)
                listed = (
                    f"the file's calibration items for {name.split('/')[-1]!r}: {'; '.join(cals)}"
                    if cals
                    else "the file has no calibration items for this channel"
                )
                raise ValueError(
                    f"{where}: Bluelake stores force channels in pN, already calibrated; "
                    "recalibrating needs the detector signal in volts = (force - offset) / Rf. "
                    "Pass force_sensitivity_pN_per_V=<Rf> (and force_offset_pN=<offset>) of the "
                    f"calibration that was active when the data were taken ({listed})"
                )
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


def _sample_rate_from_attrs(dset, where: str):
    """``(rate, attribute name)`` from the first of :data:`SAMPLE_RATE_ATTRS` present; several
    present and disagreeing is an error."""
    found = [
        (a, positive_number(dset.attrs[a], f"attribute {a!r}", "Hz", where))
        for a in SAMPLE_RATE_ATTRS
        if a in dset.attrs
    ]
    if not found:
        return None, None
    for a, r in found[1:]:
        if not math.isclose(r, found[0][1], rel_tol=1e-9):
            raise ValueError(
                f"{where}: the sample-rate attributes disagree: {found[0][0]!r} = {found[0][1]!r} Hz "
                f"but {a!r} = {r!r} Hz"
            )
    return found[0][1], found[0][0]


def _read_1d(h5py, f, path, name: str, what: str, column):
    where = f"{path}, dataset {name!r}"
    obj = f.get(name)
    if not isinstance(obj, h5py.Dataset):
        found = "a group, not a dataset" if isinstance(obj, h5py.Group) else "not in the file"
        listed = _dataset_listing(h5py, f)
        raise ValueError(f"{where}: {found}; the datasets present are {_listing(listed)}")
    arr = numeric_trace(obj[()], where, what)
    if arr.ndim == 2:
        if column is None:
            raise ValueError(
                f"{where}: {what} is 2-D with shape {arr.shape}; a recording is one trace: pass "
                f"column=<0..{arr.shape[1] - 1}> to take dataset[:, column] (rows are samples)"
            )
        if isinstance(column, bool) or not isinstance(column, (int, np.integer)) or not (
            -arr.shape[1] <= column < arr.shape[1]
        ):
            raise ValueError(
                f"{where}: column = {column!r} is not a column index of the shape {arr.shape} "
                f"dataset; expected an integer 0..{arr.shape[1] - 1}"
            )
        arr = arr[:, int(column)]
    elif column is not None:
        raise ValueError(
            f"{where}: column = {column!r} was given but the dataset is {arr.ndim}-D (shape "
            f"{arr.shape}); column only selects a column of a 2-D dataset: remove it"
        )
    if arr.ndim != 1:
        raise ValueError(f"{where}: {what} has shape {arr.shape}; expected a 1-D trace (or 2-D with column=)")
    return obj, arr, where


def load_h5(
    path,
    dataset: str,
    sample_rate=None,
    *,
    position_unit: str = "nm",
    exposure=None,
    time_dataset: str | None = None,
    column: int | None = None,
    displacement_sensitivity_m_per_V=None,
    **recording_kwargs,
) -> Recording:
    """Load one recording from a dataset of positions in any HDF5 file.

    **Arguments:**

    - `dataset`: path of a 1-D numeric dataset (or 2-D with `column`, which takes
      ``dataset[:, column]``).
    - `sample_rate` [Hz]: default the dataset's attribute ``Sample rate (Hz)``, ``sample_rate``
      or ``fs``; or give `time_dataset`, a 1-D dataset of time stamps [s] (the frame interval is
      then inferred from them, as :func:`load_csv` does). A `sample_rate` that disagrees with
      the attribute is an error.
    - `position_unit`: m, mm, um (µm), nm, px (with ``pixel_size_m``), or ``"V"`` with
      `displacement_sensitivity_m_per_V` [m/V].
    - `exposure` [s]: required.
    - the remaining keywords are passed to :class:`Recording`.

    **Raises:** ``ImportError`` without h5py; ``ValueError`` naming the file and dataset (a
    missing dataset lists those present; NaN names its index).
    """
    h5py = _import_h5py()
    path = Path(os.fspath(path))
    if not isinstance(dataset, str) or not dataset.strip("/"):
        raise ValueError(f"{path}: dataset must be the path of a dataset in the file; got {dataset!r}")
    name = dataset.strip("/")
    meta: dict = {"source": str(path), "dataset": name}
    with _open(h5py, path) as f:
        obj, values, where = _read_1d(h5py, f, path, name, "the dataset", column)
        attr_rate, attr_name = _sample_rate_from_attrs(obj, where)
        attr_names = list(obj.attrs)
        times = None
        if time_dataset is not None:
            tname = time_dataset.strip("/") if isinstance(time_dataset, str) else time_dataset
            if not isinstance(tname, str) or not tname:
                raise ValueError(f"{where}: time_dataset must be a dataset path; got {time_dataset!r}")
            _, times, twhere = _read_1d(h5py, f, path, tname, "the time dataset", None)
            if times.shape[0] != values.shape[0]:
                raise ValueError(
                    f"{twhere}: has {times.shape[0]} time stamps but {name!r} has "
                    f"{values.shape[0]} samples; they must match"
                )
            times = times.astype(np.float64)
            check_increasing_times(times, twhere, "times")
            meta["time_dataset"] = tname
    if column is not None:
        meta["column"] = int(column)
    if sample_rate is not None:
        rate = positive_number(sample_rate, "sample_rate", "Hz", where)
        if attr_rate is not None and not math.isclose(rate, attr_rate, rel_tol=1e-9):
            raise ValueError(
                f"{where}: sample_rate = {rate!r} Hz was given but the dataset's attribute "
                f"{attr_name!r} = {attr_rate!r} Hz; they disagree (remove sample_rate to use the "
                "file's rate, or fix the file)"
            )
        source = f"sample_rate = {rate!r} Hz"
    elif attr_rate is not None:
        rate = attr_rate
        source = f"the dataset's attribute {attr_name!r} = {rate!r} Hz (is it in kHz?)"
    else:
        rate = None
    if rate is not None:
        frame_interval = 1.0 / rate
        meta["sample_rate_Hz"] = rate
    elif times is not None:
        if times.shape[0] < 2:
            raise ValueError(f"{where}: positions must hold at least 2 samples; got {times.shape[0]}")
        frame_interval = infer_frame_interval(times)
        meta["frame_interval_inferred"] = True
        source = f"the time stamps in {meta['time_dataset']!r} (they must be in seconds)"
    else:
        attrs = _listing(attr_names) if attr_names else "none"
        raise ValueError(
            f"{where}: no sample rate: pass sample_rate=<Hz> or time_dataset=<a 1-D dataset of "
            f"time stamps in s>, or store the rate as a dataset attribute named "
            f"{' / '.join(repr(a) for a in SAMPLE_RATE_ATTRS)} (the dataset's attributes: {attrs})"
        )
    if exposure is None:
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


def load_h5_any(path, **kwargs) -> Recording:
    """:func:`load` for ``.h5`` / ``.hdf5``: ``channel=`` or a Bluelake-like file ->
    :func:`load_bluelake`; ``dataset=`` -> :func:`load_h5`; otherwise an error listing the
    datasets."""
    channel = kwargs.pop("channel", None)
    dataset = kwargs.pop("dataset", None)
    path = Path(os.fspath(path))
    if channel is not None and dataset is not None:
        raise ValueError(
            f"{path}: give either channel= (a Bluelake channel) or dataset= (any HDF5 dataset), "
            f"not both; got channel={channel!r}, dataset={dataset!r}"
        )
    if channel is not None:
        return load_bluelake(path, channel, **kwargs)
    if dataset is not None:
        return load_h5(path, dataset, **kwargs)
    h5py = _import_h5py()
    with _open(h5py, path) as f:
        bluelake = is_bluelake(f)
        listed = _dataset_listing(h5py, f)
    if bluelake:
        return load_bluelake(path, **kwargs)
    raise ValueError(
        f"{path}: not a Bluelake export (no 'Bluelake version' attribute, no 'Force HF' group): "
        f"pass dataset=<the dataset of positions> (with sample_rate and exposure); the datasets "
        f"present are {_listing(listed)}"
    )
