"""x/y recordings: CSV loading (nm, px, V), validation, projection and rotation."""

import math

import numpy as np
import pytest

from blurtrap.data import XYRecording, load_xy_csv, write_xy_csv, xy_from_arrays

DT, W = 5e-4, 4e-4


def _arrays(n=200, seed=0):
    rng = np.random.default_rng(seed)
    return rng.normal(0, 20e-9, n), rng.normal(0, 10e-9, n)


def _write(path, header, rows):
    path.write_text(header + "\n" + "\n".join(rows) + "\n")
    return path


def test_round_trip_nm(tmp_path):
    x, y = _arrays()
    xy = xy_from_arrays(x, y, frame_interval=DT, exposure=W)
    write_xy_csv(xy, tmp_path / "a.csv")
    assert (tmp_path / "a.csv").read_text().startswith("t_s,x_nm,y_nm\n")
    back = load_xy_csv(tmp_path / "a.csv", exposure=W)
    np.testing.assert_allclose(back.x.positions, x, rtol=1e-14)
    np.testing.assert_allclose(back.y.positions, y, rtol=1e-14)
    assert back.frame_interval == pytest.approx(DT, rel=1e-9)
    assert back.metadata["position_unit"] == "nm"
    assert back.positions.shape == (200, 2)


def test_pixels_and_volts(tmp_path):
    rows = [f"{i * DT!r},{10 + (i % 7) * 0.3},{5 - (i % 5) * 0.2}" for i in range(50)]
    p = _write(tmp_path / "px.csv", "t_s,x_px,y_px", rows)
    xy = load_xy_csv(p, exposure=W, pixel_size_m=100e-9)
    assert xy.x.positions[1] == pytest.approx(10.3 * 100e-9, rel=1e-12)
    assert xy.y.positions[1] == pytest.approx(4.8 * 100e-9, rel=1e-12)
    with pytest.raises(ValueError, match="pixel"):
        load_xy_csv(p, exposure=W)
    rows = [f"{i * DT!r},{0.1 * math.sin(i)},{0.05 * math.cos(i)}" for i in range(50)]
    v = load_xy_csv(_write(tmp_path / "v.csv", "t_s,x_V,y_V", rows), exposure=W)
    assert v.position_unit == "V" and v.y.position_unit == "V"


def test_missing_y_column(tmp_path):
    p = _write(tmp_path / "x.csv", "t_s,x_nm", ["0,1", "0.0005,2"])
    with pytest.raises(ValueError, match=r"x\.csv, line 1: .*has no y column"):
        load_xy_csv(p, exposure=W)


def test_header_errors(tmp_path):
    p = _write(tmp_path / "u.csv", "t_s,x_nm,y_um", ["0,1,2", "0.0005,2,3"])
    with pytest.raises(ValueError, match="different units"):
        load_xy_csv(p, exposure=W)
    p = _write(tmp_path / "z.csv", "t_s,x_nm,z_nm", ["0,1,2", "0.0005,2,3"])
    with pytest.raises(ValueError, match="expected 't_s,x_<unit>,y_<unit>'"):
        load_xy_csv(p, exposure=W)
    p = _write(tmp_path / "w.csv", "t_s,x_nm,y_nm", ["0,1,2", "0.0005,2,3"])
    with pytest.raises(ValueError, match="position_unit = 'um'"):
        load_xy_csv(p, exposure=W, position_unit="um")


def test_bad_rows_name_the_line(tmp_path):
    rows = [f"{i * DT!r},{i % 3 + 1},{i % 4 + 1}" for i in range(20)]
    rows[6] = f"{6 * DT!r},3"  # a missing y cell: line 8 (header is line 1)
    p = _write(tmp_path / "b.csv", "t_s,x_nm,y_nm", rows)
    with pytest.raises(ValueError, match=r"b\.csv, line 8: expected 3 field"):
        load_xy_csv(p, exposure=W)
    rows[6] = f"{6 * DT!r},3,nan"
    p = _write(tmp_path / "n.csv", "t_s,x_nm,y_nm", rows)
    with pytest.raises(ValueError, match=r"line 8: non-finite value 'nan' .* in column y_nm"):
        load_xy_csv(p, exposure=W)


def test_unequal_lengths_and_mismatch():
    x, y = _arrays()
    with pytest.raises(ValueError, match=r"same length; got len\(x\) = 200 and len\(y\) = 199"):
        xy_from_arrays(x, y[:-1], frame_interval=DT, exposure=W)
    a = xy_from_arrays(x, y, frame_interval=DT, exposure=W)
    b = xy_from_arrays(x, y, frame_interval=DT, exposure=W / 2)
    with pytest.raises(ValueError, match="share exposure"):
        XYRecording(a.x, b.y)
    with pytest.raises(TypeError, match="y must be a Recording"):
        XYRecording(a.x, y)
    with pytest.raises(ValueError, match=r"\(n_frames, 2\)"):
        xy_from_arrays(x, None, frame_interval=DT, exposure=W)
    two = xy_from_arrays(np.stack([x, y], axis=1), None, frame_interval=DT, exposure=W)
    np.testing.assert_array_equal(two.positions, a.positions)


def test_project_and_rotate_against_rotation_matrix():
    x, y = _arrays()
    xy = xy_from_arrays(x, y, frame_interval=DT, exposure=W, name="bead")
    ang = 0.7
    rot = np.array([[math.cos(ang), -math.sin(ang)], [math.sin(ang), math.cos(ang)]])
    np.testing.assert_allclose(xy.rotated(ang).positions, xy.positions @ rot.T, rtol=1e-13)
    u, v = xy.project(ang)
    # the coordinates along the rotated axes: R^T (x, y)
    np.testing.assert_allclose(np.stack([u.positions, v.positions], 1), xy.positions @ rot,
                               rtol=1e-13, atol=1e-24)
    assert u.metadata["axis_angle_rad"] == ang and u.name == "bead:axis1"
    with pytest.raises(AttributeError):
        xy.x = None
