"""``simulate(..., effects=[...])``: an effect object simulates exactly what its injection does
(same key -> identical arrays), mixed with ``injections=``; the detector's own effects change
nothing; effects that cannot be simulated, or lack a value, are refused by name."""

import jax
import numpy as np
import pytest

import blurtrap as bt
from blurtrap import effects as fx
from blurtrap.effects import injections as inj

K, GAMMA, W, DT, N = 5e-5, 2.7e-8, 5e-4, 1e-3, 256
V, D, A = 4e-18, 2e-16, 3e-9  # tracking variance [m^2], drift [m^2/s], line amplitude [m]

CASES = {
    "tracking_noise": ([fx.TrackingNoise(tracking_var=V)],
                       dict(injections=(inj.TrackingNoise(np.sqrt(V)),)), {}),
    "drift": ([fx.Drift(drift_diffusion=D)], dict(injections=(inj.RandomWalkDrift(D),)), {}),
    "line_noise": ([fx.LineNoise(line_amplitude=A, frequency=50.0)],
                   dict(injections=(inj.SinusoidDrift(A, 1.0 / 50.0),)), {}),
    "timing_jitter": ([fx.TimingJitter(std=2e-5)], dict(injections=(inj.TimingJitter(2e-5),)),
                      dict(return_times=True)),
    "detector_filter": ([fx.DetectorFilter(f3db=300.0, diode_alpha=0.3)],
                        dict(injections=(inj.PhotodiodeFilter(300.0, 0.3),)),
                        dict(method="exact_frames")),
    "hydrodynamics": ([fx.Hydrodynamics(hydro_radius=1.5e-6)],
                      dict(injections=(inj.HydrodynamicFriction(1.5e-6),)),
                      dict(method="spectral")),
    "exposure_kernel": ([fx.ExposureKernel(rise_fraction=0.5)],
                        dict(exposure_profile=bt.TrapezoidProfile(0.5)), dict(substeps=8)),
    "stage_drive": ([fx.StageDrive(amplitude=5e-8, frequency=40.0)],
                    dict(injections=(inj.StageDrive(5e-8, 40.0),)), {}),
    # mixed: effects are appended after the injections, in order
    "mixed": ([fx.TrackingNoise(tracking_var=V), fx.LineNoise(line_amplitude=A)],
              dict(injections=(inj.RandomWalkDrift(D), inj.TrackingNoise(np.sqrt(V)),
                               inj.SinusoidDrift(A, 1.0 / 50.0))),
              dict(injections=(inj.RandomWalkDrift(D),))),
}


def _sim(**kw):
    out = bt.simulate(K, GAMMA, W, DT, N, key=jax.random.key(7), n_traces=2, **kw)
    return tuple(np.asarray(a) for a in out) if isinstance(out, tuple) else (np.asarray(out),)


@pytest.mark.parametrize("case", sorted(CASES))
def test_effect_objects_equal_their_injections(case):
    effects, reference, common = CASES[case]
    with_objects = _sim(effects=effects, **common)
    with_injections = _sim(**reference, **{k: v for k, v in common.items()
                                           if k not in reference})
    bare = _sim(**{k: v for k, v in common.items() if k != "injections"})
    for a, b in zip(with_objects, with_injections):
        assert a.shape == b.shape and np.array_equal(a, b), case
    # not trivially equal: the effect changes the frames
    assert not np.array_equal(with_objects[0], bare[0]), case


def test_detector_properties_change_nothing():
    assert np.array_equal(_sim(effects=[fx.MotionBlur(), fx.Aliasing()])[0], _sim()[0])


@pytest.mark.parametrize("effects, match", [
    ([fx.PowerOffset(power_offset=1e-3)], "effect 'power_offset' .*cannot be simulated"),
    ([fx.Anharmonicity()], "effect 'anharmonicity' .*quartic_force"),
    ([fx.Drift()], r"Drift\(drift_diffusion=None\) cannot be simulated"),
    (["drift"], "effects must be effect objects from blurtrap.effects.*'drift'"),
    ([inj.RandomWalkDrift(D)], "effects must be effect objects.*RandomWalkDrift"),
])
def test_refused_effects_are_named(effects, match):
    with pytest.raises(ValueError, match=match):
        bt.simulate(K, GAMMA, W, DT, N, key=jax.random.key(0), effects=effects)


def test_exposure_kernel_and_profile_not_both():
    with pytest.raises(ValueError, match="ExposureKernel sets the exposure profile.*give one"):
        bt.simulate(K, GAMMA, W, DT, N, key=jax.random.key(0),
                    effects=[fx.ExposureKernel(rise_fraction=0.2)],
                    exposure_profile=bt.TrapezoidProfile(0.2))
