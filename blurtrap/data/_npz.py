"""NPZ storage: bit-exact arrays plus a JSON header with the scalar fields and metadata.

Layout: ``__blurtrap__`` (a 0-d unicode array holding JSON), ``positions_<i>`` and, where
present, ``times_<i>`` and ``stage_<i>``. No pickles are written or read. The unit of the
positions (metres, or volts) is in the metadata (``position_unit``).
"""

from __future__ import annotations

import json
import os
import zipfile
from pathlib import Path

import numpy as np

from .._constants import DEFAULT_TEMPERATURE
from ._recording import Recording, thaw
from ._recording_set import RecordingSet

_HEADER_KEY = "__blurtrap__"
_FORMAT = "blurtrap.recordings"
_VERSION = 1


def save_npz(recordings: Recording | RecordingSet, path, *, compress: bool = False) -> None:
    """Save a :class:`Recording` or :class:`RecordingSet` to ``path`` (exact file name kept).

    Positions and times are stored as raw float64, so :func:`load_npz` returns them bit for
    bit; scalars and metadata go through JSON with repr precision (also exact).
    """
    if isinstance(recordings, Recording):
        kind, recs = "recording", (recordings,)
    elif isinstance(recordings, RecordingSet):
        kind, recs = "set", tuple(recordings)
    else:
        raise TypeError(
            f"save_npz expects a Recording or RecordingSet; got {type(recordings).__name__}"
        )
    arrays: dict[str, np.ndarray] = {}
    entries = []
    for i, r in enumerate(recs):
        arrays[f"positions_{i}"] = np.asarray(r.positions)
        if r.times is not None:
            arrays[f"times_{i}"] = np.asarray(r.times)
        if r.stage is not None:
            arrays[f"stage_{i}"] = np.asarray(r.stage)
        entries.append(
            {
                "frame_interval": r.frame_interval,
                "exposure": r.exposure,
                "temperature": r.temperature,
                "laser_power": r.laser_power,
                "name": r.name,
                "metadata": thaw(r.metadata),
                "allow_irregular": r.allow_irregular,
                "timing_tolerance": r.timing_tolerance,
                "check_units": r.check_units,
                "has_times": r.times is not None,
                "has_stage": r.stage is not None,
            }
        )
    header = {"format": _FORMAT, "version": _VERSION, "kind": kind, "recordings": entries}
    arrays[_HEADER_KEY] = np.array(json.dumps(header))
    with open(os.fspath(path), "wb") as f:
        # the array names (positions_<i>, ..., __blurtrap__) never collide with allow_pickle
        (np.savez_compressed if compress else np.savez)(f, **arrays)  # pyright: ignore[reportArgumentType]


def load_npz(
    path,
    *,
    frame_interval=None,
    exposure=None,
    temperature=DEFAULT_TEMPERATURE,
    laser_power=None,
) -> Recording | RecordingSet:
    """Load what :func:`save_npz` wrote (a Recording or a RecordingSet, as saved).

    A plain NPZ without a blurtrap header is accepted if it holds ``positions`` [m] (1-D, or
    2-D with one recording per row; a column vector of shape (N, 1) is one recording) and
    optionally ``times`` [s]; ``frame_interval``,
    ``exposure``, ``temperature`` and ``laser_power`` are then taken from arrays of those
    names in the file, else from the keywords.
    """
    path = Path(os.fspath(path))
    _check_npz_signature(path)
    try:
        loaded = np.load(path, allow_pickle=False)
        if not isinstance(loaded, np.lib.npyio.NpzFile):  # a bare .npy array
            raise ValueError(f"it holds a single {type(loaded).__name__}, not named arrays")
        with loaded as z:
            data = {k: z[k] for k in z.files}
    except (zipfile.BadZipFile, OSError, ValueError, EOFError) as e:
        if isinstance(e, FileNotFoundError):
            raise
        raise ValueError(f"{path}: not a readable .npz file ({e})") from None
    try:
        if _HEADER_KEY in data:
            return _from_blurtrap(data)
        return _from_plain(data, frame_interval, exposure, temperature, laser_power)
    except ValueError as e:
        raise ValueError(f"{path}: {e}") from None


_ZIP_MAGIC = (b"PK\x03\x04", b"PK\x05\x06")  # a zip archive (NPZ); empty zip
_NPY_MAGIC = b"\x93NUMPY"  # a bare .npy array (reported by np.load's reader below)


def _looks_like_text(head: bytes) -> bool:
    if b"\x00" in head:
        return False
    for cut in range(4):  # the block may end inside a multi-byte UTF-8 character
        try:
            head[: len(head) - cut].decode("utf-8")
            return True
        except UnicodeDecodeError:
            continue
    return False


def _check_npz_signature(path: Path) -> None:
    """Refuse, with a clear message, a file that is not a zip archive (np.load would try to
    unpickle it and suggest allow_pickle=True, which is never the answer here)."""
    try:
        with open(path, "rb") as f:
            head = f.read(4096)
    except FileNotFoundError:
        raise
    except OSError as e:
        raise ValueError(f"{path}: not a readable .npz file ({e})") from None
    if head.startswith(_ZIP_MAGIC) or head.startswith(_NPY_MAGIC):
        return
    if not head:
        raise ValueError(f"{path}: not a readable .npz file (the file is empty)")
    if _looks_like_text(head):
        first = head.split(b"\n", 1)[0][:60].decode("utf-8", errors="replace")
        raise ValueError(
            f"{path}: not a readable .npz file: this is not an NPZ archive (it looks like "
            f"text/CSV, starting {first!r}); use load_csv, or a .csv name so that load() "
            "reads it as CSV"
        )
    raise ValueError(
        f"{path}: not a readable .npz file: this is not an NPZ archive (a zip file as written "
        f"by save_npz or numpy.savez); it starts with {head[:8]!r}"
    )


_ENTRY_KEYS = ("frame_interval", "exposure", "temperature", "laser_power", "name", "metadata",
               "allow_irregular", "timing_tolerance", "check_units", "has_times")


def _from_blurtrap(data):
    raw = data[_HEADER_KEY]
    try:
        if raw.ndim != 0 or raw.dtype.kind != "U":
            raise ValueError(f"expected a 0-d text array; got dtype {raw.dtype}, shape {raw.shape}")
        header = json.loads(str(raw))
    except (ValueError, RecursionError) as e:  # JSONDecodeError is a ValueError
        raise ValueError(f"corrupt {_HEADER_KEY} header ({e})") from None
    if not isinstance(header, dict):
        raise ValueError(f"corrupt {_HEADER_KEY} header: expected a JSON object; got {header!r:.60}")
    if header.get("format") != _FORMAT or header.get("version") != _VERSION:
        raise ValueError(
            f"unsupported header format {header.get('format')!r} version "
            f"{header.get('version')!r}; expected {_FORMAT!r} version {_VERSION}"
        )
    kind, entries = header.get("kind"), header.get("recordings")
    if kind not in ("recording", "set"):
        raise ValueError(f"corrupt {_HEADER_KEY} header: kind = {kind!r}; expected 'recording' or 'set'")
    if not isinstance(entries, list) or not entries or (kind == "recording" and len(entries) != 1):
        raise ValueError(
            f"corrupt {_HEADER_KEY} header: 'recordings' must list the recordings (exactly one "
            f"for kind 'recording'); got {entries!r:.60}"
        )
    recs = []
    for i, e in enumerate(entries):
        if not isinstance(e, dict):
            raise ValueError(f"corrupt {_HEADER_KEY} header: recordings[{i}] is not an object")
        missing = [k for k in _ENTRY_KEYS if k not in e]
        if missing:
            raise ValueError(f"corrupt {_HEADER_KEY} header: recordings[{i}] lacks {missing}")
        e.setdefault("has_stage", False)  # files written before stages were stored
        for flag in ("has_times", "has_stage", "allow_irregular", "check_units"):
            if not isinstance(e[flag], bool):
                raise ValueError(
                    f"corrupt {_HEADER_KEY} header: recordings[{i}].{flag} = {e[flag]!r} is not "
                    "true/false"
                )
        needed = [f"positions_{i}"] + ([f"times_{i}"] if e["has_times"] else [])
        needed += [f"stage_{i}"] if e["has_stage"] else []
        absent = [a for a in needed if a not in data]
        if absent:
            raise ValueError(f"array(s) {absent} missing (named in the {_HEADER_KEY} header)")
        try:
            recs.append(
                Recording(
                    data[f"positions_{i}"],
                    frame_interval=e["frame_interval"],
                    exposure=e["exposure"],
                    temperature=e["temperature"],
                    times=data[f"times_{i}"] if e["has_times"] else None,
                    laser_power=e["laser_power"],
                    metadata=e["metadata"],
                    name=e["name"],
                    allow_irregular=e["allow_irregular"],
                    timing_tolerance=e["timing_tolerance"],
                    check_units=e["check_units"],
                    stage=data[f"stage_{i}"] if e["has_stage"] else None,
                )
            )
        except ValueError as err:
            raise ValueError(f"recording {i}: {err}") from None
    if kind == "recording":
        return recs[0]
    return RecordingSet(recs)


def _from_plain(data, frame_interval, exposure, temperature, laser_power):
    from ._io import from_arrays

    if "positions" not in data:
        raise ValueError(
            f"no 'positions' array (found {sorted(data)}); expected a file written by "
            "save_npz or one with 'positions' [m] and optionally 'times' [s]"
        )

    def pick(key, given):
        if key in data:
            v = data[key]
            return v.item() if v.ndim == 0 else v
        return given

    fi = pick("frame_interval", frame_interval)
    w = pick("exposure", exposure)
    if fi is None or w is None:
        raise ValueError(
            "frame_interval and exposure are not stored in the file; pass them as keywords [s]"
        )
    return from_arrays(
        data["positions"],
        frame_interval=fi,
        exposure=w,
        temperature=pick("temperature", temperature),
        laser_power=pick("laser_power", laser_power),
        times=data.get("times"),
    )
