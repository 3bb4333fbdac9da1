"""The manifest's instrument keys (issue 17): every key accepted and stored in the recording's
metadata under its own name, every invalid value rejected naming the manifest, the entry,
the file and the key; top-level defaults and per-recording overrides; and
``instrument_settings``, the same validator for Python users, with its defaults."""

import json
import re

import numpy as np
import pytest

from blurtrap.data import INSTRUMENT_KEYS, Recording, instrument_settings, load_manifest

DT = 1e-4  # s: Nyquist 5 kHz
N = 400
DEFAULTS = {
    "detector": None,
    "anti_aliasing": False,
    "diode_filter": None,
    "bead_radius_m": None,
    "viscosity_Pa_s": None,
    "distance_to_surface_m": None,
    "bead_density_kg_per_m3": None,
    "fluid_density_kg_per_m3": None,
    "friction": "free",
    "hydrodynamics": "auto",
    "drive": None,
    "fit_range_Hz": None,
    "excluded_ranges_Hz": None,
    "bead_radius_err_m": None,
    "viscosity_err_Pa_s": None,
    "temperature_err_K": None,
}


def write_csv(path, *, stage=False, unit="nm", seed=0):
    rng = np.random.default_rng(seed)
    scale = 0.2 if unit == "V" else 20.0
    x = rng.normal(0, scale, N)
    header = f"t_s,x_{unit}" + (",stage_nm" if stage else "")
    rows = [header]
    for i in range(N):
        row = f"{i * DT!r},{float(x[i])!r}"
        if stage:
            row += f",{float(100 * np.sin(2 * np.pi * 32 * i * DT))!r}"
        rows.append(row)
    path.write_text("\n".join(rows) + "\n")


def manifest(tmp_path, entries, unit="nm", stage=False, **top):
    """A manifest with one CSV per entry (a.csv, b.csv, ...); returns its path."""
    recs = []
    for i, extra in enumerate(entries):
        name = "abcdefgh"[i] + ".csv"
        write_csv(tmp_path / name, stage=stage, unit=unit, seed=i)
        recs.append({"file": name, "frame_interval_s": DT, "exposure_s": DT, **extra})
    p = tmp_path / "m.json"
    p.write_text(json.dumps({"position_unit": unit, **top, "recordings": recs}))
    return p


# -- every key accepted and stored --------------------------------------------------------------

PHOTODIODE = {"detector": "photodiode"}
ACCEPTED = [
    # (entry keys, the key checked, its value in metadata, its value from instrument_settings)
    ({"detector": "camera"}, "detector", "camera", "camera"),
    ({"detector": "photodiode"}, "detector", "photodiode", "photodiode"),
    ({**PHOTODIODE, "anti_aliasing": True}, "anti_aliasing", True, True),
    ({"anti_aliasing": False}, "anti_aliasing", False, False),
    ({**PHOTODIODE, "diode_filter": "fit"}, "diode_filter", "fit", "fit"),
    ({"diode_filter": "none"}, "diode_filter", "none", "none"),
    (
        {**PHOTODIODE, "diode_filter": {"alpha": 0.3, "f3db_Hz": 8000}},
        "diode_filter",
        {"alpha": 0.3, "f3db_Hz": 8000.0},
        {"alpha": 0.3, "f3db_Hz": 8000.0},
    ),
    ({"bead_radius_m": 5e-7}, "bead_radius_m", 5e-7, 5e-7),
    ({"viscosity_Pa_s": 9.5e-4}, "viscosity_Pa_s", 9.5e-4, 9.5e-4),
    ({"distance_to_surface_m": 2e-6}, "distance_to_surface_m", 2e-6, 2e-6),
    ({"bead_radius_m": 5e-7, "distance_to_surface_m": 6e-7}, "distance_to_surface_m", 6e-7, 6e-7),
    ({"bead_density_kg_per_m3": 1050}, "bead_density_kg_per_m3", 1050.0, 1050.0),
    ({"fluid_density_kg_per_m3": 997.0}, "fluid_density_kg_per_m3", 997.0, 997.0),
    ({"friction": "free"}, "friction", "free", "free"),
    ({"friction": "stokes", "bead_radius_m": 5e-7}, "friction", "stokes", "stokes"),
    ({"drive": {"frequency_Hz": 16.8}}, "drive", {"frequency_Hz": 16.8}, {"frequency_Hz": 16.8}),
    ({"fit_range_Hz": [0, 4000]}, "fit_range_Hz", (0.0, 4000.0), (0.0, 4000.0)),
    (
        {"excluded_ranges_Hz": [[49, 51], [99.5, 100.5]]},
        "excluded_ranges_Hz",
        ((49.0, 51.0), (99.5, 100.5)),
        ((49.0, 51.0), (99.5, 100.5)),
    ),
    ({"excluded_ranges_Hz": []}, "excluded_ranges_Hz", (), ()),
]


@pytest.mark.parametrize("entry, key, stored, setting", ACCEPTED, ids=lambda v: str(v)[:40])
def test_every_key_is_accepted_and_stored_under_its_name(tmp_path, entry, key, stored, setting):
    p = manifest(tmp_path, [entry], stage="drive" in entry)
    rec = load_manifest(p)[0]
    assert rec.metadata[key] == stored
    got = instrument_settings(rec)
    assert got[key] == setting
    # the keys not given keep their defaults
    for k, v in DEFAULTS.items():
        if k not in entry and not (k == "diode_filter" and entry.get("detector") == "camera"):
            assert got[k] == v, k


def test_all_keys_together_and_instrument_keys_listed(tmp_path):
    entry = {
        "detector": "photodiode",
        "anti_aliasing": True,
        "diode_filter": {"alpha": 0.5, "f3db_Hz": 9000.0},
        "bead_radius_m": 5e-7,
        "viscosity_Pa_s": 1e-3,
        "distance_to_surface_m": 3e-6,
        "bead_density_kg_per_m3": 1050.0,
        "fluid_density_kg_per_m3": 1000.0,
        "friction": "stokes",
        "hydrodynamics": False,
        "drive": {"frequency_Hz": 32.0},
        "fit_range_Hz": [10.0, 4000.0],
        "excluded_ranges_Hz": [[30.0, 34.0]],
        "bead_radius_err_m": 1.5e-8,
        "viscosity_err_Pa_s": 2e-5,
        "temperature_err_K": 0.5,
    }
    assert set(entry) == set(INSTRUMENT_KEYS)
    rec = load_manifest(manifest(tmp_path, [entry], unit="V", stage=True))[0]
    got = instrument_settings(rec)
    assert got["fit_range_Hz"] == (10.0, 4000.0) and got["excluded_ranges_Hz"] == ((30.0, 34.0),)
    assert {k: v for k, v in got.items() if k not in ("fit_range_Hz", "excluded_ranges_Hz")} == {
        k: v for k, v in entry.items() if k not in ("fit_range_Hz", "excluded_ranges_Hz")
    }
    assert rec.position_unit == "V" and rec.stage is not None


# -- every invalid value rejected, naming the manifest, entry, file and key ---------------------

REJECTED = [
    ({"bead_radius_err_m": -1e-9}, "bead_radius_err_m", r"standard error and must be >= 0"),
    ({"temperature_err_K": "1 K"}, "temperature_err_K", r"must be a number"),
    ({"detector": "ccd"}, "detector", r"must be 'camera' or 'photodiode'"),
    ({"detector": 1}, "detector", r"must be 'camera' or 'photodiode'"),
    ({**PHOTODIODE, "anti_aliasing": "yes"}, "anti_aliasing", r"true or false"),
    ({**PHOTODIODE, "anti_aliasing": 1}, "anti_aliasing", r"true or false"),
    ({"anti_aliasing": True}, "anti_aliasing", r"needs detector 'photodiode'.*None"),
    ({"detector": "camera", "anti_aliasing": True}, "anti_aliasing", r"needs detector 'photodiode'"),
    ({**PHOTODIODE, "diode_filter": "auto"}, "diode_filter", r"'fit', 'none' or an object"),
    ({**PHOTODIODE, "diode_filter": {"alpha": 0.3}}, "diode_filter", r"exactly the keys"),
    ({**PHOTODIODE, "diode_filter": {"alpha": 1.5, "f3db_Hz": 8e3}}, "diode_filter alpha", r"\[0, 1\]"),
    ({**PHOTODIODE, "diode_filter": {"alpha": 0.3, "f3db_Hz": 0}}, "diode_filter f3db_Hz", r"> 0"),
    ({"detector": "camera", "diode_filter": "fit"}, "diode_filter", r"needs detector 'photodiode'"),
    ({"bead_radius_m": 0}, "bead_radius_m", r"> 0"),
    ({"bead_radius_m": -5e-7}, "bead_radius_m", r"> 0"),
    ({"bead_radius_m": 0.5}, "bead_radius_m", r"not below 1e-3 m.*um or nm"),
    ({"bead_radius_m": "5e-7"}, "bead_radius_m", r"must be a number"),
    ({"bead_radius_m": True}, "bead_radius_m", r"must be a number"),
    ({"viscosity_Pa_s": 0}, "viscosity_Pa_s", r"> 0"),
    ({"distance_to_surface_m": -1e-6}, "distance_to_surface_m", r"> 0"),
    ({"bead_radius_m": 5e-7, "distance_to_surface_m": 4e-7}, "distance_to_surface_m", r"exceed bead_radius_m"),
    ({"bead_density_kg_per_m3": 0}, "bead_density_kg_per_m3", r"> 0"),
    ({"bead_density_kg_per_m3": 1.05}, "bead_density_kg_per_m3", r"g/cm\^3"),
    ({"fluid_density_kg_per_m3": -1000}, "fluid_density_kg_per_m3", r"> 0"),
    ({"friction": "fixed"}, "friction", r"'free' or 'stokes'"),
    ({"friction": "stokes"}, "friction", r"needs bead_radius_m"),
    ({"drive": 16.8}, "drive", r"exactly the keys \['frequency_Hz'\]"),
    ({"drive": {"frequency_Hz": 16.8, "amplitude_m": 1e-7}}, "drive", r"exactly the keys"),
    ({"drive": {"frequency_Hz": 0}}, "drive frequency_Hz", r"> 0"),
    ({"fit_range_Hz": [100, 10]}, "fit_range_Hz", r"0 <= fmin < fmax"),
    ({"fit_range_Hz": [-1, 10]}, "fit_range_Hz", r"0 <= fmin < fmax"),
    ({"fit_range_Hz": [10]}, "fit_range_Hz", r"a pair \[fmin, fmax\]"),
    ({"fit_range_Hz": "10-100"}, "fit_range_Hz", r"a pair \[fmin, fmax\]"),
    ({"fit_range_Hz": [6000, 7000]}, "fit_range_Hz", r"Nyquist frequency 5000 Hz"),
    ({"excluded_ranges_Hz": [[51, 49]]}, r"excluded_ranges_Hz\[0\]", r"0 <= fmin < fmax"),
    ({"excluded_ranges_Hz": [[1, 2], [3]]}, r"excluded_ranges_Hz\[1\]", r"a pair"),
    ({"excluded_ranges_Hz": 50}, "excluded_ranges_Hz", r"a list of pairs"),
]


@pytest.mark.parametrize("entry, key, problem", REJECTED, ids=lambda v: str(v)[:40])
def test_invalid_values_are_rejected_naming_manifest_entry_file_and_key(tmp_path, entry, key, problem):
    p = manifest(tmp_path, [{}, entry])
    with pytest.raises(ValueError, match=problem) as err:
        load_manifest(p)
    msg = str(err.value)
    assert msg.startswith(f"{p}, recordings[1] (b.csv)"), msg
    assert re.search(key, msg), msg


def test_a_drive_needs_the_stage_column(tmp_path):
    p = manifest(tmp_path, [{"drive": {"frequency_Hz": 32.0}}], stage=False)
    with pytest.raises(ValueError, match=r"recordings\[0\] \(a.csv\).*drive .*needs the stage "
                       r"positions: a stage_nm"):
        load_manifest(p)
    p = manifest(tmp_path, [{"drive": {"frequency_Hz": 32.0}}], stage=True)
    assert load_manifest(p)[0].metadata["drive"] == {"frequency_Hz": 32.0}


def test_drive_above_nyquist_is_rejected(tmp_path):
    p = manifest(tmp_path, [{"drive": {"frequency_Hz": 5000.0}}], stage=True)
    with pytest.raises(ValueError, match=r"drive frequency_Hz = 5000.0 Hz is not below the Nyquist"):
        load_manifest(p)


def test_keys_in_metadata_are_validated_and_may_not_be_given_twice(tmp_path):
    p = manifest(tmp_path, [{"metadata": {"bead_radius_m": 500}}])
    with pytest.raises(ValueError, match=r"recordings\[0\].*bead_radius_m = 500.0 m"):
        load_manifest(p)
    p = manifest(tmp_path, [{"bead_radius_m": 5e-7, "metadata": {"bead_radius_m": 5e-7}}])
    with pytest.raises(ValueError, match=r"\['bead_radius_m'\] given both as entry key\(s\) and in "
                       r"'metadata'"):
        load_manifest(p)
    p = manifest(tmp_path, [{"metadata": {"detector": "camera", "note": "x"}}])
    rec = load_manifest(p)[0]
    assert rec.metadata["detector"] == "camera" and rec.metadata["note"] == "x"


def test_misspelt_keys_are_still_unknown(tmp_path):
    with pytest.raises(ValueError, match=r"unknown key\(s\) \['bead_radius_um'\]"):
        load_manifest(manifest(tmp_path, [{"bead_radius_um": 0.5}]))
    with pytest.raises(ValueError, match=r"unknown top-level key\(s\) \['detectors'\]"):
        load_manifest(manifest(tmp_path, [{}], detectors="camera"))


# -- top-level defaults and per-recording overrides ---------------------------------------------


def test_top_level_defaults_and_overrides(tmp_path):
    p = manifest(
        tmp_path,
        [{}, {"bead_radius_m": 1.5e-6}, {"detector": None, "friction": "free"}],
        detector="photodiode",
        bead_radius_m=5e-7,
        friction="stokes",
        fit_range_Hz=[1, 4000],
    )
    a, b, c = load_manifest(p)
    sa, sb, sc = (instrument_settings(r) for r in (a, b, c))
    assert (sa["detector"], sa["bead_radius_m"], sa["friction"]) == ("photodiode", 5e-7, "stokes")
    assert (sb["detector"], sb["bead_radius_m"], sb["friction"]) == ("photodiode", 1.5e-6, "stokes")
    assert (sc["detector"], sc["bead_radius_m"], sc["friction"]) == (None, 5e-7, "free")
    assert "detector" not in c.metadata  # null removed the default
    assert sa["fit_range_Hz"] == sb["fit_range_Hz"] == sc["fit_range_Hz"] == (1.0, 4000.0)


def test_an_invalid_top_level_default_names_itself(tmp_path):
    p = manifest(tmp_path, [{"bead_radius_m": 5e-7}, {}], friction="stokes")
    with pytest.raises(ValueError, match=r"recordings\[1\] \(b.csv\), with the top-level default\(s\) "
                       r"\['friction'\]: friction 'stokes' .*needs bead_radius_m"):
        load_manifest(p)
    p = manifest(tmp_path, [{}], detector="ccd")
    with pytest.raises(ValueError, match=r"top-level default\(s\) \['detector'\]: detector must be"):
        load_manifest(p)


def test_check_units_false_lets_an_odd_density_through(tmp_path):
    p = manifest(tmp_path, [{"bead_density_kg_per_m3": 50.0, "check_units": False}])
    rec = load_manifest(p)[0]
    assert instrument_settings(rec)["bead_density_kg_per_m3"] == 50.0


# -- instrument_settings for Python users -------------------------------------------------------


def rec(metadata=None, **kw):
    x = np.random.default_rng(0).normal(0, 2e-8, N)
    return Recording(x, frame_interval=DT, exposure=DT, metadata=metadata, name="w1", **kw)


def test_defaults_of_a_bare_recording():
    assert instrument_settings(rec()) == DEFAULTS
    assert instrument_settings(rec({"detector": "camera"}))["diode_filter"] == "none"
    assert instrument_settings(rec({"detector": "photodiode"}))["diode_filter"] is None


@pytest.mark.parametrize(
    "metadata, match",
    [
        ({"detector": "qpd"}, r"detector must be 'camera' or 'photodiode'; got 'qpd'"),
        ({"bead_radius_m": 1.0}, r"bead_radius_m = 1.0 m is not below 1e-3 m"),
        ({"friction": "stokes"}, r"friction 'stokes' .*needs bead_radius_m"),
        ({"fit_range_Hz": (5000, 6000)}, r"fit_range_Hz = \[5000.0, 6000.0\] Hz starts at or above"),
        ({"drive": {"frequency_Hz": 30.0}}, r"drive .*needs the stage positions.*Recording\(stage=...\)"),
        ({"anti_aliasing": True, "detector": "camera"}, r"anti_aliasing = true needs detector"),
    ],
)
def test_invalid_metadata_names_the_recording_and_key(metadata, match):
    with pytest.raises(ValueError, match=r"^recording 'w1': metadata: " + match):
        instrument_settings(rec(metadata))


def test_settings_from_python_metadata_and_numpy_values():
    st = 1e-7 * np.sin(np.arange(N))
    r = rec({"drive": {"frequency_Hz": np.float64(30)}, "fit_range_Hz": np.array([1.0, 2e3]),
             "bead_radius_m": np.float32(5e-7)}, stage=st)
    got = instrument_settings(r)
    assert got["drive"] == {"frequency_Hz": 30.0} and got["fit_range_Hz"] == (1.0, 2000.0)
    assert got["bead_radius_m"] == pytest.approx(5e-7, rel=1e-7)
    assert isinstance(got["fit_range_Hz"][0], float)


def test_hydrodynamics_key_is_validated_and_defaults_to_auto():
    import blurtrap as bt
    from blurtrap.data import instrument_settings

    rec = bt.Recording(np.arange(64.0) * 1e-9 % 7e-9, frame_interval=1e-3, exposure=1e-3)
    assert instrument_settings(rec)["hydrodynamics"] == "auto"
    for v in ("auto", True, False, np.True_, np.False_):  # numpy bools (HDF5 attributes)
        r = bt.Recording(rec.positions, frame_interval=1e-3, exposure=1e-3,
                         metadata={"hydrodynamics": v})
        got = instrument_settings(r)["hydrodynamics"]
        assert got == v and (got == "auto" or type(got) is bool)
    for bad in ("yes", 1, "true"):
        r = bt.Recording(rec.positions, frame_interval=1e-3, exposure=1e-3,
                         metadata={"hydrodynamics": bad})
        with pytest.raises(ValueError, match="hydrodynamics must be"):
            instrument_settings(r)
