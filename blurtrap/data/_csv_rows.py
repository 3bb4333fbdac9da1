"""Row parsing of CSV recordings: a vectorised path for clean blocks and a line-by-line path
that reports (or excludes) every bad row; both give the same float64 bits for the same text."""

from __future__ import annotations

import math
import re
import warnings

import numpy as np

from ._units import decimal_exponent, parse_number

TIME_COLUMN = "t_s"
_TRAILING_BLANKS = re.compile(rb"[ \t]+\n")


def _short(text: str, n: int = 60) -> str:
    return repr(text if len(text) <= n else text[:n] + "...")


class _RowParser:
    """Parses the data lines of a CSV block by block (streaming, bounded memory).

    Each block goes through a vectorised fast path (``np.fromstring`` of the whole block,
    correctly rounded like ``float``) when it is plain ASCII, every line has the expected
    number of fields, no position cell has an exponent (positions in mm/um/nm get the decimal
    exponent appended as text, so the scaling stays exact), all values are finite and the time
    stamps increase. Anything else is parsed line by line by :meth:`_slow`, which reports or
    excludes the bad rows; both paths give the same float64 bits for the same text.
    """

    def __init__(self, path, has_time, xcol, unit, on_bad_rows, stage=None):
        """`stage`: ``(column name, unit)`` of a stage column, or None."""
        self.path = path
        self.has_time = has_time
        self.has_stage = stage is not None
        self.colnames = [TIME_COLUMN] * has_time + [xcol] + ([stage[0]] if stage else [])
        stage_unit = stage[1] if stage else None
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
        self.stage_values: np.ndarray | None = None  # the stage column, set by result()
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
        """``(times or None, positions, excluded)`` (and the stage column in
        ``stage_values``); the per-block parts are released one column at a time, so the peak
        is the output plus one column."""
        times = None
        if self.has_time:
            times = np.concatenate(self.times) if self.times else np.zeros(0)
            self.times.clear()
        pos = np.concatenate(self.positions) if self.positions else np.zeros(0)
        self.positions.clear()
        if self.has_stage:
            self.stage_values = np.concatenate(self.stage) if self.stage else np.zeros(0)
            self.stage.clear()
        return times, pos, self.excluded

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
