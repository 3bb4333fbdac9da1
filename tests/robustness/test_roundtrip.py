"""Round trips with hypothesis-generated recordings: write then read gives the same recordings
bit for bit (positions, times, every scalar field, names, metadata).

Manifest + CSV: positions in m, mm, um, µm, nm are written as exact decimals, so they come
back identical to the last bit (including -0.0, subnormals, 17-digit values and, with
``check_units=False``, magnitudes up to 1e300 m); recordings without time stamps come back with
``t = i * frame_interval``; the metadata keys that the loader sets itself (``_LOADER_KEYS`` and
``manifest``) are the only additions. NPZ keeps the raw float64 arrays and gives back an equal
Recording / RecordingSet.
"""

import tempfile
from pathlib import Path

import numpy as np
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

from blurtrap.data import Recording, RecordingSet, load, load_manifest, load_npz, save_manifest, save_npz
from blurtrap.data._manifest import _LOADER_KEYS

ROUND = settings(
    max_examples=40,
    deadline=None,
    derandomize=True,
    database=None,
    suppress_health_check=[HealthCheck.too_slow],
)
RESERVED = set(_LOADER_KEYS) | {"manifest"}

_meta_leaf = (st.none() | st.booleans() | st.integers(-(2**70), 2**70)
              | st.floats(allow_nan=False) | st.text(max_size=8))
METADATA = st.dictionaries(
    st.text(min_size=1, max_size=8).filter(lambda k: k not in RESERVED),
    st.recursive(_meta_leaf, lambda c: st.lists(c, max_size=3)
                 | st.dictionaries(st.text(max_size=5), c, max_size=2), max_leaves=5),
    max_size=4,
)


@st.composite
def recordings(draw, check_units=None):
    n = draw(st.integers(2, 40))
    check = draw(st.booleans()) if check_units is None else check_units
    bound = 1e-5 if check else 1e300  # check_units: a position std within 2e-11..1e-5 m
    pos = draw(st.lists(st.floats(-bound, bound, allow_nan=False), min_size=n, max_size=n))
    pos[0] = draw(st.sampled_from([pos[0], 0.0, -0.0, 5e-324, -2.2250738585072014e-308]))
    assume(len(set(pos)) > 1)
    if check:
        assume(2e-11 <= np.std(pos) <= 1e-5)
    # (irregular stamps stretch it by up to 1.5; check_units rejects intervals >= 0.1 s)
    dt = draw(st.floats(1e-6, 0.06 if check else 0.5))
    times, allow_irregular, tol = None, False, 1e-3
    kind = draw(st.sampled_from(["none", "regular", "irregular"]))
    if kind == "regular":
        times = draw(st.floats(-1e3, 1e5)) + np.arange(n) * dt
        assume(np.all(np.diff(times) > 0))
    elif kind == "irregular":  # dropped / uneven frames, kept with allow_irregular
        times = np.cumsum(draw(st.lists(st.floats(0.5, 1.5), min_size=n, max_size=n))) * dt
        assume(np.all(np.diff(times) > 0))
        dt = float(np.median(np.diff(times)))
        allow_irregular, tol = True, draw(st.sampled_from([1e-3, 0.25, 1.0]))
    return Recording(
        np.array(pos),
        frame_interval=dt,
        exposure=dt * draw(st.floats(1e-6, 1.0)),
        temperature=draw(st.floats(100.0, 400.0)),
        times=times,
        laser_power=draw(st.none() | st.floats(0.0, 10.0)),
        metadata=draw(METADATA),
        name=draw(st.none() | st.text(max_size=12)),
        allow_irregular=allow_irregular,
        timing_tolerance=tol,
        check_units=check,
    )


def bits(a):
    return np.asarray(a, dtype=np.float64).tobytes()


SCALARS = ("frame_interval", "exposure", "temperature", "laser_power", "name", "allow_irregular",
           "timing_tolerance", "check_units")


def assert_same_after_csv(a: Recording, b: Recording):
    assert bits(b.positions) == bits(a.positions)
    t_ref = a.times if a.times is not None else np.arange(a.n_frames, dtype=np.float64) * a.frame_interval
    assert bits(b.times) == bits(t_ref)
    for f in SCALARS:
        va, vb = getattr(a, f), getattr(b, f)
        assert va == vb and type(va) is type(vb), (f, va, vb)
        if isinstance(va, float):
            assert bits(va) == bits(vb), f
    user = {k: v for k, v in b.metadata.items() if k not in RESERVED}
    assert user == dict(a.metadata)


@ROUND
@given(st.lists(recordings(), min_size=1, max_size=3), st.sampled_from(["m", "mm", "um", "µm", "nm"]))
def test_manifest_round_trip_bit_exact(recs, unit):
    s = RecordingSet(recs)
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "set.json"
        written = save_manifest(s, path, position_unit=unit)
        assert len(written) == len(s) + 1 and len({p.name.lower() for p in written}) == len(written)
        back = load_manifest(path)
        again = load(path)
    assert len(back) == len(s)
    for a, b in zip(s, back, strict=True):
        assert_same_after_csv(a, b)
    assert back == again  # loading is deterministic


@ROUND
@given(st.lists(recordings(), min_size=1, max_size=3), st.booleans())
def test_npz_round_trip_bit_exact(recs, compress):
    data = RecordingSet(recs) if len(recs) > 1 else recs[0]
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "data.npz"
        save_npz(data, path, compress=compress)
        back = load_npz(path)
    assert type(back) is type(data) and back == data  # every field, metadata included
    pairs = zip(data, back, strict=True) if isinstance(data, RecordingSet) else [(data, back)]
    for a, b in pairs:
        assert bits(b.positions) == bits(a.positions)
        assert (a.times is None and b.times is None) or bits(b.times) == bits(a.times)
        assert all(bits(getattr(b, f)) == bits(getattr(a, f)) for f in SCALARS[:3])
        assert b.timing_jitter == a.timing_jitter


@ROUND
@given(recordings(check_units=True))
def test_manifest_then_npz_then_manifest(rec):
    """Chaining the formats loses nothing either: CSV -> NPZ -> CSV gives the same bits."""
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        save_manifest(rec, tmp / "a.json")
        (first,) = load_manifest(tmp / "a.json")
        save_npz(first, tmp / "b.npz")
        second = load_npz(tmp / "b.npz")
        (tmp / "c").mkdir()
        save_manifest(second, tmp / "c" / "c.json", position_unit="um")
        (third,) = load_manifest(tmp / "c" / "c.json")
    assert second == first
    assert bits(third.positions) == bits(rec.positions) and bits(third.times) == bits(first.times)
