"""Writing a manifest JSON and its CSV files (:func:`save_manifest`); the reader, and the
format, are in ``_manifest``."""

from __future__ import annotations

import json
import os
import re
from decimal import Decimal
from pathlib import Path

from ._csv import write_csv
from ._instrument import INSTRUMENT_KEYS
from ._manifest import _LOADER_KEYS
from ._recording import DEFAULT_TIMING_TOLERANCE, Recording, thaw
from ._recording_set import RecordingSet
from ._units import canonical_unit, check_pixel_size, decimal_text
from ._xy import XYRecording, write_xy_csv


def _safe_stem(name: str | None, i: int) -> str:
    if not name:
        return f"recording_{i:03d}"
    stem = re.sub(r"[^A-Za-z0-9._-]+", "_", name).strip("._") or f"recording_{i:03d}"
    return stem


def _items(recordings) -> list:
    """Recording / XYRecording / RecordingSet / a sequence of either kind -> a list."""
    if isinstance(recordings, (Recording, XYRecording)):
        return [recordings]
    if isinstance(recordings, RecordingSet):
        return list(recordings)
    items = list(recordings)
    if any(isinstance(r, XYRecording) for r in items):
        for i, r in enumerate(items):
            if not isinstance(r, XYRecording):
                raise TypeError(f"save_manifest: item {i} is a {type(r).__name__} among x/y "
                                f"recordings; a manifest holds one kind (XYRecording or "
                                f"Recording): save them in two manifests")
        return items
    return list(RecordingSet(items))


def save_manifest(
    recordings,
    path,
    position_unit: str | None = None,
    *,
    pixel_size_m=None,
) -> list[Path]:
    """Write a manifest JSON at ``path`` and one CSV per recording next to it.

    `position_unit`: the unit of the CSV files' positions; None (default): ``"V"`` for
    recordings in volts, else ``"nm"`` (a manifest has one unit: volts and metres cannot be
    mixed). The instrument keys of the metadata are written as entry keys and a recording's
    stage as a ``stage_nm`` column. `recordings` may also be an :class:`XYRecording` or a
    list of them: each is written as ``t_s,x_<unit>,y_<unit>`` with ``"axes": "xy"`` (a
    length unit or V; not px).

    CSV names come from the recording names (made file-system safe and unique), else
    ``recording_000.csv``, ... Positions are written as exact decimals in `position_unit`
    and times with repr precision, so :func:`load_manifest` gives back identical float64
    values (for ``px`` only to within a rounding). Existing files are overwritten.

    **Returns:** the paths written (manifest first).
    """
    recordings = _items(recordings)
    unit = _save_unit(recordings, position_unit)
    px = check_pixel_size(unit, pixel_size_m)
    path = Path(os.fspath(path))
    folder = path.parent
    used: set[str] = set()
    entries = []
    decimals: dict[str, str] = {}
    written = [path]
    for i, r in enumerate(recordings):
        stem = _safe_stem(r.name, i)
        fname, k = f"{stem}.csv", 1
        while fname.lower() in used or (folder / fname).resolve() == path.resolve():
            fname, k = f"{stem}_{k}.csv", k + 1
        used.add(fname.lower())
        xy = isinstance(r, XYRecording)
        if xy:
            if unit == "px":
                raise ValueError("save_manifest: x/y recordings are written in a length unit "
                                 "or V; position_unit = 'px' is not supported for them")
            write_xy_csv(r, folder / fname, unit)
            name, r = r.name, r.x  # the acquisition settings are shared by both axes
        else:
            write_csv(r, folder / fname, unit, px)
            name = r.name
        written.append(folder / fname)
        entries.append(_entry(r, i, fname, name, xy, decimals))
    doc: dict = {"position_unit": unit}
    if unit == "px":
        doc["pixel_size_m"] = px
    doc["recordings"] = entries
    text = json.dumps(doc, indent=1, ensure_ascii=False)
    for token, dec in decimals.items():
        text = text.replace(f'"{token}"', dec)
    path.write_text(text + "\n", encoding="utf-8", newline="\n")
    return written


def _save_unit(recordings: list, position_unit: str | None) -> str:
    """The manifest's position unit: the one asked for, checked against volts vs metres."""
    in_volts = {r.position_unit == "V" for r in recordings}
    if len(in_volts) > 1:
        raise ValueError(
            "save_manifest: some recordings are in volts and others in metres; a manifest has "
            "one position_unit: save them in two manifests"
        )
    if position_unit is None:
        position_unit = "V" if in_volts == {True} else "nm"
    unit = canonical_unit(position_unit)
    if (unit == "V") != (in_volts == {True}):
        raise ValueError(
            f"save_manifest: position_unit = {position_unit!r} but the recordings are in "
            f"{'volts' if in_volts == {True} else 'metres'}; pass "
            f"{'V' if in_volts == {True} else 'a length unit (nm, um, m, ...)'} or None"
        )
    return unit


def _entry(r: Recording, i: int, fname: str, name, xy: bool, decimals: dict) -> dict:
    """The manifest entry of recording ``r`` (written as ``fname``); the laser power goes in
    as a token that ``decimals`` maps to its exact decimal text."""
    entry: dict = {
        "file": fname,
        "frame_interval_s": r.frame_interval,
        "exposure_s": r.exposure,
        "temperature_K": r.temperature,
    }
    if r.laser_power is not None:
        token = f"@@DECIMAL{i}@@"
        decimals[token] = decimal_text(Decimal(repr(r.laser_power)).scaleb(3))
        entry["laser_power_mW"] = token
    # always written: a missing name would come back as the file stem (null stays None)
    entry["name"] = name
    if xy:
        entry["axes"] = "xy"
    plain = thaw(r.metadata)
    assert isinstance(plain, dict)  # thaw maps a mapping to a dict
    for k in INSTRUMENT_KEYS:
        if plain.get(k) is not None:
            entry[k] = plain[k]
    skip = (*_LOADER_KEYS, "manifest", *INSTRUMENT_KEYS)
    meta = {k: v for k, v in plain.items() if k not in skip}
    if meta:
        entry["metadata"] = meta
    if r.allow_irregular:
        entry["allow_irregular"] = True
    if r.timing_tolerance != DEFAULT_TIMING_TOLERANCE:
        entry["timing_tolerance"] = r.timing_tolerance
    if not r.check_units:
        entry["check_units"] = False
    return entry
