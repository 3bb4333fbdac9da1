"""HDF5 recordings: plain datasets (:func:`load_h5`), and :func:`load_h5_any`, which picks
between them and Lumicks Bluelake exports (:func:`load_bluelake`, in ``_bluelake``).

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

from ._bluelake import is_bluelake, load_bluelake
from ._csv import infer_frame_interval
from ._h5_common import _dataset_listing, _import_h5py, _open
from ._recording import Recording
from ._trace import (
    _listing,
    build_recording,
    check_increasing_times,
    missing_exposure,
    numeric_trace,
    positive_number,
)

#: Dataset attributes read as the sample rate [Hz] by :func:`load_h5`, in this order.
SAMPLE_RATE_ATTRS = ("Sample rate (Hz)", "sample_rate", "fs")


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
        obj_rate = (*_sample_rate_from_attrs(obj, where), list(obj.attrs))
        times = None
        if time_dataset is not None:
            times = _read_times(h5py, f, path, time_dataset, name, values.shape[0], where, meta)
    if column is not None:
        meta["column"] = int(column)
    frame_interval, source = _frame_interval(sample_rate, obj_rate, times, where, meta)
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


def _read_times(h5py, f, path, time_dataset, name: str, n_values: int, where: str, meta: dict):
    """The time stamps [s] of ``time_dataset``: one per sample, increasing."""
    tname = time_dataset.strip("/") if isinstance(time_dataset, str) else time_dataset
    if not isinstance(tname, str) or not tname:
        raise ValueError(f"{where}: time_dataset must be a dataset path; got {time_dataset!r}")
    _, times, twhere = _read_1d(h5py, f, path, tname, "the time dataset", None)
    if times.shape[0] != n_values:
        raise ValueError(
            f"{twhere}: has {times.shape[0]} time stamps but {name!r} has "
            f"{n_values} samples; they must match"
        )
    times = times.astype(np.float64)
    check_increasing_times(times, twhere, "times")
    meta["time_dataset"] = tname
    return times


def _frame_interval(sample_rate, obj_rate, times, where: str, meta: dict):
    """``(frame interval [s], where it came from)``: `sample_rate`, else the dataset's
    sample-rate attribute (``obj_rate = (rate, attribute name, attribute names)``), else the
    time stamps; none of them is an error listing the attributes."""
    attr_rate, attr_name, attr_names = obj_rate
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
    return frame_interval, source


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
