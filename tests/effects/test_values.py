"""Effect objects carry their parameter values (SI, checked when made); a model keeps only the
effect's structure; each effect says how it is simulated or why it cannot be."""

import math

import equinox as eqx
import numpy as np
import pytest

from blurtrap import effects as fx
from blurtrap.diagnostics._candidates import valid_candidates
from blurtrap.effects import injections as inj
from blurtrap.inference import get_model

#: (class, value field, a valid value, invalid values, the expectation the error states)
FIELDS = [
    (fx.TrackingNoise, "tracking_var", 1e-17, [-1e-18, math.nan], ">= 0 m^2"),
    (fx.Drift, "drift_diffusion", 2e-16, [-1.0, math.inf], ">= 0 m^2/s"),
    (fx.LineNoise, "line_amplitude", 1e-9, [-1e-9], ">= 0 m"),
    (fx.DetectorFilter, "f3db", 8e3, [0.0, -5.0], "> 0 Hz"),
    (fx.DetectorFilter, "diode_alpha", 0.4, [1.5, -0.1], "in [0, 1]"),
    (fx.Hydrodynamics, "hydro_radius", 1.5e-6, [0.0], "> 0 m"),
    (fx.TimingJitter, "std", 1e-6, [-1e-6], ">= 0 s"),
    (fx.ExposureKernel, "rise_fraction", 0.25, [0.6, -0.01], "in [0, 0.5]"),
    (fx.PowerOffset, "power_offset", 1e-3, [-1e-3], ">= 0 W"),
    (fx.LaserHeating, "heating", 10.0, [-2.0], ">= 0 K/W"),
    (fx.StageDrive, "amplitude", 1e-7, [-1e-7], ">= 0 m"),
]


@pytest.mark.parametrize("cls, field, good, bads, expect", FIELDS)
def test_values_are_float64_arrays_and_bad_ones_are_named(cls, field, good, bads, expect):
    e = cls(**{field: good})
    v = getattr(e, field)
    assert isinstance(v, np.ndarray) and v.dtype == np.float64 and float(v) == good
    assert set(e.values()) == {field} and float(e.values()[field]) == good
    assert getattr(cls(), field) is None and cls().values() == {}
    # arrays broadcast (a grid of values for simulate)
    assert getattr(cls(**{field: [good, good]}), field).shape == (2,)
    for bad in [*bads, "abc"]:
        with pytest.raises(ValueError) as err:
            cls(**{field: bad})
        msg = str(err.value)
        assert cls.__name__ in msg and field in msg and expect in msg, msg
        shown = repr(bad) if isinstance(bad, str) else str(float(bad))
        assert shown in msg, msg


def test_without_values_keeps_the_configuration():
    e = fx.LineNoise(line_amplitude=2e-9, frequency=120.0, width=0.5)
    bare = e.without_values()
    assert bare.line_amplitude is None and bare.frequency == 120.0 and bare.width == 0.5
    assert e.line_amplitude is not None  # the original is unchanged
    with pytest.raises(ValueError, match="frequency must be a finite number > 0 Hz"):
        fx.LineNoise(frequency=-50.0)


def test_model_keeps_structure_not_values():
    """TrapModel.add drops the values: the model equals (and hashes like) the one made from
    names, so calibrate compiles once whatever the values; the configuration stays."""
    by_obj = get_model("standard").add(fx.Drift(drift_diffusion=2e-16),
                                       fx.LineNoise(line_amplitude=1e-9, frequency=60.0))
    by_name = get_model("standard+drift").add("line_noise", frequency=60.0)
    assert by_obj == by_name and hash(by_obj) == hash(by_name)
    assert by_obj.param_names == by_name.param_names
    assert all(e.values() == {} for e in by_obj.extra)
    assert get_model("standard").add(fx.Drift) == get_model("standard+drift")  # a class too
    # flags given as objects (with a value) set the flag
    assert get_model("naive").add(fx.TrackingNoise(tracking_var=1e-18)).noise


def test_add_routes_settings_to_the_effects_that_have_them():
    """Settings go to the named effects that have them (drift has no frequency: this was a
    raw TypeError from Drift's constructor); a setting none of them has is an error naming
    it (it was a TypeError, or ignored where the effect was an instance)."""
    both = get_model("standard").add("drift", "line_noise", frequency=60.0, width=0.5)
    want = get_model("standard+drift").add(fx.LineNoise(frequency=60.0, width=0.5))
    assert both == want and both.effects[-2:] == ("drift", "line_noise")
    with pytest.raises(ValueError, match="frequency is not a setting.*drift"):
        get_model("standard").add("drift", frequency=60.0)
    with pytest.raises(ValueError, match="frequency is not a setting.*line_noise"):
        get_model("standard").add(fx.LineNoise(frequency=50.0), frequency=60.0)


@pytest.mark.parametrize("effect, expected", [
    (fx.TrackingNoise(tracking_var=4e-18), inj.TrackingNoise(2e-9)),
    (fx.Drift(drift_diffusion=2e-16), inj.RandomWalkDrift(2e-16)),
    (fx.LineNoise(line_amplitude=1e-9, frequency=50.0), inj.SinusoidDrift(1e-9, 0.02)),
    (fx.TimingJitter(std=1e-6), inj.TimingJitter(1e-6)),
    (fx.DetectorFilter(f3db=8e3, diode_alpha=0.4), inj.PhotodiodeFilter(8e3, 0.4)),
    (fx.Hydrodynamics(hydro_radius=1e-6, distance=5e-6),
     inj.HydrodynamicFriction(1e-6, distance=5e-6)),
    (fx.ExposureKernel(rise_fraction=0.25), inj.TrapezoidProfile(0.25)),
    (fx.StageDrive(amplitude=1e-7, frequency=28.0, phase=0.5, mode="additive"),
     inj.StageDrive(1e-7, 28.0, 0.5, "additive")),
])
def test_to_injection_builds_the_simulators_injection(effect, expected):
    got = effect.to_injection()
    assert type(got) is type(expected)
    assert eqx.tree_equal(got, expected, rtol=1e-15, atol=0.0), (got, expected)


@pytest.mark.parametrize("effect", [fx.MotionBlur(), fx.Aliasing()])
def test_detector_properties_are_no_ops(effect):
    assert effect.to_injection() is None


@pytest.mark.parametrize("effect, field", [
    (fx.Drift(), "drift_diffusion"), (fx.TrackingNoise(), "tracking_var"),
    (fx.DetectorFilter(f3db=8e3), "diode_alpha"), (fx.TimingJitter(), "std")])
def test_unknown_value_cannot_be_simulated(effect, field):
    with pytest.raises(ValueError, match=rf"{type(effect).__name__}\({field}=None\) cannot be "
                                         rf"simulated.*{effect.name}"):
        effect.to_injection()


def test_scalar_needed_where_the_simulator_takes_a_scalar():
    with pytest.raises(ValueError, match="hydro_radius must be a scalar.*shape \\(2,\\)"):
        fx.Hydrodynamics(hydro_radius=[1e-6, 2e-6]).to_injection()


@pytest.mark.parametrize("effect, hint", [
    (fx.PowerOffset(power_offset=1e-3), "k = c \\(P - P0\\)"),
    (fx.LaserHeating(heating=10.0), "T0 \\+ b P"),
    (fx.Anharmonicity(), "quartic_force")])
def test_effects_that_cannot_be_simulated_say_so(effect, hint):
    with pytest.raises(ValueError, match=rf"effect '{effect.name}' .*cannot be simulated.*{hint}"):
        effect.to_injection()


def test_stage_drive_is_a_known_input_not_a_model_piece():
    with pytest.raises(ValueError, match="'stage_drive' is a known input, not part of the model"):
        get_model("standard+stage_drive")
    with pytest.raises(ValueError, match="mode must be 'fluid' or 'additive'; got mode = 'x'"):
        fx.StageDrive(mode="x")
    with pytest.raises(ValueError, match="frequency must be a finite number > 0 Hz"):
        fx.StageDrive(frequency=0.0)
    assert "stage_drive" not in valid_candidates()  # diagnose never proposes it
