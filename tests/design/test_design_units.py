"""bt.design's inputs in the wrong unit are named (parameter, value, likely unit, what was
expected) before any computation, instead of "dt >> tau ... allow a faster frame rate"; the
current design's frame counts are checked; plausible inputs are designed as before."""

import warnings

import pytest

import blurtrap as bt

BASE = dict(k=(1e-5, 5e-5), radius=1.53e-6, max_fps=1500, total_time=60, tracking_std=2e-9,
            target="both")


def design(**kw):
    return bt.design(**{**BASE, **kw})


@pytest.mark.parametrize("kw, pattern", [
    (dict(radius=1.53), r"radius = 1\.53 m is not below 0\.001 m.*looks like 1\.53 um = 1\.53e-06 m, "
                        r"not metres.*design takes metres"),
    (dict(radius=765.0), r"radius = 765 m .*looks like 765 nm = 7\.65e-07 m"),
    (dict(tracking_std=2.0), r"tracking_std = 2 m is above 1e-05 m .*looks like nm \(2 nm\), not metres"),
    (dict(k=(10.0, 50.0)), r"k = 10 N/m is outside the plausible range of the trap stiffness, "
                           r"1e-10\.\.1 N/m: this looks like lab units \(10 pN/um = 1e-05 N/m or "
                           r"10 pN/nm = 0\.01 N/m\), not N/m\. design takes SI \(N/m\)"),
    (dict(radius=None, gamma=0.0289), r"gamma = 0\.0289 N s/m is outside the plausible range of the "
                                      r"friction coefficient.*0\.0289 pN s/um = 2\.89e-08 N s/m"),
    (dict(temperature=22.0), r"temperature = 22\.0 K is below 100 K: this looks like Celsius"),
    (dict(min_exposure=0.5), r"min_exposure = 0\.5 s is at least 0\.1 s.*looks like ms"),
    (dict(current=[(0.667, 0.5, 10_000)]), r"current\[0\]: frame_interval = 0\.667 s .*looks like ms"),
])
def test_unit_slips_are_named(kw, pattern):
    with pytest.raises(ValueError, match=pattern) as err:
        design(**kw)
    assert "dt >> tau" not in str(err.value)


@pytest.mark.parametrize("frames", [0, 1, -5])
def test_current_design_needs_at_least_two_frames(frames):
    with pytest.raises(ValueError, match=rf"current\[1\]: frames = {frames}; a recording needs at least 2 "
                                         r"frames"):
        design(current=[(1 / 1500, 1 / 1500, 1000), (1 / 1500, 1 / 1500, frames)])


def test_plausible_inputs_and_the_escape_hatch_are_designed():
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no warning for plausible inputs
        res = bt.design(k=5e-5, radius=1.53e-6, max_fps=1500, n_frames=4096, tracking_std=2e-9,
                        series=(), current=[(1 / 1500, 1 / 3000, 4096)])
    assert res.best.objective > 0
    # check_units=False keeps the old behaviour: a 1 mm "bead" is designed for (no identification)
    with pytest.raises(ValueError, match=r"no candidate design identifies"):
        bt.design(k=5e-5, radius=1.53, max_fps=1500, n_frames=4096, series=(), check_units=False)


def test_slow_frame_rate_is_accepted_with_a_warning_naming_khz():
    """1.5 frames/s may be a slow camera on a soft trap: designed, but the kHz slip is named."""
    with pytest.warns(UserWarning, match=r"max_fps = 1\.5 Hz is below 10 frames/s: if the camera runs at "
                                         r"1\.5 kHz, pass max_fps=1500 \(Hz\)"):
        res = bt.design(k=5e-5, radius=1.53e-6, max_fps=1.5, total_time=600, series=(), target="k",
                        friction_error=0.05)
    assert res.best.recordings[0][0] == pytest.approx(1 / 1.5)


@pytest.mark.parametrize("kw, pattern", [
    (dict(min_exposure=2e-3), r"min_exposure = 0\.002 s is longer than the frame interval at max_fps = 1500 Hz "
                              r"\(1/max_fps = 0\.000667 s\): an exposure cannot be longer than the frame "
                              r"interval; lower min_exposure or max_fps"),
    (dict(min_exposure=5e-4, max_fps=2000), r"min_exposure = 0\.0005 s is as long as the frame interval at "
                                            r"max_fps = 2000 Hz"),
    (dict(dead_time=1e-3), r"dead_time = 0\.001 s leaves no time for an exposure: .*dead_time must be below "
                           r"1/max_fps - min_exposure = 0\.000666 s"),
    (dict(dead_time=-1e-3), r"dead_time must be >= 0 s; got dead_time = -0\.001"),
])
def test_exposure_longer_than_the_frame_interval_is_named(kw, pattern):
    """No range with a negative end ("[0, -0.00133)"): the exposure that does not fit in the
    frame interval, or the dead time that leaves no exposure, is named."""
    with pytest.raises(ValueError, match=pattern) as err:
        design(**kw)
    assert "[0, -" not in str(err.value)


@pytest.mark.parametrize("kw, n_rec, need", [(dict(total_time=0.01), 4, 0.171),
                                             (dict(total_time=0.3, series=(1, 10)), 10, 0.427),
                                             (dict(total_time=0.1, laser_powers=(0.5, 1, 2, 3, 4)), 5, 0.214)])
def test_a_total_time_too_short_for_64_frames_per_recording_is_refused(kw, n_rec, need):
    """A total time split into recordings of a few frames each (7 frames per recording, SEs of
    35 %, were designed) is refused, naming the frames it gives and the time it takes."""
    with pytest.raises(ValueError, match=rf"total_time = {kw['total_time']:g} s is .* frames at max_fps = "
                                         rf"1500 Hz, too few to split into {n_rec} recordings .* at least 64 "
                                         rf"frames each: give total_time >= {need}"):
        design(**kw)
    enough = design(**{**kw, "total_time": need})
    assert all(n >= 64 for _, _, n in enough.best.recordings)
