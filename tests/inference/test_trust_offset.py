"""A constant offset of the positions changes nothing: every calibration path is invariant.

The trap centre is unknown (REML in the exact likelihood, the mean removed from periodograms
and variances), so ``x`` and ``x + c`` must give the same values and standard errors to
rounding. A 1 m offset on a ~10 nm trace costs log10(1e16) = 16 digits wherever a sum of
squares of the raw frames is formed before the mean is taken out, which is what these tests
catch (the exact likelihood lost them all: k 12 SE off, or a 'singular Fisher information').

The traces are built here, independently of blurtrap's simulator: an exact AR(1)
(Ornstein-Uhlenbeck) recursion on a fine grid (scipy.signal.lfilter), averaged over the
exposure, plus white tracking noise.
"""

import math

import numpy as np
import pytest
from scipy.signal import lfilter

import blurtrap as bt
from blurtrap.inference import arma_loglik

KT = 1.380649e-23 * 295.0
K = 5e-5  # N/m
GAMMA = 6 * math.pi * 9.3e-4 * 1.53e-6  # N s/m (tau = 0.54 ms)
DT = 1 / 1500
N = 4096
OFFSETS = (1e-6, 1e-4, 0.1, 1.0)  # m
RTOL = 1e-6


def _trace(seed, n=N, sub=20, w_sub=20, eps=3e-9):
    """Frames every DT averaging the first ``w_sub`` of ``sub`` OU substeps (exposure
    W = DT w_sub / sub), plus white noise of SD ``eps``."""
    rng = np.random.default_rng(seed)
    h = DT / sub
    rho = math.exp(-h * K / GAMMA)
    s2 = KT / K
    e = rng.standard_normal(n * sub) * math.sqrt(s2 * (1.0 - rho * rho))
    e[0] = rng.standard_normal() * math.sqrt(s2)
    x = lfilter([1.0], [1.0, -rho], e)
    frames = x.reshape(n, sub)[:, :w_sub].mean(axis=1)
    return frames + eps * rng.standard_normal(n), DT * w_sub / sub


@pytest.fixture(scope="module")
def trace():
    return _trace(1)


def _same(a, b, what):
    va, vb = np.asarray(a.values), np.asarray(b.values)
    sa = np.sqrt(np.diag(np.asarray(a.covariance)))
    sb = np.sqrt(np.diag(np.asarray(b.covariance)))
    np.testing.assert_allclose(vb, va, rtol=RTOL, err_msg=f"{what}: values")
    np.testing.assert_allclose(sb, sa, rtol=RTOL, err_msg=f"{what}: standard errors")
    np.testing.assert_allclose(b.k_per_recording, a.k_per_recording, rtol=RTOL)


def _rec(x, w, **kw):
    return bt.Recording(x, frame_interval=DT, exposure=w, **kw)


def test_arma_loglik_is_shift_invariant(trace):
    """The REML and profile likelihoods at fixed parameters do not move with the offset
    (was: the profiled quadratic form cancelled; at 1 m it was pure rounding)."""
    x, _ = trace
    y = x[:1024]
    c0, c1, rho = float(np.var(y)), 0.4 * float(np.var(y)), 0.3
    for mean in ("reml", "profile"):
        ref = float(arma_loglik(y, c0, c1, rho, mean=mean))
        for c in OFFSETS:
            got = float(arma_loglik(y + c, c0, c1, rho, mean=mean))
            # |ll| ~ 2e4; rounding of the shifted frames (ulp(c)/sd ~ 1e-8 at c = 1 m)
            assert abs(got - ref) < 1e-4, (mean, c, got, ref)
    # masked (padded) recordings too: the mean is that of the real frames only
    mask = np.r_[np.ones(1000), np.zeros(24)]
    yp = np.r_[y[:1000], np.zeros(24)]
    ref = float(arma_loglik(yp, c0, c1, rho, mask=mask))
    got = float(arma_loglik(np.r_[y[:1000] + 1.0, np.zeros(24)], c0, c1, rho, mask=mask))
    assert abs(got - ref) < 1e-4


@pytest.mark.parametrize("kw", [
    dict(method="likelihood", likelihood="exact"),
    dict(),  # auto: picks the exact likelihood for 4096 frames
    dict(method="likelihood", likelihood="whittle"),
    dict(method="psd"),
    dict(method="equipartition"),
    dict(method="equipartition", diffusion=KT / GAMMA),
], ids=["exact", "auto", "whittle", "psd", "equipartition", "equipartition_D"])
def test_single_recording_paths_are_offset_invariant(trace, kw):
    x, w = trace
    ref = bt.calibrate(_rec(x, w), **kw)
    for c in OFFSETS:
        _same(ref, bt.calibrate(_rec(x + c, w), **kw), f"{kw} offset {c} m")


def test_offset_in_nm_manifest_units(trace):
    """A trace given in nm with a 1e6 nm offset (what the loaders convert to 1e-3 m)."""
    x, w = trace
    ref = bt.calibrate(_rec(x, w), method="likelihood", likelihood="exact")
    nm = np.round((x * 1e9 + 1e6) * 1e6) / 1e6  # 1e-6 nm resolution, as in a CSV
    _same(ref, bt.calibrate(_rec(nm * 1e-9, w), method="likelihood", likelihood="exact"),
          "nm trace with 1e6 nm offset")


@pytest.fixture(scope="module")
def exposure_series():
    # exposures 0.1, 0.3, 0.65 ms (alpha = W/tau 0.18 .. 1.2) at fixed dt, different seeds
    return [_trace(10 + i, n=2048, sub=20, w_sub=m) for i, m in enumerate((3, 9, 20))]


@pytest.mark.parametrize("method", ["variance_vs_exposure", "likelihood_set"])
def test_recording_sets_are_offset_invariant(exposure_series, method):
    """Joint fits: every recording with its own offset."""
    kw = (dict(method="likelihood", likelihood="exact") if method == "likelihood_set"
          else dict(method=method))
    ref = bt.calibrate([_rec(x, w) for x, w in exposure_series], **kw)
    for c in (1e-4, 1.0):
        recs = [_rec(x + c * (i + 1), w) for i, (x, w) in enumerate(exposure_series)]
        _same(ref, bt.calibrate(recs, **kw), f"{method} offset {c} m")


def test_variance_vs_power_is_offset_invariant():
    recs, ref_recs = [], []
    for i, p in enumerate((0.05, 0.1, 0.2)):
        rng = np.random.default_rng(20 + i)
        k = K * p / 0.1
        rho = math.exp(-DT * k / GAMMA)
        e = rng.standard_normal(2048) * math.sqrt(KT / k * (1 - rho * rho))
        x = lfilter([1.0], [1.0, -rho], e) + 2e-9 * rng.standard_normal(2048)
        ref_recs.append(_rec(x, 1e-5, laser_power=p))
        recs.append(_rec(x + 0.3 * (i + 1), 1e-5, laser_power=p))
    _same(bt.calibrate(ref_recs, method="variance_vs_power", model="blur"),
          bt.calibrate(recs, method="variance_vs_power", model="blur"), "variance_vs_power")


@pytest.mark.parametrize("likelihood", ["exact", "whittle"])
def test_posterior_log_likelihood_is_offset_invariant(trace, likelihood):
    """The posterior's (compiled, batched) log-density at the same points, shifted or not."""
    from blurtrap.inference._posterior import _setup

    x, w = trace
    ref = _setup(_rec(x, w), None, None, 8, likelihood, None, None)
    shifted = _setup(_rec(x + 1.0, w), None, None, 8, likelihood, None, None)
    np.testing.assert_allclose(shifted.theta_start, ref.theta_start, rtol=0, atol=1e-8)
    thetas = ref.theta_start[None, :] + 0.05 * np.random.default_rng(0).standard_normal((8, 3))
    lp_ref, lp = ref.log_prob(thetas), shifted.log_prob(thetas)
    assert np.all(np.isfinite(lp_ref))
    np.testing.assert_allclose(lp, lp_ref, rtol=0, atol=1e-4)
