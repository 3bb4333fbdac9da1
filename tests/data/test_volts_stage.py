"""Recordings in volts (``position_unit="V"``, ``x_V``) and with a driven stage's positions
(``stage=``, ``stage_nm``): validation, the unit-slip checks both ways, and the CSV, manifest
and NPZ round trips (bit-exact)."""

import json

import numpy as np
import pytest

from blurtrap.data import (
    Recording,
    RecordingSet,
    from_arrays,
    instrument_settings,
    load_csv,
    load_manifest,
    load_npz,
    save_manifest,
    save_npz,
)
from blurtrap.data._csv import write_csv

DT = 1e-4
N = 500


def bits(a):
    return np.asarray(a, dtype=np.float64).view(np.int64)


@pytest.fixture
def volts():
    return np.random.default_rng(3).normal(0, 0.25, N)  # a QPD signal: ~0.25 V std


@pytest.fixture
def stage():
    t = np.arange(N) * DT
    return 150e-9 * np.sin(2 * np.pi * 32 * t) + np.random.default_rng(4).normal(0, 1e-10, N)


def vrec(x, **kw):
    return Recording(x, frame_interval=DT, exposure=DT, position_unit="V", **kw)


# -- volts --------------------------------------------------------------------------------------


@pytest.mark.parametrize("std", [1e-6, 1e-3, 0.3, 8.0])
def test_volts_with_volt_scale_stds_are_accepted(std):
    x = np.random.default_rng(0).normal(0, std, N)
    r = vrec(x)
    assert r.position_unit == "V" and r.metadata["position_unit"] == "V"
    assert bits(r.positions).tolist() == bits(x).tolist()  # kept in volts, not converted
    # the metadata spelling is the same thing
    assert Recording(x, frame_interval=DT, exposure=DT, metadata={"position_unit": "V"}) == r


@pytest.mark.parametrize(
    "std, match",
    [
        (2e-8, r"standard deviation [0-9.]+e-08 V, below 1e-07 V.*positions in metres declared as volts"),
        (1e-10, r"below 1e-07 V.*position_unit='m'"),
        (500.0, r"above 100 V.*nm, pixels or mV declared as volts"),
    ],
)
def test_metre_scale_values_declared_as_volts_are_rejected(std, match):
    x = np.random.default_rng(1).normal(0, std, N)
    with pytest.raises(ValueError, match=match):
        vrec(x)
    assert vrec(x, check_units=False).position_unit == "V"


def test_volts_declared_as_metres_are_rejected_with_the_volts_hint(volts):
    with pytest.raises(ValueError, match=r"0\.2.* m, above 1e-05 m.*not metres \(or a detector "
                       r"signal in volts: declare position_unit='V'\)"):
        Recording(volts, frame_interval=DT, exposure=DT)


def test_metre_recordings_say_m(volts):
    r = Recording(volts * 1e-7, frame_interval=DT, exposure=DT)
    assert r.position_unit == "m" and "position_unit" not in r.metadata
    r = from_arrays(volts * 100, frame_interval=DT, exposure=DT, position_unit="nm")
    assert r.position_unit == "m" and r.metadata["position_unit"] == "nm"


def test_position_unit_argument_is_checked(volts):
    with pytest.raises(ValueError, match=r"position_unit must be 'm' .* or 'V' .*; got 'nm'"):
        Recording(volts * 1e-7, frame_interval=DT, exposure=DT, position_unit="nm")
    with pytest.raises(ValueError, match=r"position_unit = 'm' but metadata\['position_unit'\] = 'V'"):
        Recording(volts, frame_interval=DT, exposure=DT, position_unit="m",
                  metadata={"position_unit": "V"})
    with pytest.raises(ValueError, match=r"position_unit = 'V' but metadata\['position_unit'\] = 'nm'"):
        vrec(volts, metadata={"position_unit": "nm"})


def test_from_arrays_in_volts(volts):
    r = from_arrays(volts, frame_interval=DT, exposure=DT, position_unit="V")
    assert r.position_unit == "V" and bits(r.positions).tolist() == bits(volts).tolist()
    two = from_arrays(np.stack([volts, -volts]), frame_interval=DT, exposure=DT, position_unit="volts")
    assert [x.position_unit for x in two] == ["V", "V"]


def test_replace_keeps_volts_and_stage(volts, stage):
    r = vrec(volts, stage=stage, name="a")
    r2 = r.replace(metadata={"note": 1})
    assert r2.position_unit == "V" and r2.stage is r2.stage and np.array_equal(r2.stage, stage)
    assert r.replace(name="b").position_unit == "V"
    assert r.replace(stage=None).stage is None
    assert "position_unit='V'" in repr(r) and "stage=yes" in repr(r)
    assert "stage" not in repr(r.replace(stage=None))


# -- stage --------------------------------------------------------------------------------------


def test_stage_is_stored_read_only_and_compared(volts, stage):
    r = vrec(volts, stage=stage)
    assert bits(r.stage).tolist() == bits(stage).tolist()
    with pytest.raises(ValueError):
        r.stage[0] = 1.0
    assert vrec(volts).stage is None
    assert r != vrec(volts) and r != vrec(volts, stage=stage + 1e-9)
    assert r == vrec(volts, stage=stage.copy())
    assert vrec(volts, stage=list(stage.astype(np.float32))).stage.dtype == np.float64


@pytest.mark.parametrize(
    "bad, match",
    [
        (np.zeros(N - 1), r"stage must be a 1-D array with one stage position per frame \(500\)"),
        (np.zeros((N, 1)), r"one stage position per frame \(500\) \[m\]; got shape \(500, 1\)"),
        (np.r_[np.zeros(N - 1), np.nan], r"stage contains 1 non-finite.*stage\[499\] = nan"),
        (np.array(["1"] * N), r"stage must be numeric \[m\]; got text"),
        (np.linspace(-500, 500, N), r"stage has standard deviation .* above 0.0001 m.*look like nm or um"),
    ],
)
def test_invalid_stage_is_rejected(volts, bad, match):
    with pytest.raises(ValueError, match=match):
        vrec(volts, stage=bad)


# -- CSV ----------------------------------------------------------------------------------------


@pytest.mark.parametrize("unit", ["nm", "um", "m"])
def test_csv_stage_column_round_trip_is_bit_exact(tmp_path, volts, stage, unit):
    r = Recording(volts * 3e-8, frame_interval=DT, exposure=DT, stage=stage, times=np.arange(N) * DT)
    p = tmp_path / "s.csv"
    write_csv(r, p, unit)
    assert p.read_text().splitlines()[0] == f"t_s,x_{unit},stage_nm"
    back = load_csv(p, exposure=DT, frame_interval=DT)
    assert bits(back.stage).tolist() == bits(stage).tolist()
    assert bits(back.positions).tolist() == bits(r.positions).tolist()


@pytest.mark.parametrize("col, scale", [("stage_nm", 1e-9), ("stage_um", 1e-6), ("stage_m", 1.0)])
def test_csv_stage_units(tmp_path, col, scale):
    # the line-by-line path (exponents in the stage cells) and the vectorised one agree
    rows = [f"{i * DT!r},{(-1) ** i * 10 + i * 0.01},{0.25 * (i % 7)}" for i in range(N)]
    p, q = tmp_path / "a.csv", tmp_path / "b.csv"
    p.write_text(f"t_s,x_nm,{col}\n" + "\n".join(rows) + "\n")
    q.write_text(f"t_s,x_nm,{col}\n" + "\n".join(r.rsplit(",", 1)[0] + "," +
                 f"{float(r.rsplit(',', 1)[1]) * 10:g}E-1" for r in rows) + "\n")
    a = load_csv(p, exposure=DT, frame_interval=DT, check_units=False)
    b = load_csv(q, exposure=DT, frame_interval=DT, check_units=False)
    want = np.array([float(f"{0.25 * (i % 7)}e0") * scale for i in range(N)])
    np.testing.assert_allclose(a.stage, want, rtol=1e-15)
    assert bits(a.stage).tolist() == bits(b.stage).tolist()
    assert bits(a.positions).tolist() == bits(b.positions).tolist()


@pytest.mark.parametrize(
    "header, match",
    [
        ("t_s,x_nm,stage_px", r"stage column 'stage_px' must name a length unit"),
        ("t_s,x_nm,stage_V", r"stage column 'stage_V' must name a length unit"),
        ("t_s,x_nm,y_nm", r"header .* has columns \['t_s', 'x_nm', 'y_nm'\]"),
        ("t_s,stage_nm,x_nm", r"header .* has columns \['t_s', 'stage_nm', 'x_nm'\]"),
        ("stage_nm", r"position column 'stage_nm' not understood"),
    ],
)
def test_csv_bad_stage_headers(tmp_path, header, match):
    p = tmp_path / "a.csv"
    p.write_text(header + "\n0,1,2\n0.0001,2,3\n")
    with pytest.raises(ValueError, match=r"a.csv, line 1: " + match):
        load_csv(p, exposure=DT, frame_interval=DT)


def test_csv_in_volts(tmp_path, volts):
    r = vrec(volts)
    p = tmp_path / "v.csv"
    write_csv(r, p, "V")
    assert p.read_text().startswith("t_s,x_V\n")
    back = load_csv(p, exposure=DT)
    assert back.position_unit == "V" and bits(back.positions).tolist() == bits(volts).tolist()
    with pytest.raises(ValueError, match=r"position_unit = 'nm' but the recording's positions are in volts"):
        write_csv(r, p, "nm")
    with pytest.raises(ValueError, match=r"position_unit = 'V' but the recording's positions are in metres"):
        write_csv(r.replace(positions=volts * 1e-7, metadata={}, position_unit="m"), p, "V")


@pytest.mark.parametrize("unit, column", [("nm", "x_V"), ("V", "x_nm"), ("um", "x_V"), ("V", "x_m")])
def test_manifest_header_unit_mismatch_is_an_error(tmp_path, unit, column):
    (tmp_path / "a.csv").write_text(f"t_s,{column}\n0,0.5\n0.0001,-0.25\n0.0002,0.1\n")
    (tmp_path / "m.json").write_text(json.dumps(
        {"position_unit": unit, "recordings": [{"file": "a.csv", "exposure_s": DT}]}))
    with pytest.raises(ValueError, match=rf"a.csv, line 1: column '{column}' is in .* but "
                       rf"position_unit = '{unit}' was given; they must agree"):
        load_manifest(tmp_path / "m.json")


# -- manifest and NPZ round trips ---------------------------------------------------------------


def test_manifest_round_trip_with_volts_stage_and_instrument_keys(tmp_path, volts, stage):
    meta = {"detector": "photodiode", "drive": {"frequency_Hz": 32.0}, "bead_radius_m": 5e-7,
            "friction": "stokes", "fit_range_Hz": [10.0, 4000.0], "note": "kept"}
    r = vrec(volts, stage=stage, name="drive", metadata=meta, times=np.arange(N) * DT)
    save_manifest(r, tmp_path / "m.json")  # volts: position_unit V by default
    doc = json.loads((tmp_path / "m.json").read_text())
    entry = doc["recordings"][0]
    assert doc["position_unit"] == "V"
    assert entry["drive"] == {"frequency_Hz": 32.0} and entry["metadata"] == {"note": "kept"}
    back = load_manifest(tmp_path / "m.json")[0]
    assert back.position_unit == "V"
    assert bits(back.positions).tolist() == bits(volts).tolist()
    assert bits(back.stage).tolist() == bits(stage).tolist()
    assert instrument_settings(back) == instrument_settings(r)
    assert back.metadata["note"] == "kept"


def test_save_manifest_refuses_mixed_units(tmp_path, volts):
    v, m = vrec(volts, name="v"), Recording(volts * 1e-7, frame_interval=DT, exposure=DT, name="m")
    with pytest.raises(ValueError, match=r"some recordings are in volts and others in metres"):
        save_manifest(RecordingSet([v, m]), tmp_path / "m.json")
    with pytest.raises(ValueError, match=r"position_unit = 'nm' but the recordings are in volts"):
        save_manifest(v, tmp_path / "m.json", "nm")
    with pytest.raises(ValueError, match=r"position_unit = 'V' but the recordings are in metres"):
        save_manifest(m, tmp_path / "m.json", "V")
    save_manifest(m, tmp_path / "m.json")
    assert json.loads((tmp_path / "m.json").read_text())["position_unit"] == "nm"


def test_npz_round_trip_with_stage_and_volts(tmp_path, volts, stage):
    s = RecordingSet([vrec(volts, stage=stage, name="a", metadata={"drive": {"frequency_Hz": 32}}),
                      Recording(volts * 1e-7, frame_interval=DT, exposure=DT, name="b")])
    save_npz(s, tmp_path / "s.npz")
    back = load_npz(tmp_path / "s.npz")
    assert back == s
    assert back[0].position_unit == "V" and back[1].position_unit == "m" and back[1].stage is None
    assert bits(back[0].stage).tolist() == bits(stage).tolist()


def test_npz_without_stage_entries_still_loads(tmp_path, volts):
    """Files written before stages were stored have no 'has_stage' in their header."""
    r = Recording(volts * 1e-7, frame_interval=DT, exposure=DT)
    save_npz(r, tmp_path / "r.npz")
    with np.load(tmp_path / "r.npz") as z:
        data = {k: z[k] for k in z.files}
    header = json.loads(str(data["__blurtrap__"]))
    del header["recordings"][0]["has_stage"]
    data["__blurtrap__"] = np.array(json.dumps(header))
    np.savez(tmp_path / "old.npz", **data)
    assert load_npz(tmp_path / "old.npz") == r
    header["recordings"][0]["has_stage"] = True  # promised but missing: an error
    data["__blurtrap__"] = np.array(json.dumps(header))
    np.savez(tmp_path / "bad.npz", **data)
    with pytest.raises(ValueError, match=r"array\(s\) \['stage_0'\] missing"):
        load_npz(tmp_path / "bad.npz")
