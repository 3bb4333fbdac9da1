"""Forward selection (select_model): add the best significant effect until adequate."""

import jax
import numpy as np
import pytest

import blurtrap as bt
from blurtrap.diagnostics import select_model

GAMMA = 6 * np.pi * 0.00093 * 1.53e-6
DT = 1 / 1500
K = 1e-5
N = 16384
CANDIDATES = ["drift", "line_noise", "anharmonicity"]


def record(seed, injections=(), eps=2e-9):
    x = np.asarray(bt.simulate(K, GAMMA, DT, DT, N, key=jax.random.key(seed),
                               method="exact_frames", tracking_std=eps,
                               injections=injections))[0]
    return bt.Recording(x, frame_interval=DT, exposure=DT)


def test_two_hidden_effects_are_added_in_turn():
    """Drift and a 50 Hz line hidden together: the selection adds both (strongest first),
    stops adequate, and the final fit recovers k and gamma within 3 SE (the first model
    does not). Candidates are limited to three (drift, line_noise and the cheap kurtosis
    test) to keep the test fast: identification among all candidates is tested in
    test_hidden_effects.py; here the selection loop is."""
    rec = record(2, injections=(bt.RandomWalkDrift(2e-16), bt.SinusoidDrift(20e-9, 1 / 50.0)))
    sel = select_model(rec, max_steps=3, candidates=CANDIDATES)
    assert sel.adequate, sel.summary()
    assert set(sel.added) == {"drift", "line_noise"}, sel.summary()
    assert len(sel.steps) == 3 and sel.steps[-1].adequate
    first, fit = sel.steps[0].fit, sel.fit
    assert not (abs(first.k - K) < 3 * first.k_err and abs(first.gamma - GAMMA) < 3 * first.gamma_err)
    assert abs(fit.k - K) < 3 * fit.k_err and abs(fit.gamma - GAMMA) < 3 * fit.gamma_err
    assert sel.model.has("drift") and sel.model.has("line_noise")
    assert "final model" in sel.summary()


def test_max_steps_stops_the_selection():
    rec = record(2, injections=(bt.RandomWalkDrift(2e-16), bt.SinusoidDrift(20e-9, 1 / 50.0)))
    sel = select_model(rec, max_steps=1, candidates=CANDIDATES)
    assert len(sel.added) == 1 and not sel.adequate
    assert any("max_steps = 1" in n for n in sel.notes)
    # the JSON form (here rather than after 3 steps: every step's fit.to_dict() computes its
    # profile intervals, a compilation per model; the added effects and the steps are the same)
    js = sel.to_dict()
    assert js["added"] == list(sel.added) and len(js["steps"]) == len(sel.steps) == 2
    assert js["model"] == sel.steps[-1].model and js["adequate"] is False
    with pytest.raises(ValueError, match="max_steps must be an integer >= 1; got max_steps = 0"):
        select_model(rec, max_steps=0)
