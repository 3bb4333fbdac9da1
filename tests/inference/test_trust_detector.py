"""Saturated (clipped) and quantised detectors: calibrate refuses or says so in its notes.

A clipped trace used to calibrate with k ~10 SE off, a good goodness of fit and no note.
Traces are built here independently of blurtrap's simulator (exact AR(1) recursion plus white
tracking noise), then clipped with np.clip and rounded with np.round, as a detector would.
"""

import math
import re

import numpy as np
import pytest
from scipy.signal import lfilter

import blurtrap as bt

KT = 1.380649e-23 * 295.0
K = 5e-5
GAMMA = 6 * math.pi * 9.3e-4 * 1.53e-6
DT = 1 / 1500
SIG = math.sqrt(KT / K)  # 9.0 nm


def _trace(n=4096, seed=0, eps=0.1 * SIG):
    rng = np.random.default_rng(seed)
    rho = math.exp(-DT * K / GAMMA)
    e = rng.standard_normal(n) * SIG * math.sqrt(1.0 - rho * rho)
    e[0] = rng.standard_normal() * SIG
    return lfilter([1.0], [1.0, -rho], e) + eps * rng.standard_normal(n)


def _rec(x):
    return bt.Recording(x, frame_interval=DT, exposure=1e-5)


@pytest.fixture(scope="module")
def x():
    return _trace()


def _clip(x, lo_q=None, hi_q=None):
    lo = None if lo_q is None else np.quantile(x, lo_q)
    hi = None if hi_q is None else np.quantile(x, hi_q)
    return np.clip(x, lo, hi)


@pytest.mark.parametrize("lo_q,hi_q", [(None, 0.99), (0.02, None), (0.05, 0.95),
                                       (None, 0.9), (0.003, 0.997)])
@pytest.mark.parametrize("method", ["auto", "psd", "equipartition"])
def test_saturated_frames_are_refused(x, lo_q, hi_q, method):
    xc = _clip(x, lo_q, hi_q)
    with pytest.raises(ValueError, match="saturated") as err:
        bt.calibrate(_rec(xc), method=method)
    msg = str(err.value)
    # names how many frames sit at which value
    for q, side, val in ((lo_q, "minimum", xc.min()), (hi_q, "maximum", xc.max())):
        if q is None:
            assert side not in msg
            continue
        count = int(np.sum(xc == val))
        assert re.search(rf"{count} frames \([\d.]+ %\) at exactly the {side} {val:.6g} m", msg)


def test_saturated_8bit_camera_is_refused(x):
    """Quantised and clipped (an 8-bit range that is too narrow): still saturation."""
    q = SIG / 8
    xq = np.clip(np.round(x / q), -12, 12) * q
    with pytest.raises(ValueError, match=r"at exactly the minimum .* at exactly the maximum"):
        bt.calibrate(_rec(xq), method="equipartition")


def test_strict_false_fits_saturated_data_with_a_loud_note(x):
    res = bt.calibrate(_rec(_clip(x, None, 0.95)), method="equipartition", strict=False)
    assert any(n.startswith("NOT TRUSTWORTHY") and "saturated" in n for n in res.notes)


def test_a_few_saturated_frames_give_a_note(x):
    xc = np.clip(x, None, np.sort(x)[-4])  # 4 frames at the maximum (0.1 %)
    res = bt.calibrate(_rec(xc), method="equipartition")
    (note,) = [n for n in res.notes if "saturated" in n]
    assert "4 frames" in note and "maximum" in note and "too few frames to matter" in note


@pytest.mark.parametrize("seed", range(6))
@pytest.mark.parametrize("step", [0.0, 0.05, 0.3, 0.6, 1.0])
def test_unclipped_traces_are_not_called_saturated(step, seed):
    """No false alarm: continuous traces (extremes unique) and quantised ones (the outermost
    level holds fewer frames than the next) of several lengths."""
    x = _trace(n=[256, 1024, 4096, 16384, 600, 2000][seed], seed=100 + seed)
    if step:
        x = np.round(x / (step * SIG)) * step * SIG
    from blurtrap.inference._frames import _inspect_frames

    notes = _inspect_frames([_rec(x)], strict=True)
    assert not any("saturated" in n for n in notes), notes


@pytest.mark.parametrize("step", [0.3, 0.5, 0.9])
def test_moderate_quantisation_is_noted(x, step):
    q = step * SIG
    xq = np.round(x / q) * q
    res = bt.calibrate(_rec(xq), method="equipartition")
    (note,) = [n for n in res.notes if "quantised" in n]
    sd = float(np.std(xq))
    assert f"steps of {q:.4g} m" in note
    assert f"{q * q / 12:.3g} m^2" in note and f"{100 * q * q / 12 / sd**2:.2g} %" in note
    assert "eps^2 absorbs" in note


def _honest_se(res, name):
    """The fit's SE, or, where a parameter sits at its bound (eps^2 = 0: 4 of these 8 traces,
    exposure ~ 0 and 0.9 nm noise), the 95 % profile interval's half width / 1.96: the Wald
    errors there are the unconstrained bound (conservative, not the spread either)
    (benchmarks/RESULTS_boundary.md), so they are not a yardstick for a shift."""
    if not res.at_bounds:
        return res.errors[res.param_names.index(name)]
    lo, hi = res.intervals[name]
    return (hi - lo) / (2 * 1.959964)


def test_moderate_quantisation_does_not_bias_the_exact_fit():
    """The note's claim: with steps up to ~std the rounding is white noise that eps^2
    absorbs. Each trace's fit moves by its added noise (measured: |shift| <= 0.3 SE); over 8
    traces the mean shift of k and gamma is not a bias (its SD is ~0.2/sqrt(8) = 0.07 SE)."""
    q = 0.5 * SIG
    dk, dg = [], []
    for seed in range(8):
        x = _trace(seed=200 + seed)
        ref = bt.calibrate(_rec(x), method="likelihood", likelihood="exact")
        res = bt.calibrate(_rec(np.round(x / q) * q), method="likelihood", likelihood="exact")
        assert any("quantised" in n for n in res.notes)
        # it took up (part of) q^2/12 (1.7e-18 m^2): the estimate rises, or where eps^2 sits at
        # its bound 0 in both fits (4 of 8; the reported value is only where the search
        # stopped, < 1e-24 m^2) the upper end of its 95 % profile interval does
        if ref.at_bounds:
            assert res.at_bounds == ref.at_bounds
            assert res.intervals["tracking_var"][1] > ref.intervals["tracking_var"][1]
        else:
            assert res.tracking_var > ref.tracking_var
        dk.append((res.k - ref.k) / _honest_se(ref, "k"))
        dg.append((res.gamma - ref.gamma) / _honest_se(ref, "gamma"))
    assert np.all(np.abs(dk) < 1.0) and np.all(np.abs(dg) < 1.0), (dk, dg)
    assert abs(np.mean(dk)) < 0.3 and abs(np.mean(dg)) < 0.3, (dk, dg)


@pytest.mark.parametrize("step", [1.5, 3.0])
def test_coarse_quantisation_is_refused(x, step):
    q = step * SIG
    xq = np.round(x / q) * q
    with pytest.raises(ValueError, match=rf"quantised in steps of {q:.4g} m"):
        bt.calibrate(_rec(xq), method="psd")


def test_fine_quantisation_is_silent(x):
    q = SIG / 10  # adds 0.08 % to the variance
    res = bt.calibrate(_rec(np.round(x / q) * q), method="equipartition")
    assert not any("quantised" in n or "saturated" in n for n in res.notes)
    # in nm units with a resolution of 1e-3 nm: also silent
    res = bt.calibrate(_rec(np.round(x * 1e12) * 1e-12), method="equipartition")
    assert not any("quantised" in n or "saturated" in n for n in res.notes)


def test_diagnose_refuses_saturated_frames_before_fitting(x, monkeypatch):
    """diagnose fits its base model with strict=False (which only notes): it checks the frames
    itself, before any fit."""
    from blurtrap.diagnostics import _diagnose

    def no_fit(*a, **kw):
        raise AssertionError("fitted saturated data")

    monkeypatch.setattr(_diagnose, "calibrate", no_fit)
    with pytest.raises(ValueError, match="saturated"):
        bt.diagnose(_rec(_clip(x, 0.02, 0.98)))
    with pytest.raises(ValueError, match="quantised in steps"):
        bt.diagnose(_rec(np.round(x / (2 * SIG)) * 2 * SIG))
