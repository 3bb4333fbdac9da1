"""Bad-input messages of the loaders that name the cause: time stamps rounded to a resolution
comparable to the frame interval (not a unit slip), a column-vector NPZ, positions rounded to
whole pixels. Inputs are plain numpy (no blurtrap simulator); correct inputs still load."""

import json

import numpy as np
import pytest

from blurtrap.data import Recording, from_arrays, load_csv, load_manifest, load_npz

DT = 1 / 1500  # 1500 frames/s
N = 4096


def trace(n=N, std=10e-9, seed=0):
    return np.random.default_rng(seed).normal(0.0, std, n)


def rounded_times(n=N, dt=DT, decimals=4):
    """Time stamps of a regular clock written with 0.1 ms resolution: steps of 0.6 and 0.7 ms."""
    return np.round(np.arange(n) * dt, decimals)


def write_csv(path, times, x, fmt_t="{:.4f}", column="x_nm"):
    rows = [f"{fmt_t.format(float(t))},{float(v)!r}" for t, v in zip(times, x)]
    path.write_text(f"t_s,{column}\n" + "\n".join(rows) + "\n")
    return path


# -- rounded time stamps ---------------------------------------------------------------------


def test_rounded_time_stamps_are_named_with_the_tolerance_that_accepts_them():
    t = rounded_times()
    with pytest.raises(ValueError, match=r"0\.0007 s \(median step\)") as err:
        Recording(trace(), frame_interval=DT, exposure=DT, times=t)
    msg = str(err.value)
    assert "rounded to a resolution of 0.0001 s" in msg
    assert "0.0006, 0.0007 s" in msg and "mean 0.000666667 s matches frame_interval" in msg
    assert "not a unit slip" in msg and "timing_tolerance=0.15" in msg
    assert "Check the units" not in msg
    # allow_irregular does not hide the mismatch of the median: the same cause is named
    with pytest.raises(ValueError, match=r"rounded to a resolution of 0\.0001 s.*timing_tolerance=0\.15"):
        Recording(trace(), frame_interval=DT, exposure=DT, times=t, allow_irregular=True)
    # ... and the tolerance it names accepts them
    rec = Recording(trace(), frame_interval=DT, exposure=DT, times=t, timing_tolerance=0.15)
    assert rec.timing_jitter.max_deviation <= 0.5e-4 + 1e-12


def test_rounded_time_stamps_in_a_manifest_csv(tmp_path):
    write_csv(tmp_path / "tround.csv", rounded_times(), trace() * 1e9)
    entry = {"file": "tround.csv", "frame_interval_s": DT, "exposure_s": DT, "temperature_K": 295.0}
    man = tmp_path / "m.json"
    man.write_text(json.dumps({"position_unit": "nm", "recordings": [entry]}))
    with pytest.raises(ValueError, match=r"tround\.csv: .*look rounded to a resolution of 0\.0001 s.*"
                                         r"timing_tolerance=0\.15 \(relative; a manifest key too\)"):
        load_manifest(man)
    man.write_text(json.dumps({"position_unit": "nm", "recordings": [{**entry, "timing_tolerance": 0.15}]}))
    assert load_manifest(man)[0].frame_interval == DT


def test_rounded_times_between_the_two_checks_are_named_as_rounding_not_dropped_frames():
    """Median within the tolerance, grid deviation not: the irregularity message names rounding."""
    dt = 1 / 1010
    t = np.round(np.arange(N) * dt, 5)  # steps of 0.99 and 1.00 ms
    with pytest.raises(ValueError, match=r"times are irregular.*rounded to a resolution of 1e-05 s.*"
                                         r"not jitter or dropped frames: pass timing_tolerance=0\.011") as err:
        Recording(trace(), frame_interval=dt, exposure=dt, times=t, timing_tolerance=5e-3)
    assert "dropped frames?" not in str(err.value)
    Recording(trace(), frame_interval=dt, exposure=dt, times=t, timing_tolerance=0.011)


def test_frame_interval_inferred_from_rounded_stamps_is_the_clocks_not_the_median(tmp_path):
    """Before: the median step (0.7 ms, 5 % off) was taken as the frame interval."""
    p = write_csv(tmp_path / "r.csv", rounded_times(), trace() * 1e9)
    rec = load_csv(p, exposure=DT, timing_tolerance=0.15)
    assert rec.frame_interval == pytest.approx(DT, rel=1e-6)
    with pytest.raises(ValueError, match=r"r\.csv: .*rounded to a resolution of 0\.0001 s"):
        load_csv(p, exposure=DT)


def test_real_unit_slips_and_dropped_frames_keep_their_messages():
    x = trace()
    with pytest.raises(ValueError, match=r"the times look like ms\)\. Check the units of both") as err:
        Recording(x, frame_interval=DT, exposure=DT, times=np.arange(N) * DT * 1e3)
    assert "rounded" not in str(err.value)
    with pytest.raises(ValueError, match=r"frame_interval looks like ms\)\. Check the units"):
        Recording(x, frame_interval=DT * 1e3, exposure=DT, times=np.arange(N) * DT, check_units=False)
    dropped = np.delete(np.arange(N + 5) * DT, [10, 20, 30, 40, 50])
    with pytest.raises(ValueError, match=r"\(dropped frames\?\)\. Pass allow_irregular=True") as err:
        Recording(x, frame_interval=DT, exposure=DT, times=dropped)
    assert "rounded" not in str(err.value)
    jittery = np.arange(N) * DT + np.random.default_rng(1).normal(0.0, 1e-5, N)
    with pytest.raises(ValueError, match=r"times are irregular") as err:
        Recording(x, frame_interval=DT, exposure=DT, times=jittery)
    assert "rounded" not in str(err.value)


def test_stamps_with_full_precision_still_load(tmp_path):
    t = np.arange(N) * DT
    rec = Recording(trace(), frame_interval=DT, exposure=DT, times=t)
    assert rec.frame_interval == DT
    p = write_csv(tmp_path / "ok.csv", t, trace() * 1e9, fmt_t="{!r}")
    assert load_csv(p, exposure=DT).frame_interval == pytest.approx(DT, rel=1e-12)
    # 1 us resolution at 1500 frames/s: rounding far below the tolerance, accepted as before
    assert Recording(trace(), frame_interval=DT, exposure=DT, times=np.round(t, 6)).times is not None


# -- column-vector NPZ -----------------------------------------------------------------------


def test_npz_column_vector_is_one_recording(tmp_path):
    """An (N, 1) array was read as N recordings of 1 frame ("at least 2 frames; got 1")."""
    x = trace()
    np.savez(tmp_path / "col.npz", positions=x[:, None], frame_interval=DT, exposure=DT)
    rec = load_npz(tmp_path / "col.npz")
    assert isinstance(rec, Recording)
    np.testing.assert_array_equal(rec.positions, x)
    t = np.arange(N) * DT
    np.savez(tmp_path / "colt.npz", positions=x[:, None], times=t[:, None], frame_interval=DT,
             exposure=DT)
    np.testing.assert_array_equal(load_npz(tmp_path / "colt.npz").times, t)
    # as from_arrays, and as the 1-D array it holds
    flat = from_arrays(x, frame_interval=DT, exposure=DT)
    np.testing.assert_array_equal(from_arrays(x[:, None], frame_interval=DT, exposure=DT).positions,
                                  flat.positions)


def test_row_vector_and_rows_of_recordings_unchanged(tmp_path):
    x = np.stack([trace(seed=1), trace(seed=2)])
    np.savez(tmp_path / "rows.npz", positions=x, frame_interval=DT, exposure=DT)
    assert len(load_npz(tmp_path / "rows.npz")) == 2
    np.savez(tmp_path / "row.npz", positions=x[:1], frame_interval=DT, exposure=DT)
    assert len(load_npz(tmp_path / "row.npz")) == 1


def test_recordings_in_columns_name_the_transpose():
    x = np.stack([trace(seed=1), trace(seed=2)], axis=1)  # (N, 2): recordings in columns
    x[5] = 0.0  # row 5 (a "recording" of 2 frames) is constant
    with pytest.raises(ValueError, match=r"shape \(4096, 2\): rows are recordings, so this is 4096 "
                                         r"recordings of 2 frames each; .* pass positions\.T"):
        from_arrays(x, frame_interval=DT, exposure=DT)


# -- positions rounded to whole pixels -------------------------------------------------------


def test_positions_rounded_to_whole_pixels_are_named(tmp_path):
    px = 110e-9
    x_px = np.round(trace(std=9e-9) / px)  # all |x| < 55 nm: every frame rounds to pixel 0
    assert np.all(x_px == 0)
    t = np.arange(N) * DT
    write_csv(tmp_path / "px.csv", t, x_px, fmt_t="{!r}", column="x_px")
    entry = {"file": "px.csv", "frame_interval_s": DT, "exposure_s": DT, "temperature_K": 295.0}
    man = tmp_path / "m_px.json"
    man.write_text(json.dumps({"position_unit": "px", "pixel_size_m": px, "recordings": [entry]}))
    with pytest.raises(ValueError, match=r"px\.csv: positions is constant .*position_unit 'px'\) look "
                                         r"quantised, rounded to whole pixels.*Export sub-pixel positions"):
        load_manifest(man)
    with pytest.raises(ValueError, match=r"rounded to whole pixels"):
        from_arrays(x_px, frame_interval=DT, exposure=DT, position_unit="px", pixel_size_m=px)
    # sub-pixel positions in the same file load
    sub = trace(std=9e-9) / px
    write_csv(tmp_path / "px.csv", t, sub, fmt_t="{!r}", column="x_px")
    assert load_manifest(man)[0].positions.std() == pytest.approx(sub.std() * px)


def test_constant_trace_in_metres_keeps_its_message():
    with pytest.raises(ValueError, match=r"positions is constant .*not a position trace") as err:
        Recording(np.zeros(100), frame_interval=DT, exposure=DT)
    assert "pixels" not in str(err.value)
