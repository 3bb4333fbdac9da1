"""CSV recordings: header ``t_s,x_<unit>`` (or just ``x_<unit>``), one frame per line, and
optionally a third column ``stage_<unit>`` (a driven stage's position; nm, um, mm or m).

Every problem is reported with the file, the 1-based line number (the header is line 1) and
the offending text. UTF-8 with or without BOM, LF / CRLF / CR line endings are accepted.
"""

from __future__ import annotations

import math
import os
import re
import warnings
from pathlib import Path

import numpy as np

from .._constants import DEFAULT_TEMPERATURE
from ._recording import DEFAULT_TIMING_TOLERANCE, Recording
from ._units import (
    ALLOWED_UNITS,
    canonical_unit,
    check_pixel_size,
    decimal_exponent,
    format_scaled,
    parse_number,
)

TIME_COLUMN = "t_s"
STAGE_PREFIX = "stage_"
_STAGE_UNITS = ("m", "mm", "um", "nm")
_ON_BAD_ROWS = ("error", "exclude")


class ExcludedRowsWarning(UserWarning):
    """Rows of a CSV file were excluded because ``on_bad_rows="exclude"`` was requested."""


def _short(text: str, n: int = 60) -> str:
    return repr(text if len(text) <= n else text[:n] + "...")


_BLOCK_BYTES = 1 << 20  # bytes read at a time; blocks always end at a line break
_BOM = b"\xef\xbb\xbf"
_TRAILING_BLANKS = re.compile(rb"[ \t]+\n")


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
    """``(colnames, has_time, unit, px, stage_unit or None)`` of a header
    ``[t_s,]x_<unit>[,stage_<unit>]``."""
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
    stage_unit = None
    if stage_col is not None:
        text = stage_col[len(STAGE_PREFIX) :]
        try:
            stage_unit = canonical_unit(text, what=f"unit of column {stage_col!r}")
        except ValueError:
            stage_unit = None
        if stage_unit not in _STAGE_UNITS:
            raise ValueError(
                f"{path}, line 1: stage column {stage_col!r} must name a length unit: "
                f"{', '.join(STAGE_PREFIX + u for u in _STAGE_UNITS)} (the stage position is "
                "converted to metres)"
            )
    return cols, has_time, unit, px, stage_unit


class _RowParser:
    """Parses the data lines of a CSV block by block (streaming, bounded memory).

    Each block goes through a vectorised fast path (``np.fromstring`` of the whole block,
    correctly rounded like ``float``) when it is plain ASCII, every line has the expected
    number of fields, no position cell has an exponent (positions in mm/um/nm get the decimal
    exponent appended as text, so the scaling stays exact), all values are finite and the time
    stamps increase. Anything else is parsed line by line by :meth:`_slow`, which reports or
    excludes the bad rows; both paths give the same float64 bits for the same text.
    """

    def __init__(self, path, colnames, has_time, unit, stage_unit, on_bad_rows):
        self.path = path
        self.has_time = has_time
        self.has_stage = stage_unit is not None
        self.colnames = list(colnames)
        self.ncols = len(self.colnames)
        self.i_pos = 1 if has_time else 0
        p = decimal_exponent(unit)
        scales = [0] * self.ncols  # t_s is already SI
        scales[self.i_pos] = 0 if p is None else p
        if stage_unit is not None:
            scales[-1] = decimal_exponent(stage_unit) or 0
        self.scales = tuple(scales)
        # exact scaling of the text by the vectorised path: an exponent appended to the cells
        self.suffixes = {c: f"e-{q}".encode() for c, q in enumerate(scales) if q}
        self.on_bad_rows = on_bad_rows
        self.lineno = 2  # line number of the next data line (the header is line 1)
        self.prev_t, self.prev_line, self.prev_cell = -math.inf, 0, ""
        self.times: list[np.ndarray] = []
        self.positions: list[np.ndarray] = []
        self.stage: list[np.ndarray] = []
        self.excluded: list[tuple[int, str]] = []

    @property
    def n_lines(self) -> int:
        return self.lineno - 2

    def feed(self, block: bytes) -> None:
        n = block.count(b"\n")
        if not self._fast(block, n):
            self._slow(block.decode("utf-8").split("\n")[:-1])
        self.lineno += n

    def result(self):
        """``(times or None, positions, stage or None, excluded)``; the per-block parts are
        released one column at a time, so the peak is the output plus one column."""
        times = stage = None
        if self.has_time:
            times = np.concatenate(self.times) if self.times else np.zeros(0)
            self.times.clear()
        pos = np.concatenate(self.positions) if self.positions else np.zeros(0)
        self.positions.clear()
        if self.has_stage:
            stage = np.concatenate(self.stage) if self.stage else np.zeros(0)
            self.stage.clear()
        return times, pos, stage, self.excluded

    # -- vectorised path ------------------------------------------------------------------
    def _fast(self, block: bytes, n: int) -> bool:
        if not block.isascii() or b"\r" in block:
            return False
        if b" \n" in block or b"\t\n" in block:
            block = _TRAILING_BLANKS.sub(b"\n", block)
        arr = np.frombuffer(block, dtype=np.uint8)
        if np.any((arr < 32) & (arr != 10) & (arr != 9)):
            return False  # control characters: the line-by-line parser reports them
        nl = np.flatnonzero(arr == 10)
        ncols = self.ncols
        cm = np.flatnonzero(arr == 44)
        if ncols >= 2:
            # exactly ncols - 1 commas on every line (the block ends with a line break)
            if cm.size != n * (ncols - 1):
                return False
            if np.any(np.bincount(np.searchsorted(nl, cm), minlength=n) != ncols - 1):
                return False
            ends = np.flatnonzero((arr == 44) | (arr == 10))
        elif cm.size:
            return False
        else:
            ends = nl
        # every cell must hold a non-blank character (np.fromstring reads a blank cell as -1)
        starts = np.empty_like(ends)
        starts[0] = 0
        starts[1:] = ends[:-1] + 1
        if np.any(starts == ends):
            return False
        filled = np.cumsum((arr != 32) & (arr != 9), dtype=np.intp)
        before = np.where(starts > 0, filled[starts - 1], 0)
        if np.any(filled[ends - 1] == before):
            return False
        if self.suffixes:
            e_at = np.flatnonzero((arr | 32) == 101)  # 'e' or 'E'
            if e_at.size:
                # column of each exponent: the commas before it on its line
                col = np.searchsorted(cm, e_at) - np.searchsorted(nl, e_at) * (ncols - 1)
                if np.any(np.isin(col, list(self.suffixes))):
                    return False  # an exponent in a scaled cell: scaled by the exact slow path
            where = [ends[c::ncols] for c in self.suffixes]
            idx = np.concatenate(
                [np.repeat(w, len(sfx)) for w, sfx in zip(where, self.suffixes.values())]
            )
            add = np.concatenate(
                [
                    np.tile(np.frombuffer(sfx, dtype=np.uint8), w.size)
                    for w, sfx in zip(where, self.suffixes.values())
                ]
            )
            # equal indices keep their order: each cell gets its exponent text, in order
            text = np.insert(arr, idx, add).tobytes().replace(b"\n", b",")
        else:
            text = block.replace(b"\n", b",")
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("error")
                vals = np.fromstring(text, dtype=np.float64, sep=",")
        except (ValueError, DeprecationWarning):
            return False
        if vals.size != n * ncols or not np.all(np.isfinite(vals)):
            return False
        vals = vals.reshape(n, ncols)
        if self.has_time:
            t = vals[:, 0]
            if not (t[0] > self.prev_t and np.all(t[1:] > t[:-1])):
                return False
            last = block[(nl[-2] + 1 if n > 1 else 0) : cm[-(ncols - 1)]]
            self.prev_t, self.prev_line = float(t[-1]), self.lineno + n - 1
            self.prev_cell = last.decode("ascii").strip()
            self.times.append(t.copy())
        self.positions.append(vals[:, self.i_pos].copy())
        if self.has_stage:
            self.stage.append(vals[:, -1].copy())
        return True

    # -- line by line: exact error reports ------------------------------------------------
    def _slow(self, lines: list[str]) -> None:
        ncols, colnames = self.ncols, self.colnames
        times: list[float] = []
        pos: list[float] = []
        stage: list[float] = []
        for lineno, line in enumerate(lines, start=self.lineno):
            fields = line.split(",")
            problem = None
            if len(fields) != ncols:
                problem = (
                    f"expected {ncols} field(s) ({','.join(colnames)}), got {len(fields)}: "
                    f"{_short(line)}"
                )
            else:
                values = []
                for col, cell, scale_p in zip(colnames, fields, self.scales, strict=True):
                    v = parse_number(cell, scale_p)
                    if v is None:
                        try:
                            special = float(cell)
                        except ValueError:
                            special = None
                        if special is not None and not math.isfinite(special):
                            problem = f"non-finite value {cell.strip()!r} (NaN/inf) in column {col}"
                        else:
                            problem = f"non-numeric value {_short(cell)} in column {col}"
                        break
                    if not math.isfinite(v):
                        problem = f"value {cell.strip()!r} in column {col} overflows float64"
                        break
                    values.append(v)
                if problem is None and self.has_time and values[0] <= self.prev_t:
                    problem = (
                        f"time stamp {TIME_COLUMN} = {fields[0].strip()!r} is not after the "
                        f"previous one ({self.prev_cell!r}, line {self.prev_line}); time stamps "
                        "must strictly increase"
                    )
            if problem is not None:
                if self.on_bad_rows == "error":
                    raise ValueError(f"{self.path}, line {lineno}: {problem}")
                self.excluded.append((lineno, problem))
                continue
            if self.has_time:
                self.prev_t, self.prev_line, self.prev_cell = values[0], lineno, fields[0].strip()
                times.append(values[0])
            pos.append(values[self.i_pos])
            if self.has_stage:
                stage.append(values[-1])
        if self.has_time:
            self.times.append(np.array(times, dtype=np.float64))
        self.positions.append(np.array(pos, dtype=np.float64))
        if self.has_stage:
            self.stage.append(np.array(stage, dtype=np.float64))


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
    colnames, has_time, unit, px, stage_unit = _parse_header(path, header, position_unit, pixel_size_m)
    parser = _RowParser(path, colnames, has_time, unit, stage_unit, on_bad_rows)
    if cut + 1 < len(first):
        parser.feed(first[cut + 1 :])
    del first
    for block in blocks:
        parser.feed(block)
    times, positions, stage, excluded = parser.result()
    if decimal_exponent(unit) is None:
        assert px is not None  # check_pixel_size requires a pixel size for 'px'
        positions = positions * px
    return times, positions, stage, excluded, parser.n_lines, unit


def infer_frame_interval(times: np.ndarray, tol: float = DEFAULT_TIMING_TOLERANCE) -> float:
    """Frame interval [s] from time stamps: the median step, refined to the least-squares
    slope of ``t`` against frame index when the two agree to ``tol`` (regular stamps)."""
    d = np.diff(times)
    med = float(np.median(d))
    i = np.arange(times.shape[0], dtype=np.float64)
    ic = i - i.mean()
    slope = float(np.dot(ic, times - times.mean()) / np.dot(ic, ic))
    return slope if abs(slope - med) <= tol * med else med


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

    meta = {} if metadata is None else dict(metadata)
    meta["source"] = str(path)
    if unit != "m":
        meta["position_unit"] = unit
    if temperature is None:
        temperature = DEFAULT_TEMPERATURE
        meta["defaults_applied"] = {"temperature_K": DEFAULT_TEMPERATURE}
    if excluded:
        meta["excluded_rows"] = {
            "count": len(excluded),
            "lines": [ln for ln, _ in excluded],
            "reasons": [why for _, why in excluded],
        }
    try:
        if frame_interval is None:
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
