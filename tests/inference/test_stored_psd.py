"""Fitting a stored, averaged power spectrum (``bt.fit_psd``).

Data: exact camera frames by circulant embedding (numpy, not blurtrap's simulator); the
spectra are numpy block-averaged periodograms written here."""

import math

import numpy as np
import pytest
from test_fixed import DT, GAMMA, K, T, _frames

import blurtrap as bt


def _blocked(x, n_blocks):
    m = x.size // n_blocks
    b = x[: m * n_blocks].reshape(n_blocks, m)
    b = b - b.mean(axis=1, keepdims=True)
    p = (np.abs(np.fft.rfft(b, axis=1)[:, 1:]) ** 2).mean(axis=0) * DT / m
    return np.arange(1, m // 2 + 1) / (m * DT), p


def test_same_estimate_as_the_blocked_psd_method_on_the_trace():
    x = _frames(K, DT, 4e-18, 2**16, 1)
    f, p = _blocked(x, 64)
    nb = np.where(f == f[-1], 32.0, 64.0)  # the Nyquist ordinate is chi^2 with 1 dof
    r = bt.fit_psd(f, p, frame_interval=DT, exposure=DT, n_blocks=nb, temperature=T)
    ref = bt.calibrate(bt.Recording(x, frame_interval=DT, exposure=DT, temperature=T),
                       method="psd", n_blocks=64)
    np.testing.assert_allclose(r.values, ref.values, rtol=1e-6)
    np.testing.assert_allclose(r.errors, ref.errors, rtol=1e-4)
    one = bt.fit_psd(f, 2 * p, frame_interval=DT, exposure=DT, n_blocks=nb, temperature=T,
                     onesided=True)
    np.testing.assert_allclose(one.values, r.values, rtol=1e-9)


def test_log_binned_spectrum_is_unbiased_with_honest_errors():
    """Ordinates averaged in log-spaced bins (as lab software stores them), the count per
    bin as n_blocks: z-scores of k and gamma over 24 seeds have mean ~0 and SD ~1."""
    zk, zg = [], []
    for seed in range(24):
        f, p = _blocked(_frames(K, DT, 4e-18, 2**15, 50 + seed), 16)
        edges = np.unique(np.geomspace(1, f.size, 120).astype(int)) - 1
        fb = np.array([f[a:b].mean() for a, b in zip(edges[:-1], edges[1:])])
        pb = np.array([p[a:b].mean() for a, b in zip(edges[:-1], edges[1:])])
        cnt = 16.0 * np.diff(edges)
        r = bt.fit_psd(fb, pb, frame_interval=DT, exposure=DT, n_blocks=cnt, temperature=T)
        assert "P_d" in r.notes[-1]
        zk.append((r.k - K) / r.k_err)
        zg.append((r.gamma - GAMMA) / r.gamma_err)
    for z in (np.array(zk), np.array(zg)):
        assert abs(z.mean()) < 3 / math.sqrt(z.size) + 0.25  # bin-centre error: < 0.25 SE
        assert 0.65 < z.std(ddof=1) < 1.45


@pytest.mark.parametrize("kw, match", [
    (dict(power=-1.0), "power"),
    (dict(frequencies=[1.0, 2.0, 2.0, 3.0]), "increase"),
    (dict(n_blocks=0), "n_blocks"),
    (dict(exposure=2 * DT), "exposure"),
    (dict(f_range=(1e5, 2e5)), "no frequencies"),
])
def test_bad_input_is_refused(kw, match):
    f = np.arange(1.0, 65.0)
    base = dict(frequencies=f, power=np.ones_like(f) * 1e-20, frame_interval=DT, exposure=DT)
    base.update(kw)
    if np.ndim(base["power"]) == 0:
        base["power"] = np.full(len(base["frequencies"]), base["power"])
    if len(base["power"]) != len(base["frequencies"]):
        base["power"] = np.ones(len(base["frequencies"])) * 1e-20
    f_, p_ = base.pop("frequencies"), base.pop("power")
    with pytest.raises(ValueError, match=match):
        bt.fit_psd(f_, p_, **base)
