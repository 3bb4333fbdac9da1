"""One exposure with tracking noise free: the frames cannot tell W from eps^2.

The frame autocovariance is C(0) = kT/k S(a) + eps^2, C(m) = kT/k B(a) rho^m (a = W/tau,
paper eqs. 7-8), so any declared W fits equally well with k and gamma proportional to B(W/tau).
Frames from circulant embedding (tests/_circulant.py), not blurtrap's simulator."""

from __future__ import annotations

import math

import pytest
from _circulant import circulant_frames

import blurtrap as bt

K, GAMMA, TEMP, DT = 2e-5, 1e-8, 295.0, 1 / 1500


def _b(a):
    return 2.0 * (math.cosh(a) - 1.0) / a**2


def _frames(w_true, n=65536, seed=3):
    return circulant_frames(K, GAMMA, w_true, DT, 4e-18, n, seed, temperature=TEMP)


def _fit(y, w, **kw):
    return bt.calibrate(bt.Recording(y, frame_interval=DT, exposure=w, temperature=TEMP),
                        likelihood="whittle", **kw)


def test_any_declared_exposure_fits_equally_with_k_scaled_by_b():
    y = _frames(0.3 * DT)
    a, b = _fit(y, 0.6 * DT), _fit(y, 1.0 * DT)
    assert a.extras["nll"] == pytest.approx(b.extras["nll"], rel=1e-9, abs=1e-6)
    tau = a.gamma / a.k
    assert b.gamma / b.k == pytest.approx(tau, rel=1e-5)
    assert b.k / a.k == pytest.approx(_b(DT / tau) / _b(0.6 * DT / tau), rel=1e-5)


def test_a_note_says_how_much_k_rests_on_the_exposure():
    """W declared as the frame interval (a common default) where the camera exposed 0.3 dt:
    k 14 % (3.6 SE) high with a perfect goodness of fit. The data cannot see it; the note
    says how strongly k rests on W."""
    res = _fit(_frames(0.3 * DT), DT)
    note = next(n for n in res.notes if "rest on the declared exposure" in n)
    a = DT / (res.gamma / res.k)
    want = (_b(1.1 * a) / _b(a) - 1.0) * 100
    assert f"gives k and gamma {want:.2g} % larger" in note


@pytest.mark.parametrize("case", ["short exposure", "eps2 held", "short record"])
def test_no_exposure_note_where_k_does_not_rest_on_it(case):
    if case == "short exposure":
        res = _fit(_frames(0.1 * DT), 0.1 * DT)
    elif case == "eps2 held":
        res = _fit(_frames(0.3 * DT), DT, fixed={"tracking_var": (4e-18, 0.0)})
    else:  # k's error larger than the shift
        res = _fit(_frames(0.3 * DT, n=4096), DT)
    assert not any("rest on the declared exposure" in n for n in res.notes)
