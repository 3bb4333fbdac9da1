"""Property-based fuzzing of the CSV loader.

Whatever the file contains, ``load_csv`` either returns a recording holding exactly the rows
of the file (bit for bit), or raises ``ValueError`` whose message names the file (and, for a
bad row, its line). Never another exception type, never a silently dropped row.
"""

import math
import tempfile
import warnings
from decimal import Decimal
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from blurtrap.data import ExcludedRowsWarning, load_csv

DT = 1e-3
W = 1e-4
SETTINGS = settings(max_examples=150, deadline=None, suppress_health_check=list(HealthCheck))

# garbage that can never be a number: it always contains one of these characters
_poison = st.sampled_from(list("qz#!?xé\x00"))
_garbage = st.builds(
    lambda a, p, b: a + p + b,
    st.text(max_size=4),
    _poison,
    st.text(max_size=4),
).map(lambda s: "".join(c for c in s if c not in ",\n\r"))
_mutation = st.one_of(
    st.tuples(st.just("garbage_x"), _garbage),
    st.tuples(st.just("garbage_t"), _garbage),
    st.tuples(st.just("extra_field"), st.just("")),
    st.tuples(st.just("missing_field"), st.just("")),
    st.tuples(st.just("nonfinite"), st.sampled_from(["nan", "NaN", "inf", "-inf", "Infinity"])),
    st.tuples(st.just("dup_time"), st.just("")),
    st.tuples(st.just("blank_line"), st.just("")),
)


@st.composite
def csv_files(draw):
    n = draw(st.integers(2, 25))
    values = draw(st.lists(st.floats(-1e3, 1e3, allow_nan=False), min_size=n, max_size=n))
    pad = draw(st.sampled_from(["", " ", "\t"]))
    rows = [[repr(i * DT), repr(v)] for i, v in enumerate(values)]
    mutated = draw(st.dictionaries(st.integers(0, n - 1), _mutation, max_size=3))
    lines = []  # (text, row index or None)
    for i, row in enumerate(rows):
        kind, payload = mutated.get(i, (None, None))
        cells = list(row)
        if kind == "garbage_x":
            cells[1] = payload
        elif kind == "garbage_t":
            cells[0] = payload
        elif kind == "extra_field":
            cells.append("1")
        elif kind == "missing_field":
            cells = cells[:1]
        elif kind == "nonfinite":
            cells[1] = payload
        elif kind == "dup_time" and i > 0:
            cells[0] = rows[i - 1][0]
        elif kind == "blank_line":
            lines.append(("", None))
        lines.append((",".join(pad + c + pad for c in cells), i))
    bad_lines = {
        k + 2
        for k, (text, i) in enumerate(lines)
        if i is None or (i in mutated and mutated[i][0] not in ("dup_time", "blank_line"))
    }
    dup_lines = {
        k + 2
        for k, (_, i) in enumerate(lines)
        if i is not None and i > 0 and mutated.get(i, ("",))[0] == "dup_time"
    }
    newline = draw(st.sampled_from(["\n", "\r\n", "\r"]))
    body = newline.join(["t_s,x_nm"] + [t for t, _ in lines])
    if draw(st.booleans()):
        body += newline
    if draw(st.booleans()):
        body = "\ufeff" + body
    return body, values, lines, bad_lines, dup_lines


def _write(tmp, text) -> Path:
    p = Path(tmp) / "fuzz_input.csv"
    p.write_bytes(text.encode("utf-8") if isinstance(text, str) else text)
    return p


def _nm(v: float) -> float:
    """Independent reference for the exact decimal nm -> m conversion."""
    return float(Decimal(repr(v)).scaleb(-9))


def _check_error_names_file(err: ValueError, path: Path):
    assert path.name in str(err), str(err)


@SETTINGS
@given(csv_files())
def test_fuzz_error_mode(case):
    text, values, lines, bad_lines, dup_lines = case
    with tempfile.TemporaryDirectory() as tmp:
        p = _write(tmp, text)
        first_bad = min(bad_lines | dup_lines, default=None)
        constant = len(set(_nm(v) for v in values)) == 1
        # a trapped bead's positions have a std between 2e-11 and 1e-5 m (unit-slip check)
        plausible = 2e-11 <= float(np.std([_nm(v) for v in values])) <= 1e-5
        try:
            r = load_csv(p, exposure=W, frame_interval=DT)
        except ValueError as e:
            _check_error_names_file(e, p)
            if first_bad is not None:
                assert f"line {first_bad}:" in str(e), str(e)
            elif not constant:
                assert not plausible and "positions have standard deviation" in str(e), str(e)
            return
        assert first_bad is None and not constant and plausible
        assert r.n_frames == len(values)
        np.testing.assert_array_equal(r.positions, [_nm(v) for v in values])
        np.testing.assert_array_equal(r.times, [float(repr(i * DT)) for i in range(len(values))])


@SETTINGS
@given(csv_files())
def test_fuzz_exclude_mode_accounts_for_every_row(case):
    text, values, lines, bad_lines, _ = case
    with tempfile.TemporaryDirectory() as tmp:
        p = _write(tmp, text)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", ExcludedRowsWarning)
            try:
                r = load_csv(
                    p, exposure=W, frame_interval=DT, on_bad_rows="exclude", allow_irregular=True
                )
            except ValueError as e:
                _check_error_names_file(e, p)
                return
        ex = r.metadata.get("excluded_rows", {"count": 0, "lines": ()})
        assert ex["count"] == len(ex["lines"])
        assert r.n_frames + ex["count"] == len(lines)  # every data line is kept or counted
        assert bad_lines <= set(ex["lines"])
        kept = [i for k, (_, i) in enumerate(lines) if k + 2 not in set(ex["lines"])]
        assert None not in kept
        np.testing.assert_array_equal(r.positions, [_nm(values[i]) for i in kept])


@SETTINGS
@given(
    st.one_of(st.text(max_size=200), st.binary(max_size=200)), st.sampled_from(["error", "exclude"])
)
def test_fuzz_arbitrary_content_only_raises_valueerror(content, mode):
    with tempfile.TemporaryDirectory() as tmp:
        p = _write(tmp, content)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", ExcludedRowsWarning)
            try:
                r = load_csv(
                    p, exposure=W, frame_interval=DT, on_bad_rows=mode, allow_irregular=True
                )
            except ValueError as e:
                _check_error_names_file(e, p)
                return
        assert r.n_frames >= 2 and np.all(np.isfinite(r.positions))


@pytest.mark.parametrize("mode", ["error", "exclude"])
def test_fuzz_header_variants_with_random_rows(mode, rng):
    """Non-hypothesis smoke test so that a broken strategy cannot hide the property."""
    vals = rng.normal(0, 50, 40).tolist()
    text = "\ufeff t_s , x_nm \r\n" + "".join(f"{i * DT!r}, {v!r} \r\n" for i, v in enumerate(vals))
    with tempfile.TemporaryDirectory() as tmp:
        r = load_csv(_write(tmp, text), exposure=W, on_bad_rows=mode)
    np.testing.assert_array_equal(r.positions, [_nm(v) for v in vals])
    assert math.isclose(r.frame_interval, DT, rel_tol=1e-12)
