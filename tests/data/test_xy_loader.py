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


# --- bt.load routing and manifests --------------------------------------------------------


def test_load_routes_by_header(tmp_path):
    import blurtrap as bt
    from blurtrap.data import holds_xy
    from blurtrap.data._csv import write_csv

    x, y = _arrays()
    xy = xy_from_arrays(x, y, frame_interval=DT, exposure=W)
    write_xy_csv(xy, tmp_path / "xy.csv")
    got = bt.load(tmp_path / "xy.csv", exposure=W)
    assert isinstance(got, XYRecording)
    np.testing.assert_allclose(got.positions, xy.positions, rtol=1e-14)
    write_csv(xy.x, tmp_path / "x.csv")  # one column: still a single trace
    one = bt.load(tmp_path / "x.csv", exposure=W)
    assert not isinstance(one, XYRecording) and one.n_frames == 200
    assert holds_xy(tmp_path / "xy.csv") and not holds_xy(tmp_path / "x.csv")
    # an x column followed by something else than y_ is not routed (load_csv names it)
    p = _write(tmp_path / "z.csv", "t_s,x_nm,z_nm", ["0,1,2", "0.0005,2,3"])
    with pytest.raises(ValueError, match=r"z\.csv, line 1: header"):
        bt.load(p, exposure=W)


def _xy_set(n=2):
    out = []
    for i in range(n):
        x, y = _arrays(seed=i)
        out.append(xy_from_arrays(x, y, frame_interval=DT, exposure=W * (i + 1) / 2,
                                  temperature=290.0 + i, name=f"bead{i}",
                                  laser_power=0.05 * (i + 1)))
    return out


def test_manifest_round_trip(tmp_path):
    import json

    import blurtrap as bt
    from blurtrap.data import holds_xy, load_manifest, save_manifest

    items = _xy_set()
    written = save_manifest(items, tmp_path / "m.json")
    doc = json.loads(written[0].read_text())
    assert [e["axes"] for e in doc["recordings"]] == ["xy", "xy"]
    assert written[1].read_text().startswith("t_s,x_nm,y_nm\n")
    back = load_manifest(tmp_path / "m.json")
    assert isinstance(back, list) and len(back) == 2 and holds_xy(tmp_path / "m.json")
    for a, b in zip(items, back, strict=True):
        assert isinstance(b, XYRecording) and b.name == a.name
        np.testing.assert_allclose(b.positions, a.positions, rtol=1e-14)
        assert (b.frame_interval, b.exposure, b.temperature) == (
            a.frame_interval, a.exposure, a.temperature)
        assert b.x.laser_power == a.x.laser_power and b.y.laser_power == a.x.laser_power
    # without the 'axes' key the CSV's header decides; bt.load goes through the manifest
    for e in doc["recordings"]:
        del e["axes"]
    (tmp_path / "m.json").write_text(json.dumps(doc))
    again = bt.load(tmp_path / "m.json")
    np.testing.assert_array_equal(again[1].positions, back[1].positions)
    # a single XYRecording and volts
    x, y = _arrays()
    v = xy_from_arrays(x * 1e7, y * 1e7, frame_interval=DT, exposure=W, position_unit="V",
                       name="v")
    save_manifest(v, tmp_path / "v.json")
    (vb,) = load_manifest(tmp_path / "v.json")
    assert vb.position_unit == "V"
    np.testing.assert_allclose(vb.positions, v.positions, rtol=1e-14)


def _manifest(tmp_path, entry_extra, header="t_s,x_nm,y_nm", top=None):
    import json

    rows = [f"{i * DT!r},{i % 3 + 1},{i % 4 + 1}" for i in range(20)]
    _write(tmp_path / "a.csv", header, rows)
    entry = {"file": "a.csv", "exposure_s": W, **entry_extra}
    doc = {"position_unit": "nm", "recordings": [entry], **(top or {})}
    (tmp_path / "m.json").write_text(json.dumps(doc))
    return tmp_path / "m.json"


@pytest.mark.parametrize("axes, header, message", [
    ("z", "t_s,x_nm,y_nm", r"recordings\[0\] \(a\.csv\): 'axes' must be one of \['x', 'xy'\].*"
                           r"got 'z'"),
    (2, "t_s,x_nm,y_nm", r"'axes' must be one of .*got 2"),
    ("x", "t_s,x_nm,y_nm", r"'axes' is \"x\" but the CSV's header has a y column"),
    ("xy", "t_s,x_nm", r"recordings\[0\]: .*a\.csv, line 1: .*has no y column"),
])
def test_bad_axes_entries(tmp_path, axes, header, message):
    from blurtrap.data import load_manifest

    with pytest.raises(ValueError, match=message):
        load_manifest(_manifest(tmp_path, {"axes": axes}, header))


def test_xy_entry_errors_name_the_entry(tmp_path):
    import json

    from blurtrap.data import load_manifest, save_manifest

    # a drive needs a stage column, which an x/y CSV does not have
    with pytest.raises(ValueError, match=r"recordings\[0\].*drive.*stage"):
        load_manifest(_manifest(tmp_path, {"drive": {"frequency_Hz": 32.0}}))
    # a bad row: the manifest, the file and the line
    p = _manifest(tmp_path, {})
    (tmp_path / "a.csv").write_text("t_s,x_nm,y_nm\n0,1,2\n0.0005,2\n")
    with pytest.raises(ValueError, match=r"m\.json, recordings\[0\]: .*a\.csv, line 3"):
        load_manifest(p)
    (tmp_path / "a.csv").write_text("t_s,x_nm,y_nm\n0,1,2\n0.0005,2\n0.001,3,4\n")
    (kept,) = load_manifest(p, on_bad_rows="exclude")  # dropped from both axes, reported
    np.testing.assert_allclose(kept.positions, [[1e-9, 2e-9], [3e-9, 4e-9]], rtol=1e-15)
    assert list(kept.metadata["excluded_rows"]["lines"]) == [3]
    # one manifest, one kind
    one = xy_from_arrays(*_arrays(), frame_interval=DT, exposure=W, name="xy")
    save_manifest([one], tmp_path / "k.json")
    doc = json.loads((tmp_path / "k.json").read_text())
    _write(tmp_path / "single.csv", "t_s,x_nm", [f"{i * DT!r},{i % 3}" for i in range(20)])
    doc["recordings"].append({"file": "single.csv", "exposure_s": W})
    (tmp_path / "k.json").write_text(json.dumps(doc))
    with pytest.raises(ValueError, match=r"recordings\[0\] is an x/y recording but "
                                         r"recordings\[1\] is a single trace"):
        load_manifest(tmp_path / "k.json")
    with pytest.raises(TypeError, match="item 1 is a Recording among x/y recordings"):
        save_manifest([one, one.x], tmp_path / "mixed.json")
