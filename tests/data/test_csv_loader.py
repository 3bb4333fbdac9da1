"""CSV loader: units, header handling, BOM/CRLF, inference of frame_interval, every row error
(with file, line and value), and on_bad_rows='exclude' accounting."""

import warnings
from decimal import Decimal

import numpy as np
import pytest

from blurtrap.data import ExcludedRowsWarning, load, load_csv

DT = 1e-3
W = 2e-4


def write(tmp_path, text, name="rec.csv", encoding="utf-8"):
    p = tmp_path / name
    p.write_bytes(text.encode(encoding) if isinstance(text, str) else text)
    return p


def good_text(n=20, unit="nm", newline="\n", dt=DT):
    rows = [f"t_s,x_{unit}"] + [f"{i * dt!r},{(-1) ** i * (i + 1) * 1.5}" for i in range(n)]
    return newline.join(rows) + newline


def nm_to_m(values):
    """Exact decimal conversion, as the loader does it: '1.5' nm -> float('1.5e-9')."""
    return np.array([float(Decimal(repr(v)).scaleb(-9)) for v in np.asarray(values).tolist()])


def expected_values(n=20):
    return np.array([(-1) ** i * (i + 1) * 1.5 for i in range(n)])


@pytest.mark.parametrize(
    "unit, factor", [("m", 1.0), ("mm", 1e3), ("um", 1e6), ("µm", 1e6), ("nm", 1e9)]
)
def test_units(tmp_path, unit, factor):
    metres = expected_values() * 1e-8
    text = f"t_s,x_{unit}\n" + "".join(
        f"{i * DT!r},{v!r}\n" for i, v in enumerate((metres * factor).tolist())
    )
    r = load_csv(write(tmp_path, text), exposure=W)
    np.testing.assert_allclose(r.positions, metres, rtol=3e-16, atol=0)
    if unit != "m":
        assert r.metadata["position_unit"] == ("um" if unit == "µm" else unit)


def test_nm_text_is_converted_exactly(tmp_path):
    """'12.345' nm must be the float64 nearest to 12.345e-9 m (decimal scaling)."""
    r = load_csv(write(tmp_path, "x_nm\n12.345\n-0.1\n3e2\n"), exposure=W, frame_interval=DT)
    np.testing.assert_array_equal(r.positions, [12.345e-9, -0.1e-9, 3e-7])


def test_pixels(tmp_path):
    text = "t_s,x_px\n" + "".join(f"{i * DT!r},{v}\n" for i, v in enumerate([3, -1, 4, 1, -5]))
    r = load_csv(write(tmp_path, text), exposure=W, pixel_size_m=1e-7)
    np.testing.assert_allclose(r.positions, np.array([3, -1, 4, 1, -5]) * 1e-7, rtol=1e-15)
    with pytest.raises(ValueError, match=r"rec.csv: position unit 'px' needs pixel_size_m"):
        load_csv(write(tmp_path, text), exposure=W)
    with pytest.raises(ValueError, match="pixel_size_m = 100.0 m is larger than 1 mm"):
        load_csv(write(tmp_path, text), exposure=W, pixel_size_m=100.0)


def test_unit_in_header_must_match_requested(tmp_path):
    p = write(tmp_path, good_text(unit="um"))
    with pytest.raises(
        ValueError, match=r"rec.csv, line 1: column 'x_um' is in 'um' but position_unit = 'nm'"
    ):
        load_csv(p, exposure=W, position_unit="nm")
    # (values 1.5..30 um: a 20 um std is no trapped bead, so the unit check is off here)
    assert load_csv(p, exposure=W, position_unit="µm", check_units=False).n_frames == 20


def test_unknown_unit_lists_allowed(tmp_path):
    with pytest.raises(
        ValueError, match=r"line 1: .*'furlong'.*expected one of 'm', 'mm', 'um', 'µm', 'nm', 'px'"
    ):
        load_csv(write(tmp_path, "t_s,x_furlong\n0,1\n0.001,2\n"), exposure=W)


def test_frame_interval_inferred(tmp_path):
    dt = 1 / 1500
    r = load_csv(write(tmp_path, good_text(200, dt=dt)), exposure=1e-4)
    assert r.frame_interval == pytest.approx(dt, rel=1e-12)
    assert r.metadata["frame_interval_inferred"] is True
    # time stamps rounded to microseconds: still regular enough, interval still accurate
    text = "t_s,x_nm\n" + "".join(f"{i * dt:.6f},{(-1) ** i}\n" for i in range(3000))
    r = load_csv(write(tmp_path, text), exposure=1e-4)
    assert r.frame_interval == pytest.approx(dt, rel=1e-6)


def test_inferred_interval_equal_to_exposure(tmp_path):
    """The time stamps cannot resolve an exposure a hair above the inferred interval."""
    p = write(tmp_path, good_text(50))
    r = load_csv(p, exposure=DT)
    assert r.exposure == DT and r.frame_interval == pytest.approx(DT, rel=1e-12)
    w = DT * (1 + 1e-9)
    r = load_csv(p, exposure=w)
    assert r.exposure == r.frame_interval == w
    with pytest.raises(ValueError, match="rec.csv: exposure = 0.00101 s is longer than"):
        load_csv(p, exposure=1.01e-3)


def test_no_time_column(tmp_path):
    p = write(tmp_path, "x_nm\n1\n2\n-1\n")
    assert load_csv(p, exposure=W, frame_interval=DT).times is None
    with pytest.raises(ValueError, match="rec.csv: frame_interval not given and there is no 't_s'"):
        load_csv(p, exposure=W)


def test_temperature_default_noted(tmp_path):
    p = write(tmp_path, good_text())
    r = load_csv(p, exposure=W)
    assert r.temperature == 295.0 and r.metadata["defaults_applied"] == {"temperature_K": 295.0}
    r = load_csv(p, exposure=W, temperature=300.0)
    assert r.temperature == 300.0 and "defaults_applied" not in r.metadata


@pytest.mark.parametrize("newline", ["\r\n", "\r", "\n"])
@pytest.mark.parametrize("bom", [True, False])
def test_bom_and_line_endings(tmp_path, newline, bom):
    text = good_text(newline=newline)
    p = write(tmp_path, ("\ufeff" if bom else "") + text)
    r = load_csv(p, exposure=W, frame_interval=DT)
    np.testing.assert_array_equal(r.positions, nm_to_m(expected_values()))
    np.testing.assert_array_equal(r.times, np.arange(20) * DT)


def test_trailing_blank_lines_are_not_data(tmp_path):
    r = load_csv(write(tmp_path, good_text() + "\n \n"), exposure=W)
    assert r.n_frames == 20


@pytest.mark.parametrize(
    "text, match",
    [
        ("", r"rec.csv: file is empty"),
        ("\ufeff\r\n", r"rec.csv: file is empty"),
        ("t_s,x_nm\n", r"rec.csv: no data rows after the header"),
        ("0.0,1.0\n0.001,2.0\n", r"rec.csv, line 1: found data '0.0,1.0' where the header"),
        ("time,x_nm\n0,1\n", r"rec.csv, line 1: header 'time,x_nm' has columns"),
        ("t_s,x_nm,y_nm\n0,1,1\n", r"rec.csv, line 1: header .* has columns"),
        ("t_s,pos\n0,1\n", r"rec.csv, line 1: position column 'pos' not understood"),
        ("t_s;x_nm\n0;1\n", r"rec.csv, line 1: header 't_s;x_nm' separates its columns with "
         r"semicolons; .* uses commas"),
        ("t_s\tx_nm\n0\t1\n", r"rec.csv, line 1: header .* separates its columns with tabs"),
        (
            "t_s,x_nm\n0,1\n0.001,abc\n0.002,3\n",
            r"rec.csv, line 3: non-numeric value 'abc' in column x_nm",
        ),
        ("t_s,x_nm\n0,1\n0.001,\n", r"rec.csv, line 3: non-numeric value '' in column x_nm"),
        ("t_s,x_nm\n0,1\n0.001,1_0\n", r"rec.csv, line 3: non-numeric value '1_0'"),
        (
            "t_s,x_nm\n0,1\n0.001,2,3\n",
            r"rec.csv, line 3: expected 2 field\(s\) \(t_s,x_nm\), got 3: '0.001,2,3'",
        ),
        ("t_s,x_nm\n0,1\n0.001\n", r"rec.csv, line 3: expected 2 field\(s\).*got 1"),
        ("t_s,x_nm\n0,1\n\n0.002,2\n", r"rec.csv, line 3: expected 2 field\(s\).*got 1: ''"),
        (
            "t_s,x_nm\n0,1\n0.001,NaN\n",
            r"rec.csv, line 3: non-finite value 'NaN' \(NaN/inf\) in column x_nm",
        ),
        ("t_s,x_nm\n0,1\n0.001,-inf\n", r"rec.csv, line 3: non-finite value '-inf'"),
        ("t_s,x_nm\n0,1\nnan,2\n", r"rec.csv, line 3: non-finite value 'nan' .* column t_s"),
        (
            "t_s,x_nm\n0,1\n0.001,1e999\n",
            r"rec.csv, line 3: value '1e999' in column x_nm overflows",
        ),
        (
            "t_s,x_nm\n0,1\n0.001,2\n0.001,3\n",
            r"rec.csv, line 4: time stamp t_s = '0.001' is not after the previous one "
            r"\('0.001', line 3\)",
        ),
        (
            "t_s,x_nm\n0,1\n0.002,2\n0.001,3\n",
            r"rec.csv, line 4: time stamp t_s = '0.001' is not after",
        ),
        ("t_s,x_nm\n0,1\n", r"rec.csv: .*at least 2 frames; got 1"),
        ("t_s,x_nm\n0,1\n0.001,1\n0.002,1\n", r"rec.csv: positions is constant"),
        ("t_s,x_nm\n0,1\n0.001,2\n0.003,3\n0.004,1\n", r"rec.csv: times are irregular"),
    ],
)
def test_errors_name_file_line_and_value(tmp_path, text, match):
    with pytest.raises(ValueError, match=match):
        load_csv(write(tmp_path, text), exposure=W)


def test_exposure_longer_than_frame_interval_names_file(tmp_path):
    with pytest.raises(
        ValueError, match=r"rec.csv: exposure = 0.002 s is longer than frame_interval = 0.001 s"
    ):
        load_csv(write(tmp_path, good_text()), exposure=2e-3)


def test_not_utf8(tmp_path):
    with pytest.raises(ValueError, match=r"rec.csv: not UTF-8 text"):
        load_csv(write(tmp_path, b"t_s,x_nm\n0,\xff\xfe\n"), exposure=W)


def test_bad_on_bad_rows_value(tmp_path):
    with pytest.raises(ValueError, match=r"on_bad_rows must be one of \('error', 'exclude'\)"):
        load_csv(write(tmp_path, good_text()), exposure=W, on_bad_rows="drop")


def test_exclude_accounts_for_every_dropped_row(tmp_path):
    lines = good_text(10).splitlines()
    lines[3] = "0.002,oops"  # line 4
    lines[7] = "0.006,nan"  # line 8
    lines.insert(9, "0.0075")  # new line 10: wrong field count
    lines.append("0.0085,7")  # time going backwards after line 12 (t=0.009)
    p = write(tmp_path, "\n".join(lines) + "\n")
    with pytest.raises(ValueError, match="line 4: non-numeric value 'oops'"):
        load_csv(p, exposure=W)
    with pytest.warns(
        ExcludedRowsWarning, match=r"rec.csv: excluded 4 of 12 rows \(lines \[4, 8, 10, 13\]\)"
    ):
        r = load_csv(p, exposure=W, frame_interval=DT, on_bad_rows="exclude", allow_irregular=True)
    ex = r.metadata["excluded_rows"]
    assert ex["count"] == 4 and ex["lines"] == (4, 8, 10, 13)
    assert "non-numeric" in ex["reasons"][0] and "not after" in ex["reasons"][3]
    assert r.n_frames == 12 - 4  # nothing else lost
    kept = [i for i in range(10) if i not in (2, 6)]
    np.testing.assert_array_equal(r.positions, nm_to_m(expected_values()[kept]))


def test_exclude_trailing_truncated_row_keeps_regular_timing(tmp_path):
    p = write(tmp_path, good_text(30) + "0.03")
    with pytest.warns(ExcludedRowsWarning, match="excluded 1 of 31 rows"):
        r = load_csv(p, exposure=W, on_bad_rows="exclude")
    assert r.n_frames == 30 and r.is_regular and r.metadata["excluded_rows"]["lines"] == (32,)


def test_exclude_without_bad_rows_does_not_warn(tmp_path):
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        r = load_csv(write(tmp_path, good_text()), exposure=W, on_bad_rows="exclude")
    assert "excluded_rows" not in r.metadata


def test_exclude_everything_is_an_error(tmp_path):
    with pytest.raises(ValueError, match=r"rec.csv: no data rows after the header \(2 bad row"):
        load_csv(write(tmp_path, "t_s,x_nm\na,b\nc,d\n"), exposure=W, on_bad_rows="exclude")


def test_load_dispatches_csv(tmp_path):
    r = load(write(tmp_path, good_text()), exposure=W)
    assert r.n_frames == 20
    with pytest.raises(ValueError, match=r"unknown file type '.txt'; expected one of"):
        load(tmp_path / "x.txt")


@pytest.mark.parametrize("true_nm", [0.64, 2.0, 10.0])
def test_um_values_in_an_nm_column_are_caught(tmp_path, true_nm):
    """A trace with std 0.64-10 nm written in um under an x_nm header reads as 6.4e-13 ..
    1e-11 m: an error naming the file and the slip; check_units=False keeps it."""
    x_um = np.random.default_rng(3).normal(0, true_nm * 1e-3, 200)
    text = "t_s,x_nm\n" + "".join(f"{i * DT!r},{v!r}\n" for i, v in enumerate(x_um.tolist()))
    p = write(tmp_path, text)
    with pytest.raises(
        ValueError, match=r"rec.csv: positions have standard deviation .* m, below .*"
        r"positions look like um declared as nm.*position_unit='um' or a column x_um"
    ):
        load_csv(p, exposure=W)
    assert load_csv(p, exposure=W, check_units=False).n_frames == 200


def test_metres_in_an_nm_column_are_caught(tmp_path):
    x_m = np.random.default_rng(4).normal(0, 2e-8, 200)
    text = "t_s,x_nm\n" + "".join(f"{i * DT!r},{v!r}\n" for i, v in enumerate(x_m.tolist()))
    with pytest.raises(ValueError, match=r"rec.csv: .*positions look like metres declared as nm"):
        load_csv(write(tmp_path, text), exposure=W)


@pytest.mark.parametrize("fps", [1000, 1500, 2000, 5000, 10_000])
def test_time_column_in_ms_is_caught(tmp_path, fps):
    """t_s written in ms: with the interval inferred from it, and with frame_interval given
    in seconds; both name the file and the t_s column's unit."""
    x = np.random.default_rng(1).normal(0, 20.0, 50)
    text = "t_s,x_nm\n" + "".join(f"{i * 1e3 / fps!r},{v!r}\n" for i, v in enumerate(x.tolist()))
    p = write(tmp_path, text)
    with pytest.raises(ValueError, match=r"rec.csv: frame_interval = .* s is at least 0.1 s .*"
                       r"looks like ms.*inferred from the t_s column: its time stamps look like "
                       r"milliseconds"):
        load_csv(p, exposure=1e-4)
    with pytest.raises(ValueError, match=r"rec.csv: times imply a frame interval of .*"
                       r"the times look like ms"):
        load_csv(p, exposure=1e-4, frame_interval=1 / fps)
    r = load_csv(p, exposure=1e-4, check_units=False)
    assert r.frame_interval == pytest.approx(1e3 / fps, rel=1e-9)


def test_frame_numbers_in_the_time_column_are_named(tmp_path):
    x = np.random.default_rng(1).normal(0, 20.0, 50)
    text = "t_s,x_nm\n" + "".join(f"{i},{v!r}\n" for i, v in enumerate(x.tolist()))
    with pytest.raises(ValueError, match=r"frame numbers rather than times: then give "
                       r"frame_interval"):
        load_csv(write(tmp_path, text), exposure=1e-4)


@pytest.mark.parametrize("unit", ["m", "mm", "um", "nm"])
def test_pixel_size_with_a_unit_other_than_px_is_an_error(tmp_path, unit):
    """pixel_size_m used to be ignored silently for positions not in pixels."""
    from blurtrap.data import from_arrays

    p = write(tmp_path, good_text(unit=unit))
    match = rf"pixel_size_m = 1e-07 was given but the positions are in '{unit}', not 'px'"
    with pytest.raises(ValueError, match=r"rec.csv: " + match):
        load_csv(p, exposure=W, pixel_size_m=1e-7, check_units=False)
    with pytest.raises(ValueError, match=match):
        from_arrays(np.arange(5.0), frame_interval=DT, exposure=W, position_unit=unit,
                    pixel_size_m=1e-7, check_units=False)
