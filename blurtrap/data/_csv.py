"""CSV recordings: header ``t_s,x_<unit>`` (or just ``x_<unit>``), one frame per line, and
optionally a third column ``stage_<unit>`` (a driven stage's position; nm, um, mm or m).

Every problem is reported with the file, the 1-based line number (the header is line 1) and
the offending text. UTF-8 with or without BOM, LF / CRLF / CR line endings are accepted.
"""

from __future__ import annotations

import math
import os
import warnings
from pathlib import Path

import numpy as np

from .._constants import DEFAULT_TEMPERATURE
from ._csv_rows import TIME_COLUMN as TIME_COLUMN
from ._csv_rows import _RowParser as _RowParser
from ._csv_rows import _short
from ._recording import DEFAULT_TIMING_TOLERANCE, Recording
from ._timing import infer_frame_interval as infer_frame_interval
from ._units import (
    ALLOWED_UNITS,
    canonical_unit,
    check_pixel_size,
    decimal_exponent,
    format_scaled,
    parse_number,
)

STAGE_PREFIX = "stage_"
_STAGE_UNITS = ("m", "mm", "um", "nm")
_ON_BAD_ROWS = ("error", "exclude")


class ExcludedRowsWarning(UserWarning):
    """Rows of a CSV file were excluded because ``on_bad_rows="exclude"`` was requested."""


_BLOCK_BYTES = 1 << 20  # bytes read at a time; blocks always end at a line break
_BOM = b"\xef\xbb\xbf"


def _has_lf(path: Path) -> bool:
    with open(path, "rb") as f:
        while True:
            data = f.read(_BLOCK_BYTES)
            if not data:
                return False
            if b"\n" in data:
                return True


def _check_utf8(path: Path, block: bytes, offset: int) -> None:
    if block.isascii():
        return
    try:
        block.decode("utf-8")
    except UnicodeDecodeError as e:
        raise ValueError(
            f"{path}: not UTF-8 text (undecodable byte {block[e.start : e.start + 1]!r} at byte "
            f"offset {offset + e.start}); save the file as UTF-8 CSV"
        ) from None


def _raw_blocks(path: Path):
    """The file as blocks of whole lines, each line terminated by ``b"\n"``.

    Same lines as splitting the whole decoded text: if the file contains a LF anywhere, lines
    end at LF and lose one trailing CR (LF and CRLF files); otherwise they end at CR (old Mac
    files). A UTF-8 BOM at the start is dropped; every block is checked to be UTF-8. Memory
    is bounded by the block size (plus the longest line).
    """
    sep = b"\n" if _has_lf(path) else b"\r"
    with open(path, "rb") as f:
        pieces: list[bytes] = []  # a line that continues past the last block read
        offset = 0  # file offset of the next block
        first = True
        while True:
            data = f.read(max(_BLOCK_BYTES, len(_BOM)) if first else _BLOCK_BYTES)
            if first:
                first = False
                if data.startswith(_BOM):
                    data, offset = data[len(_BOM) :], len(_BOM)
                    if not data:
                        continue
            if not data:
                if not pieces:
                    return
                block, pieces = b"".join(pieces) + sep, []
                eof = True
            else:
                cut = data.rfind(sep)
                if cut < 0:
                    pieces.append(data)
                    continue
                block = b"".join(pieces) + data[: cut + 1]
                pieces = [data[cut + 1 :]] if cut + 1 < len(data) else []
                eof = False
            _check_utf8(path, block, offset)
            offset += len(block)
            if sep == b"\r":
                block = block.replace(b"\r", b"\n")
            elif b"\r" in block:
                block = block.replace(b"\r\n", b"\n")  # removes one trailing CR per line
            yield block
            if eof:
                return


def _is_blank(line: bytes) -> bool:
    return not line.decode("utf-8").strip()


def _line_blocks(path: Path):
    """:func:`_raw_blocks` without the blank lines at the end of the file (they carry no
    data); blank lines followed by more text are kept (and are bad rows)."""
    pending = b""
    for block in _raw_blocks(path):
        if pending:
            block = pending + block
        end = len(block)
        while end > 0:
            start = block.rfind(b"\n", 0, end - 1) + 1
            if not _is_blank(block[start : end - 1]):
                break
            end = start
        pending = block[end:]
        if end:
            yield block[:end] if pending else block


def _parse_header(path: Path, header: str, position_unit, pixel_size_m):
    """``(has_time, xcol, unit, px)`` of a header ``[t_s,]x_<unit>[,stage_<unit>]``."""
    for sep, name in ((";", "semicolons"), ("\t", "tabs")):
        if sep in header and "," not in header:  # a spreadsheet's export, not blurtrap's
            raise ValueError(f"{path}, line 1: header {_short(header)} separates its columns "
                             f"with {name}; blurtrap's CSV uses commas ('t_s,x_nm'): re-save "
                             "it with comma separators (and '.' as the decimal point)")
    cols = [c.strip() for c in header.split(",")]
    expected = (
        f"'{TIME_COLUMN},x_<unit>' or 'x_<unit>' with <unit> one of {', '.join(ALLOWED_UNITS)}, "
        f"optionally followed by a stage column '{STAGE_PREFIX}<unit>' (nm, um, mm or m)"
    )
    if all(parse_number(c) is not None for c in cols if c):
        raise ValueError(
            f"{path}, line 1: found data {_short(header)} where the header was expected; "
            f"the first line must name the columns, e.g. 't_s,x_nm' ({expected})"
        )
    has_time = bool(cols) and cols[0].lower() == TIME_COLUMN
    rest = cols[1:] if has_time else cols
    stage_col = rest[1] if len(rest) == 2 and rest[1].lower().startswith(STAGE_PREFIX) else None
    if not (len(rest) == 1 or stage_col is not None):
        raise ValueError(
            f"{path}, line 1: header {_short(header)} has columns {cols}; expected {expected}"
        )
    xcol = rest[0]
    if not xcol.lower().startswith("x_"):
        raise ValueError(
            f"{path}, line 1: position column {xcol!r} not understood; expected {expected}"
        )
    try:
        unit = canonical_unit(xcol[2:], what=f"unit of column {xcol!r}")
    except ValueError as e:
        raise ValueError(f"{path}, line 1: {e}") from None
    if position_unit is not None:
        want = canonical_unit(position_unit)
        if want != unit:
            raise ValueError(
                f"{path}, line 1: column {xcol!r} is in {unit!r} but position_unit = "
                f"{position_unit!r} was given; they must agree"
            )
    px = check_pixel_size(unit, pixel_size_m, where=str(path))
    _stage_column(path, header)
    return has_time, xcol, unit, px


def _stage_column(path: Path, header: str) -> tuple[str, str] | None:
    """``(column name, unit)`` of the stage column of a (valid) header, or None."""
    stage_col = header.split(",")[-1].strip()
    if not stage_col.lower().startswith(STAGE_PREFIX):
        return None
    try:
        stage_unit = canonical_unit(stage_col[len(STAGE_PREFIX) :], what="stage unit")
    except ValueError:
        stage_unit = None
    if stage_unit not in _STAGE_UNITS:
        raise ValueError(
            f"{path}, line 1: stage column {stage_col!r} must name a length unit: "
            f"{', '.join(STAGE_PREFIX + u for u in _STAGE_UNITS)} (the stage position is "
            "converted to metres)"
        )
    return stage_col, stage_unit


def _read_csv(path: Path, position_unit, pixel_size_m, on_bad_rows):
    """Stream ``path``: header checks, then the rows block by block.

    Returns ``(times or None, positions [m or V], stage [m] or None, excluded rows, number of
    data lines, unit)``."""
    blocks = _line_blocks(path)
    first = next(blocks, None)
    if first is None:
        raise ValueError(
            f"{path}: file is empty; expected a header line such as 't_s,x_nm' and data rows"
        )
    cut = first.index(b"\n")
    header = first[:cut].decode("utf-8")
    has_time, xcol, unit, px = _parse_header(path, header, position_unit, pixel_size_m)
    parser = _RowParser(path, has_time, xcol, unit, on_bad_rows, _stage_column(path, header))
    if cut + 1 < len(first):
        parser.feed(first[cut + 1 :])
    del first
    for block in blocks:
        parser.feed(block)
    times, positions, excluded = parser.result()
    stage = parser.stage_values
    if decimal_exponent(unit) is None:
        assert px is not None  # check_pixel_size requires a pixel size for 'px'
        positions = positions * px
    return times, positions, stage, excluded, parser.n_lines, unit


def file_metadata(path, unit, temperature, metadata):
    """``(metadata, temperature)`` of a recording read from `path`: the caller's metadata plus
    the source file, the file's position unit and the default temperature when none was
    given (recorded under ``defaults_applied``)."""
    meta = {} if metadata is None else dict(metadata)
    meta["source"] = str(path)
    if unit != "m":
        meta["position_unit"] = unit
    if temperature is None:
        temperature = DEFAULT_TEMPERATURE
        meta["defaults_applied"] = {"temperature_K": DEFAULT_TEMPERATURE}
    return meta, temperature


def load_csv(
    path,
    *,
    exposure,
    frame_interval=None,
    temperature=None,
    laser_power=None,
    position_unit=None,
    pixel_size_m=None,
    on_bad_rows: str = "error",
    name: str | None = None,
    metadata=None,
    allow_irregular: bool = False,
    timing_tolerance: float = DEFAULT_TIMING_TOLERANCE,
    check_units: bool = True,
) -> Recording:
    """Load one recording from a CSV file with header ``t_s,x_<unit>`` (or ``x_<unit>``),
    optionally followed by a stage column ``stage_<unit>`` (``Recording.stage``, in metres).

    **Arguments:**

    - `path`: the CSV file.
    - `exposure`: [s].
    - `frame_interval`: [s]; inferred from the time stamps (:func:`infer_frame_interval`)
      when None, which needs a ``t_s`` column.
    - `temperature`: [K]; None means 295 K, noted in ``metadata["defaults_applied"]``.
    - `laser_power`: [W] or None.
    - `position_unit`: the unit the file must be in; None takes it from the header. One of
      m, mm, um (µm), nm, px (needs `pixel_size_m` [m]), or V (a detector signal in volts,
      kept in volts: ``Recording.position_unit == "V"``). A header that names another unit
      is an error.
    - `on_bad_rows`: ``"error"`` (default) raises at the first bad row; ``"exclude"`` drops
      bad rows, records ``{"count", "lines", "reasons"}`` in ``metadata["excluded_rows"]``
      and warns with :class:`ExcludedRowsWarning`.
    - the remaining keywords are passed to :class:`Recording`.

    **Raises:** ``ValueError`` whose message starts with the file name (and line number for
    row problems).
    """
    path = Path(os.fspath(path))
    if on_bad_rows not in _ON_BAD_ROWS:
        raise ValueError(f"on_bad_rows must be one of {_ON_BAD_ROWS}; got {on_bad_rows!r}")
    times, positions, stage, excluded, n_data, unit = _read_csv(
        path, position_unit, pixel_size_m, on_bad_rows
    )
    if positions.shape[0] == 0:
        detail = f" ({len(excluded)} bad row(s) excluded)" if excluded else ""
        raise ValueError(f"{path}: no data rows after the header{detail}")

    meta, temperature = file_metadata(path, unit, temperature, metadata)
    if excluded:
        meta["excluded_rows"] = {
            "count": len(excluded),
            "lines": [ln for ln, _ in excluded],
            "reasons": [why for _, why in excluded],
        }
    try:
        if frame_interval is None:
            frame_interval = _inferred_interval(times, exposure, timing_tolerance, meta)
        rec = Recording(
            positions,
            frame_interval=frame_interval,
            exposure=exposure,
            temperature=temperature,
            times=times,
            laser_power=laser_power,
            metadata=meta,
            name=name,
            allow_irregular=allow_irregular,
            timing_tolerance=timing_tolerance,
            check_units=check_units,
            stage=stage,
        )
    except ValueError as e:
        extra = (
            f" ({len(excluded)} of {n_data} rows were excluded as bad: lines "
            f"{[ln for ln, _ in excluded][:10]})"
            if excluded
            else ""
        )
        if meta.get("frame_interval_inferred") and str(e).startswith("frame_interval = "):
            extra += (
                f" (frame_interval was inferred from the {TIME_COLUMN} column: its time stamps "
                "look like milliseconds; the column must hold seconds)"
            )
        raise ValueError(f"{path}: {e}{extra}") from None
    if excluded:
        shown = [ln for ln, _ in excluded][:10]
        warnings.warn(
            f"{path}: excluded {len(excluded)} of {n_data} rows (lines {shown}"
            f"{', ...' if len(excluded) > 10 else ''}); first: line {excluded[0][0]}: "
            f"{excluded[0][1]}. See recording.metadata['excluded_rows']",
            ExcludedRowsWarning,
            stacklevel=2,
        )
    return rec


def _inferred_interval(times, exposure, timing_tolerance, meta: dict) -> float:
    """The frame interval [s] from the ``t_s`` column (noted in `meta`); an exposure just
    above it, within the timing tolerance, is taken as the interval."""
    if times is None:
        raise ValueError(
            f"frame_interval not given and there is no {TIME_COLUMN!r} column to "
            "infer it from; pass frame_interval [s]"
        )
    if times.shape[0] < 2:
        raise ValueError(f"positions must hold at least 2 frames; got {times.shape[0]}")
    frame_interval = infer_frame_interval(times, float(timing_tolerance))
    meta["frame_interval_inferred"] = True
    try:
        w = float(exposure)
    except (TypeError, ValueError):
        w = math.nan
    if frame_interval < w <= frame_interval * (1 + float(timing_tolerance)):
        # time stamps cannot resolve the difference: the exposure fills the interval
        frame_interval = w
    return frame_interval


def write_csv(recording: Recording, path, position_unit: str = "nm", pixel_size_m=None) -> None:
    """Write ``t_s,x_<unit>`` (and ``stage_nm`` when the recording has a stage) with exact
    decimal text (a reload gives the same float64 bits for m/mm/um/nm/V). Recordings without
    time stamps get ``t_s = i * frame_interval``. A recording in volts is written in ``V``
    only, one in metres in a length unit only."""
    unit = canonical_unit(position_unit)
    if (unit == "V") != (recording.position_unit == "V"):
        raise ValueError(
            f"position_unit = {position_unit!r} but the recording's positions are in "
            f"{'volts' if recording.position_unit == 'V' else 'metres'}: write "
            f"{'volts as V' if recording.position_unit == 'V' else 'metres in a length unit'}"
        )
    px = check_pixel_size(unit, pixel_size_m)
    p = decimal_exponent(unit)
    pos = recording.positions
    if p is None:
        cells = [repr(v) for v in (pos / px).tolist()]
    else:
        cells = [format_scaled(v, p) for v in pos.tolist()]
    t = recording.times
    if t is None:
        t = np.arange(recording.n_frames, dtype=np.float64) * recording.frame_interval
    header = f"{TIME_COLUMN},x_{unit}"
    if recording.stage is not None:
        header += f",{STAGE_PREFIX}nm"
        cells = [
            f"{x},{format_scaled(z, 9)}"
            for x, z in zip(cells, recording.stage.tolist(), strict=True)
        ]
    rows = [header]
    rows.extend(f"{ti!r},{x}" for ti, x in zip(t.tolist(), cells, strict=True))
    Path(os.fspath(path)).write_text("\n".join(rows) + "\n", encoding="utf-8", newline="\n")
