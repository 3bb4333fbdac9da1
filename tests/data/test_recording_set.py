"""RecordingSet: sequence behaviour, per-recording arrays, grouping and consistency notes."""

import numpy as np
import pytest

from blurtrap.data import Recording, RecordingSet


def rec(rng, exposure=1e-4, power=None, temperature=295.0, name=None, dt=1e-3):
    return Recording(
        rng.normal(0, 1e-8, 100),
        frame_interval=dt,
        exposure=exposure,
        laser_power=power,
        temperature=temperature,
        name=name,
    )


def test_sequence_protocol(rng):
    rs = [rec(rng, exposure=w, name=f"r{i}") for i, w in enumerate([1e-4, 2e-4, 5e-4])]
    s = RecordingSet(rs)
    assert len(s) == 3 and list(s) == rs and s[1] is rs[1] and s[-1] is rs[2]
    sub = s[1:]
    assert isinstance(sub, RecordingSet) and sub.names == ("r1", "r2")
    np.testing.assert_array_equal(s.exposures, [1e-4, 2e-4, 5e-4])
    np.testing.assert_array_equal(s.frame_intervals, [1e-3] * 3)
    np.testing.assert_array_equal(s.temperatures, [295.0] * 3)
    np.testing.assert_array_equal(s.n_frames, [100] * 3)
    assert s.notes == ()
    with pytest.raises(AttributeError, match="immutable"):
        s._recordings = ()
    assert s == RecordingSet(tuple(rs))


def test_laser_powers_nan_where_absent_and_reported(rng):
    s = RecordingSet([rec(rng, power=0.1), rec(rng), rec(rng, power=0.05)])
    p = s.laser_powers
    assert p[0] == 0.1 and np.isnan(p[1]) and p[2] == 0.05
    assert any("laser_power is missing for 1 of 3 recordings (indices [1])" in n for n in s.notes)
    with pytest.raises(
        ValueError, match=r"laser_power is missing for 1 of 3 recordings \(indices \[1\]"
    ):
        s.require_laser_power()


def test_group_by_power(rng):
    s = RecordingSet([rec(rng, power=0.2), rec(rng), rec(rng, power=0.1), rec(rng, power=0.2)])
    g = s.group_by_power()
    assert list(g) == [0.1, 0.2, None]
    assert [len(v) for v in g.values()] == [1, 2, 1]
    assert g[0.2][0] is s[0] and g[0.2][1] is s[3] and g[None][0] is s[1]


def test_notes_for_mixed_temperature_interval_and_names(rng):
    s = RecordingSet(
        [rec(rng, temperature=295.0, name="a"), rec(rng, temperature=310.0, name="a", dt=2e-3)]
    )
    text = " | ".join(s.notes)
    assert "2 different temperatures" in text
    assert "2 different frame intervals" in text
    assert "duplicate recording names: ['a']" in text


def test_empty_and_wrong_items(rng):
    with pytest.raises(ValueError, match="at least one recording; got an empty"):
        RecordingSet([])
    with pytest.raises(TypeError, match="item 1 is a ndarray, not a Recording"):
        RecordingSet([rec(rng), np.zeros(3)])
    with pytest.raises(TypeError, match="iterable of Recording"):
        RecordingSet(5)
