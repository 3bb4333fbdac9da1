"""diagnose/select_model take effect objects as candidates (the very object that simulated the
hidden effect), and the default candidates come from the effect classes' own hooks."""

import types

import jax
import numpy as np
import pytest

import blurtrap as bt
from blurtrap import effects as fx
from blurtrap.diagnostics._candidates import default_candidates
from blurtrap.inference import get_model

K, GAMMA, DT, N = 5e-5, 2.7e-8, 1e-3, 8192
DRIFT = fx.Drift(drift_diffusion=2e-16)  # 200 nm^2/s: found in 10/10 records (drift docstring)


@pytest.fixture(scope="module")
def drifting():
    x = bt.simulate(K, GAMMA, DT, DT, N, key=jax.random.key(11), method="exact_frames",
                    effects=[fx.TrackingNoise(tracking_var=1e-18), DRIFT])
    return bt.Recording(np.asarray(x).ravel(), frame_interval=DT, exposure=DT)


def test_hidden_effect_found_with_the_same_object(drifting):
    d = bt.diagnose(drifting, candidates=[DRIFT])
    assert not d.adequate and [c.effect for c in d.ranking] == ["drift"]
    best = d.best
    assert best is not None and best.significant and best.model.has("drift")
    assert "drift_diffusion" in best.fit.param_names


def test_object_values_start_or_fix_calibrate(drifting):
    """The model drops the values; calibrate takes them as start or as fixed values."""
    assert DRIFT.values() == {"drift_diffusion": 2e-16}
    fixed = bt.calibrate(drifting, model=bt.TrapModel() + DRIFT, method="likelihood",
                         likelihood="whittle", fixed=DRIFT.values())
    assert fixed.params["drift_diffusion"] == 2e-16
    started = bt.calibrate(drifting, model="standard+drift", method="likelihood",
                           likelihood="whittle", start=DRIFT.values())
    assert started.params["drift_diffusion"] != 2e-16 and started.k > 0


def test_select_model_adds_the_object(drifting):
    sel = bt.select_model(drifting, candidates=[DRIFT], max_steps=1)
    assert sel.added == ("drift",) and sel.model.has("drift")


def test_candidates_mix_names_classes_and_objects():
    from blurtrap.diagnostics._candidates import _check_candidates

    got = _check_candidates(["line_noise", fx.Drift, DRIFT, fx.LineNoise()])
    assert got == ["line_noise", "drift"]  # one entry per name, the first one kept
    assert _check_candidates(DRIFT) == [DRIFT]
    assert _check_candidates([DRIFT, "drift"])[0] is DRIFT
    for bad in (["no_such_effect"], [3.0], [bt.RandomWalkDrift(1e-16)], ["stage_drive"],
                [fx.StageDrive(amplitude=1e-7)]):
        with pytest.raises(ValueError, match="candidates: unknown effect name.*or object"):
            bt.diagnose(bt.Recording(np.arange(8.0) * 1e-9, frame_interval=DT,
                                     exposure=DT), candidates=bad)


def _recs(fs, exposures, times=False):
    return [types.SimpleNamespace(frame_interval=1.0 / fs, exposure=w,
                                  times=np.arange(3.0) if times else None) for w in exposures]


@pytest.mark.parametrize("recs, model, k, multi, expected", [
    (_recs(1000.0, [1e-3]), "standard", "shared", False,
     ["drift", "line_noise", "anharmonicity"]),
    (_recs(1e5, [1e-6, 5e-6], times=True), "naive", "linear_power", True,
     ["motion_blur", "aliasing", "tracking_noise", "drift", "line_noise", "detector_filter",
      "hydrodynamics", "motion_blur+aliasing", "motion_blur+aliasing+tracking_noise",
      "power_offset", "laser_heating",
      "anharmonicity", "timing_jitter"]),
    (_recs(1000.0, [2e-4, 5e-4, 1e-3]), "standard", "per_power", True,
     ["drift", "line_noise", "exposure_kernel", "anharmonicity"]),
    (_recs(2e4, [5e-5], times=True), "standard+drift", "shared", False,
     ["line_noise", "detector_filter", "hydrodynamics", "anharmonicity", "timing_jitter"]),
])
def test_default_candidates_come_from_the_classes(recs, model, k, multi, expected):
    """Same lists as the former hand-written rules (photodiode-rate effects at >= 10 kHz, the
    kernel for a blurred model over several exposures, relations for linear_power over >= 3
    powers, timing_jitter with time stamps), in signal-chain order."""
    assert default_candidates(recs, get_model(model), k, multi) == expected


def test_object_values_start_the_screening_fit():
    """A candidate object's positive scalar values replace the start of its own parameters;
    zero, arrays and other effects' parameters are left out."""
    from blurtrap.diagnostics._candidates import _object_start

    warm = {"k": 5e-5, "gamma": 2.7e-8}
    start = _object_start(warm, (fx.Drift(drift_diffusion=3e-16),
                                 fx.LineNoise(line_amplitude=0.0),
                                 fx.TrackingNoise(tracking_var=[1e-18, 2e-18]), "aliasing"))
    assert start == {**warm, "drift_diffusion": 3e-16}
    assert warm == {"k": 5e-5, "gamma": 2.7e-8}  # not modified


def test_a_single_effect_class_is_one_candidate():
    from blurtrap.diagnostics._candidates import _check_candidates
    from blurtrap.effects import Drift

    assert _check_candidates(Drift) == ["drift"]
    assert _check_candidates([Drift, "line_noise"]) == ["drift", "line_noise"]
