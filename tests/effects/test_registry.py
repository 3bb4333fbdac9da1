"""The registry of effects is discovered from the modules of ``blurtrap.effects``: a new effect
is one new module (here written by the test into an extra package directory) and reaches
TrapModel, calibrate, simulate and diagnose with no other edit."""

import sys
import textwrap

import jax
import numpy as np
import pytest

import blurtrap as bt
import blurtrap.effects as fx
from blurtrap.diagnostics._candidates import default_candidates
from blurtrap.inference import get_model

#: DESIGN section 3
CANONICAL = {"motion_blur", "aliasing", "tracking_noise", "drift", "exposure_kernel",
             "detector_filter", "hydrodynamics", "anharmonicity", "laser_heating",
             "power_offset", "line_noise", "timing_jitter", "stage_drive"}

TOY = '''
"""A toy effect for the registry test: extra white noise after the detector."""
from typing import ClassVar

import numpy as np

from blurtrap.effects._base import AbstractEffect, Param, value_field
from blurtrap.effects.injections import TrackingNoise


class ExcessNoise(AbstractEffect):
    """White noise of variance ``excess_var`` [m^2] added to every frame."""

    name: ClassVar[str] = "excess_noise"
    kind: ClassVar[str] = "additive"
    params: ClassVar = (Param("excess_var", "m^2", 1e18, "nm^2", "excess noise variance",
                              bounds=(1e-30, 1e-10), start=lambda c: 0.1 * c.variance),)
    signature: ClassVar[str] = "flat excess floor"
    excess_var: np.ndarray | None = value_field("m^2", ">= 0")

    def psd_add(self, f, dt, extras):
        return extras["excess_var"] * dt

    def to_injection(self):
        return TrackingNoise(np.sqrt(self._value("excess_var")))
'''


def _install(tmp_path, files: dict):
    """Put modules into an extra directory of the blurtrap.effects package and rediscover;
    returns the cleanup."""
    pkg = tmp_path / "extra_effects"
    pkg.mkdir()
    for name, text in files.items():
        (pkg / f"{name}.py").write_text(textwrap.dedent(text))
    fx.__path__.append(str(pkg))

    def cleanup():
        fx.__path__.remove(str(pkg))
        for name in files:
            sys.modules.pop(f"blurtrap.effects.{name}", None)
        fx.discover()
    return cleanup


def test_registry_is_the_canonical_vocabulary_in_signal_chain_order():
    assert set(fx.EFFECTS) == CANONICAL
    orders = [cls.order for cls in fx.EFFECTS.values()]
    assert orders == sorted(orders)
    for name, cls in fx.EFFECTS.items():
        assert cls.__module__ == f"blurtrap.effects.{name}"  # one module per effect
        assert all(fx.QUANTITIES[p.name] is p for p in cls.params)


@pytest.fixture
def toy(tmp_path):
    cleanup = _install(tmp_path, {"excess_noise": TOY})
    try:
        fx.discover()
        yield fx.EFFECTS["excess_noise"]
    finally:
        cleanup()
    assert "excess_noise" not in fx.EFFECTS and "excess_var" not in fx.QUANTITIES
    assert not hasattr(fx, "ExcessNoise")


K, GAMMA, DT, N = 5e-5, 2.7e-8, 1e-3, 8192
V = 2.5e-17  # 5 nm rms


def test_a_new_effect_module_is_picked_up_everywhere(toy):
    assert toy.__name__ == "ExcessNoise" and fx.ExcessNoise is toy
    assert fx.QUANTITIES["excess_var"].unit == "m^2"
    mdl = get_model("blur+excess_noise")
    assert mdl.param_names == ("k", "gamma", "excess_var") and mdl.closed_form
    obj = toy(excess_var=V)
    # simulate: the object is its injection
    x = bt.simulate(K, GAMMA, DT, DT, N, key=jax.random.key(3), method="exact_frames",
                    effects=[obj])
    ref = bt.simulate(K, GAMMA, DT, DT, N, key=jax.random.key(3), method="exact_frames",
                      injections=(bt.TrackingNoise(np.sqrt(V)),))
    assert np.array_equal(np.asarray(x), np.asarray(ref))
    rec = bt.Recording(np.asarray(x).ravel(), frame_interval=DT, exposure=DT)
    # calibrate fits its parameter (it plays eps^2 for the blur model): within 3 SE
    fit = bt.calibrate(rec, model=mdl, method="likelihood", likelihood="whittle")
    i = fit.param_names.index("excess_var")
    assert abs(fit.params["excess_var"] - V) < 3 * fit.errors[i], (fit.params, fit.errors)
    # diagnose: a default candidate of the blur model, and found with the very object
    assert "excess_noise" in default_candidates([rec], get_model("blur"), "shared", False)
    d = bt.diagnose(rec, model="blur", candidates=[obj])
    assert d.best is not None and d.best.effect == "excess_noise" and d.best.significant


def test_a_module_must_define_exactly_one_named_effect(tmp_path):
    two = TOY + '\n\nclass OtherNoise(ExcessNoise):\n    name: ClassVar[str] = "other_noise"\n'
    cleanup = _install(tmp_path, {"two_effects": two})
    try:
        with pytest.raises(ImportError, match="two_effects must define exactly one.*"
                                              "ExcessNoise.*OtherNoise"):
            fx.discover()
    finally:
        cleanup()
    assert set(fx.EFFECTS) == CANONICAL


def test_two_modules_claiming_one_name_are_refused(tmp_path):
    cleanup = _install(tmp_path, {"drift_again": TOY.replace('"excess_noise"', '"drift"')})
    try:
        with pytest.raises(ValueError, match="effect name 'drift' is defined twice"):
            fx.discover()
    finally:
        cleanup()
    assert set(fx.EFFECTS) == CANONICAL
