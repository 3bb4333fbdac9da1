"""Recording: construction, immutability, derived properties and every validation error."""

import numpy as np
import pytest

from blurtrap.data import Recording, TimingJitter

DT = 1e-3
W = 4e-4


def trace(rng, n=200, scale=1e-8):
    return rng.normal(0.0, scale, n)


def make(rng, **kw):
    args = dict(frame_interval=DT, exposure=W)
    args.update(kw)
    pos = args.pop("positions", None)
    return Recording(trace(rng) if pos is None else pos, **args)


def test_fields_and_derived(rng):
    x = trace(rng, 250)
    r = Recording(x, frame_interval=DT, exposure=W, temperature=300.0, laser_power=0.05, name="a")
    assert r.positions.dtype == np.float64
    np.testing.assert_array_equal(r.positions, x)
    assert r.n_frames == 250
    assert r.duration == pytest.approx(0.25, rel=1e-15)
    assert r.sampling_rate == pytest.approx(1000.0, rel=1e-15)
    assert (r.frame_interval, r.exposure, r.temperature, r.laser_power) == (DT, W, 300.0, 0.05)
    assert r.name == "a" and r.times is None and r.timing_jitter is None
    assert Recording(x, frame_interval=DT, exposure=W).temperature == 295.0


def test_immutable_and_private_copy(rng):
    x = trace(rng)
    r = Recording(x, frame_interval=DT, exposure=W, metadata={"a": [1, 2]})
    x[0] = 1.0  # the caller's array is not aliased
    assert r.positions[0] != 1.0
    with pytest.raises(ValueError, match="read-only"):
        r.positions[0] = 0.0
    with pytest.raises(AttributeError, match="immutable"):
        r.exposure = 1e-4
    with pytest.raises(TypeError):
        r.metadata["b"] = 1
    assert r.metadata["a"] == (1, 2)


def test_replace_revalidates(rng):
    r = make(rng)
    r2 = r.replace(exposure=2e-4)
    assert r2.exposure == 2e-4 and r.exposure == W
    with pytest.raises(ValueError, match="exposure = 0.002 s is longer than frame_interval"):
        r.replace(exposure=2e-3)


def test_equality(rng):
    x = trace(rng)
    a = Recording(x, frame_interval=DT, exposure=W)
    assert a == Recording(x.copy(), frame_interval=DT, exposure=W)
    assert a != Recording(x, frame_interval=DT, exposure=W / 2)


def test_integer_positions_converted_and_noted(rng):
    counts = rng.integers(-50, 50, 300)
    r = Recording(counts, frame_interval=DT, exposure=W, check_units=False)
    assert r.positions.dtype == np.float64
    assert r.metadata["input_dtype"] == "int64"
    np.testing.assert_array_equal(r.positions, counts.astype(float))


def test_float32_positions_noted(rng):
    r = Recording(trace(rng).astype(np.float32), frame_interval=DT, exposure=W)
    assert r.positions.dtype == np.float64 and r.metadata["input_dtype"] == "float32"


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_nonfinite_positions_report_index_and_count(rng, bad):
    x = trace(rng)
    x[[7, 42]] = bad
    with pytest.raises(ValueError, match=r"2 non-finite value\(s\).*index \[7, 42\]"):
        Recording(x, frame_interval=DT, exposure=W)


@pytest.mark.parametrize(
    "positions, match",
    [
        (np.array([1e-8]), "at least 2 frames; got 1"),
        (np.zeros((3, 4)), r"1-D array .*got shape \(3, 4\)"),
        (np.float64(1.0), r"1-D array .*got shape \(\)"),
        (np.full(10, 3e-9), "constant"),
        (np.array([True, False]), "boolean"),
        (np.array([1j, 2j]), "complex"),
        (np.array(["a", "b"]), "numeric"),
    ],
)
def test_bad_positions(positions, match):
    with pytest.raises(ValueError, match=match):
        Recording(positions, frame_interval=DT, exposure=W)


@pytest.mark.parametrize(
    "kw, match",
    [
        (dict(exposure=0.0), "exposure must be > 0"),
        (dict(exposure=-1e-4), "exposure must be > 0"),
        (dict(exposure=2e-3), "exposure = 0.002 s is longer than frame_interval = 0.001 s"),
        (dict(frame_interval=0.0), "frame_interval must be > 0"),
        (dict(frame_interval=np.nan), "frame_interval must be finite"),
        (dict(frame_interval="1e-3"), "frame_interval must be a real scalar"),
        (dict(exposure=None), "exposure must be a number"),
        (dict(exposure=True), "exposure must be a number"),
        (dict(temperature=0.0), "temperature must be > 0"),
        (dict(temperature=-5.0), "temperature must be > 0"),
        (dict(temperature=22.0), r"temperature = 22.0 K .*looks like Celsius.*295.15 K"),
        (dict(frame_interval=5.0, exposure=1e-3), r"frame_interval = 5.0 s .*looks like ms"),
        (dict(frame_interval=0.01, exposure=0.0), "exposure must be > 0"),
        (dict(laser_power=-0.1), "laser_power must be >= 0"),
        (dict(laser_power=100.0), "looks like mW"),
        (dict(timing_tolerance=0.0), "timing_tolerance must be > 0"),
        (dict(name=3), "name must be a str"),
        (dict(metadata={1: "x"}), "metadata keys must be strings"),
        (dict(metadata={"x": object()}), r"metadata\['x'\] .* has type object"),
    ],
)
def test_bad_scalars(rng, kw, match):
    with pytest.raises(ValueError, match=match):
        make(rng, **kw)


def test_exposure_in_ms_hint(rng):
    with pytest.raises(ValueError, match=r"exposure = 2.0 s .*looks like ms.*0.002 s"):
        make(rng, frame_interval=0.05, exposure=2.0)
    # with the heuristics off, genuinely slow acquisitions are allowed
    r = make(rng, frame_interval=5.0, exposure=2.0, check_units=False)
    assert r.exposure == 2.0


def test_exposure_equal_to_frame_interval_is_allowed(rng):
    assert make(rng, exposure=DT).exposure == DT


def test_positions_in_nm_hint(rng):
    with pytest.raises(ValueError, match="positions look like nm or pixels, not metres"):
        Recording(trace(rng, scale=20.0), frame_interval=DT, exposure=W)
    r = Recording(trace(rng, scale=20.0), frame_interval=DT, exposure=W, check_units=False)
    assert r.n_frames == 200


def test_regular_times_and_jitter_property(rng):
    n = 500
    t = 10.0 + np.arange(n) * DT + rng.normal(0, 1e-4 * DT, n)  # jitter well inside 1e-3
    r = make(rng, positions=trace(rng, n), times=t)
    j = r.timing_jitter
    assert isinstance(j, TimingJitter)
    assert 0 < j.std < 2e-4 * DT and j.max_deviation < 1e-3 * DT
    assert j.fitted_interval == pytest.approx(DT, rel=1e-5)
    assert r.is_regular


def test_irregular_times_error_then_allowed(rng):
    n = 400
    t = np.arange(n) * DT
    t[200:] += DT  # a dropped frame
    x = trace(rng, n)
    with pytest.raises(ValueError, match=r"times are irregular: .*std .* s and max .* s"):
        Recording(x, frame_interval=DT, exposure=W, times=t)
    r = Recording(x, frame_interval=DT, exposure=W, times=t, allow_irregular=True)
    assert not r.is_regular
    assert r.timing_jitter.max_deviation == pytest.approx(0.5 * DT, rel=0.05)


def test_nonincreasing_times_report_index_and_values(rng):
    t = np.arange(200) * DT
    t[50] = t[49]
    with pytest.raises(
        ValueError, match=r"strictly increasing; times\[50\] = 0.049 s is not after times\[49\]"
    ):
        make(rng, times=t)


@pytest.mark.parametrize(
    "times, match",
    [
        (np.arange(199) * DT, r"one time stamp per frame \(200\)"),
        (np.where(np.arange(200) == 3, np.nan, np.arange(200) * DT), "times contains 1 non-finite"),
        (np.arange(200) * 1e-6, r"imply a frame interval of 1e-06 s .*frame_interval = 0.001 s"),
    ],
)
def test_bad_times(rng, times, match):
    with pytest.raises(ValueError, match=match):
        make(rng, times=times)


def test_accepts_jax_arrays(rng):
    import jax.numpy as jnp

    x = trace(rng)
    r = Recording(jnp.asarray(x), frame_interval=jnp.asarray(DT), exposure=W)
    np.testing.assert_array_equal(r.positions, x)
    assert isinstance(r.positions, np.ndarray)


# ---- unit slips in the position scale (both directions) ----------------------------------------
KT = 1.380649e-23 * 295.0
SCALE = {"m": 1.0, "mm": 1e-3, "um": 1e-6, "nm": 1e-9}
WORD = {"m": "metres", "mm": "mm", "um": "um", "nm": "nm"}


def _gauss(std, n=400):
    x = np.random.default_rng(7).standard_normal(n)
    return x / x.std() * std


@pytest.mark.parametrize("k", [1e-7, 1e-6, 1e-5, 1e-4, 1e-3, 1e-2])
@pytest.mark.parametrize("blur", [1.0, 1e-3])
@pytest.mark.parametrize("unit", ["m", "um", "nm"])
def test_every_physical_trap_passes_the_scale_check(k, blur, unit):
    """Thermal std sqrt(kT/k) from very soft (1e-7 N/m) to very stiff (1e-2 N/m) traps, with
    the variance blurred down up to 1000-fold, declared in the right unit: accepted."""
    from blurtrap.data import from_arrays

    std = np.sqrt(KT / k * blur)
    r = from_arrays(_gauss(std) / SCALE[unit], frame_interval=DT, exposure=W, position_unit=unit)
    assert r.positions.std() == pytest.approx(std, rel=1e-9)


SLIPS = [(true, declared) for true in SCALE for declared in SCALE if true != declared]


@pytest.mark.parametrize("true_unit, declared", SLIPS, ids=[f"{t}-as-{d}" for t, d in SLIPS])
@pytest.mark.parametrize("true_std", [0.64e-9, 1e-8, 2e-7])
def test_unit_slips_of_a_physical_trace_are_caught_and_named(true_unit, declared, true_std):
    """The numbers of a real trace (std 0.64 nm .. 200 nm) written in one unit and declared
    in another: whenever the result is outside any trapped bead's range it is an error that
    names the slip (for a typical 10 nm trace, the exact units), else it passes; with
    check_units=False it is always accepted."""
    from blurtrap.data import from_arrays

    numbers = _gauss(true_std) / SCALE[true_unit]
    seen = true_std * SCALE[declared] / SCALE[true_unit]  # the std the loader sees [m]
    kw = dict(frame_interval=DT, exposure=W, position_unit=declared)
    if 2e-11 <= seen <= 1e-5:
        from_arrays(numbers, **kw)
        return
    with pytest.raises(ValueError, match=r"positions have standard deviation .* m, (below|above)") as e:
        from_arrays(numbers, **kw)
    msg = str(e.value)
    assert "check_units=False" in msg and f"declared unit {declared!r}" in msg
    if true_std == 1e-8:
        if declared == "m" and seen > 1e-5:
            assert f"positions look like {WORD[true_unit]} or pixels, not metres" in msg
        else:
            assert f"positions look like {WORD[true_unit]} declared as {WORD[declared]}" in msg
    assert from_arrays(numbers, check_units=False, **kw).n_frames == 400


@pytest.mark.parametrize(
    "numbers, unit, match",
    [
        (_gauss(1e-8), "nm", r"1e-17 m, below .*positions look like metres declared as nm"),
        (_gauss(0.01), "nm", r"1e-11 m, below .*positions look like um declared as nm"),
        (_gauss(0.001), "nm", r"1e-12 m, below .*positions look like um declared as nm"),
        (_gauss(20.0), "m", r"20 m, above .*positions look like nm or pixels, not metres"),
        (_gauss(30.0), "um", r"3e-05 m, above .*positions look like nm declared as um"),
    ],
)
def test_unit_slip_examples(numbers, unit, match):
    from blurtrap.data import from_arrays

    with pytest.raises(ValueError, match=match):
        from_arrays(numbers, frame_interval=DT, exposure=W, position_unit=unit)


def test_position_bounds_are_at_their_stated_values():
    ok = [2.01e-11, 9.99e-6]
    for std in ok:
        Recording(_gauss(std), frame_interval=DT, exposure=W)
    for std in (1.99e-11, 1.01e-5):
        with pytest.raises(ValueError, match="positions have standard deviation"):
            Recording(_gauss(std), frame_interval=DT, exposure=W)


# ---- time in ms, temperature in mK ---------------------------------------------------------------
RATES = [100, 200, 500, 1000, 1500, 2000, 5000, 10_000]  # frames/s; in ms: 10 .. 0.1 "s"


@pytest.mark.parametrize("fps", RATES)
def test_frame_interval_in_ms_is_caught_for_common_rates(fps):
    dt_ms = 1e3 / fps
    with pytest.raises(ValueError, match=rf"frame_interval = {dt_ms!r} s is at least 0.1 s "
                       rf".*looks like ms.*did you mean {dt_ms * 1e-3!r} s, {fps:g} frames/s"):
        Recording(trace(np.random.default_rng(0)), frame_interval=dt_ms, exposure=1e-4)
    with pytest.raises(ValueError, match=rf"exposure = {dt_ms!r} s is at least 0.1 s .*looks like ms"):
        Recording(trace(np.random.default_rng(0)), frame_interval=0.05, exposure=dt_ms)
    r = Recording(trace(np.random.default_rng(0)), frame_interval=dt_ms, exposure=1e-4,
                  check_units=False)
    assert r.frame_interval == dt_ms


@pytest.mark.parametrize("fps", [20, 25, 30, 60, 100, 1500, 1e4, 1e5, 1e6])
def test_genuine_frame_rates_pass(fps):
    r = Recording(trace(np.random.default_rng(0)), frame_interval=1 / fps, exposure=0.5 / fps)
    assert r.sampling_rate == pytest.approx(fps)


def test_interval_bound_is_at_0_1_s():
    x = trace(np.random.default_rng(0))
    Recording(x, frame_interval=0.0999, exposure=0.05)
    with pytest.raises(ValueError, match="frame_interval = 0.1 s is at least 0.1 s"):
        Recording(x, frame_interval=0.1, exposure=0.05)


def test_times_in_ms_with_frame_interval_in_s():
    t_ms = np.arange(200) * (1e3 / 1500)
    with pytest.raises(ValueError, match=r"times imply a frame interval of 0.666667 s .*"
                       r"frame_interval = 0.000666667 s.*the times look like ms"):
        Recording(trace(np.random.default_rng(0)), frame_interval=1 / 1500, exposure=1e-4,
                  times=t_ms)


@pytest.mark.parametrize(
    "temp, match",
    [
        (295_000.0, r"temperature = 295000.0 K is above 400 K: this looks like millikelvin "
                    r"\(did you mean 295 K\?\)"),
        (310_150.0, r"looks like millikelvin \(did you mean 310.15 K\?\)"),
        (1e6, r"temperature = 1000000.0 K is above 400 K: no trapping experiment .*"
              r"Expected kelvin between 100 and 400 K"),
        (400.5, r"temperature = 400.5 K is above 400 K"),
        (5000.0, r"above 400 K: no trapping experiment in liquid water"),
    ],
)
def test_implausibly_hot_temperatures(temp, match):
    x = trace(np.random.default_rng(0))
    with pytest.raises(ValueError, match=match):
        Recording(x, frame_interval=DT, exposure=W, temperature=temp)
    assert Recording(x, frame_interval=DT, exposure=W, temperature=temp,
                     check_units=False).temperature == temp


@pytest.mark.parametrize("temp", [100.0, 273.15, 295.0, 373.15, 400.0])
def test_plausible_temperatures_pass(temp):
    assert make(np.random.default_rng(0), temperature=temp).temperature == temp


# ---- text where numbers are expected -------------------------------------------------------------
TEXT_POSITIONS = [
    np.array(["1e-9", "2e-9", "-1e-9"]),  # numpy str (would cast silently)
    ["1e-9", "2e-9", "-1e-9"],  # list of str
    np.array([b"1e-9", b"2e-9"]),  # bytes
    [1e-9, "2e-9", 3e-9],  # mixed: numpy makes all of it text
    np.array([1e-9, "2e-9", 3e-9], dtype=object),  # object array with a str
    np.array(["a", "b"]),
]


@pytest.mark.parametrize("positions", TEXT_POSITIONS, ids=range(len(TEXT_POSITIONS)))
def test_text_positions_are_a_clear_error(positions):
    from blurtrap.data import from_arrays

    match = r"positions must be numeric \[{}\]; got text \(an array of dtype .*\)\. Convert"
    with pytest.raises(ValueError, match=match.format("m")):
        Recording(positions, frame_interval=DT, exposure=W)
    with pytest.raises(ValueError, match=match.format("nm")):
        from_arrays(positions, frame_interval=DT, exposure=W, position_unit="nm")


def test_text_times_are_a_clear_error(rng):
    with pytest.raises(ValueError, match=r"times must be numeric \[s\]; got text"):
        make(rng, times=[str(i * DT) for i in range(200)])


def test_object_arrays_of_numbers_are_converted_with_the_unit():
    """An object array of numbers (e.g. Decimal) is converted, and from_arrays applies the
    unit to it (it used to pass such arrays on without converting nm to m)."""
    from decimal import Decimal

    from blurtrap.data import from_arrays

    vals = np.array([Decimal("1.5"), Decimal("-2"), Decimal("3")], dtype=object)
    r = from_arrays(vals, frame_interval=DT, exposure=W, position_unit="nm")
    np.testing.assert_array_equal(r.positions, [1.5e-9, -2e-9, 3e-9])


# ---- timing jitter: per-interval, not the accumulated clock wander ------------------------------
def test_jitter_of_a_wandering_clock_is_the_per_interval_std():
    """Intervals dt + e_i with independent e_i of std 33 us (the clock wanders): the reported
    jitter std is ~33 us, while the deviation from the best regular grid (grid_std) is the
    accumulated wander, tens of times larger."""
    rng = np.random.default_rng(12)
    n, dt, s = 90_000, 1 / 1500, 33e-6
    t = np.concatenate([[0.0], np.cumsum(dt + rng.normal(0, s, n - 1))])
    r = Recording(rng.normal(0, 1e-8, n), frame_interval=dt, exposure=1e-4, times=t,
                  allow_irregular=True)
    j = r.timing_jitter
    assert j.std == pytest.approx(s, rel=0.02)
    assert j.std == pytest.approx(float(np.std(np.diff(t))), rel=1e-12)
    assert j.grid_std > 20 * j.std and j.max_deviation > j.grid_std
    assert j.fitted_interval == pytest.approx(dt, rel=1e-3)


def test_jitter_of_independent_stamp_errors():
    """t_i = i dt + delta_i, delta_i independent with std sigma: std = sqrt(2) sigma (the
    intervals' std) and grid_std = sigma."""
    rng = np.random.default_rng(13)
    n, dt, sigma = 50_000, 1e-3, 2e-5
    t = np.arange(n) * dt + rng.normal(0, sigma, n)
    j = Recording(rng.normal(0, 1e-8, n), frame_interval=dt, exposure=1e-4, times=t,
                  allow_irregular=True).timing_jitter
    assert j.std == pytest.approx(np.sqrt(2) * sigma, rel=0.02)
    assert j.grid_std == pytest.approx(sigma, rel=0.02)


def test_irregular_error_reports_both_jitters():
    rng = np.random.default_rng(14)
    t = np.concatenate([[0.0], np.cumsum(DT + rng.normal(0, 1e-5, 999))])
    with pytest.raises(ValueError, match=r"per-interval jitter \(std of the frame intervals\) std "
                       r"\S+e-0[56] s and max deviation .* grid deviation std .* s\).*"
                       r"allow_irregular=True"):
        Recording(trace(rng, 1000), frame_interval=DT, exposure=W, times=t)


def test_timing_jitter_positional_construction_still_works():
    j = TimingJitter(1e-5, 2e-5, 1e-3)
    assert (j.std, j.max_deviation, j.fitted_interval, j.grid_std) == (1e-5, 2e-5, 1e-3, None)
