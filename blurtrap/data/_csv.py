"""CSV recordings: header ``t_s,x_<unit>`` (or just ``x_<unit>``), one frame per line.

Every problem is reported with the file, the 1-based line number (the header is line 1) and
the offending text. UTF-8 with or without BOM, LF / CRLF / CR line endings are accepted.
"""

from __future__ import annotations

import math
import os
import warnings
from pathlib import Path

import numpy as np

from ..physics._constants import DEFAULT_TEMPERATURE
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
_ON_BAD_ROWS = ("error", "exclude")


class ExcludedRowsWarning(UserWarning):
    """Rows of a CSV file were excluded because ``on_bad_rows="exclude"`` was requested."""


def _short(text: str, n: int = 60) -> str:
    return repr(text if len(text) <= n else text[:n] + "...")


def _read_lines(path: Path) -> list[str]:
    data = path.read_bytes()
    try:
        text = data.decode("utf-8-sig")
    except UnicodeDecodeError as e:
        raise ValueError(
            f"{path}: not UTF-8 text (undecodable byte {data[e.start : e.start + 1]!r} at byte "
            f"offset {e.start}); save the file as UTF-8 CSV"
        ) from None
    if "\n" in text:
        lines = text.split("\n")
        lines = [ln[:-1] if ln.endswith("\r") else ln for ln in lines]
    else:
        lines = text.split("\r")
    while lines and not lines[-1].strip():  # trailing blank lines carry no data
        lines.pop()
    if not lines:
        raise ValueError(
            f"{path}: file is empty; expected a header line such as 't_s,x_nm' and data rows"
        )
    return lines


def _parse_header(path: Path, header: str, position_unit, pixel_size_m):
    cols = [c.strip() for c in header.split(",")]
    expected = (
        f"'{TIME_COLUMN},x_<unit>' or 'x_<unit>' with <unit> one of {', '.join(ALLOWED_UNITS)}"
    )
    if all(parse_number(c) is not None for c in cols if c):
        raise ValueError(
            f"{path}, line 1: found data {_short(header)} where the header was expected; "
            f"the first line must name the columns, e.g. 't_s,x_nm' ({expected})"
        )
    if len(cols) == 2 and cols[0].lower() == TIME_COLUMN:
        has_time, xcol = True, cols[1]
    elif len(cols) == 1:
        has_time, xcol = False, cols[0]
    else:
        raise ValueError(
            f"{path}, line 1: header {_short(header)} has columns {cols}; expected {expected}"
        )
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
    return has_time, xcol, unit, px


def _parse_rows(path, lines, has_time, xcol, unit, pixel_size, on_bad_rows):
    ncols = 2 if has_time else 1
    p = decimal_exponent(unit)
    p_pos = 0 if p is None else p
    colnames = [TIME_COLUMN, xcol] if has_time else [xcol]
    scales = (0, p_pos) if has_time else (p_pos,)  # decimal exponents: t_s is already SI
    times: list[float] = []
    pos: list[float] = []
    excluded: list[tuple[int, str]] = []
    prev_t, prev_line, prev_cell = -math.inf, 0, ""
    for lineno in range(2, len(lines) + 1):
        line = lines[lineno - 1]
        fields = line.split(",")
        problem = None
        if len(fields) != ncols:
            problem = (
                f"expected {ncols} field(s) ({','.join(colnames)}), got {len(fields)}: "
                f"{_short(line)}"
            )
        else:
            values = []
            for col, cell, scale_p in zip(colnames, fields, scales, strict=True):
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
            if problem is None and has_time and values[0] <= prev_t:
                problem = (
                    f"time stamp {TIME_COLUMN} = {fields[0].strip()!r} is not after the previous "
                    f"one ({prev_cell!r}, line {prev_line}); time stamps must strictly increase"
                )
        if problem is not None:
            if on_bad_rows == "error":
                raise ValueError(f"{path}, line {lineno}: {problem}")
            excluded.append((lineno, problem))
            continue
        if has_time:
            prev_t, prev_line, prev_cell = values[0], lineno, fields[0].strip()
            times.append(values[0])
        pos.append(values[-1])
    positions = np.array(pos, dtype=np.float64)
    if p is None:
        positions = positions * pixel_size
    return (np.array(times, dtype=np.float64) if has_time else None), positions, excluded


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
    """Load one recording from a CSV file with header ``t_s,x_<unit>`` (or ``x_<unit>``).

    **Arguments:**

    - `path`: the CSV file.
    - `exposure`: [s].
    - `frame_interval`: [s]; inferred from the time stamps (:func:`infer_frame_interval`)
      when None, which needs a ``t_s`` column.
    - `temperature`: [K]; None means 295 K, noted in ``metadata["defaults_applied"]``.
    - `laser_power`: [W] or None.
    - `position_unit`: the unit the file must be in; None takes it from the header. One of
      m, mm, um (µm), nm, px (needs `pixel_size_m` [m]).
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
    lines = _read_lines(path)
    has_time, xcol, unit, px = _parse_header(path, lines[0], position_unit, pixel_size_m)
    times, positions, excluded = _parse_rows(path, lines, has_time, xcol, unit, px, on_bad_rows)
    n_data = len(lines) - 1
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
        )
    except ValueError as e:
        extra = (
            f" ({len(excluded)} of {n_data} rows were excluded as bad: lines "
            f"{[ln for ln, _ in excluded][:10]})"
            if excluded
            else ""
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
    """Write ``t_s,x_<unit>`` with exact decimal text (a reload gives the same float64 bits
    for m/mm/um/nm). Recordings without time stamps get ``t_s = i * frame_interval``."""
    unit = canonical_unit(position_unit)
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
    rows = [f"{TIME_COLUMN},x_{unit}"]
    rows.extend(f"{ti!r},{x}" for ti, x in zip(t.tolist(), cells, strict=True))
    Path(os.fspath(path)).write_text("\n".join(rows) + "\n", encoding="utf-8", newline="\n")
