"""Manifest JSON: a set of CSV recordings with their acquisition settings (DESIGN section 6).

```json
{"position_unit": "nm",
 "recordings": [{"file": "w010.csv", "frame_interval_s": 6.667e-4, "exposure_s": 1.0e-4,
                 "temperature_K": 295.0, "laser_power_mW": 100.0}]}
```
Files are relative to the manifest. Numbers are read as exact decimals, so the mW -> W
conversion and the saved/loaded values are bit-exact. The instrument keys
(:data:`INSTRUMENT_KEYS`: ``detector``, ``bead_radius_m``, ``drive``, ...) may be given per
recording or at the top level as the default for every recording; they are validated and
stored in the recording's metadata under the same names (see :func:`instrument_settings`).
"""

from __future__ import annotations

import dataclasses
import json
import math
import os
from decimal import Decimal
from pathlib import Path
from typing import Any

from .._constants import DEFAULT_TEMPERATURE
from ._csv import load_csv
from ._instrument import INSTRUMENT_KEYS, check_instrument
from ._recording import DEFAULT_TIMING_TOLERANCE
from ._recording_set import RecordingSet
from ._units import canonical_unit, check_pixel_size
from ._xy import XYRecording, is_xy_csv, load_xy_csv

_TOP_KEYS = (
    "position_unit",
    "pixel_size_m",
    "recordings",
    "description",
    "allow_irregular",
    *INSTRUMENT_KEYS,
)
_ENTRY_KEYS = (
    "file",
    "frame_interval_s",
    "exposure_s",
    "temperature_K",
    "laser_power_mW",
    "name",
    "metadata",
    "allow_irregular",
    "timing_tolerance",
    "check_units",
    "axes",
    *INSTRUMENT_KEYS,
)
_AXES = ("x", "xy")
# metadata keys that the loaders set themselves; not written back by save_manifest
# (``_manifest_save``)
_LOADER_KEYS = ("source", "excluded_rows", "defaults_applied", "position_unit")


def _plain(obj) -> Any:
    """Decimals from the JSON parser -> float, recursively."""
    if isinstance(obj, Decimal):
        return float(obj)
    if isinstance(obj, dict):
        return {k: _plain(v) for k, v in obj.items()}
    if isinstance(obj, list):
        return [_plain(v) for v in obj]
    return obj


class _DuplicateKey(Exception):
    pass


def _no_duplicates(pairs):
    out = {}
    for k, v in pairs:
        if k in out:
            raise _DuplicateKey(k, [key for key, _ in pairs])
        out[k] = v
    return out


def _flag(where: str, key: str, value) -> bool:
    if not isinstance(value, bool):
        raise ValueError(f"{where}: {key} must be true or false (a JSON boolean); got {value!r}")
    return value


def _number(where: str, key: str, value, scale_exp: int = 0) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, Decimal, float)):
        raise ValueError(f"{where}: {key} must be a number; got {value!r}")
    if isinstance(value, float):  # NaN / Infinity constants
        return value
    return float(Decimal(value).scaleb(-scale_exp))


def _entry_axes(where: str, e: dict, csv_path: Path) -> str:
    """``"x"`` or ``"xy"``: the entry's ``axes`` key, checked against the CSV's header, or
    (no key) what the header says."""
    has_y = is_xy_csv(csv_path)
    if "axes" not in e:
        return "xy" if has_y else "x"
    axes = e["axes"]
    if not isinstance(axes, str) or axes not in _AXES:
        raise ValueError(f"{where}: 'axes' must be one of {list(_AXES)} (\"x\": one trace, "
                         f"\"xy\": an x/y recording); got {_plain(axes)!r:.60}")
    if axes == "x" and has_y:
        raise ValueError(f"{where}: 'axes' is \"x\" but the CSV's header has a y column; "
                         f"use \"axes\": \"xy\" (or leave 'axes' out) for an x/y recording")
    return axes


def _check_kinds(path: Path, recs: list) -> None:
    """A manifest holds one kind: single traces or x/y recordings."""
    xy = [i for i, r in enumerate(recs) if isinstance(r, XYRecording)]
    if xy and len(xy) != len(recs):
        one = next(i for i, r in enumerate(recs) if not isinstance(r, XYRecording))
        raise ValueError(f"{path}: recordings[{xy[0]}] is an x/y recording but recordings[{one}] "
                         f"is a single trace; a manifest holds one kind (write two manifests)")


def load_manifest(path, *, on_bad_rows: str = "error") -> RecordingSet | list[XYRecording]:
    """Load a manifest JSON and its CSV files into a :class:`RecordingSet`, or, when its
    entries are x/y recordings, a list of :class:`XYRecording` (one per entry).

    Entry keys: ``file`` and ``exposure_s`` (required), ``frame_interval_s`` (else inferred
    from the CSV time stamps), ``temperature_K`` (else 295 K, noted in
    ``metadata["defaults_applied"]``), ``laser_power_mW``, ``name`` (default: file stem),
    ``metadata``, ``allow_irregular`` (keep irregular time stamps; their jitter is reported
    in ``timing_jitter``), ``timing_tolerance``, ``check_units``, ``axes`` (``"x"``: one
    trace; ``"xy"``: an x/y recording, CSV header ``t_s,x_<unit>,y_<unit>``; default: the
    CSV's header decides; one manifest holds one kind), and the instrument keys (below).
    Top level: ``position_unit`` (required; ``"V"`` for a detector signal in volts),
    ``pixel_size_m`` (for ``px`` only), ``recordings``, ``description`` (a string),
    ``allow_irregular`` and the instrument keys (defaults for the entries that do not set
    them; an entry's ``null`` removes a default). Unknown keys are errors (so ``exposure_ms``
    cannot be ignored).

    Instrument keys (all optional; stored in ``metadata`` under the same names, read by
    :func:`instrument_settings`): ``detector`` (``"camera"`` | ``"photodiode"``),
    ``anti_aliasing`` (bool, photodiode only), ``diode_filter`` (``"fit"`` | ``"none"`` |
    ``{"alpha": a, "f3db_Hz": f}``, photodiode only unless ``"none"``), ``bead_radius_m``
    (< 1e-3), ``viscosity_Pa_s``, ``distance_to_surface_m`` (> the radius),
    ``bead_density_kg_per_m3``, ``fluid_density_kg_per_m3``, ``friction`` (``"free"`` |
    ``"stokes"``, which needs ``bead_radius_m``), ``hydrodynamics`` (``"auto"`` | true |
    false), ``drive`` (``{"frequency_Hz": f}``; the
    CSV then needs a ``stage_nm`` column), ``fit_range_Hz`` (``[fmin, fmax]``),
    ``excluded_ranges_Hz`` (``[[a, b], ...]``). They may also be given inside an entry's
    ``metadata`` object, but not in both places.

    **Raises:** ``ValueError`` naming the manifest, the entry and the problem;
    ``FileNotFoundError`` for a missing CSV.
    """
    path = Path(os.fspath(path))
    doc = _read_doc(path)
    unit, px = _position_unit(path, doc)
    # manifest-level defaults for the entries that do not set them themselves
    irregular_default = _flag(str(path), "allow_irregular", doc.get("allow_irregular", False))
    top_instrument = {k: _plain(doc[k]) for k in INSTRUMENT_KEYS if k in doc}
    entries = doc.get("recordings")
    if not isinstance(entries, list) or not entries:
        raise ValueError(f"{path}: 'recordings' must be a non-empty list of entries")
    defaults = _Defaults(unit, px, irregular_default, top_instrument, on_bad_rows)
    recs: list = [_load_entry(path, i, e, defaults) for i, e in enumerate(entries)]
    _check_kinds(path, recs)
    return recs if isinstance(recs[0], XYRecording) else RecordingSet(recs)


def _read_doc(path: Path) -> dict:
    """The manifest's JSON object (numbers as exact decimals), with clear errors for text
    that is not UTF-8, empty, invalid or duplicated keys, and unknown top-level keys."""
    try:
        text = path.read_bytes().decode("utf-8-sig")
    except UnicodeDecodeError as e:
        raise ValueError(f"{path}: not UTF-8 text ({e})") from None
    if not text.strip():
        raise ValueError(f"{path}: manifest file is empty")
    try:
        doc = json.loads(text, parse_float=Decimal, object_pairs_hook=_no_duplicates)
    except json.JSONDecodeError as e:
        raise ValueError(
            f"{path}: invalid JSON at line {e.lineno}, column {e.colno}: {e.msg}"
        ) from None
    except _DuplicateKey as e:
        raise ValueError(
            f"{path}: key {e.args[0]!r} appears twice in one JSON object (in the object with "
            f"keys {e.args[1]}); each setting must be given once"
        ) from None
    except RecursionError:
        raise ValueError(f"{path}: invalid JSON (nested too deeply)") from None
    except ValueError as e:  # e.g. integers longer than Python's digit limit
        raise ValueError(f"{path}: invalid JSON ({e})") from None
    if not isinstance(doc, dict):
        raise ValueError(f"{path}: the manifest must be a JSON object with 'recordings'")
    unknown = sorted(set(doc) - set(_TOP_KEYS))
    if unknown:
        raise ValueError(f"{path}: unknown top-level key(s) {unknown}; allowed: {list(_TOP_KEYS)}")
    description = doc.get("description")
    if description is not None and not isinstance(description, str):
        raise ValueError(
            f"{path}: 'description' must be a string (or null); got "
            f"{type(_plain(description)).__name__} {_plain(description)!r:.60}"
        )
    return doc


def _position_unit(path: Path, doc: dict) -> tuple[str, float | None]:
    """The manifest's position unit and pixel size (for ``px``)."""
    if "position_unit" not in doc:
        raise ValueError(f'{path}: \'position_unit\' is missing (e.g. "position_unit": "nm")')
    px_given = (
        None if "pixel_size_m" not in doc else _number(str(path), "pixel_size_m", doc["pixel_size_m"])
    )
    try:
        unit = canonical_unit(doc["position_unit"])
        px = check_pixel_size(unit, px_given)
    except ValueError as e:
        raise ValueError(f"{path}: {e}") from None
    return unit, px


@dataclasses.dataclass(frozen=True)
class _Defaults:
    """What the manifest's top level sets for every entry."""

    unit: str
    px: float | None
    allow_irregular: bool
    instrument: dict
    on_bad_rows: str


def _entry_file(path: Path, i: int, e) -> tuple[str, Path]:
    """The entry's place for messages and its CSV path, after the key checks."""
    where = f"{path}, recordings[{i}]"
    if not isinstance(e, dict):
        raise ValueError(f"{where}: each entry must be a JSON object; got {e!r}")
    unknown = sorted(set(e) - set(_ENTRY_KEYS))
    if unknown:
        raise ValueError(f"{where}: unknown key(s) {unknown}; allowed: {list(_ENTRY_KEYS)}")
    for key in ("file", "exposure_s"):
        if key not in e:
            raise ValueError(f"{where}: required key {key!r} is missing")
    if not isinstance(e["file"], str) or not e["file"]:
        raise ValueError(f"{where}: 'file' must be a file name; got {e['file']!r}")
    csv_path = path.parent / e["file"]
    shown = e["file"] if len(e["file"]) <= 80 else e["file"][:77] + "..."
    where = f"{where} ({shown})"
    try:
        found = csv_path.is_file()
    except (OSError, ValueError) as err:  # e.g. a name too long for the file system
        raise ValueError(f"{where}: cannot use this file name ({err})") from None
    if not found:
        raise FileNotFoundError(f"{where}: file not found: {csv_path}")
    return where, csv_path


def _entry_numbers(where: str, e: dict) -> tuple[dict, dict]:
    """Loader keywords from the entry's acquisition numbers, and the defaults applied."""
    kw = {}
    defaults = {}
    kw["exposure"] = _number(where, "exposure_s", e["exposure_s"])
    if "frame_interval_s" in e:
        kw["frame_interval"] = _number(where, "frame_interval_s", e["frame_interval_s"])
    if "temperature_K" in e:
        kw["temperature"] = _number(where, "temperature_K", e["temperature_K"])
    else:
        kw["temperature"] = DEFAULT_TEMPERATURE
        defaults["temperature_K"] = DEFAULT_TEMPERATURE
    if e.get("laser_power_mW") is not None:
        kw["laser_power"] = _number(where, "laser_power_mW", e["laser_power_mW"], 3)
    return kw, defaults


def _entry_instrument(where: str, e: dict, top: dict) -> tuple[dict, dict, str]:
    """The entry's metadata, its instrument settings (entry keys, ``metadata`` and the
    top-level defaults) and the place for messages naming the defaults used."""
    meta = e.get("metadata", {})
    if not isinstance(meta, dict):
        raise ValueError(f"{where}: 'metadata' must be a JSON object; got {meta!r}")
    meta = _plain(meta)
    twice = sorted(k for k in INSTRUMENT_KEYS if k in e and k in meta)
    if twice:
        raise ValueError(
            f"{where}: {twice} given both as entry key(s) and in 'metadata'; give each once"
        )
    inherited = sorted(k for k in top if k not in e and k not in meta)
    instrument = {k: top[k] for k in inherited}
    instrument.update({k: _plain(e[k]) for k in INSTRUMENT_KEYS if k in e})
    instrument.update({k: meta[k] for k in INSTRUMENT_KEYS if k in meta})
    where_i = where + (f", with the top-level default(s) {inherited}" if inherited else "")
    return meta, instrument, where_i


def _load_entry(path: Path, i: int, e, top: _Defaults):
    """One manifest entry -> a Recording (or XYRecording), every key checked."""
    where, csv_path = _entry_file(path, i, e)
    kw, defaults = _entry_numbers(where, e)
    meta, instrument, where_i = _entry_instrument(where, e, top.instrument)
    fi = kw.get("frame_interval", math.nan)
    nyquist = 0.5 / fi if 0 < fi < math.inf else None
    units_checked = e.get("check_units", True) is not False
    meta.update(check_instrument(instrument, where_i, nyquist=nyquist, check_units=units_checked))
    meta["manifest"] = str(path)
    if defaults:
        meta["defaults_applied"] = defaults
    name = e.get("name", Path(e["file"]).stem)
    kw["allow_irregular"] = _flag(
        where, "allow_irregular", e.get("allow_irregular", top.allow_irregular)
    )
    kw["check_units"] = _flag(where, "check_units", e.get("check_units", True))
    kw["timing_tolerance"] = _number(
        where, "timing_tolerance", e.get("timing_tolerance", Decimal(str(DEFAULT_TIMING_TOLERANCE)))
    )
    axes = _entry_axes(where, e, csv_path)
    loader = load_xy_csv if axes == "xy" else load_csv
    try:
        rec = loader(
            csv_path,
            position_unit=top.unit,
            pixel_size_m=top.px,
            on_bad_rows=top.on_bad_rows,
            name=name,
            metadata=meta,
            **kw,
        )
    except ValueError as err:
        raise ValueError(f"{path}, recordings[{i}]: {err}") from None
    # what needs the data: the stage column of a drive, the Nyquist frequency
    check_instrument(
        instrument,
        where_i,
        has_stage=getattr(rec, "stage", None) is not None,
        nyquist=0.5 / rec.frame_interval,
        check_units=units_checked,
    )
    return rec
