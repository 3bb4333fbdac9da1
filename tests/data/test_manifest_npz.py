"""Manifest + CSV and NPZ round trips (bit-exact), manifest validation, from_arrays, load."""

import json

import numpy as np
import pytest

from blurtrap.data import (
    Recording,
    RecordingSet,
    from_arrays,
    load,
    load_manifest,
    load_npz,
    save_manifest,
    save_npz,
)


def bits(a):
    return np.asarray(a, dtype=np.float64).view(np.int64)


def make_set(rng):
    """Awkward values on purpose: full-precision randoms, tiny/huge exponents, -0.0."""
    n = 300
    x0 = rng.normal(0, 3e-8, n)
    x0[:4] = [0.0, -0.0, 1.234567890123456e-21, -7.0000000000000001e-5]
    dt = 1 / 1500
    t = 123.456 + np.arange(n) * dt
    return RecordingSet(
        [
            Recording(
                x0,
                frame_interval=dt,
                exposure=1e-4,
                times=t,
                laser_power=0.1234567,
                temperature=296.15,
                name="w010",
                metadata={"bead": "1 um PS", "n": [1, 2]},
            ),
            Recording(
                rng.normal(0, 1e-7, n) * np.pi,
                frame_interval=dt,
                exposure=dt,
                laser_power=1 / 3,
                name="w/unsafe name",
            ),
            Recording(rng.normal(0, 2e-8, 50), frame_interval=1e-3, exposure=5e-4),
        ]
    )


@pytest.mark.parametrize("unit", ["m", "mm", "um", "µm", "nm"])
def test_manifest_round_trip_bit_exact(tmp_path, rng, unit):
    s = make_set(rng)
    written = save_manifest(s, tmp_path / "manifest.json", position_unit=unit)
    assert all(p.exists() for p in written) and len(written) == 4
    back = load_manifest(tmp_path / "manifest.json")
    assert isinstance(back, RecordingSet) and len(back) == 3
    for a, b in zip(s, back, strict=True):
        np.testing.assert_array_equal(bits(b.positions), bits(a.positions))
        if a.times is not None:
            np.testing.assert_array_equal(bits(b.times), bits(a.times))
        else:
            np.testing.assert_array_equal(b.times, np.arange(a.n_frames) * a.frame_interval)
        assert (b.frame_interval, b.exposure, b.temperature, b.laser_power) == (
            a.frame_interval,
            a.exposure,
            a.temperature,
            a.laser_power,
        )
    assert back[0].name == "w010" and back[1].name == "w/unsafe name"
    assert back[0].metadata["bead"] == "1 um PS" and back[0].metadata["n"] == (1, 2)
    assert back[0].metadata["source"].endswith("w010.csv")


def test_manifest_format_matches_design(tmp_path, rng):
    s = make_set(rng)
    save_manifest(s, tmp_path / "m.json")
    doc = json.loads((tmp_path / "m.json").read_text())
    assert doc["position_unit"] == "nm"
    e = doc["recordings"][0]
    assert e["file"] == "w010.csv" and e["exposure_s"] == 1e-4
    assert e["laser_power_mW"] == 123.4567 and e["temperature_K"] == 296.15
    assert doc["recordings"][1]["file"] == "w_unsafe_name.csv"
    assert "laser_power_mW" not in doc["recordings"][2]
    assert (tmp_path / "w010.csv").read_text().splitlines()[0] == "t_s,x_nm"


def test_manifest_pixels(tmp_path, rng):
    s = make_set(rng)
    save_manifest(s, tmp_path / "m.json", position_unit="px", pixel_size_m=8.3e-8)
    assert (tmp_path / "w010.csv").read_text().startswith("t_s,x_px\n")
    back = load(tmp_path / "m.json")
    for a, b in zip(s, back, strict=True):
        np.testing.assert_allclose(b.positions, a.positions, rtol=5e-16, atol=1e-300)


def write_manifest(tmp_path, doc, csv_text="t_s,x_nm\n0,1\n0.001,2\n0.002,-1\n"):
    (tmp_path / "a.csv").write_text(csv_text)
    (tmp_path / "m.json").write_text(doc if isinstance(doc, str) else json.dumps(doc))
    return tmp_path / "m.json"


def entry(**kw):
    e = {"file": "a.csv", "frame_interval_s": 1e-3, "exposure_s": 1e-4}
    e.update(kw)
    return e


def test_manifest_defaults_and_conversions(tmp_path):
    p = write_manifest(
        tmp_path, {"position_unit": "nm", "recordings": [entry(laser_power_mW=100.0)]}
    )
    (r,) = load_manifest(p)
    assert r.temperature == 295.0 and r.metadata["defaults_applied"] == {"temperature_K": 295.0}
    assert r.laser_power == 0.1 and r.name == "a"
    np.testing.assert_array_equal(r.positions, [1e-9, 2e-9, -1e-9])
    p = write_manifest(
        tmp_path,
        {
            "position_unit": "nm",
            "recordings": [{"file": "a.csv", "exposure_s": 1e-4, "temperature_K": 300}],
        },
    )
    (r,) = load_manifest(p)
    assert r.frame_interval == pytest.approx(1e-3, rel=1e-12) and r.temperature == 300.0
    assert "defaults_applied" not in r.metadata


@pytest.mark.parametrize(
    "doc, match",
    [
        ("", r"m.json: manifest file is empty"),
        ('{"position_unit": ', r"m.json: invalid JSON at line 1"),
        ("[]", r"m.json: the manifest must be a JSON object"),
        ({"recordings": [entry()]}, r"m.json: 'position_unit' is missing"),
        (
            {"position_unit": "inch", "recordings": [entry()]},
            r"m.json: position_unit = 'inch' is not a supported.*'m', 'mm', 'um', 'µm', 'nm', 'px'",
        ),
        (
            {"position_unit": "px", "recordings": [entry()]},
            r"m.json: position unit 'px' needs pixel_size_m",
        ),
        ({"position_unit": "nm", "recordings": []}, r"'recordings' must be a non-empty list"),
        (
            {"position_unit": "nm", "units": 1, "recordings": [entry()]},
            r"unknown top-level key\(s\) \['units'\]",
        ),
        (
            {"position_unit": "nm", "recordings": [entry(exposure_ms=0.1)]},
            r"recordings\[0\]: unknown key\(s\) \['exposure_ms'\]",
        ),
        (
            {"position_unit": "nm", "recordings": [{"file": "a.csv"}]},
            r"recordings\[0\]: required key 'exposure_s' is missing",
        ),
        (
            {"position_unit": "nm", "recordings": [entry(exposure_s="0.1")]},
            r"exposure_s must be a number; got '0.1'",
        ),
        (
            {"position_unit": "nm", "recordings": [entry(exposure_s=2e-3)]},
            r"m.json, recordings\[0\]: .*a.csv: exposure = 0.002 s is longer than "
            r"frame_interval = 0.001 s",
        ),
        (
            {"position_unit": "nm", "recordings": [entry(temperature_K=20)]},
            r"a.csv: temperature = 20.0 K .*Celsius",
        ),
        (
            {"position_unit": "um", "recordings": [entry()]},
            r"a.csv, line 1: column 'x_nm' is in 'nm' but position_unit = 'um'",
        ),
        (
            {"position_unit": "nm", "recordings": [entry(laser_power_mW=5e4)]},
            r"laser_power = 50.0 W .*looks like mW",
        ),
    ],
)
def test_manifest_errors(tmp_path, doc, match):
    with pytest.raises(ValueError, match=match):
        load_manifest(write_manifest(tmp_path, doc))


@pytest.mark.parametrize(
    "csv_text, match",
    [
        ("t_s,x_nm\n0,0.001\n0.001,0.002\n0.002,-0.001\n", r"um declared as nm"),
        ("t_s,x_nm\n0,1e-9\n0.001,2e-9\n0.002,-1e-9\n", r"metres declared as nm"),
        ("t_s,x_um\n0,10\n0.001,20\n0.002,-10\n", r"nm declared as um"),
    ],
)
def test_manifest_position_unit_slips(tmp_path, csv_text, match):
    unit = csv_text.split(",x_")[1].split("\n")[0]
    p = write_manifest(tmp_path, {"position_unit": unit, "recordings": [entry()]}, csv_text)
    with pytest.raises(ValueError, match=r"m.json, recordings\[0\]: .*a.csv: positions have "
                       r"standard deviation .*positions look like " + match):
        load_manifest(p)
    p = write_manifest(tmp_path, {"position_unit": unit,
                                  "recordings": [entry(check_units=False)]}, csv_text)
    assert load_manifest(p)[0].n_frames == 3


def test_manifest_row_error_names_manifest_csv_and_line(tmp_path):
    p = write_manifest(
        tmp_path, {"position_unit": "nm", "recordings": [entry()]}, "t_s,x_nm\n0,1\n0.001,x\n"
    )
    with pytest.raises(
        ValueError, match=r"m.json, recordings\[0\]: .*a.csv, line 3: non-numeric value 'x'"
    ):
        load_manifest(p)


def test_manifest_missing_csv(tmp_path):
    p = write_manifest(tmp_path, {"position_unit": "nm", "recordings": [entry(file="nope.csv")]})
    with pytest.raises(FileNotFoundError, match=r"recordings\[0\] \(nope.csv\): file not found"):
        load_manifest(p)


def test_npz_round_trip_set_and_single(tmp_path, rng):
    s = make_set(rng)
    save_npz(s, tmp_path / "s.npz")
    back = load_npz(tmp_path / "s.npz")
    assert isinstance(back, RecordingSet) and back == s  # every field, metadata included
    for a, b in zip(s, back, strict=True):
        np.testing.assert_array_equal(bits(b.positions), bits(a.positions))
    save_npz(s[0], tmp_path / "one.data")  # the exact file name is kept
    one = load_npz(tmp_path / "one.data")
    assert isinstance(one, Recording) and one == s[0]
    save_npz(s, tmp_path / "c.npz", compress=True)
    assert load(tmp_path / "c.npz") == s


def test_npz_irregular_times_round_trip(tmp_path, rng):
    t = np.cumsum(rng.uniform(0.5e-3, 1.5e-3, 100))
    r = Recording(
        rng.normal(0, 1e-8, 100),
        frame_interval=float(np.median(np.diff(t))),
        exposure=1e-4,
        times=t,
        allow_irregular=True,
    )
    save_npz(r, tmp_path / "r.npz")
    back = load_npz(tmp_path / "r.npz")
    assert back == r and back.timing_jitter == r.timing_jitter


def test_plain_npz(tmp_path, rng):
    x = rng.normal(0, 1e-8, (2, 100))
    np.savez(tmp_path / "p.npz", positions=x, exposure=1e-4)
    s = load_npz(tmp_path / "p.npz", frame_interval=1e-3)
    assert len(s) == 2 and np.array_equal(s[1].positions, x[1]) and s[0].exposure == 1e-4
    with pytest.raises(ValueError, match=r"p.npz: frame_interval and exposure are not stored"):
        load_npz(tmp_path / "p.npz")
    np.savez(tmp_path / "q.npz", y=x)
    with pytest.raises(ValueError, match=r"q.npz: no 'positions' array \(found \['y'\]\)"):
        load_npz(tmp_path / "q.npz")
    (tmp_path / "bad.npz").write_bytes(b"not a zip")
    with pytest.raises(ValueError, match=r"bad.npz: not a readable .npz file"):
        load_npz(tmp_path / "bad.npz")


def test_from_arrays_1d_2d_units_and_jax(rng):
    import jax.numpy as jnp

    x_nm = rng.normal(0, 10.0, (3, 200))
    s = from_arrays(
        jnp.asarray(x_nm),
        frame_interval=1e-3,
        exposure=[1e-4, 2e-4, 5e-4],
        laser_power=[0.1, np.nan, 0.2],
        position_unit="nm",
        name="run",
    )
    assert isinstance(s, RecordingSet) and len(s) == 3
    np.testing.assert_array_equal(s[2].positions, x_nm[2] / 1e9)
    np.testing.assert_array_equal(s.exposures, [1e-4, 2e-4, 5e-4])
    assert s[1].laser_power is None and s.names == ("run[0]", "run[1]", "run[2]")
    assert s[0].metadata["position_unit"] == "nm"
    r = from_arrays(
        jnp.asarray(x_nm[0], dtype=jnp.float32),
        frame_interval=1e-3,
        exposure=1e-4,
        position_unit="µm",
        check_units=False,
    )
    assert isinstance(r, Recording) and r.metadata["input_dtype"] == "float32"
    np.testing.assert_array_equal(r.positions, x_nm[0].astype(np.float32).astype(float) / 1e6)
    px = from_arrays(
        rng.integers(0, 9, 100),
        frame_interval=1e-3,
        exposure=1e-4,
        position_unit="px",
        pixel_size_m=1e-7,
    )
    assert px.metadata["input_dtype"] == "int64" and px.positions.max() <= 8e-7 * (1 + 1e-15)


@pytest.mark.parametrize(
    "kw, match",
    [
        (
            dict(positions=np.zeros((2, 2, 2))),
            r"1-D \(one recording\) or 2-D .*got shape \(2, 2, 2\)",
        ),
        (
            dict(exposure=[1e-4, 1e-4]),
            r"exposure must be a scalar or have one value per recording \(3\)",
        ),
        (
            dict(exposure=[1e-4, 1e-4, 2e-3]),
            r"recording 2 \(row 2 of positions\): exposure = 0.002 s is longer",
        ),
        (dict(position_unit="furlong"), r"position_unit = 'furlong' is not a supported"),
        (dict(times=np.zeros((2, 50))), r"times must be 1-D \(shared\) or 2-D with one row"),
        (dict(name=["a"]), r"name must have one entry per recording \(3\)"),
    ],
)
def test_from_arrays_errors(rng, kw, match):
    args = dict(positions=rng.normal(0, 1e-8, (3, 50)), frame_interval=1e-3, exposure=1e-4)
    args.update(kw)
    with pytest.raises(ValueError, match=match):
        from_arrays(args.pop("positions"), **args)


def test_ms_and_mk_slips_through_manifest_and_npz(tmp_path):
    """The unit checks of Recording hold for every loader: a t_s column in ms (1500 frames/s)
    in a manifest without frame_interval_s, a temperature in mK, and a plain NPZ whose
    frame_interval is in ms."""
    csv_ms = "t_s,x_nm\n" + "".join(f"{i / 1.5!r},{(-1) ** i * 3.0}\n" for i in range(20))
    p = write_manifest(tmp_path, {"position_unit": "nm",
                                  "recordings": [{"file": "a.csv", "exposure_s": 1e-4}]}, csv_ms)
    with pytest.raises(ValueError, match=r"m.json, recordings\[0\]: .*a.csv: frame_interval = "
                       r"0.66666.* s is at least 0.1 s .*looks like ms.*t_s column"):
        load_manifest(p)
    p = write_manifest(tmp_path, {"position_unit": "nm", "recordings": [entry(temperature_K=295000)]})
    with pytest.raises(ValueError, match=r"m.json, recordings\[0\]: .*temperature = 295000.0 K is "
                       r"above 400 K: this looks like millikelvin"):
        load_manifest(p)
    x = np.random.default_rng(2).normal(0, 1e-8, 64)
    np.savez(tmp_path / "plain.npz", positions=x, frame_interval=np.array(0.6667),
             exposure=np.array(1e-4))
    with pytest.raises(ValueError, match=r"plain.npz: frame_interval = 0.6667 s is at least 0.1 s"):
        load_npz(tmp_path / "plain.npz")


@pytest.mark.parametrize("value", [5, 1.5, True, ["a"], {"text": "x"}])
def test_manifest_description_must_be_text(tmp_path, value):
    p = write_manifest(tmp_path, {"position_unit": "nm", "description": value,
                                  "recordings": [entry()]})
    with pytest.raises(ValueError, match=r"m.json: 'description' must be a string \(or null\); got "):
        load_manifest(p)
    for ok in ("bead A, 1500 fps", None):
        p = write_manifest(tmp_path, {"position_unit": "nm", "description": ok,
                                      "recordings": [entry()]})
        assert len(load_manifest(p)) == 1


def test_manifest_pixel_size_without_px_is_an_error(tmp_path):
    p = write_manifest(tmp_path, {"position_unit": "nm", "pixel_size_m": 1e-7,
                                  "recordings": [entry()]})
    with pytest.raises(ValueError, match=r"m.json: pixel_size_m = 1e-07 was given but the "
                       r"positions are in 'nm', not 'px'"):
        load_manifest(p)
    with pytest.raises(ValueError, match=r"pixel_size_m = 1e-07 was given but .* 'nm', not 'px'"):
        save_manifest(make_set(np.random.default_rng(0)), tmp_path / "s.json", "nm",
                      pixel_size_m=1e-7)


@pytest.mark.parametrize(
    "content, match",
    [
        (b"t_s,x_nm\n0,1\n0.001,2\n", r"it looks like text/CSV, starting 't_s,x_nm'\); use load_csv"),
        ("\ufeffx_um\r\n1\r\n2\r\n".encode(), r"it looks like text/CSV"),
        (b"0.0,1.5\n" * 2000, r"it looks like text/CSV, starting '0.0,1.5'"),  # > one read
        ("µa".encode() * 3000, r"it looks like text/CSV"),  # the read ends inside a 'µ'
        (b"\x89PNG\r\n\x1a\n\x00\x00\x00", r"this is not an NPZ archive .*starts with b'\\x89PNG"),
        (b"", r"the file is empty"),
    ],
)
def test_text_or_other_files_named_npz(tmp_path, content, match):
    """np.load used to answer CSV text with a message suggesting allow_pickle."""
    p = tmp_path / "rec.npz"
    p.write_bytes(content)
    for fn in (load_npz, load):
        with pytest.raises(ValueError, match=r"rec.npz: not a readable .npz file.*" + match) as e:
            fn(p)
        assert "pickle" not in str(e.value)


def _irregular_csv(n=400, seed=15):
    rng = np.random.default_rng(seed)
    t = np.concatenate([[0.0], np.cumsum(1e-3 + rng.normal(0, 2e-5, n - 1))])
    x = rng.normal(0, 20.0, n)
    return t, "t_s,x_nm\n" + "".join(f"{a!r},{b!r}\n" for a, b in zip(t.tolist(), x.tolist(), strict=True))


@pytest.mark.parametrize(
    "top, per_entry, kept",
    [
        (None, None, False),
        (None, True, True),
        (True, None, True),
        (False, True, True),
        (True, False, False),  # the entry's own setting wins
    ],
)
def test_manifest_allow_irregular_per_entry_and_default(tmp_path, top, per_entry, kept):
    t, text = _irregular_csv()
    e = {"file": "a.csv", "exposure_s": 1e-4}  # frame interval inferred from the stamps
    if per_entry is not None:
        e["allow_irregular"] = per_entry
    doc = {"position_unit": "nm", "recordings": [e]}
    if top is not None:
        doc["allow_irregular"] = top
    p = write_manifest(tmp_path, doc, text)
    if not kept:
        with pytest.raises(ValueError, match=r"m.json, recordings\[0\]: .*a.csv: times are "
                           r"irregular: .*allow_irregular=True \(a manifest key too\)"):
            load_manifest(p)
        return
    (r,) = load_manifest(p)
    assert r.allow_irregular and not r.is_regular
    assert r.timing_jitter.std == pytest.approx(float(np.std(np.diff(t))), rel=1e-9)
    assert r.timing_jitter.std == pytest.approx(2e-5, rel=0.1)


@pytest.mark.parametrize("value", ["yes", 1, None, [True]])
def test_manifest_allow_irregular_default_must_be_boolean(tmp_path, value):
    p = write_manifest(tmp_path, {"position_unit": "nm", "allow_irregular": value,
                                  "recordings": [entry()]})
    with pytest.raises(ValueError, match=r"m.json: allow_irregular must be true or false"):
        load_manifest(p)
