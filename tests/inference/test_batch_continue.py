"""calibrate_batch continues the items its first vmapped Newton pass leaves unconverged (eps^2
running to its bound 0) together, instead of refitting each alone; the fits are calibrate's.

Frames: the numpy circulant-embedding sampler of the exact frame law (tests/_circulant.py),
camera 1500 fps, W = 0.1 dt, eps = 2 nm, 4096 frames: eps^2 ends at its bound in ~10-30 % of
records, and those items need more than the first pass's 16 Newton steps."""

from __future__ import annotations

import math

import jax
import numpy as np

import blurtrap as bt
from blurtrap.inference import _batch
from tests._circulant import circulant_frames

DT = 1 / 1500
W = 0.1 * DT
K = 5e-5
GAMMA = 6 * math.pi * 0.00093 * 1.53e-6


def test_unconverged_items_are_continued_together_and_equal_calibrate(monkeypatch):
    y = circulant_frames(K, GAMMA, W, DT, (2e-9) ** 2, 4096, seed=11, reps=32)  # 64 records
    alone = []
    real_refit = _batch._refit_alone
    monkeypatch.setattr(_batch, "_refit_alone", lambda i, *a: (alone.append(i),
                                                                real_refit(i, *a)))
    first_pass = []
    real_continue = _batch._continue_unfinished

    def spy(y_, shared, acq, n_blocks, m, check_units, per, nbin, fits, skip, mesh=None):
        first_pass.append(int(np.sum(~fits[2] & ~skip)))
        return real_continue(y_, shared, acq, n_blocks, m, check_units, per, nbin, fits, skip,
                             mesh)

    monkeypatch.setattr(_batch, "_continue_unfinished", spy)
    r = bt.calibrate_batch(y, frame_interval=DT, exposure=W)
    assert first_pass[0] >= 3  # the case this covers: items the first pass leaves unconverged
    assert alone == []  # all of them were finished by the batched continuation
    assert r.success.all()
    assert r.at_bound.sum() >= 3
    # the items at the bound (those that needed the continuation) equal calibrate's fit
    for i in np.flatnonzero(r.at_bound)[:3]:
        one = bt.calibrate(bt.Recording(y[i], frame_interval=DT, exposure=W),
                            likelihood="whittle")
        assert one.at_bounds == ("tracking_var",)
        np.testing.assert_allclose([r.k[i], r.gamma[i]], [one.k, one.gamma], rtol=1e-8)
        np.testing.assert_allclose([r.k_err[i], r.gamma_err[i]], [one.k_err, one.gamma_err],
                                   rtol=1e-6)


def test_continuation_reuses_the_compiled_fit():
    """Another batch of the same shape with a different number of unconverged items compiles
    nothing: the continuation runs in the first pass's chunk shape (before: a program per
    count of unconverged items)."""
    bt.calibrate_batch(circulant_frames(K, GAMMA, W, DT, (2e-9) ** 2, 4096, seed=12, reps=32),
                       frame_interval=DT, exposure=W)
    y = circulant_frames(K, GAMMA, W, DT, (2e-9) ** 2, 4096, seed=13, reps=32)
    names = []

    def listen(event, duration, **kw):
        if event == "/jax/core/compile/backend_compile_duration":
            names.append(str(kw.get("fun_name", "?")))

    jax.monitoring.register_event_duration_secs_listener(listen)
    try:
        r = bt.calibrate_batch(y, frame_interval=DT, exposure=W)
    finally:
        jax.monitoring.unregister_event_duration_listener(listen)
    assert r.at_bound.sum() >= 1
    assert names == [], names
