"""Instrument files: Lumicks Bluelake HDF5, plain HDF5 datasets, LabVIEW TDMS, and the
``load`` dispatcher. h5py and npTDMS are optional: tests that write such files skip without
them (the ``test`` extra installs both).

The Bluelake files are written in the layout that pylake reads and its own tests write
(lumicks/pylake, ``lumicks/pylake/tests/data/mock_file.py``, MockDataFile_v2, and
``lumicks/pylake/channel.py``): root attributes ``Bluelake version`` and ``File format
version``; continuous channels are float datasets with attributes ``Start time (ns)``,
``Stop time (ns)``, ``Sample rate (Hz)`` and ``Kind = "Continuous"``; timeline channels are
compound ``(Timestamp int64 [ns], Value float64)`` arrays with ``Kind = b"TimeSeries"``;
calibration items are groups ``Calibration/<n>/<channel name>`` with attributes such as
``Rf (pN/V)`` and ``Offset (pN)``.
"""

import subprocess
import sys

import numpy as np
import pytest

import blurtrap as bt
from blurtrap.data import load, load_bluelake, load_h5, load_tdms

RATE = 78125.0  # Hz, a Bluelake high-frequency rate (dt = 12800 ns exactly)
RF = 250.0  # pN/V
OFFSET = 3.0  # pN
SENS = 1.5e-7  # m/V


@pytest.fixture
def h5py():
    return pytest.importorskip("h5py")


@pytest.fixture
def nptdms():
    return pytest.importorskip("nptdms")


def volts_supported():
    try:
        bt.data._units.canonical_unit("V")
    except ValueError:
        return False
    return True


def write_bluelake(h5py, path, volts, *, timeline=None, extra=None):
    """A Bluelake-layout file (see the module docstring) holding Force HF/Force 1x =
    RF * volts + OFFSET [pN], one calibration item, and optionally a timeline channel."""
    dt_ns = int(round(1e9 / RATE))
    with h5py.File(path, "w") as f:
        f.attrs["Bluelake version"] = "2.6.0"
        f.attrs["File format version"] = 2
        f.attrs["Experiment"] = "blurtrap test"
        f.attrs["Description"] = ""
        f.attrs["GUID"] = "{00000000-0000-0000-0000-000000000000}"
        f.attrs["Export time (ns)"] = 1_700_000_000_000_000_000
        g = f.create_group("Force HF")
        g["Force 1x"] = RF * volts + OFFSET
        d = g["Force 1x"]
        start = 1_700_000_000_000_000_000
        d.attrs["Start time (ns)"] = start
        d.attrs["Stop time (ns)"] = start + len(volts) * dt_ns
        d.attrs["Sample rate (Hz)"] = 1 / dt_ns * 1e9
        d.attrs["Kind"] = "Continuous"
        cal = f.create_group("Calibration").create_group("1").create_group("Force 1x")
        cal.attrs["Rf (pN/V)"] = RF
        cal.attrs["Offset (pN)"] = OFFSET
        cal.attrs["Kind"] = "Full calibration"
        tags = f.create_group("Photon Time Tags")
        tags["Red"] = np.arange(0, 1000, 7, dtype=np.int64) + start
        tags["Red"].attrs["Kind"] = "TimeTags"
        if timeline is not None:
            group, name, stamps, values = timeline
            compound = np.dtype([("Timestamp", np.int64), ("Value", float)])
            grp = f.require_group(group)
            grp[name] = np.array(list(zip(stamps, values)), compound)
            grp[name].attrs["Kind"] = b"TimeSeries"
        if extra:
            extra(f)


@pytest.fixture
def volts(rng):
    return rng.normal(0.0, 0.4, 4096)


# -- Bluelake -----------------------------------------------------------------------------


def test_bluelake_force_channel_to_positions(h5py, tmp_path, volts):
    p = tmp_path / "trap.h5"
    write_bluelake(h5py, p, volts)
    rec = load_bluelake(
        p, force_sensitivity_pN_per_V=RF, force_offset_pN=OFFSET, displacement_sensitivity_m_per_V=SENS
    )
    assert isinstance(rec, bt.Recording)
    assert rec.n_frames == volts.size
    assert rec.frame_interval == 1 / RATE
    assert rec.exposure == rec.frame_interval  # integrating ADC by default
    assert rec.times is None
    forces = RF * volts + OFFSET
    np.testing.assert_array_equal(rec.positions, (forces - OFFSET) / RF * SENS)
    np.testing.assert_allclose(rec.positions, volts * SENS, rtol=1e-12, atol=1e-22)
    m = rec.metadata
    assert m["channel"] == "Force HF/Force 1x" and m["source"] == str(p)
    assert m["detector"] == "photodiode"
    assert m["sample_rate_Hz"] == RATE
    assert m["start_time_ns"] == 1_700_000_000_000_000_000
    assert m["force_sensitivity_pN_per_V"] == RF and m["force_offset_pN"] == OFFSET
    assert m["displacement_sensitivity_m_per_V"] == SENS and m["signal_unit"] == "V"
    assert m["defaults_applied"]["exposure_s"] == 1 / RATE
    assert m["defaults_applied"]["temperature_K"] == 295.0


def test_bluelake_exposure_and_recording_keywords(h5py, tmp_path, volts):
    p = tmp_path / "trap.h5"
    write_bluelake(h5py, p, volts)
    rec = load_bluelake(
        p,
        force_sensitivity_pN_per_V=RF,
        displacement_sensitivity_m_per_V=SENS,
        exposure=5e-6,
        temperature=300.0,
        name="bead 1",
        metadata={"note": "x"},
    )
    assert rec.exposure == 5e-6 and rec.temperature == 300.0 and rec.name == "bead 1"
    assert "defaults_applied" not in rec.metadata and rec.metadata["note"] == "x"
    with pytest.raises(ValueError, match=r"trap\.h5, channel 'Force HF/Force 1x': exposure = .* longer"):
        load_bluelake(p, force_sensitivity_pN_per_V=RF, displacement_sensitivity_m_per_V=SENS, exposure=1e-4)


def test_bluelake_force_channel_needs_the_force_sensitivity(h5py, tmp_path, volts):
    p = tmp_path / "trap.h5"
    write_bluelake(h5py, p, volts)
    with pytest.raises(ValueError, match=r"in pN.*force_sensitivity_pN_per_V.*1: Rf = 250\.0 pN/V, offset = 3\.0"):
        load_bluelake(p, displacement_sensitivity_m_per_V=SENS)
    with pytest.raises(ValueError, match=r"position_unit must be 'V', not 'nm'"):
        load_bluelake(p, force_sensitivity_pN_per_V=RF, position_unit="nm")
    with pytest.raises(ValueError, match=r"force_sensitivity_pN_per_V must be finite and > 0"):
        load_bluelake(p, force_sensitivity_pN_per_V=-1.0, displacement_sensitivity_m_per_V=SENS)


def test_bluelake_volts_need_a_displacement_sensitivity(h5py, tmp_path, volts):
    p = tmp_path / "trap.h5"
    write_bluelake(h5py, p, volts)
    # without a displacement sensitivity the signal stays in volts (a photodiode recording)
    assert volts_supported()
    rec = load_bluelake(p, force_sensitivity_pN_per_V=RF, force_offset_pN=OFFSET)
    assert rec.n_frames == volts.size and rec.position_unit == "V"
    np.testing.assert_allclose(rec.positions, volts, rtol=1e-12, atol=1e-12)
    assert bt.data.instrument_settings(rec)["detector"] == "photodiode"
    # and converted with one, in metres
    conv = load_bluelake(p, force_sensitivity_pN_per_V=RF, force_offset_pN=OFFSET,
                         displacement_sensitivity_m_per_V=SENS)
    assert conv.position_unit == "m"
    with pytest.raises(ValueError, match=r"larger than 1 mm/V: this looks like nm/V"):
        load_bluelake(p, force_sensitivity_pN_per_V=RF, displacement_sensitivity_m_per_V=150.0)


def test_bluelake_timeline_channel(h5py, tmp_path, volts, rng):
    n = 500
    start = 1_700_000_000_000_000_000
    stamps = start + np.arange(n, dtype=np.int64) * 1_000_000  # 1 kHz
    distance_um = 2.5 + rng.normal(0.0, 0.01, n)
    p = tmp_path / "trap.h5"
    write_bluelake(h5py, p, volts, timeline=("Distance", "Distance 1", stamps, distance_um))
    with pytest.raises(ValueError, match=r"'Distance/Distance 1': exposure not given"):
        load_bluelake(p, "Distance/Distance 1", position_unit="um")  # a camera: unknown shutter
    rec = load_bluelake(p, "Distance/Distance 1", position_unit="um", exposure=2e-4)
    assert rec.n_frames == n
    np.testing.assert_array_equal(rec.times, np.arange(n) / 1e3)  # correctly rounded
    assert rec.frame_interval == pytest.approx(1e-3, rel=1e-12)
    assert rec.exposure == 2e-4 and "detector" not in rec.metadata
    with pytest.raises(ValueError, match=r"not a Force channel .*would be ignored"):
        load_bluelake(p, "Distance/Distance 1", position_unit="um", exposure=2e-4, force_sensitivity_pN_per_V=RF)
    np.testing.assert_array_equal(rec.positions, distance_um / 1e6)
    assert rec.metadata["position_unit"] == "um"
    assert rec.metadata["start_time_ns"] == start and rec.metadata["frame_interval_inferred"]


def test_bluelake_force_timeline_channel(h5py, tmp_path, volts):
    """Force LF: the high-frequency force averaged over each interval (exposure = interval)."""
    n = 256
    stamps = 10**18 + np.arange(n, dtype=np.int64) * 2_000_000  # 500 Hz
    lf_volts = volts[:n] / 8
    p = tmp_path / "trap.h5"
    write_bluelake(h5py, p, volts, timeline=("Force LF", "Force 1x", stamps, RF * lf_volts + OFFSET))
    rec = load_bluelake(
        p, "Force LF/Force 1x", force_sensitivity_pN_per_V=RF, force_offset_pN=OFFSET,
        displacement_sensitivity_m_per_V=SENS,
    )
    assert rec.frame_interval == pytest.approx(2e-3, rel=1e-12) and rec.exposure == rec.frame_interval
    np.testing.assert_allclose(rec.positions, lf_volts * SENS, rtol=1e-12, atol=1e-22)
    assert rec.metadata["detector"] == "photodiode"
    assert rec.metadata["defaults_applied"]["exposure_s"] == rec.frame_interval


def test_bluelake_timeline_with_a_repeated_time_stamp(h5py, tmp_path, volts):
    stamps = 10**18 + np.arange(50, dtype=np.int64) * 1_000_000
    stamps[20] = stamps[19]
    p = tmp_path / "trap.h5"
    write_bluelake(h5py, p, volts, timeline=("Distance", "Distance 1", stamps, np.linspace(2, 3, 50)))
    with pytest.raises(ValueError, match=r"'Distance/Distance 1': Timestamp must increase strictly; Timestamp\[20\]"):
        load_bluelake(p, "Distance/Distance 1", position_unit="um", exposure=1e-4)


def test_bluelake_missing_channel_lists_the_channels(h5py, tmp_path, volts):
    p = tmp_path / "trap.h5"
    stamps = 10**18 + np.arange(50, dtype=np.int64) * 1_000_000
    write_bluelake(h5py, p, volts, timeline=("Force LF", "Force 1x", stamps, np.zeros(50)))
    with pytest.raises(ValueError, match=r"'Force HF/Force 2x': not in the file; the channels present are "
                       r"\['Force HF/Force 1x', 'Force LF/Force 1x'\]") as e:
        load_bluelake(p, "Force HF/Force 2x")
    assert str(p) in str(e.value)
    with pytest.raises(ValueError, match=r"'Force HF': a group, not a dataset"):
        load_bluelake(p, "Force HF")
    with pytest.raises(ValueError, match=r"photon time tags.*\['Force HF/Force 1x', 'Force LF/Force 1x'\]"):
        load_bluelake(p, "Photon Time Tags/Red")
    # a dataset without Kind or Sample rate (pylake refuses direct access to these too)
    p2 = tmp_path / "other.h5"
    write_bluelake(h5py, p2, volts, extra=lambda f: f.create_dataset("Info/notes", data=np.arange(3.0)))
    with pytest.raises(ValueError, match=r"'Info/notes': not a Bluelake signal channel \(no 'Kind'"):
        load_bluelake(p2, "Info/notes")


def test_bluelake_nan_names_the_index(h5py, tmp_path, volts):
    bad = volts.copy()
    bad[17] = np.nan
    p = tmp_path / "trap.h5"
    write_bluelake(h5py, p, bad)
    with pytest.raises(ValueError, match=(
        r"trap\.h5, channel 'Force HF/Force 1x': positions"
        r" contains 1 non-finite .*index \[17\]"
    )):
        load_bluelake(p, force_sensitivity_pN_per_V=RF, displacement_sensitivity_m_per_V=SENS)


def test_not_an_hdf5_file(h5py, tmp_path):
    p = tmp_path / "fake.h5"
    p.write_text("t_s,x_nm\n0,1\n")
    with pytest.raises(ValueError, match=r"fake\.h5: cannot be read as an HDF5 file"):
        load_bluelake(p)
    with pytest.raises(FileNotFoundError, match=r"nope\.h5: no such file"):
        load_h5(tmp_path / "nope.h5", "x", 1e3, exposure=1e-3)


# -- generic HDF5 ---------------------------------------------------------------------------


def write_h5(h5py, path, name, data, attrs=None, extra=None):
    with h5py.File(path, "w") as f:
        d = f.create_dataset(name, data=data)
        for k, v in (attrs or {}).items():
            d.attrs[k] = v
        for k, v in (extra or {}).items():
            f.create_dataset(k, data=v)


@pytest.mark.parametrize("attr", ["Sample rate (Hz)", "sample_rate", "fs"])
def test_h5_sample_rate_from_attribute(h5py, tmp_path, rng, attr):
    x = rng.normal(0.0, 30.0, 1000)
    p = tmp_path / "run.hdf5"
    write_h5(h5py, p, "bead/x", x, {attr: 1000.0})
    rec = load_h5(p, "bead/x", exposure=2e-4)
    assert rec.frame_interval == 1e-3 and rec.exposure == 2e-4
    np.testing.assert_array_equal(rec.positions, x / 1e9)
    assert rec.metadata["dataset"] == "bead/x" and rec.metadata["sample_rate_Hz"] == 1000.0
    assert rec.metadata["position_unit"] == "nm"


def test_h5_sample_rate_argument_and_disagreement(h5py, tmp_path, rng):
    x = rng.normal(0.0, 0.03, 1000)
    p = tmp_path / "run.h5"
    write_h5(h5py, p, "x", x)
    rec = load_h5(p, "x", 2000.0, position_unit="um", exposure=1e-4)
    assert rec.frame_interval == 5e-4
    np.testing.assert_array_equal(rec.positions, x / 1e6)
    write_h5(h5py, p, "x", x, {"fs": 1000.0})
    with pytest.raises(ValueError, match=(
        r"sample_rate = 2000\.0 Hz was given but the"
        r" dataset's attribute 'fs' = 1000\.0"
    )):
        load_h5(p, "x", 2000.0, position_unit="um", exposure=1e-4)
    write_h5(h5py, p, "x", x, {"fs": 1000.0, "sample_rate": 1e3 + 1})
    with pytest.raises(ValueError, match=r"sample-rate attributes disagree"):
        load_h5(p, "x", position_unit="um", exposure=1e-4)


def test_h5_sample_rate_in_khz_is_caught(h5py, tmp_path, rng):
    p = tmp_path / "run.h5"
    write_h5(h5py, p, "x", rng.normal(0.0, 30.0, 100), {"fs": 5.0})
    with pytest.raises(ValueError, match=r"frame_interval = 0\.2 s .*attribute 'fs' = 5\.0 Hz \(is it in kHz\?\)"):
        load_h5(p, "x", exposure=1e-4)


def test_h5_time_dataset(h5py, tmp_path, rng):
    x = rng.normal(0.0, 30.0, 800)
    t = 0.25 + np.arange(800) * 6.667e-4
    p = tmp_path / "run.h5"
    write_h5(h5py, p, "x", x, extra={"t": t})
    rec = load_h5(p, "x", time_dataset="t", exposure=1e-4)
    assert rec.frame_interval == pytest.approx(6.667e-4, rel=1e-9)
    np.testing.assert_array_equal(rec.times, t)
    assert rec.metadata["time_dataset"] == "t" and rec.metadata["frame_interval_inferred"]
    t_bad = t.copy()
    t_bad[300] = t_bad[299]
    write_h5(h5py, p, "x", x, extra={"t": t_bad})
    with pytest.raises(ValueError, match=r"dataset 't': times must increase strictly; times\[300\]"):
        load_h5(p, "x", time_dataset="t", exposure=1e-4)
    write_h5(h5py, p, "x", x, extra={"t": t[:-1]})
    with pytest.raises(ValueError, match=r"has 799 time stamps but 'x' has 800 samples"):
        load_h5(p, "x", time_dataset="t", exposure=1e-4)


def test_h5_missing_sample_rate_names_what_was_looked_for(h5py, tmp_path, rng):
    p = tmp_path / "run.h5"
    write_h5(h5py, p, "x", rng.normal(0.0, 30.0, 100), {"units": "nm"})
    with pytest.raises(
        ValueError,
        match=r"run\.h5, dataset 'x': no sample rate: pass sample_rate=.*time_dataset=.*"
        r"'Sample rate \(Hz\)' / 'sample_rate' / 'fs' \(the dataset's attributes: \['units'\]\)",
    ):
        load_h5(p, "x", exposure=1e-4)


def test_h5_exposure_is_required(h5py, tmp_path, rng):
    p = tmp_path / "run.h5"
    write_h5(h5py, p, "x", rng.normal(0.0, 30.0, 100), {"fs": 1e4})
    with pytest.raises(ValueError, match=r"dataset 'x': exposure not given.*\(0\.0001 s here\)"):
        load_h5(p, "x")


def test_h5_nan_names_the_index(h5py, tmp_path, rng):
    x = rng.normal(0.0, 30.0, 100)
    x[42] = np.nan
    p = tmp_path / "run.h5"
    write_h5(h5py, p, "x", x, {"fs": 1e3})
    with pytest.raises(ValueError, match=r"run\.h5, dataset 'x': positions contains 1 non-finite .*index \[42\]"):
        load_h5(p, "x", exposure=1e-4)


def test_h5_non_numeric_dataset(h5py, tmp_path):
    p = tmp_path / "run.h5"
    write_h5(h5py, p, "x", np.array([b"1.0", b"2.0", b"3.0"]), {"fs": 1e3})
    with pytest.raises(ValueError, match=r"dataset 'x': the dataset holds text \(dtype \|S3\); expected real numbers"):
        load_h5(p, "x", exposure=1e-4)
    write_h5(h5py, p, "x", np.array([True, False, True]), {"fs": 1e3})
    with pytest.raises(ValueError, match=r"holds booleans"):
        load_h5(p, "x", exposure=1e-4)
    compound = np.array([(1, 2.0), (2, 3.0)], dtype=[("Timestamp", np.int64), ("Value", float)])
    write_h5(h5py, p, "x", compound, {"fs": 1e3})
    with pytest.raises(ValueError, match=r"is a table with fields \['Timestamp', 'Value'\]"):
        load_h5(p, "x", exposure=1e-4)


def test_h5_two_dimensional_dataset_needs_a_column(h5py, tmp_path, rng):
    xy = rng.normal(0.0, 30.0, (500, 2))
    p = tmp_path / "run.h5"
    write_h5(h5py, p, "xy", xy, {"fs": 1e3})
    with pytest.raises(ValueError, match=r"'xy': the dataset is 2-D with shape \(500, 2\).*column=<0\.\.1>"):
        load_h5(p, "xy", exposure=1e-4)
    rec = load_h5(p, "xy", exposure=1e-4, column=1)
    np.testing.assert_array_equal(rec.positions, xy[:, 1] / 1e9)
    assert rec.metadata["column"] == 1
    with pytest.raises(ValueError, match=r"column = 2 is not a column index"):
        load_h5(p, "xy", exposure=1e-4, column=2)
    write_h5(h5py, p, "x", xy[:, 0], {"fs": 1e3})
    with pytest.raises(ValueError, match=r"column = 0 was given but the dataset is 1-D"):
        load_h5(p, "x", exposure=1e-4, column=0)


def test_h5_missing_dataset_lists_the_datasets(h5py, tmp_path, rng):
    p = tmp_path / "run.h5"
    write_h5(h5py, p, "bead/x", rng.normal(0.0, 30.0, 100), {"fs": 1e3}, extra={"t": np.arange(100.0)})
    with pytest.raises(ValueError, match=(
        r"dataset 'x': not in the file; the datasets present are"
        r" \['bead/x \(100,\)', 't \(100,\)'\]"
    )):
        load_h5(p, "x", exposure=1e-4)


def test_h5_units(h5py, tmp_path, rng):
    v = rng.normal(0.0, 0.2, 300)
    p = tmp_path / "run.h5"
    write_h5(h5py, p, "v", v, {"fs": 1e4})
    rec = load_h5(p, "v", position_unit="V", displacement_sensitivity_m_per_V=SENS, exposure=1e-4)
    np.testing.assert_array_equal(rec.positions, v * SENS)
    with pytest.raises(ValueError, match=(
        r"displacement_sensitivity_m_per_V = 1e-07 was"
        r" given but position_unit = 'nm'"
    )):
        load_h5(p, "v", displacement_sensitivity_m_per_V=1e-7, exposure=1e-4)
    with pytest.raises(ValueError, match=r"position_unit = 'furlong' is not a supported position unit.*or 'V'"):
        load_h5(p, "v", position_unit="furlong", exposure=1e-4)
    # nm declared as metres: the recording's unit-slip check, prefixed with the file
    write_h5(h5py, p, "x", rng.normal(0.0, 30.0, 300), {"fs": 1e4})
    with pytest.raises(ValueError, match=r"run\.h5, dataset 'x': positions have standard deviation .* look like nm"):
        load_h5(p, "x", position_unit="m", exposure=1e-4)


# -- TDMS -----------------------------------------------------------------------------------


def write_tdms(nptdms, path, channels):
    """channels: [(group, channel, data, properties)]"""
    with nptdms.TdmsWriter(str(path)) as w:
        w.write_segment([nptdms.ChannelObject(g, c, d, properties=props) for g, c, d, props in channels])


def test_tdms_wf_increment(nptdms, tmp_path, rng):
    x = rng.normal(0.0, 25.0, 2000)
    p = tmp_path / "run.tdms"
    write_tdms(nptdms, p, [("Trap", "X", x, {"wf_increment": 2e-5, "unit_string": "nm"}),
                           ("Trap", "Y", x[::-1].copy(), {"wf_increment": 2e-5})])
    rec = load_tdms(p, "Trap", "X", exposure=2e-5)
    assert rec.frame_interval == 2e-5 and rec.exposure == 2e-5 and rec.n_frames == 2000
    np.testing.assert_array_equal(rec.positions, x / 1e9)
    m = rec.metadata
    assert (m["group"], m["channel"], m["unit_string"]) == ("Trap", "X", "nm")
    assert m["sample_rate_Hz"] == 1 / 2e-5
    # sample_rate that agrees is fine, one that disagrees is an error
    same = load_tdms(p, "Trap", "X", sample_rate=5e4, exposure=2e-5)
    assert same.frame_interval == rec.frame_interval
    np.testing.assert_array_equal(same.positions, rec.positions)
    with pytest.raises(ValueError, match=(
        r"sample_rate = 10000\.0 Hz was given but the"
        r" channel's wf_increment = 2e-05 s"
    )):
        load_tdms(p, "Trap", "X", sample_rate=1e4, exposure=2e-5)
    with pytest.raises(ValueError, match=r"unit_string property is 'nm' but position_unit = 'um'"):
        load_tdms(p, "Trap", "X", position_unit="um", exposure=2e-5)


def test_volts_from_h5_and_tdms_stay_volts(h5py, nptdms, tmp_path, rng):
    v = rng.normal(0.0, 0.3, 1000)
    write_h5(h5py, tmp_path / "v.h5", "qpd/x", v, {"fs": 1e5})
    rec = load_h5(tmp_path / "v.h5", "qpd/x", position_unit="V", exposure=1e-5)
    assert rec.position_unit == "V" and np.array_equal(rec.positions, v)
    write_tdms(nptdms, tmp_path / "v.tdms", [("Trap", "X", v, {"wf_increment": 1e-5, "unit_string": "V"})])
    rec = load_tdms(tmp_path / "v.tdms", exposure=1e-5)  # the unit from unit_string
    assert rec.position_unit == "V" and np.array_equal(rec.positions, v)
    with pytest.raises(ValueError, match=r"unit_string property is 'V' but position_unit = 'nm'"):
        load_tdms(tmp_path / "v.tdms", position_unit="nm", exposure=1e-5)
    with pytest.raises(ValueError, match=r"declared in volts .* below 1e-07 V"):
        load_h5(tmp_path / "v.h5", "qpd/x", position_unit="V", exposure=1e-5).replace(
            positions=v * 1e-9)


def test_tdms_missing_names_and_rate(nptdms, tmp_path, rng):
    x = rng.normal(0.0, 25.0, 500)
    p = tmp_path / "run.tdms"
    write_tdms(nptdms, p, [("Trap", "X", x, {"wf_increment": 1e-4}), ("Trap", "raw", x, {"gain": 2.0}),
                           ("Stage", "Z", x, {})])
    with pytest.raises(ValueError, match=r"run\.tdms: group 'trap' not found; the groups present are \[") as e:
        load_tdms(p, "trap", "X", exposure=1e-4)
    assert "'Trap'" in str(e.value) and "'Stage'" in str(e.value)
    with pytest.raises(ValueError, match=(
        r"group 'Trap': channel 'x' not found; the"
        r" channels present are \['X', 'raw'\]"
    )):
        load_tdms(p, "Trap", "x", exposure=1e-4)
    with pytest.raises(ValueError, match=r"group not given and the file has 2 groups"):
        load_tdms(p, channel="X", exposure=1e-4)
    with pytest.raises(ValueError, match=r"channel 'raw': no sample rate: the channel has no wf_increment.*\['gain'\]"):
        load_tdms(p, "Trap", "raw", exposure=1e-4)
    rec = load_tdms(p, "Trap", "raw", sample_rate=1e4, exposure=1e-4)
    assert rec.frame_interval == 1e-4
    # a single group and channel need not be named
    p1 = tmp_path / "one.tdms"
    write_tdms(nptdms, p1, [("G", "C", x, {"wf_increment": 1e-4})])
    assert load_tdms(p1, exposure=1e-4).metadata["channel"] == "C"


def test_tdms_nan_and_text(nptdms, tmp_path, rng):
    x = rng.normal(0.0, 25.0, 500)
    x[7] = np.inf
    p = tmp_path / "run.tdms"
    write_tdms(nptdms, p, [("Trap", "X", x, {"wf_increment": 1e-4}),
                           ("Trap", "label", np.array(["a", "b"]), {"wf_increment": 1e-4})])
    with pytest.raises(ValueError, match=r"group 'Trap', channel 'X': positions contains 1 non-finite .*index \[7\]"):
        load_tdms(p, "Trap", "X", exposure=1e-4)
    with pytest.raises(ValueError, match=r"channel 'label': the channel holds (text|objects)"):
        load_tdms(p, "Trap", "label", exposure=1e-4)


def test_not_a_tdms_file(nptdms, tmp_path):
    p = tmp_path / "fake.tdms"
    p.write_text("t_s,x_nm\n0,1\n" * 10)
    with pytest.raises(ValueError, match=r"fake\.tdms: cannot be read as a TDMS file"):
        load_tdms(p, exposure=1e-4)
    with pytest.raises(FileNotFoundError, match=r"nope\.tdms: no such file"):
        load_tdms(tmp_path / "nope.tdms", exposure=1e-4)


# -- dispatcher -----------------------------------------------------------------------------


def test_load_dispatches_instrument_files(h5py, nptdms, tmp_path, rng, volts):
    bl = tmp_path / "trap.h5"
    write_bluelake(h5py, bl, volts)
    kw = dict(force_sensitivity_pN_per_V=RF, displacement_sensitivity_m_per_V=SENS)
    assert bt.load(bl, **kw) == load_bluelake(bl, **kw)
    assert load(bl, channel="Force HF/Force 1x", **kw).metadata["channel"] == "Force HF/Force 1x"
    x = rng.normal(0.0, 30.0, 500)
    gen = tmp_path / "run.HDF5"
    write_h5(h5py, gen, "x", x, {"fs": 1e3}, extra={"y": x})
    assert load(gen, dataset="x", exposure=1e-4) == load_h5(gen, "x", exposure=1e-4)
    with pytest.raises(ValueError, match=(
        r"run\.HDF5: not a Bluelake export"
        r" .*dataset=.*\['x \(500,\)', 'y \(500,\)'\]"
    )):
        load(gen, exposure=1e-4)
    with pytest.raises(ValueError, match=r"not both"):
        load(gen, dataset="x", channel="x")
    with pytest.raises(ValueError, match=r"channel 'x': not a Bluelake signal channel"):
        load(gen, channel="x")  # channel= means Bluelake, even on another file
    td = tmp_path / "run.tdms"
    write_tdms(nptdms, td, [("Trap", "X", x, {"wf_increment": 1e-3})])
    assert load(td, group="Trap", channel="X", exposure=1e-4) == load_tdms(td, "Trap", "X", exposure=1e-4)
    with pytest.raises(ValueError, match=r"unknown file type '\.mat'.*HDF5, TDMS"):
        load(tmp_path / "run.mat")


# -- optional dependencies ------------------------------------------------------------------


@pytest.mark.parametrize(
    ("module", "call", "hint"),
    [
        ("h5py", lambda p: load_bluelake(p), 'pip install "blurtrap[h5py]"'),
        ("h5py", lambda p: load_h5(p, "x"), 'pip install "blurtrap[h5py]"'),
        ("h5py", lambda p: load(p.with_suffix(".hdf5")), 'pip install "blurtrap[h5py]"'),
        ("nptdms", lambda p: load_tdms(p.with_suffix(".tdms")), 'pip install "blurtrap[tdms]"'),
    ],
)
def test_missing_optional_dependency_says_what_to_install(monkeypatch, tmp_path, module, call, hint):
    monkeypatch.setitem(sys.modules, module, None)  # makes `import module` raise ImportError
    with pytest.raises(ImportError, match=hint.replace("[", r"\[").replace("]", r"\]")):
        call(tmp_path / "f.h5")


def test_import_loads_no_optional_dependency():
    code = (
        "import sys, blurtrap.data, blurtrap\n"
        "bad = sorted(m for m in sys.modules if m.split('.')[0] in {'h5py', 'nptdms', 'jax'})\n"
        "print(bad); sys.exit(1 if bad else 0)\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert out.returncode == 0, out.stdout + out.stderr
