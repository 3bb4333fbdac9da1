"""One exposure with tracking noise free: the frames cannot tell W from eps^2.

The frame autocovariance is C(0) = kT/k S(a) + eps^2, C(m) = kT/k B(a) rho^m (a = W/tau,
paper eqs. 7-8), so any declared W fits equally well with k and gamma proportional to B(W/tau).
Frames from circulant embedding (tests/_circulant.py), not blurtrap's simulator."""

from __future__ import annotations

import math
import re

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


def _pd_frames(eps2, gamma=GAMMA, seed=5):
    """Point samples (an exposure of 0.001 dt) of a trap with relaxation time gamma/K."""
    return circulant_frames(K, gamma, 1e-3 * DT, DT, eps2, 65536, seed, temperature=TEMP)


def _pd_fit(y, w, detector="photodiode"):
    return bt.calibrate(bt.Recording(y, frame_interval=DT, exposure=w, temperature=TEMP),
                        likelihood="whittle", detector=detector)


def _eps2(res):
    i = res.param_names.index("tracking_var")
    return res.values[i], math.sqrt(res.covariance[i, i])


@pytest.mark.parametrize("eps2", [0.0, 25e-18])
def test_a_photodiode_declared_to_integrate_over_dt_names_the_point_sample_reading(eps2):
    """Point samples declared W = dt (an integrating ADC): eps^2 absorbs the missing blur and
    comes out tens of SE above its truth, with the same likelihood as the right W. The note
    gives the reading at the shortest exposure that fits: point samples (5 nm rms of real
    noise: eps^2 within 3 SE of the truth and of a fit declared with a short exposure, k to
    0.2 SE of it), or the exposure W' where eps^2 reaches 0 (no real noise: a fit declared
    with W' has eps^2 within 0.5 SE of 0 and k within 0.2 SE of the note's)."""
    y = _pd_frames(eps2, 0.75 * DT * K)  # tau = 0.75 dt
    res = _pd_fit(y, DT)
    value, se = _eps2(res)
    assert value - eps2 > 10 * se  # the confident wrong eps^2 the note is about
    note = next(n for n in res.notes if "rests on the photodiode integrating over the declared exposure" in n)
    got = re.search(r"point samples \(W -> 0\) with eps\^2 = ([-\d.e+]+) nm\^2 \(k = ([\d.e+-]+) pN/nm", note)
    if eps2 > 0:
        assert got, note
        eps2_point, k_point = float(got[1]) * 1e-18, float(got[2]) * 1e-3
        assert abs(eps2_point - eps2) < 3 * se
        short = _pd_fit(y, 1e-3 * DT)
        assert abs(k_point - short.k) < 0.2 * short.k_err
        assert abs(eps2_point - _eps2(short)[0]) < 0.1 * _eps2(short)[1]
    else:
        got = re.search(r"an exposure of ([\d.e+-]+) ms and no tracking noise \(k = ([\d.e+-]+) pN/nm", note)
        assert got, note
        at = _pd_fit(y, float(got[1]) * 1e-3)
        assert abs(float(got[2]) * 1e-3 - at.k) < 0.2 * at.k_err
        assert abs(_eps2(at)[0]) < 0.5 * se
        short = at
    assert not any("rests on the photodiode" in n for n in short.notes)


def test_the_point_sample_note_is_for_photodiodes():
    """A camera that integrates over W = dt is what the model says: no such note."""
    y = circulant_frames(K, 0.75 * DT * K, DT, DT, 4e-18, 65536, 5, temperature=TEMP)
    assert not any("rests on the photodiode" in n for n in _pd_fit(y, DT, detector="camera").notes)


def test_no_point_sample_note_for_an_integrating_photodiode_with_real_noise():
    """An ADC that integrates over W = dt, declared so, with 5 nm of tracking noise: point
    samples would leave most of the noise and k within 0.5 SE, so the declaration stands
    (a reviewer found the note on 10/10 such recordings)."""
    gamma = 8 * DT * K  # tau = 8 dt
    y = circulant_frames(K, gamma, DT, DT, 25e-18, 65536, 7, temperature=TEMP)
    res = _pd_fit(y, DT)
    assert not any("rests on the photodiode" in n for n in res.notes)
