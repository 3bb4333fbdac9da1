"""Fuzzing the loaders: manifests, CSV headers, empty files, NPZ headers, the streamed CSV
reader (block boundaries and its vectorised fast path) and a huge file in bounded memory.

Complements ``tests/data/test_csv_fuzz.py`` (hypothesis rows: garbage, NaN/inf, wrong field
counts, duplicate times, blank lines, BOM, LF/CRLF/CR) and ``tests/data/test_csv_loader.py``:
every bad input here must raise an error naming the file (and the entry or line where there is
one), and every valid variant must parse to the same float64 bits.
"""

import json
import math
import tempfile
import tracemalloc
import warnings
from decimal import Decimal
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import blurtrap.data._csv as csv_mod
from blurtrap.data import ExcludedRowsWarning, Recording, load_csv, load_manifest, load_npz

FUZZ = settings(
    max_examples=60,
    deadline=None,
    derandomize=True,
    database=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture],
)
CSV_TEXT = "t_s,x_nm\n0,1.5\n0.001,-2.25\n0.002,0.5\n0.003,3\n"
CSV_POSITIONS = [1.5e-9, -2.25e-9, 0.5e-9, 3e-9]  # exact decimal scaling of the nm text


def entry(**kw):
    e = {"file": "a.csv", "frame_interval_s": 1e-3, "exposure_s": 1e-4}
    e.update(kw)
    return {k: v for k, v in e.items() if v is not _DROP}


_DROP = object()


def doc(**top):
    d = {"position_unit": "nm", "recordings": [entry()]}
    d.update(top)
    return {k: v for k, v in d.items() if v is not _DROP}


def write_manifest(folder: Path, content, csv_text=CSV_TEXT) -> Path:
    (folder / "a.csv").write_text(csv_text, encoding="utf-8")
    p = folder / "m.json"
    if isinstance(content, bytes):
        p.write_bytes(content)
    elif isinstance(content, str):
        p.write_text(content, encoding="utf-8")
    else:
        p.write_text(json.dumps(content), encoding="utf-8")
    return p


def R(**kw):  # one bad entry in a manifest that is otherwise fine
    return doc(recordings=[entry(**kw)])


NUM = r"must be a number; got "
# (id, manifest content, error regex after the manifest path)
MANIFEST_CASES = [
    # missing keys
    ("no position_unit", doc(position_unit=_DROP), r"'position_unit' is missing"),
    ("no recordings", doc(recordings=_DROP), r"'recordings' must be a non-empty list"),
    ("no file", R(file=_DROP), r"recordings\[0\]: required key 'file' is missing"),
    ("no exposure", R(exposure_s=_DROP), r"recordings\[0\]: required key 'exposure_s' is missing"),
    # wrong types
    *[(f"position_unit={v!r}", doc(position_unit=v), r"position_unit = .* is not a supported position unit")
      for v in (5, None, ["nm"], "", "NM", "nanometre", "inch", "µ")],
    *[(f"recordings={v!r}", doc(recordings=v), r"'recordings' must be a non-empty list")
      for v in ({}, "a.csv", 5, None, [])],
    *[(f"entry={v!r}", doc(recordings=[v]), r"recordings\[0\]: each entry must be a JSON object")
      for v in ("a.csv", 5, None, [], [entry()])],
    *[(f"file={v!r}", R(file=v), r"recordings\[0\]: 'file' must be a file name") for v in (5, None, "", [])],
    *[(f"exposure_s={v!r}", R(exposure_s=v), r"recordings\[0\] \(a.csv\): exposure_s " + NUM)
      for v in ("1e-4", True, None, [1e-4], {"s": 1e-4})],
    *[(f"frame_interval_s={v!r}", R(frame_interval_s=v), r"frame_interval_s " + NUM) for v in ("1e-3", False)],
    *[(f"temperature_K={v!r}", R(temperature_K=v), r"temperature_K " + NUM) for v in ("295", [295])],
    *[(f"laser_power_mW={v!r}", R(laser_power_mW=v), r"laser_power_mW " + NUM) for v in ("100", True, [])],
    *[(f"metadata={v!r}", R(metadata=v), r"'metadata' must be a JSON object") for v in ("x", 5, [])],
    *[(f"allow_irregular={v!r}", R(allow_irregular=v), r"allow_irregular must be true or false")
      for v in ("false", 1, None)],
    *[(f"check_units={v!r}", R(check_units=v), r"check_units must be true or false") for v in ("no", 0)],
    *[(f"timing_tolerance={v!r}", R(timing_tolerance=v), r"timing_tolerance " + NUM) for v in ("x", True)],
    *[(f"name={v!r}", R(name=v), r"a.csv: name must be a str or None") for v in (5, [1])],
    ("pixel_size_m string", doc(position_unit="px", pixel_size_m="1e-7"), r"pixel_size_m " + NUM),
    ("px without pixel size", doc(position_unit="px"), r"position unit 'px' needs pixel_size_m"),
    ("pixel_size_m 0", doc(position_unit="px", pixel_size_m=0), r"pixel_size_m must be finite and > 0"),
    ("pixel_size_m 1 m", doc(position_unit="px", pixel_size_m=1.0), r"larger than 1 mm"),
    # unknown keys (a unit slip must not be ignored)
    ("top units", doc(units="nm"), r"unknown top-level key\(s\) \['units'\]"),
    ("exposure_ms", R(exposure_ms=0.1), r"unknown key\(s\) \['exposure_ms'\]"),
    ("Exposure_s", R(Exposure_s=1e-4), r"unknown key\(s\) \['Exposure_s'\]"),
    # out-of-range values
    *[(f"exposure_s={v!r}", R(exposure_s=v), r"a.csv: exposure must be > 0 \[s\]; got exposure = ")
      for v in (-1e-4, 0)],
    ("exposure NaN", '{"position_unit": "nm", "recordings": [{"file": "a.csv", "exposure_s": NaN}]}',
     r"a.csv: exposure must be finite \[s\]; got exposure = nan"),
    ("exposure -Infinity", '{"position_unit": "nm", "recordings": [{"file": "a.csv", "exposure_s": -Infinity}]}',
     r"a.csv: exposure must be finite"),
    ("exposure > frame interval", R(exposure_s=2e-3), r"a.csv: exposure = 0.002 s is longer than frame_interval"),
    ("exposure in ms", R(exposure_s=2.0, frame_interval_s=3.0),
     r"a.csv: frame_interval = 3.0 s is at least 0.1 s .*looks like ms"),
    ("1500 fps interval in ms", R(frame_interval_s=0.6667),
     r"a.csv: frame_interval = 0.6667 s is at least 0.1 s .*looks like ms"),
    ("temperature mK", R(temperature_K=295000),
     r"temperature = 295000.0 K is above 400 K: this looks like millikelvin"),
    ("temperature 1e6 K", R(temperature_K=1e6), r"temperature = 1000000.0 K is above 400 K"),
    *[(f"frame_interval_s={v!r}", R(frame_interval_s=v), r"frame_interval must be > 0 \[s\]") for v in (-1e-3, 0)],
    ("frame_interval vs times", R(frame_interval_s=2e-3, exposure_s=1e-4),
     r"a.csv: times imply a frame interval of 0.001 s"),
    ("temperature negative", R(temperature_K=-1), r"temperature must be > 0 \[K\]"),
    ("temperature Celsius", R(temperature_K=25), r"temperature = 25.0 K is below 100 K: this looks like Celsius"),
    ("laser power negative", R(laser_power_mW=-5), r"laser_power must be >= 0 \[W\]"),
    ("laser power in W*1000", R(laser_power_mW=5e4), r"laser_power = 50.0 W is above 10 W"),
    *[(f"timing_tolerance={v!r}", R(timing_tolerance=v), r"timing_tolerance must be > 0") for v in (0, -1e-3)],
    # not (valid) JSON
    ("empty", "", r"manifest file is empty"),
    ("whitespace", " \r\n\t\n", r"manifest file is empty"),
    ("BOM only", "\ufeff", r"manifest file is empty"),
    ("truncated", '{"position_unit": ', r"invalid JSON at line 1, column 19"),
    ("// comment", '// recorded 2024\n' + json.dumps(doc()), r"invalid JSON at line 1, column 1"),
    ("# comment", '# camera A\n' + json.dumps(doc()), r"invalid JSON at line 1, column 1"),
    ("trailing comma", json.dumps(doc())[:-1] + ",}", r"invalid JSON at line 1"),
    ("single quotes", json.dumps(doc()).replace('"', "'"), r"invalid JSON at line 1, column 2"),
    ("top-level list", "[]", r"the manifest must be a JSON object"),
    ("top-level null", "null", r"the manifest must be a JSON object"),
    ("top-level string", '"nm"', r"the manifest must be a JSON object"),
    ("nested too deeply", "[" * 100_000, r"invalid JSON \(nested too deeply\)"),
    ("duplicate key", '{"position_unit": "nm", "recordings": [{"file": "a.csv", "exposure_s": 1e-4, '
     '"exposure_s": 5e-4}]}', r"key 'exposure_s' appears twice in one JSON object"),
    ("5000-digit integer", '{"position_unit": "nm", "recordings": [{"file": "a.csv", "exposure_s": 1'
     + "0" * 5000 + "}]}", r"invalid JSON \(Exceeds the limit"),
    ("not UTF-8", b'{"position_unit": "\xb5m", "recordings": []}', r"not UTF-8 text"),
    ("UTF-16", json.dumps(doc()).encode("utf-16"), r"not UTF-8 text"),
    # problems inside the CSV named through the manifest
    ("file name too long", R(file="a" * 5000 + ".csv"), r"recordings\[0\] \(a{77}\.\.\.\): cannot use this file name"),
    ("second entry bad", doc(recordings=[entry(), entry(exposure_s=-1.0)]),
     r"recordings\[1\]: .*a.csv: exposure must be > 0"),
]
CSV_THROUGH_MANIFEST = [
    ("bad row", "t_s,x_nm\n0,1\n0.001,x\n", r"a.csv, line 3: non-numeric value 'x'"),
    ("decreasing time", "t_s,x_nm\n0,1\n0.002,2\n0.001,3\n", r"a.csv, line 4: time stamp t_s = '0.001' is not after"),
    ("unit mismatch", "t_s,x_um\n0,1\n0.001,2\n", r"a.csv, line 1: column 'x_um' is in 'um' but position_unit = 'nm'"),
]


@pytest.mark.parametrize("content, match", [c[1:] for c in MANIFEST_CASES], ids=[c[0] for c in MANIFEST_CASES])
def test_manifest_bad_input(bad_input, tmp_path, content, match):
    p = write_manifest(tmp_path, content)
    bad_input("manifest", lambda: load_manifest(p), match=r"m\.json.*" + match, value=content)


@pytest.mark.parametrize("csv_text, match", [c[1:] for c in CSV_THROUGH_MANIFEST],
                         ids=[c[0] for c in CSV_THROUGH_MANIFEST])
def test_manifest_names_csv_problems(bad_input, tmp_path, csv_text, match):
    p = write_manifest(tmp_path, doc(), csv_text)
    bad_input("manifest", lambda: load_manifest(p), match=r"m\.json, recordings\[0\]: .*" + match,
              value=csv_text)


def test_manifest_missing_csv(bad_input, tmp_path):
    p = write_manifest(tmp_path, R(file="nope.csv"))
    bad_input("manifest", lambda: load_manifest(p), exc=FileNotFoundError,
              match=r"m\.json, recordings\[0\] \(nope.csv\): file not found", value="nope.csv")


def _bits(rec):
    return (rec.positions.tobytes(), None if rec.times is None else rec.times.tobytes(),
            rec.frame_interval, rec.exposure, rec.temperature, rec.laser_power, rec.name)


VALID_MANIFESTS = {
    "plain": json.dumps(doc(recordings=[entry(laser_power_mW=100)])),
    "BOM": "\ufeff" + json.dumps(doc(recordings=[entry(laser_power_mW=100)])),
    "CRLF + indent": json.dumps(doc(recordings=[entry(laser_power_mW=100)]), indent=2).replace("\n", "\r\n"),
    "trailing blank lines": json.dumps(doc(recordings=[entry(laser_power_mW=100)])) + "\n\n \n\t\n",
    "tabs, key order, exponents": '{\t"recordings" : [ {"laser_power_mW": 1E2, "exposure_s": 1.0E-4,'
                                  '"frame_interval_s": 0.001, "file": "a.csv"} ],\n"position_unit":"nm"}',
    "integer power, description": '{"position_unit": "nm", "description": null, "recordings": '
                                   '[{"file": "a.csv", "frame_interval_s": 1e-3, "exposure_s": 1e-4, '
                                   '"laser_power_mW": 100}]}',
}


@pytest.mark.parametrize("text", list(VALID_MANIFESTS.values()), ids=list(VALID_MANIFESTS))
def test_manifest_valid_variants_parse_identically(tmp_path, text):
    (ref,) = load_manifest(write_manifest(tmp_path, VALID_MANIFESTS["plain"]))
    (got,) = load_manifest(write_manifest(tmp_path, text))
    assert _bits(got) == _bits(ref)
    np.testing.assert_array_equal(got.positions, CSV_POSITIONS)
    assert got.laser_power == 0.1 and got.exposure == 1e-4


# arbitrary JSON in any key: a ValueError / FileNotFoundError naming the manifest, or a load
JSON_VALUES = st.recursive(
    st.none() | st.booleans() | st.integers() | st.floats() | st.text(max_size=8),
    lambda c: st.lists(c, max_size=3) | st.dictionaries(st.text(max_size=6), c, max_size=3),
    max_leaves=6,
)
ENTRY_KEYS = ["file", "frame_interval_s", "exposure_s", "temperature_K", "laser_power_mW", "name",
              "metadata", "allow_irregular", "timing_tolerance", "check_units", "bogus"]
TOP_KEYS = ["position_unit", "pixel_size_m", "recordings", "description", "bogus"]


@FUZZ
@given(st.lists(st.tuples(st.booleans(), st.integers(0, 10), JSON_VALUES), min_size=1, max_size=3))
def test_manifest_fuzz_values_only_clear_errors(bad_input, changes):
    d = doc(recordings=[entry(), entry(exposure_s=5e-4)])
    for top, key_i, value in sorted(changes, key=lambda c: c[0]):  # entries first
        if top:
            d[TOP_KEYS[key_i % len(TOP_KEYS)]] = value
        else:
            d["recordings"][key_i % 2][ENTRY_KEYS[key_i]] = value
    with tempfile.TemporaryDirectory() as tmp:
        p = write_manifest(Path(tmp), json.dumps(d))
        try:
            s = load_manifest(p)
        except (ValueError, FileNotFoundError) as e:
            assert str(e).startswith(str(p)), str(e)  # names the manifest (and entry)
            bad_input.record("manifest (fuzzed values)", changes, str(e))
            return
    assert len(s) == 2 and all(np.isfinite(r.positions).all() for r in s)


# ---- CSV headers and empty files ------------------------------------------------------------
BAD_HEADERS = [
    ("t_s;x_nm", r"line 1: header 't_s;x_nm' separates its columns with semicolons"),
    ("t_s\tx_nm", r"line 1: header 't_s\\tx_nm' separates its columns with tabs"),
    ('"t_s","x_nm"', r"line 1: header .* has columns"),
    ("x_nm,t_s", r"line 1: header 'x_nm,t_s' has columns"),
    ("t_ms,x_nm", r"line 1: header 't_ms,x_nm' has columns"),
    ("t_s,x_inch", r"line 1: unit of column 'x_inch' = 'inch' is not a supported position unit"),
    ("t_s,x_", r"line 1: unit of column 'x_' = '' is not a supported"),
    ("t_s,X_NM", r"line 1: unit of column 'X_NM' = 'NM' is not a supported"),
    ("# t_s,x_nm", r"line 1: position column '# t_s' not understood|line 1: header '# t_s,x_nm' has columns"),
    ("t_s,", r"line 1: position column '' not understood"),
    (",x_nm", r"line 1: header ',x_nm' has columns"),
    ("t_s,x_nm\ufeff", r"line 1: unit of column 'x_nm\\ufeff'"),
    ("t_s x_nm", r"line 1: position column 't_s x_nm' not understood"),
    ("t_s,x_nm,", r"line 1: header 't_s,x_nm,' has columns"),
]


@pytest.mark.parametrize("header, match", BAD_HEADERS, ids=[repr(h) for h, _ in BAD_HEADERS])
def test_csv_wrong_headers(bad_input, tmp_path, header, match):
    p = tmp_path / "rec.csv"
    p.write_text(header + "\n0,1\n0.001,2\n", encoding="utf-8")
    bad_input("CSV header", lambda: load_csv(p, exposure=1e-4), match=r"rec\.csv, " + match, value=header)


BAD_FILES = [
    (b"", r"rec\.csv: file is empty"),
    (b"\xef\xbb\xbf", r"rec\.csv: file is empty"),
    (b"\n", r"rec\.csv: file is empty"),
    (b"\r\n\r\n", r"rec\.csv: file is empty"),
    (b" \t \n\n", r"rec\.csv: file is empty"),
    (b"\xef\xbb\xbf\n \r\n", r"rec\.csv: file is empty"),
    (b"t_s,x_nm", r"rec\.csv: no data rows after the header"),
    (b"t_s,x_nm\n\n\n", r"rec\.csv: no data rows after the header"),
    (b"t_s,x_nm\r\n \r\n\t\r\n", r"rec\.csv: no data rows after the header"),
    ("t_s,x_µm\n0,1\n".encode("latin-1"), r"rec\.csv: not UTF-8 text \(undecodable byte b'\\xb5' at byte offset 6\)"),
    ("t_s,x_nm\n0,1\n0.001,2\n".encode("utf-16"), r"rec\.csv: not UTF-8 text"),
    (b"t_s,x_nm\n0,1\n# pause\n0.002,3\n", r"rec\.csv, line 3: expected 2 field\(s\) \(t_s,x_nm\), got 1: '# pause'"),
    (b"t_s,x_nm\n0,1\n#,3\n", r"rec\.csv, line 3: non-numeric value '#' in column t_s"),
    (b't_s,x_nm\n0,1\n0.001,"2"\n', r"rec\.csv, line 3: non-numeric value '\"2\"' in column x_nm"),
    (b"t_s,x_nm\n0,1\n0.001,1,234.5\n", r"rec\.csv, line 3: expected 2 field\(s\)"),
    (b"t_s,x_nm\n0;1\n", r"rec\.csv, line 2: expected 2 field\(s\)"),
    (b"t_s,x_nm\n0,0x1A\n", r"rec\.csv, line 2: non-numeric value '0x1A'"),
    (b"t_s,x_nm\n0,1\n0.001,  \n", r"rec\.csv, line 3: non-numeric value '  ' in column x_nm"),
    (b"t_s,x_nm\n0,1\n\t,2\n", r"rec\.csv, line 3: non-numeric value '\\t' in column t_s"),
    (b"t_s,x_nm\n0,1\n0.001,2\x0c3\n", r"rec\.csv, line 3: non-numeric value '2\\x0c3'"),
    (b"t_s,x_nm\n0,1\n0.001,+\n", r"rec\.csv, line 3: non-numeric value '\+'"),
    (b"t_s,x_nm\n0,1\n0.001,Infinity\n", r"rec\.csv, line 3: non-finite value 'Infinity'"),
    (b"t_s,x_nm\n0,1\n0.001,1e400\n", r"rec\.csv, line 3: value '1e400' in column x_nm overflows"),
    (b"t_s,x_nm\n1e400,1\n", r"rec\.csv, line 2: value '1e400' in column t_s overflows"),
    (b"t_s,x_nm\n0,1\n-0.001,2\n", r"rec\.csv, line 3: time stamp t_s = '-0.001' is not after"),
    (b"t_s,x_nm\n0,1\n0.001,2\r0.002,3\n", r"rec\.csv, line 3: expected 2 field\(s\)"),
]


@pytest.mark.parametrize("content, match", BAD_FILES, ids=[repr(c[:24]) for c, _ in BAD_FILES])
def test_csv_bad_files(bad_input, tmp_path, content, match):
    p = tmp_path / "rec.csv"
    p.write_bytes(content)
    bad_input("CSV file/rows", lambda: load_csv(p, exposure=1e-4, frame_interval=1e-3),
              match=match, value=content)


# ---- the streamed reader: block boundaries and the vectorised fast path ------------------------
_NUMS = st.one_of(
    st.floats(-1e3, 1e3, allow_nan=False).map(repr),
    st.integers(-(10**20), 10**20).map(str),
    st.floats(-1e3, 1e3, allow_nan=False).map(lambda v: f"{v:.3e}"),
    st.sampled_from(["5.", ".5", "-0", "+7", "0000.1"]),
)
_SNEAKY = st.sampled_from([" ", "\t", "", "+", "-", ".", "e5", "1e", "1 2", "0x1", "nan", "inf", "1e999",
                           "1_0", "\u0661", "\x0b1", "1\x0c", " \t ", "E", "\u00a01", "#"])
_PAD = st.sampled_from(["", " ", "\t", "  "])


@st.composite
def _cell(draw):
    core = draw(_SNEAKY) if draw(st.integers(0, 12)) == 0 else draw(_NUMS)
    return draw(_PAD) + core + draw(_PAD)


@st.composite
def csv_bytes(draw):
    has_t = draw(st.booleans())
    unit = draw(st.sampled_from(["nm", "m", "um", "px"]))
    rows, t = [], 0.0
    for _ in range(draw(st.integers(1, 40))):
        x = draw(_cell())
        if has_t:
            r = draw(st.integers(0, 15))
            if r == 0:
                tc = draw(_cell())
            elif r == 1:
                tc = repr(t)  # a repeated time stamp
            else:
                t += 1e-3
                tc = draw(_PAD) + repr(t) + draw(_PAD)
            x = tc + "," + x
        rows.append(x)
        if draw(st.integers(0, 20)) == 0:
            rows.append(draw(st.sampled_from(["", " ", "\t"])))  # a blank line inside
    nl = draw(st.sampled_from(["\n", "\r\n", "\r"]))
    body = nl.join([f"t_s,x_{unit}" if has_t else f"x_{unit}"] + rows)
    body += nl * draw(st.integers(0, 3))
    if draw(st.booleans()):
        body = "\ufeff" + body
    return body.encode("utf-8")


def _outcome(path, mode):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ExcludedRowsWarning)
        try:
            px = 1e-7 if b"x_px" in path.read_bytes()[:64] else None  # only 'px' takes one
            r = load_csv(path, exposure=1e-4, frame_interval=1e-3, on_bad_rows=mode,
                         allow_irregular=True, pixel_size_m=px, check_units=False)
        except ValueError as e:
            return ("error", str(e))
    return ("ok", _bits(r), dict(r.metadata))


@FUZZ
@given(csv_bytes(), st.sampled_from(["error", "exclude"]), st.sampled_from([1, 3, 7, 64]))
def test_streaming_is_independent_of_block_size(content, mode, block):
    """Reading in blocks of 1..64 bytes (lines split over many reads; CRLF, BOM and blank
    lines at block edges) gives the same recording or the same error as one 1 MiB block."""
    with tempfile.TemporaryDirectory() as tmp:
        p = Path(tmp) / "f.csv"
        p.write_bytes(content)
        ref = _outcome(p, mode)
        old = csv_mod._BLOCK_BYTES
        csv_mod._BLOCK_BYTES = block
        try:
            got = _outcome(p, mode)
        finally:
            csv_mod._BLOCK_BYTES = old
    assert got == ref


@FUZZ
@given(csv_bytes(), st.sampled_from(["error", "exclude"]))
def test_fast_path_equals_line_by_line_path(content, mode):
    """Whenever the vectorised path accepts a block it returns exactly what the line-by-line
    parser returns for it (same bits, no exclusions); blocks it declines go to that parser."""
    text = content.decode("utf-8").lstrip("\ufeff")
    if "\n" not in text:
        text = text.replace("\r", "\n")
    text = text.replace("\r\n", "\n")
    lines = text.split("\n")
    header, body = lines[0], "\n".join(lines[1:])
    while body.endswith("\n\n"):
        body = body[:-1]
    if not body.endswith("\n"):
        body += "\n"
    try:
        px = 1e-7 if "x_px" in header else None  # pixel_size_m only goes with 'px'
        has_time, xcol, unit, _ = csv_mod._parse_header(Path("f.csv"), header, None, px)
    except ValueError:
        return
    fast = csv_mod._RowParser(Path("f.csv"), has_time, xcol, unit, mode)
    took_fast = fast._fast(body.encode("utf-8"), body.count("\n"))
    if not took_fast:
        return
    slow = csv_mod._RowParser(Path("f.csv"), has_time, xcol, unit, mode)
    slow._slow(body.split("\n")[:-1])
    (tf, xf, exf), (ts, xs, exs) = fast.result(), slow.result()
    assert exs == [] and exf == []
    assert xf.tobytes() == xs.tobytes()
    assert (tf is None and ts is None) or tf.tobytes() == ts.tobytes()


def test_fast_path_refuses_blank_cells():
    """np.fromstring reads a blank cell as -1.0 (a numpy quirk): such blocks must never be
    taken by the vectorised path."""
    for body in (b" ,1\n", b"0.001,\t\n", b"0,1\n\t ,2\n", b"0,1\n0.001, \n"):
        parser = csv_mod._RowParser(Path("f.csv"), True, "x_m", "m", "exclude")
        assert not parser._fast(body, body.count(b"\n")), body


# ---- NPZ --------------------------------------------------------------------------------------
_ENT = {"frame_interval": 1e-3, "exposure": 1e-4, "temperature": 295.0, "laser_power": None,
        "name": None, "metadata": {}, "allow_irregular": False, "timing_tolerance": 1e-3,
        "check_units": True, "has_times": False}
_HDR = {"format": "blurtrap.recordings", "version": 1, "kind": "recording", "recordings": [_ENT]}


def _h(**kw):
    h = dict(_HDR)
    h.update(kw)
    return json.dumps(h)


NPZ_CASES = [
    ("not a zip", b"not a zip", None, r"not a readable \.npz file"),
    ("empty file", b"", None, r"not a readable \.npz file"),
    ("npy not npz", "npy", None, r"not a readable \.npz file \(it holds a single ndarray"),
    ("header not JSON", None, "{oops", r"corrupt __blurtrap__ header"),
    ("header array of ints", None, np.array([1, 2]), r"corrupt __blurtrap__ header \(expected a 0-d text array"),
    ("header 5", None, "5", r"corrupt __blurtrap__ header: expected a JSON object"),
    ("wrong format", None, _h(format="other"), r"unsupported header format 'other'"),
    ("wrong version", None, _h(version=2), r"unsupported header format .* version 2"),
    ("bad kind", None, _h(kind="zzz"), r"kind = 'zzz'; expected 'recording' or 'set'"),
    ("no recordings", None, _h(recordings=None), r"'recordings' must list the recordings"),
    ("recordings 5", None, _h(recordings=5), r"'recordings' must list the recordings"),
    ("two for kind recording", None, _h(recordings=[_ENT, _ENT]), r"exactly one for kind 'recording'"),
    ("entry not object", None, _h(recordings=[5]), r"recordings\[0\] is not an object"),
    ("entry lacks exposure", None, _h(recordings=[{k: v for k, v in _ENT.items() if k != "exposure"}]),
     r"recordings\[0\] lacks \['exposure'\]"),
    ("has_times not bool", None, _h(recordings=[{**_ENT, "has_times": "yes"}]), r"has_times = 'yes' is not true/false"),
    ("times array missing", None, _h(recordings=[{**_ENT, "has_times": True}]), r"array\(s\) \['times_0'\] missing"),
    ("metadata 5", None, _h(recordings=[{**_ENT, "metadata": 5}]), r"recording 0: metadata must be a dict"),
    ("exposure > interval", None, _h(recordings=[{**_ENT, "exposure": 2e-3}]),
     r"recording 0: exposure = 0.002 s is longer"),
    ("exposure string", None, _h(recordings=[{**_ENT, "exposure": "1e-4"}]),
     r"recording 0: exposure must be a real scalar"),
]


@pytest.mark.parametrize("raw, header, match", [c[1:] for c in NPZ_CASES], ids=[c[0] for c in NPZ_CASES])
def test_npz_bad_input(bad_input, tmp_path, raw, header, match):
    p = tmp_path / "r.npz"
    x = np.random.default_rng(5).normal(0, 1e-8, 64)
    if isinstance(raw, bytes):
        p.write_bytes(raw)
    elif raw == "npy":
        with open(p, "wb") as f:
            np.save(f, x)
    else:
        with open(p, "wb") as f:
            np.savez(f, __blurtrap__=np.asarray(header), positions_0=x)
    bad_input("NPZ", lambda: load_npz(p), match=r"r\.npz: .*" + match, value=(raw, header))


# ---- a huge file, streamed -------------------------------------------------------------------
def test_huge_csv_streams_in_bounded_memory(tmp_path):
    """2 000 000 rows (36 MB of text) load with the exact values while the traced peak memory
    stays within 4x the returned arrays (the old read-everything-then-split loader peaked at
    ~8.7x the text size: 311 MB here; see README.md)."""
    n_sec, per = 2000, 1000  # rows j.mmm s for j < 2000, m < 1000: dt = 1 ms
    rng = np.random.default_rng(11)
    x_text = [f"{v:.4f}" for v in rng.normal(0, 30.0, per)]
    tails = [f"{m:03d},{x_text[m]}".encode() for m in range(per)]
    p = tmp_path / "huge.csv"
    with open(p, "wb") as f:
        f.write(b"t_s,x_nm\n")
        for j in range(n_sec):
            prefix = b"%d." % j
            f.write(prefix + (b"\n" + prefix).join(tails) + b"\n")
    size = p.stat().st_size
    n = n_sec * per

    tracemalloc.start()
    try:
        r = load_csv(p, exposure=1e-4, frame_interval=1e-3)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()

    assert isinstance(r, Recording) and r.n_frames == n
    out_bytes = r.positions.nbytes + r.times.nbytes  # 16 bytes per row
    assert peak < 4 * out_bytes, (peak / 1e6, out_bytes / 1e6, size / 1e6)
    # positions: exact decimal nm -> m, checked on every row against Decimal
    block = np.array([float(Decimal(t).scaleb(-9)) for t in x_text])
    np.testing.assert_array_equal(r.positions, np.tile(block, n_sec))
    # times: spot checks against float() of the text, and the regular 1 ms grid everywhere
    idx = np.concatenate([[0, per - 1, per, n - 1], rng.integers(0, n, 500)])
    ref = [float(f"{i // per}.{i % per:03d}") for i in idx]
    np.testing.assert_array_equal(r.times[idx], ref)
    assert np.all(np.abs(np.diff(r.times) - 1e-3) < 1e-9) and math.isclose(r.frame_interval, 1e-3)
