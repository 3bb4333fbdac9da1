"""Spectral fit options the field uses: excluded ranges, the robust option against spikes.

Data: exact camera frames by circulant embedding (numpy), lines added here."""

import numpy as np
import pytest
from test_fixed import DT, GAMMA, K, T, _frames

import blurtrap as bt


def _rec(y):
    return bt.Recording(y, frame_interval=DT, exposure=DT, temperature=T)


@pytest.fixture(scope="module")
def spiky():
    x = _frames(K, DT, 4e-18, 2**16, 21)
    t = np.arange(x.size) * DT
    return x, x + 3e-9 * np.sin(2 * np.pi * 123.4 * t) + 2e-9 * np.sin(2 * np.pi * 50.0 * t)


def test_spikes_bias_a_plain_fit_and_robust_removes_them(spiky):
    x, y = spiky
    plain = bt.calibrate(_rec(y), method="psd", lines="keep")
    rob = bt.calibrate(_rec(y), method="psd", lines="keep", robust=True)
    clean = bt.calibrate(_rec(x), method="psd")
    assert abs(plain.gamma - GAMMA) > 5 * plain.gamma_err  # the spikes do bias it
    assert plain.gof["p_value"] < 1e-6
    for r in (rob, clean):
        assert abs(r.gamma - GAMMA) < 3 * r.gamma_err and abs(r.k - K) < 3 * r.k_err
    note = next(n for n in rob.notes if n.startswith("robust"))
    assert "49.8" in note and "123" in note
    assert abs(rob.gamma - clean.gamma) < 0.5 * clean.gamma_err


def test_excluded_ranges_leave_the_lines_out(spiky):
    _, y = spiky
    r = bt.calibrate(_rec(y), method="psd", lines="keep",
                     excluded_ranges=[(45.0, 55.0), (118.0, 128.0)])
    assert abs(r.gamma - GAMMA) < 3 * r.gamma_err
    f, w = np.ravel(r.extras["f"]), np.ravel(r.extras["weight"])
    assert np.all(w[(f > 46) & (f < 54)] == 0) and np.all(w[(f > 60) & (f < 110)] > 0)


def test_robust_on_clean_data_changes_nothing(spiky):
    x, _ = spiky
    a = bt.calibrate(_rec(x), method="likelihood", likelihood="whittle")
    b = bt.calibrate(_rec(x), method="likelihood", likelihood="whittle", robust=True)
    assert "robust: no ordinate" in " ".join(b.notes)
    np.testing.assert_allclose(a.values, b.values, rtol=1e-8)


@pytest.mark.parametrize("kw, match", [
    (dict(excluded_ranges=[(10.0, 5.0)]), "excluded_ranges"),
    (dict(excluded_ranges=[(1.0,)]), "excluded_ranges"),
    (dict(robust="yes"), "robust"),
    (dict(method="variance_vs_exposure", robust=True), "robust"),
    (dict(lines="remove"), "lines"),
])
def test_bad_options_are_refused(spiky, kw, match):
    with pytest.raises(ValueError, match=match):
        bt.calibrate(_rec(spiky[0][:4096]), **kw)
