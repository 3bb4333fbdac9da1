"""x/y recordings: one bead seen along two detector axes (a camera's x and y).

:class:`XYRecording` holds the two traces as two :class:`Recording` objects with the same
acquisition (frame interval, exposure, temperature, time stamps); :func:`xy_from_arrays`
builds one from arrays and :func:`load_xy_csv` from a CSV file with header
``t_s,x_<unit>,y_<unit>`` (or ``x_<unit>,y_<unit>``). numpy only.
"""

from __future__ import annotations

import math
import os
from pathlib import Path
from typing import Any

import numpy as np

from .._constants import DEFAULT_TEMPERATURE
from ._csv import _line_blocks, file_metadata, infer_frame_interval
from ._csv_rows import TIME_COLUMN, _RowParser, _short
from ._recording import DEFAULT_TIMING_TOLERANCE, Recording
from ._units import ALLOWED_UNITS, canonical_unit, check_pixel_size, decimal_exponent, parse_number

_EXPECTED = (
    f"'{TIME_COLUMN},x_<unit>,y_<unit>' or 'x_<unit>,y_<unit>' with the same <unit> in both, "
    f"one of {', '.join(ALLOWED_UNITS)}"
)


class XYRecording:
    """The x and y traces of one bead, recorded together (same frames).

    **Arguments:** `x`, `y`: :class:`Recording` objects with the same number of frames, frame
    interval, exposure, temperature, position unit and time stamps; `name`: optional label.

    Use :func:`xy_from_arrays` or :func:`load_xy_csv` to build one from arrays or a file.

    **Raises:** ``TypeError`` when `x` or `y` is not a Recording, ``ValueError`` when their
    acquisitions differ (naming the attribute and both values).
    """

    __slots__ = ("_x", "_y", "_name")

    def __init__(self, x: Recording, y: Recording, *, name: str | None = None):
        for label, r in (("x", x), ("y", y)):
            if not isinstance(r, Recording):
                raise TypeError(f"XYRecording: {label} must be a Recording; got "
                                f"{type(r).__name__}")
        if x.n_frames != y.n_frames:
            raise ValueError(f"XYRecording: x and y must have the same number of frames; got "
                             f"{x.n_frames} (x) and {y.n_frames} (y)")
        for attr in ("frame_interval", "exposure", "temperature", "position_unit"):
            a, b = getattr(x, attr), getattr(y, attr)
            if a != b:
                raise ValueError(f"XYRecording: x and y must share {attr}; got {a!r} (x) and "
                                 f"{b!r} (y)")
        tx, ty = x.times, y.times
        if (tx is None) != (ty is None) or (tx is not None and ty is not None
                                            and not np.array_equal(tx, ty)):
            raise ValueError("XYRecording: x and y must have the same time stamps (or none)")
        object.__setattr__(self, "_x", x)
        object.__setattr__(self, "_y", y)
        object.__setattr__(self, "_name", name if name is not None else x.name)

    def __setattr__(self, key, value):
        raise AttributeError("XYRecording is immutable")

    @property
    def x(self) -> Recording:
        """The trace along the detector's x axis."""
        return self._x

    @property
    def y(self) -> Recording:
        """The trace along the detector's y axis."""
        return self._y

    @property
    def name(self) -> str | None:
        return self._name

    @property
    def positions(self) -> np.ndarray:
        """``(n_frames, 2)`` array of (x, y) [m or V]."""
        return np.stack([self._x.positions, self._y.positions], axis=1)

    @property
    def n_frames(self) -> int:
        return self._x.n_frames

    @property
    def frame_interval(self) -> float:
        return self._x.frame_interval

    @property
    def exposure(self) -> float:
        return self._x.exposure

    @property
    def temperature(self) -> float:
        return self._x.temperature

    @property
    def position_unit(self) -> str:
        return self._x.position_unit

    @property
    def times(self) -> np.ndarray | None:
        return self._x.times

    @property
    def metadata(self):
        return self._x.metadata

    def project(self, angle: float) -> tuple[Recording, Recording]:
        """The traces along the axis at `angle` [rad] from x (counter-clockwise) and along
        the axis 90 degrees further: ``u = x cos + y sin``, ``v = -x sin + y cos``. Their
        metadata notes ``axis_angle_rad``."""
        c, s = math.cos(float(angle)), math.sin(float(angle))
        x, y = self._x.positions, self._y.positions
        out = []
        for label, pos, ang in (("1", c * x + s * y, angle), ("2", -s * x + c * y,
                                                               angle + math.pi / 2)):
            meta = dict(self._x.metadata)
            meta["axis_angle_rad"] = float(ang)
            nm = f"{self._name}:axis{label}" if self._name else f"axis{label}"
            out.append(self._x.replace(positions=pos, metadata=meta, name=nm))
        return out[0], out[1]

    def rotated(self, angle: float) -> XYRecording:
        """The same motion seen by a detector turned by ``-angle``: every (x, y) rotated
        counter-clockwise by `angle` [rad] (principal axes move from ``phi`` to
        ``phi + angle``)."""
        c, s = math.cos(float(angle)), math.sin(float(angle))
        x, y = self._x.positions, self._y.positions
        return XYRecording(self._x.replace(positions=c * x - s * y),
                           self._y.replace(positions=s * x + c * y), name=self._name)

    def __repr__(self) -> str:
        return (f"XYRecording(n_frames={self.n_frames}, frame_interval={self.frame_interval!r},"
                f" exposure={self.exposure!r}, name={self._name!r})")


def xy_from_arrays(x, y, *, frame_interval, exposure, temperature=DEFAULT_TEMPERATURE,
                   times=None, name: str | None = None, metadata=None, **kwargs) -> XYRecording:
    """An :class:`XYRecording` from two 1-D position arrays [m] (or an ``(n_frames, 2)``
    array as `x` with ``y=None``); the other keywords go to :class:`Recording`.

    **Raises:** ``ValueError`` when the lengths differ or the arrays are not 1-D.
    """
    if y is None:
        xy = np.asarray(x)
        if xy.ndim != 2 or xy.shape[1] != 2:
            raise ValueError(f"xy_from_arrays: with y=None, x must be an (n_frames, 2) array of "
                             f"(x, y); got shape {xy.shape}")
        x, y = xy[:, 0], xy[:, 1]
    nx, ny = np.shape(x), np.shape(y)
    if len(nx) != 1 or len(ny) != 1:
        raise ValueError(f"xy_from_arrays: x and y must be 1-D traces; got shapes {nx} and {ny}")
    if nx != ny:
        raise ValueError(f"xy_from_arrays: x and y must have the same length; got len(x) = "
                         f"{nx[0]} and len(y) = {ny[0]}")
    common: dict[str, Any] = dict(frame_interval=frame_interval, exposure=exposure,
                                  temperature=temperature, times=times, metadata=metadata,
                                  **kwargs)
    rx = Recording(x, name=None if name is None else f"{name}:x", **common)
    ry = Recording(y, name=None if name is None else f"{name}:y", **common)
    return XYRecording(rx, ry, name=name)


def _parse_xy_header(path: Path, header: str, position_unit, pixel_size_m):
    """``(has_time, xcol, ycol, unit, pixel size)`` of a header ``[t_s,]x_<u>,y_<u>``."""
    cols = [c.strip() for c in header.split(",")]
    if all(parse_number(c) is not None for c in cols if c):
        raise ValueError(f"{path}, line 1: found data {_short(header)} where the header was "
                         f"expected; the first line must name the columns ({_EXPECTED})")
    has_time = bool(cols) and cols[0].lower() == TIME_COLUMN
    rest = cols[1:] if has_time else cols
    if len(rest) == 1 and rest[0].lower().startswith("x_"):
        raise ValueError(f"{path}, line 1: header {_short(header)} has no y column; an x/y "
                         f"recording needs {_EXPECTED} (use load_csv for one axis)")
    if len(rest) != 2 or not rest[0].lower().startswith("x_") \
            or not rest[1].lower().startswith("y_"):
        raise ValueError(f"{path}, line 1: header {_short(header)} has columns {cols}; "
                         f"expected {_EXPECTED}")
    xcol, ycol = rest
    try:
        unit = canonical_unit(xcol[2:], what=f"unit of column {xcol!r}")
        yunit = canonical_unit(ycol[2:], what=f"unit of column {ycol!r}")
    except ValueError as e:
        raise ValueError(f"{path}, line 1: {e}") from None
    if yunit != unit:
        raise ValueError(f"{path}, line 1: columns {xcol!r} and {ycol!r} are in different units "
                         f"({unit!r}, {yunit!r}); expected the same unit for x and y")
    if position_unit is not None and canonical_unit(position_unit) != unit:
        raise ValueError(f"{path}, line 1: columns are in {unit!r} but position_unit = "
                         f"{position_unit!r} was given; they must agree")
    px = check_pixel_size(unit, pixel_size_m, where=str(path))
    return has_time, xcol, ycol, unit, px


def is_xy_csv(path) -> bool:
    """True when the CSV's header names a ``y_<unit>`` column right after its ``x_<unit>``
    column (an x/y recording); False for any other header or an unreadable file (the loader
    then reports the problem)."""
    try:
        with open(os.fspath(path), encoding="utf-8-sig", errors="replace") as f:
            header = f.readline()
    except (OSError, ValueError):
        return False
    cols = [c.strip().lower() for c in header.split(",")]
    return any(a.startswith("x_") and b.startswith("y_") for a, b in zip(cols, cols[1:]))


def _read_xy(path: Path, position_unit, pixel_size_m, on_bad_rows="error"):
    blocks = _line_blocks(path)
    first = next(blocks, None)
    if first is None:
        raise ValueError(f"{path}: file is empty; expected a header line such as "
                         f"'t_s,x_nm,y_nm' and data rows")
    cut = first.index(b"\n")
    has_time, xcol, ycol, unit, px = _parse_xy_header(
        path, first[:cut].decode("utf-8"), position_unit, pixel_size_m)
    # the y column is read as the parser's optional third column, with the x column's scale
    parser = _RowParser(path, has_time, xcol, unit, on_bad_rows, (ycol, unit))
    if cut + 1 < len(first):
        parser.feed(first[cut + 1:])
    del first
    for block in blocks:
        parser.feed(block)
    times, xs, excluded = parser.result()
    ys = parser.stage_values
    assert ys is not None
    if decimal_exponent(unit) is None:
        assert px is not None
        xs, ys = xs * px, ys * px
    return times, xs, ys, unit, excluded


def load_xy_csv(path, *, exposure, frame_interval=None, temperature=None, position_unit=None,
                pixel_size_m=None, name: str | None = None, metadata=None,
                timing_tolerance: float = DEFAULT_TIMING_TOLERANCE,
                check_units: bool = True, laser_power=None, allow_irregular: bool = False,
                on_bad_rows: str = "error") -> XYRecording:
    """Load an x/y recording from a CSV file with header ``t_s,x_<unit>,y_<unit>`` (or
    ``x_<unit>,y_<unit>``), e.g. ``t_s,x_nm,y_nm``, ``t_s,x_px,y_px`` (needs `pixel_size_m`
    [m]) or ``t_s,x_V,y_V`` (kept in volts).

    **Arguments:** `exposure` [s]; `frame_interval` [s] (inferred from ``t_s`` when None);
    `temperature` [K] (None: 295 K, noted in ``metadata["defaults_applied"]``);
    `position_unit` (the unit the file must be in); `on_bad_rows` (``"error"`` or
    ``"exclude"``: a bad row is dropped from both axes and reported in
    ``metadata["excluded_rows"]``); the rest as in :func:`load_csv`.

    **Raises:** ``ValueError`` starting with the file name (and line number for a bad row):
    a missing y column, different x and y units, a row with a missing cell, NaN, or
    non-increasing time stamps.
    """
    path = Path(os.fspath(path))
    if on_bad_rows not in ("error", "exclude"):
        raise ValueError(f"on_bad_rows must be one of ('error', 'exclude'); got {on_bad_rows!r}")
    times, xs, ys, unit, excluded = _read_xy(path, position_unit, pixel_size_m, on_bad_rows)
    if xs.shape[0] == 0:
        detail = f" ({len(excluded)} bad row(s) excluded)" if excluded else ""
        raise ValueError(f"{path}: no data rows after the header{detail}")
    meta, temperature = file_metadata(path, unit, temperature, metadata)
    if excluded:
        meta["excluded_rows"] = {"count": len(excluded), "lines": [ln for ln, _ in excluded],
                                 "reasons": [why for _, why in excluded]}
    try:
        if frame_interval is None:
            if times is None or times.shape[0] < 2:
                raise ValueError(f"frame_interval not given and there is no {TIME_COLUMN!r} "
                                 "column (with at least 2 rows) to infer it from; pass "
                                 "frame_interval [s]")
            frame_interval = infer_frame_interval(times, float(timing_tolerance))
            meta["frame_interval_inferred"] = True
            w = float(exposure)
            if frame_interval < w <= frame_interval * (1 + float(timing_tolerance)):
                frame_interval = w
        return xy_from_arrays(xs, ys, frame_interval=frame_interval, exposure=exposure,
                              temperature=temperature, times=times, name=name, metadata=meta,
                              timing_tolerance=timing_tolerance, check_units=check_units,
                              laser_power=laser_power, allow_irregular=allow_irregular)
    except ValueError as e:
        raise ValueError(f"{path}: {e}") from None


def write_xy_csv(xy: XYRecording, path, position_unit: str = "nm") -> None:
    """Write ``t_s,x_<unit>,y_<unit>`` (``repr`` of the scaled values; metres or volts)."""
    unit = canonical_unit(position_unit)
    p = decimal_exponent(unit)
    if p is None:
        raise ValueError(f"write_xy_csv: position_unit must be m, mm, um, nm or V; got "
                         f"{position_unit!r}")
    t = xy.times
    if t is None:
        t = np.arange(xy.n_frames, dtype=np.float64) * xy.frame_interval
    scale = 10.0 ** p
    rows = [f"{TIME_COLUMN},x_{unit},y_{unit}"]
    rows.extend(f"{ti!r},{xi * scale!r},{yi * scale!r}" for ti, xi, yi in
                zip(t.tolist(), xy.x.positions.tolist(), xy.y.positions.tolist(), strict=True))
    Path(os.fspath(path)).write_text("\n".join(rows) + "\n", encoding="utf-8")
