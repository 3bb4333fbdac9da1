"""diagnose names the detector model the data need when the settings say otherwise.

Frames from the independent numpy generator (tests/_instrument_gen.py)."""

import math

import pytest
from _instrument_gen import generate

import blurtrap as bt

T = 296.15
GAMMA = 6 * math.pi * 0.00093 * 0.5e-6
FS = 20000.0
AA = {"detector": "photodiode", "anti_aliasing": True}


@pytest.fixture(scope="module")
def integrating():
    """An integrating ADC (W = dt): blurred and folded."""
    x, _ = generate(3e-5, GAMMA, 1 / FS, 1 / FS, 2**16, 12, temperature=T, substeps=8,
                    tracking_std=0.2e-9)
    return x[0]


def test_folded_data_declared_anti_aliased_are_flagged(integrating):
    rec = bt.Recording(integrating, frame_interval=1 / FS, exposure=1 / FS, temperature=T,
                       metadata=AA)
    dg = bt.diagnose(rec, candidates=[])
    assert dg.model == "photodiode_aa"  # the settings choose diagnose's starting model
    note = [n for n in dg.notes if n.startswith("detector")]
    assert note and '"anti_aliasing": false' in note[0]


def test_no_detector_note_when_the_settings_fit(integrating):
    rec = bt.Recording(integrating, frame_interval=1 / FS, exposure=1 / FS, temperature=T,
                       metadata={"detector": "photodiode"})
    dg = bt.diagnose(rec, candidates=[])
    assert dg.model == "standard"
    assert not [n for n in dg.notes if n.startswith("detector")]


def test_no_anti_aliasing_note_when_a_detector_filter_explains_the_high_frequencies():
    """A folded 100 kHz record behind a photodiode low-pass (8 kHz, alpha 0.4): detector_filter
    ranks first; the detector comparison (two models without the filter) would credit the
    filter's deficit to "no folding" and tell the user to declare anti-aliasing (before: on
    every such record of the diagnose study)."""
    import jax
    import numpy as np

    from blurtrap.simulate import PhotodiodeFilter

    g = 6 * math.pi * 0.00095 * 1.5e-6
    x = bt.simulate(5e-5, g, 1e-8, 1e-5, 2**14, key=jax.random.key(3300),
                    method="exact_frames", tracking_std=0.2e-9,
                    injections=(PhotodiodeFilter(8e3, 0.4),))
    rec = bt.Recording(np.asarray(x)[0], frame_interval=1e-5, exposure=1e-8)
    dg = bt.diagnose(rec)
    assert dg.best is not None and dg.best.effect == "detector_filter"
    assert not [n for n in dg.notes if "anti-aliased photodiode" in n], dg.notes
